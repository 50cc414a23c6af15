"""Paper-001 controllers: convergence, limits, freezing, case studies, coverage, batching, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from continuum_gym.baselines import DimensionReduced, ResolvedRate, make_controller
from continuum_gym.baselines.scenarios import (
    CASE_STUDIES,
    CASE_STUDY_START,
    coverage_grid,
)
from continuum_gym.baselines.view_tracking import integrate_view_step
from continuum_gym.geometry.overlap import overlap_ratio
from continuum_gym.robots import ContinuumEndoscope, DaVinciEndoscope

ENDO = ContinuumEndoscope()
DAVINCI = DaVinciEndoscope()
LOWER, UPPER = ENDO.joint_limits


def overlap_of(q, q_davinci):
    p_c, R_c = ENDO.forward_kinematics(q)
    p_d, R_d = DAVINCI.forward_kinematics(q_davinci)
    return overlap_ratio(p_d, R_d, p_c, R_c)


def reachable_targets(n, seed):
    rng = np.random.default_rng(seed)
    q = rng.uniform([0.01, -2.5, 0.1, -np.pi, 0.1, -np.pi], [0.08, 2.5, 0.7, np.pi, 1.4, np.pi], (n, 6))
    return q, ENDO.target_pose(q)


def test_dimension_reduced_reaches_reachable_targets():
    _, target = reachable_targets(20, 0)
    start = np.broadcast_to(CASE_STUDY_START, (20, 6))
    result = DimensionReduced().solve(start, target)
    _, info = DimensionReduced().joint_rates_with_info(result["q"], target)
    # Position has priority: it converges (paper-notes §2.6: 1e-3 mm) wherever the run did not stall on a limit.
    assert np.median(info["position_error_m"]) < 1e-6
    assert np.mean(info["position_error_m"] < 1e-5) >= 0.8


@pytest.mark.parametrize("controller", [ResolvedRate(), DimensionReduced()])
def test_controllers_never_leave_the_joint_limits(controller):
    grid = coverage_grid(7)
    result = controller.solve(np.broadcast_to(CASE_STUDY_START, (len(grid), 6)), DAVINCI.target_pose(grid),
                              max_steps=300, record=True)
    history = result["history"]
    assert np.all(history >= LOWER - 1e-15) and np.all(history <= UPPER + 1e-15)
    assert np.all(np.abs(history[..., [3, 5]]) <= np.pi)


def test_frozen_joints_do_not_move():
    # theta1 at its upper limit, asked to bend further: DR freezes it and the step leaves it where it is.
    q = CASE_STUDY_START.copy()
    q[2] = UPPER[2]
    target = DAVINCI.target_pose(CASE_STUDIES["case2"])
    controller = DimensionReduced()
    rates, info = controller.joint_rates_with_info(q, target)
    assert info["frozen"][2] and rates[2] == 0.0
    q_next = np.empty(6)
    integrate_view_step(q, rates, 0.01, LOWER, UPPER, q_next)
    assert q_next[2] == q[2]
    # Freezing removes the column: the active rates differ from a solve that ignores the limit.
    unlimited = DimensionReduced(lower=np.full(6, -np.inf), upper=np.full(6, np.inf))
    assert not np.allclose(unlimited.joint_rates(q, target), rates)


def test_case_studies_match_the_papers_narrative():
    results = {}
    for case, q_davinci in CASE_STUDIES.items():
        target = DAVINCI.target_pose(q_davinci)
        for controller in (ResolvedRate(), DimensionReduced()):
            q = controller.solve(CASE_STUDY_START, target)["q"]
            _, info = controller.joint_rates_with_info(q, target)
            results[case, controller.name] = (q, float(overlap_of(q, q_davinci)), float(info["position_error_m"]))
    for case in CASE_STUDIES:
        assert results[case, "dimension_reduced"][1] > results[case, "resolved_rate"][1]
        assert results[case, "dimension_reduced"][2] < 1e-5  # position converges (priority)
        assert results[case, "resolved_rate"][2] > 1e-2  # RMRC's errors do not converge
    q_rmrc_case1 = results["case1", "resolved_rate"][0]
    np.testing.assert_allclose(q_rmrc_case1[[0, 2, 4]], UPPER[[0, 2, 4]])  # L0, theta1, theta2 stuck at limits
    assert results["case2", "dimension_reduced"][0][2] == pytest.approx(UPPER[2], abs=2e-3)  # theta1 at its limit


def test_quick_coverage_dimension_reduced_beats_resolved_rate():
    grid = coverage_grid(11)
    target = DAVINCI.target_pose(grid)
    start = np.broadcast_to(CASE_STUDY_START, (len(grid), 6))
    coverage = {}
    for controller in (ResolvedRate(), DimensionReduced()):
        q = controller.solve(start, target)["q"]
        coverage[controller.name] = np.mean(overlap_of(q, grid) > 0.8) * 100
    assert coverage["dimension_reduced"] >= 1.5 * coverage["resolved_rate"]
    assert 40 <= coverage["dimension_reduced"] <= 75


def test_batched_equals_looped_and_predict():
    q, target = reachable_targets(6, 1)
    q = q.reshape(2, 3, 6)
    target = (target[0].reshape(2, 3, 3)[::-1], target[1].reshape(2, 3, 3, 3)[::-1])
    for controller in (ResolvedRate(), DimensionReduced()):
        batch = controller.joint_rates(q, target)
        for idx in np.ndindex(2, 3):
            assert np.array_equal(batch[idx], controller.joint_rates(q[idx], (target[0][idx], target[1][idx])))
        action, state = controller.predict({"q": q, "p_target": target[0], "R_target": target[1].reshape(2, 3, 9)})
        assert state is None and np.array_equal(action, batch)
        solved = controller.solve(q, target, max_steps=50)["q"]
        for idx in np.ndindex(2, 3):
            one = controller.solve(q[idx], (target[0][idx], target[1][idx]), max_steps=50)["q"]
            assert np.array_equal(solved[idx], one)


def test_registry_and_bad_input():
    assert isinstance(make_controller("dimension_reduced"), DimensionReduced)
    assert make_controller("projected_gradient", eta1=10.0).eta1 == 10.0
    with pytest.raises(ValueError, match="dimension_reduced.*minimum_norm.*projected_gradient.*resolved_rate"):
        make_controller("dls")
    target = DAVINCI.target_pose(CASE_STUDIES["case1"])
    controller = DimensionReduced()
    with pytest.raises(ValueError, match="q"):
        controller.joint_rates(np.zeros(5), target)
    with pytest.raises(ValueError, match="finite"):
        controller.joint_rates(np.full(6, np.nan), target)
    with pytest.raises(ValueError, match="target"):
        controller.joint_rates(CASE_STUDY_START, target[0])
    with pytest.raises(ValueError, match="R_target"):
        controller.joint_rates(CASE_STUDY_START, (target[0], np.eye(2)))
    with pytest.raises(ValueError, match="max_steps"):
        controller.solve(CASE_STUDY_START, target, max_steps=0)
    with pytest.raises(ValueError, match="v_lim"):
        DimensionReduced(v_lim=-1)
    with pytest.raises(ValueError, match="observation"):
        controller.predict(np.zeros(10))
