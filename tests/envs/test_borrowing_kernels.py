"""Kernels compiled without reference counting (``kernel(borrows=True)``) free everything they allocate.

A borrowing kernel has no reference counts; should it call a kernel that returns a new array, nothing
would free that array. numba counts every allocation and free of its runtime when ``NUMBA_NRT_STATS=1``:
each child process below steps envs through every code path of the step kernels (every base controller,
both residual spaces, the visibility guard, an allocating registered controller and a compiled reward
term, resets) and reports the counts over the steps after a warm-up. The first case is a toy leak, so
the check is shown to catch one.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

CHILD = textwrap.dedent('''
    import json, sys
    import numpy as np
    from numba import njit
    from numba.core.runtime import rtsys

    def counts():
        stats = rtsys.get_allocation_stats()
        return np.array([stats.alloc, stats.free, stats.mi_alloc, stats.mi_free])

    case = sys.argv[1]
    if case == "toy_leak":
        from continuum_gym.robots.compiled import kernel

        @njit(_nrt=True)
        def fresh(n):
            return np.ones(n)

        @kernel(borrows=True)
        def drops_a_new_array(out):
            out[0] = fresh(3)[0]

        out = np.zeros(1)
        drops_a_new_array(out)
        before = counts()
        for _ in range(20):
            drops_a_new_array(out)
        print(json.dumps((counts() - before).tolist()))
        sys.exit()

    import gymnasium as gym
    import continuum_gym
    from continuum_gym.envs.occlusion.outputs import Metric
    from continuum_gym.registry import register_controller, register_reward_term
    from continuum_gym.robots.mbcr_kernels import make_workspace, tip_kernel

    @njit
    def allocating_tracker(q, gamma, p_des, R_des, v_des, dt, robot, cone, params, out):
        ws = make_workspace(robot.lengths.shape[0])
        p, R, J = np.empty(3), np.empty((3, 3)), np.empty((6, q.shape[0]))
        tip_kernel(q, robot, ws, p, R, J)
        Jv = J[:3]
        rates = Jv.T @ np.linalg.solve(Jv @ Jv.T + 1e-6 * np.eye(3), params[0] * (p_des - p) + v_des)
        for k in range(q.shape[0]):
            out[k] = rates[k]
        out[q.shape[0]] = 0.0

    @njit
    def tip_error_mm(metrics, flags, action, params):
        return -1e3 * metrics[Metric.TIP_ERROR]

    env_id, kwargs = sys.argv[1], json.loads(sys.argv[2])
    if kwargs.get("base_controller") == "allocating_tracker":
        register_controller("allocating_tracker", allocating_tracker, params=np.array([40.0]))
        register_reward_term("tip_error_mm", tip_error_mm, weight=0.5)
    rng = np.random.default_rng(0)
    venv = gym.make_vec(env_id, num_envs=6, vectorization_mode="vector_entry_point", **kwargs)
    single = gym.make(env_id, **kwargs)
    venv.reset(seed=0)
    single.reset(seed=0)

    def steps(n):
        for _ in range(n):
            venv.step(rng.uniform(-1, 1, venv.action_space.shape))
            single.step(rng.uniform(-1, 1, single.action_space.shape))
        venv.reset(seed=1)
        single.reset(seed=1)

    steps(3)
    before = counts()
    steps(40)
    print(json.dumps((counts() - before).tolist()))
''')

OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"
CASES = [
    (OCCLUSION, {}),
    (OCCLUSION, {"base_controller": "minimum_norm", "residual_space": "joint", "visibility_guard": None}),
    (OCCLUSION, {"base_controller": None, "task": "random"}),
    (OCCLUSION, {"base_controller": "allocating_tracker"}),
    (VIEW, {}),
    (VIEW, {"base_controller": "resolved_rate"}),
    (VIEW, {"residual_space": "target", "observe_target": True}),
    (VIEW, {"base_controller": None}),
    # the model-error steps (issue 37): their own kernels, a registered controller's slot included
    (OCCLUSION, {"base_controller": "allocating_tracker", "model_error": "severe"}),
    (VIEW, {"residual_space": "target", "model_error": "severe", "randomize_model_error": True}),
]


def allocation_counts(tmp_path, *args: str) -> list:
    script = tmp_path / "child.py"  # a file, not -c: numba caches only kernels with a source file
    script.write_text(CHILD)
    environ = dict(os.environ, NUMBA_NRT_STATS="1", NUMBA_CACHE_DIR=str(tmp_path / "numba-cache"))
    out = subprocess.run([sys.executable, str(script), *args], env=environ, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_the_allocation_count_catches_a_borrowing_kernel_that_drops_a_new_array(tmp_path):
    alloc, free, mi_alloc, mi_free = allocation_counts(tmp_path, "toy_leak")
    assert alloc == 20 and free == 0
    assert mi_alloc == 20 and mi_free == 0


@pytest.mark.parametrize("env_id, kwargs", CASES, ids=[f"{e.split('/')[1]}-{k}" for e, k in CASES])
def test_every_step_path_frees_what_it_allocates(tmp_path, env_id, kwargs):
    alloc, free, mi_alloc, mi_free = allocation_counts(tmp_path, env_id, json.dumps(kwargs))
    assert alloc > 0  # every step call allocates its work arrays: the counts are live
    assert (alloc, mi_alloc) == (free, mi_free)
