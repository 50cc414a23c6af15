"""ViewTracking's ``distilled_optimum`` base (``continuum_gym.envs.view_tracking.distilled``), against independent
computation: the network in numpy from the shipped weights, the controller's fixed point, and the coverage the
dimension-reduced IK reaches on the same validation targets."""

from __future__ import annotations

import importlib
import math
import os

import numpy as np
import pytest

from continuum_gym.envs.view_tracking.env import ACTION_SCALE
from continuum_gym.robots import ContinuumEndoscope, DaVinciEndoscope

VIEW = "ContinuumGym/ViewTracking-v0"


@pytest.fixture(scope="module", autouse=True)
def registrations_stay_in_this_module():
    """Importing the module registers its controller, which records the module in CONTINUUM_GYM_PLUGINS for child
    processes: imported here, not at collection, and the variable restored after the module's tests, so that other
    tests' subprocesses (``--help`` must import nothing heavy) do not inherit it."""
    from continuum_gym.plugins import ENV_VAR

    before = os.environ.get(ENV_VAR)
    global distilled_view
    distilled_view = importlib.import_module("continuum_gym.envs.view_tracking.distilled")
    yield
    if before is None:
        os.environ.pop(ENV_VAR, None)
    else:
        os.environ[ENV_VAR] = before


distilled_view = None  # set by registrations_stay_in_this_module


def numpy_network(p, R):
    """The network's configuration (n, 6), computed with numpy from the npz and the documented encoding."""
    c = DaVinciEndoscope().configuration_of(p, R)
    x = np.stack([(c[:, 0] - 0.065) / 0.015, c[:, 1] / (math.pi / 3), c[:, 2] / (math.pi / 3),
                  c[:, 3] / (math.pi / 4)], axis=1)
    with np.load(distilled_view.WEIGHTS) as w:
        y = np.tanh(np.tanh(x @ w["W0"].T + w["b0"]) @ w["W1"].T + w["b1"]) @ w["W2"].T + w["b2"]
    q = np.stack([0.1 * y[:, 0], np.arctan2(y[:, 4], y[:, 3]), y[:, 1], np.arctan2(y[:, 6], y[:, 5]), y[:, 2],
                  np.arctan2(y[:, 8], y[:, 7])], axis=1)
    lower, upper = ContinuumEndoscope().joint_limits
    return np.clip(q, lower, upper)


def targets(n, seed):
    rng = np.random.default_rng(seed)
    q_dv = np.stack([rng.uniform(0.05, 0.08, n), rng.uniform(-1.0, 1.0, n), rng.uniform(-1.0, 1.0, n),
                     rng.uniform(-0.7, 0.7, n)], axis=1)
    return DaVinciEndoscope().target_pose(q_dv)


def test_controller_is_the_documented_network_and_law():
    p, R = targets(200, 0)
    expected = numpy_network(p, R)
    np.testing.assert_allclose(distilled_view.configurations(p, R), expected, atol=1e-9, rtol=0)
    params = distilled_view.pack(dict(np.load(distilled_view.WEIGHTS)), ascent=0.0)
    robot = ContinuumEndoscope().kernel_args()
    rng = np.random.default_rng(1)
    lower, upper = ContinuumEndoscope().joint_limits
    out = np.empty(6)
    for i in range(200):
        q = rng.uniform(np.where(np.isfinite(lower), lower, -4.0), np.where(np.isfinite(upper), upper, 4.0))
        error = expected[i] - q
        error[[3, 5]] = (error[[3, 5]] + np.pi) % (2 * np.pi) - np.pi
        cap = distilled_view.CAP * ACTION_SCALE
        distilled_view.distilled_rates(q, np.ascontiguousarray(p[i]), np.ascontiguousarray(R[i]), 0.01, robot,
                                       params, out)
        np.testing.assert_allclose(out, np.clip(distilled_view.GAIN * error, -cap, cap), atol=1e-8, rtol=0)


def overlap_after(q, rates, p, R):
    """The OR after one 0.01 s step at ``rates`` from q (clipped to the joint limits), computed apart."""
    from continuum_gym.evaluation.optimum.view import overlap_of_configuration
    from continuum_gym.geometry.frustum import Frustum

    frustum, endoscope = Frustum(), ContinuumEndoscope()
    lower, upper = endoscope.joint_limits
    q_next = np.ascontiguousarray(np.clip(q + 0.01 * rates, lower, upper))
    p_dv = p - DaVinciEndoscope().Le * R[:, 2]
    return overlap_of_configuration(q_next, p_dv, np.ascontiguousarray(R), endoscope.kernel_args(), frustum.tan_half,
                                    frustum.near, frustum.far)


def test_lookahead_only_adds_a_bounded_step_that_raises_the_overlap():
    """Near the network's configuration (OR >= 0.75) the lookahead's step never lowers the OR after the step,
    stays within ASCENT action units per joint, and raises the OR on most states; elsewhere it adds nothing."""
    p, R = targets(120, 2)
    goals = numpy_network(p, R)
    weights = dict(np.load(distilled_view.WEIGHTS))
    plain, ascent = distilled_view.pack(weights, ascent=0.0), distilled_view.pack(weights)
    rng = np.random.default_rng(3)
    a, b = np.empty(6), np.empty(6)
    raised = active = 0
    for i in range(120):
        q = goals[i] + rng.normal(0.0, 0.02, 6) * np.array([0.05, 1, 1, 1, 1, 1])
        q = np.clip(q, *ContinuumEndoscope().joint_limits)
        pi, Ri = np.ascontiguousarray(p[i]), np.ascontiguousarray(R[i])
        distilled_view.distilled_rates(q, pi, Ri, 0.01, ContinuumEndoscope().kernel_args(), plain, a)
        distilled_view.distilled_rates(q, pi, Ri, 0.01, ContinuumEndoscope().kernel_args(), ascent, b)
        here = overlap_after(q, np.zeros(6), p[i], R[i])
        if here < distilled_view.ASCENT_MIN_OR:
            np.testing.assert_array_equal(a, b)
            continue
        active += 1
        assert np.all(np.abs(b - a) <= distilled_view.ASCENT * ACTION_SCALE * (1 + 1e-12))
        before, after = overlap_after(q, a, p[i], R[i]), overlap_after(q, b, p[i], R[i])
        assert after >= before
        raised += after > before
    assert active >= 60 and raised >= 0.5 * active


@pytest.fixture(scope="module")
def base_runs():
    """Zero-residual episodes on validation pan_tilt ids 0-63, with the final joints: the packaged base, the
    same without its lookahead, and the dimension-reduced IK."""
    from continuum_gym.evaluation.rollout import ZeroResidual, make_core, run_episodes

    distilled_view.register(ascent=0.0, name="distilled_without_lookahead")
    out = {}
    for base in (distilled_view.REFERENCE, "distilled_without_lookahead", "dimension_reduced"):
        core = make_core(VIEW, 64, task="pan_tilt", task_split="validation", base_controller=base)
        metrics = run_episodes(core, ZeroResidual(core.single_action_space.shape[0]), np.arange(64))
        out[base] = (metrics, core.joint_values(), core)
    return out


def test_zero_residual_settles_on_the_network_configuration(base_runs):
    """A static target: without the lookahead the closed loop's fixed point is the network's configuration."""
    _, q_final, core = base_runs["distilled_without_lookahead"]
    dv = DaVinciEndoscope()
    q_dv = np.array([core.desired(row, 0.0)[0] for row in range(64)])
    expected = numpy_network(*dv.target_pose(q_dv))
    error = q_final - expected
    error[:, [3, 5]] = (error[:, [3, 5]] + np.pi) % (2 * np.pi) - np.pi
    straight = expected[:, [2, 4]] < 1e-6  # a straight segment's bend direction is free
    error[:, 3][straight[:, 0]] = 0.0
    error[:, 5][straight[:, 1]] = 0.0
    assert np.max(np.abs(error)) < 1e-6


def test_distilled_base_covers_more_than_the_dimension_reduced_ik(base_runs):
    """Final OR > 0.8 on the same 64 validation targets (measured on 1024: 88.5 % without the lookahead), and
    the lookahead ends higher on average."""
    final = {base: runs[0]["final_or"] for base, runs in base_runs.items()}
    plain = np.mean(final["distilled_without_lookahead"] > 0.8)
    assert plain >= 0.8
    assert plain > np.mean(final["dimension_reduced"] > 0.8)
    assert np.mean(final[distilled_view.REFERENCE] > 0.8) >= plain
    assert np.mean(final[distilled_view.REFERENCE]) > np.mean(final["distilled_without_lookahead"])


def test_a_fresh_process_finds_the_base_by_its_bare_name():
    """``ViewTrackingConfig.packaged_controllers``: the bare name imports the module that registers it."""
    import subprocess
    import sys

    code = ("import gymnasium as gym, numpy as np, continuum_gym\n"
            "env = gym.make('ContinuumGym/ViewTracking-v0', base_controller='distilled_optimum')\n"
            "env.reset(seed=0)\n"
            "print(repr(env.step(np.zeros(6))[4]['base_command'].tolist()))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    import gymnasium as gym

    env = gym.make(VIEW, base_controller=distilled_view.REFERENCE)
    env.reset(seed=0)
    here = env.step(np.zeros(6))[4]["base_command"]
    assert np.any(here != 0.0)
    assert out.stdout.strip().splitlines()[-1] == repr(here.tolist())
