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

    env_id, cases = sys.argv[1], json.loads(sys.argv[2])
    if env_id.endswith("OcclusionAvoidance-v0"):
        register_controller("allocating_tracker", allocating_tracker, params=np.array([40.0]))
    results = []
    for kwargs in cases:  # one process, one compile of the env's step kernel: every case a path through it
        rng = np.random.default_rng(0)
        terms = kwargs.pop("reward_term", False)
        if terms:
            register_reward_term("tip_error_mm", tip_error_mm, weight=0.5)
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
        results.append((counts() - before).tolist())
    print(json.dumps(results))
''')

OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"
#: Per env, the paths through its step kernel (one kernel per env since issue 55: nominal and model error, every
#: base, both residual spaces, the guard, a registered controller's slot and a compiled reward term), run in one
#: child process so that the kernel compiles once; a registered reward term stays registered for the cases after.
CASES = {
    OCCLUSION: [
        {},
        {"base_controller": "minimum_norm", "residual_space": "joint", "visibility_guard": None},
        {"base_controller": None, "task": "random"},
        {"base_controller": "allocating_tracker", "reward_term": True},
        {"base_controller": "allocating_tracker", "model_error": "severe"},
    ],
    VIEW: [
        {},
        {"base_controller": "resolved_rate"},
        {"residual_space": "target", "observe_target": True},
        {"base_controller": None},
        {"residual_space": "target", "model_error": "severe", "randomize_model_error": True},
    ],
}


def allocation_counts(tmp_path, *args: str) -> list:
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    # The counts are the runtime's (NRT_STATS switches its counters on at start-up, not the compiled code), so the
    # package's kernels load from the same cache as everywhere else (precompiled, or compiled by an earlier test)
    # instead of compiling every step path again; the child's own kernels are not cached (no cache=True).
    environ = dict(os.environ, NUMBA_NRT_STATS="1")
    out = subprocess.run([sys.executable, str(script), *args], env=environ, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])  # per case; the toy case: its one count


def test_the_allocation_count_catches_a_borrowing_kernel_that_drops_a_new_array(tmp_path):
    alloc, free, mi_alloc, mi_free = allocation_counts(tmp_path, "toy_leak")
    assert alloc == 20 and free == 0
    assert mi_alloc == 20 and mi_free == 0


@pytest.mark.parametrize("env_id", list(CASES), ids=[e.split("/")[1] for e in CASES])
def test_every_step_path_frees_what_it_allocates(tmp_path, env_id):
    counts = allocation_counts(tmp_path, env_id, json.dumps(CASES[env_id]))
    assert len(counts) == len(CASES[env_id])
    for kwargs, (alloc, free, mi_alloc, mi_free) in zip(CASES[env_id], counts, strict=True):
        assert alloc > 0, kwargs  # every step call allocates its work arrays: the counts are live
        assert (alloc, mi_alloc) == (free, mi_free), kwargs
