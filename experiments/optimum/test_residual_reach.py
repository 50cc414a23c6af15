"""Hold effort and the holdable optimum: what a joint-rate residual of a given scale can reach and hold.

Not part of the package's suite (``make test`` runs ``tests/``): ``pytest experiments/optimum`` from the repository's
root (pytest puts this directory on the path, so ``residual_reach`` imports as the campaign scripts import it).
"""

from __future__ import annotations

import math

import numpy as np
from residual_reach import hold_effort, holdable_optimum

from continuum_gym.baselines.scenarios import coverage_grid
from continuum_gym.envs.view_tracking import ACTION_SCALE, ViewTrackingCore
from continuum_gym.evaluation.optimum import view_tracking_optimum

GRID = coverage_grid(21)


def _core(q_davinci, scale):
    """A coverage-task core whose rows are the given grid points (task id = grid index)."""
    ids = np.array([int(np.flatnonzero(np.all(GRID == row, axis=1))[0]) for row in q_davinci])
    core = ViewTrackingCore(num_envs=len(ids), task="coverage", task_split="test", residual_scale=scale)
    core.reset_rows(np.arange(len(ids)), ids)
    return core


def _hold(core, q_goal, seconds=10.0, gain=10.0):
    """Drive each row towards q_goal with the proportional residual that cancels the baseline; final q."""
    active = np.ones(core.num_envs, dtype=np.uint8)
    for _ in range(int(round(seconds / core.control_dt))):
        dq = q_goal - core.q
        dq[:, [3, 5]] = (dq[:, [3, 5]] + math.pi) % (2 * math.pi) - math.pi
        action = np.clip((gain * dq - core.base_cmd) / (core.residual_scale * ACTION_SCALE), -1, 1)
        core.step(np.ascontiguousarray(action), active)
    return core.q.copy()


def _distance(a, b):
    d = a - b
    d[:, [3, 5]] = (d[:, [3, 5]] + math.pi) % (2 * math.pi) - math.pi
    return np.max(np.abs(d), axis=1)


def test_hold_effort_is_the_action_that_cancels_the_envs_baseline_command():
    q_davinci = GRID[[3, 200, 400]]
    core = _core(q_davinci, 2.0)
    core.q[:] = np.random.default_rng(1).uniform([0, -1, 0, -3, 0, -3], [0.1, 1, 0.7, 3, 1.5, 3], (3, 6))
    core.observe_rows(np.arange(core.num_envs))
    expected = np.max(np.abs(core.base_cmd) / (2.0 * ACTION_SCALE), axis=1)
    np.testing.assert_allclose(hold_effort(core.q, q_davinci, 2.0), expected, rtol=1e-12)


def test_holdable_configurations_are_held_and_the_others_are_not():
    q_davinci = GRID[[180, 201, 222]]  # points whose optimum dimension-reduced IK pulls hard away from
    optimum = view_tracking_optimum(q_davinci, effort="quick", workers=1, baselines=False)
    efforts = hold_effort(optimum["q"], q_davinci, 1.0)
    assert np.all(efforts > 1.0), "these optima are beyond a residual of scale 1"
    q_hold, overlaps, hold_efforts = holdable_optimum(optimum["q"], q_davinci, 1.0)
    moved = _distance(q_hold, optimum["q"]) > 0
    assert moved.any() and np.all(hold_efforts[moved] <= 1.0)
    # The env confirms it: the holdable configurations are reached and held, the raw optima are not.
    held = _hold(_core(q_davinci, 1.0), q_hold)
    assert np.all(_distance(held, q_hold)[moved] < 1e-6)
    lost = _hold(_core(q_davinci, 1.0), optimum["q"])
    assert np.all(_distance(lost, optimum["q"]) > 1e-3)
    assert np.all(overlaps[moved] > 0.5)


def test_holdable_optimum_leaves_holdable_configurations_alone():
    q_davinci = GRID[[50, 220]]
    optimum = view_tracking_optimum(q_davinci, effort="quick", workers=1, baselines=False)
    efforts = hold_effort(optimum["q"], q_davinci, 6.0)
    assert np.all(efforts <= 1.0)
    q_hold, overlaps, _ = holdable_optimum(optimum["q"], q_davinci, 6.0)
    np.testing.assert_array_equal(q_hold, optimum["q"])
    np.testing.assert_allclose(overlaps, optimum["overlap"], atol=1e-12)
