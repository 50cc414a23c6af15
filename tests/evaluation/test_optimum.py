"""Offline optima (issue 8): the optimum beats every controller, the self-motion trace is exact, bad input fails."""

from __future__ import annotations

import argparse
import json
import math

import numpy as np
import pytest

from continuum_gym.baselines import DimensionReduced, OcclusionLimits, ResolvedRate
from continuum_gym.baselines.scenarios import (
    CASE_STUDY_START,
    coverage_grid,
    sample_hold_starts,
)
from continuum_gym.evaluation import optimum
from continuum_gym.evaluation.optimum import (
    OCCLUSION_ID,
    VIEW_TRACKING_ID,
    bounded_least_squares,
    circle_optimum,
    feasible_gamma_intervals,
    hold_optimum,
    projected_gradient_hold,
    resolve_tasks,
    trace_self_motion,
    view_tracking_optimum,
)
from continuum_gym.geometry import (
    LensCone,
    cone_coordinates,
    overlap_ratio,
    visual_occlusion_index,
)
from continuum_gym.robots import (
    ContinuumEndoscope,
    DaVinciEndoscope,
    MultiBackboneRobot,
)
from continuum_gym.robots.rotations import rotation_vector

ENDO = ContinuumEndoscope()
DAVINCI = DaVinciEndoscope()
ROBOT = MultiBackboneRobot()
LIMITS = OcclusionLimits()
UNLIMITED = None  # trace_self_motion without limits
BETA = LensCone().beta


def pose_errors(robot, q, q0):
    p, R = robot.forward_kinematics(q)
    p0, R0 = robot.forward_kinematics(q0)
    position = np.linalg.norm(p - p0, axis=-1)
    orientation = np.linalg.norm(rotation_vector(R0 @ np.swapaxes(R, -1, -2)), axis=-1)
    return position, orientation


def overlap_of(q, q_davinci):
    p_c, R_c = ENDO.forward_kinematics(q)
    p_d, R_d = DAVINCI.forward_kinematics(q_davinci)
    return overlap_ratio(p_d, R_d, p_c, R_c)


# ---------------------------------------------------------------------- view tracking
def test_view_optimum_beats_every_controller_on_small_grid():
    grid = coverage_grid(5)
    result = view_tracking_optimum(grid, effort="quick")
    lower, upper = ENDO.joint_limits
    q = result["q"]
    assert np.all(q >= lower - 1e-12) and np.all(q <= upper + 1e-12)
    assert np.allclose(overlap_of(q, grid), result["overlap"], atol=1e-12)
    start = np.broadcast_to(CASE_STUDY_START, (len(grid), 6))
    target = DAVINCI.target_pose(grid)
    for controller in (DimensionReduced(), ResolvedRate()):
        controller_or = overlap_of(controller.solve(start, target)["q"], grid)
        assert np.all(result["overlap"] >= controller_or), controller.name
    lsq_or = overlap_of(bounded_least_squares(*target), grid)
    assert np.all(result["overlap"] >= lsq_or - 1e-12)
    assert np.mean(result["overlap"]) > np.mean(lsq_or)
    assert set(result["references"]) == {"dimension_reduced", "resolved_rate", "bounded_least_squares"}
    assert result["roll_error"].shape == (25,)


def test_bounded_least_squares_within_limits_and_exact_when_reachable():
    rng = np.random.default_rng(3)
    lower, upper = ENDO.joint_limits
    q_true = CASE_STUDY_START + rng.normal(0.0, 0.05, (4, 6)) * np.array([0.02, 1, 1, 1, 1, 1])
    q_true[:, 0] = np.clip(q_true[:, 0], 0.005, 0.05)
    p_t, R_t = ENDO.target_pose(q_true)
    q = bounded_least_squares(p_t, R_t)
    assert q.shape == (4, 6)
    assert np.all(q >= lower) and np.all(q <= upper)
    p, R = ENDO.target_pose(q)
    assert np.max(np.linalg.norm(p - p_t, axis=-1)) < 1e-8
    # unreachable targets (the coverage grid's corners) stay within the limits too
    grid = coverage_grid(3)
    q = bounded_least_squares(*DAVINCI.target_pose(grid), q0=CASE_STUDY_START)
    assert np.all(q >= lower) and np.all(q <= upper)


# ---------------------------------------------------------------------- self-motion
def test_trace_keeps_the_tip_pose_and_stops_at_the_limits():
    arc = trace_self_motion(ROBOT, ROBOT.psi_a, LIMITS)
    assert not arc.closed and len(arc.q) > 50
    assert np.array_equal(arc.q[arc.start_index], ROBOT.psi_a)
    position, orientation = pose_errors(ROBOT, arc.q, ROBOT.psi_a)
    assert position.max() <= 1e-9 and orientation.max() <= 1e-9
    assert np.all(arc.q >= LIMITS.lower) and np.all(arc.q <= LIMITS.upper)
    assert all(end.startswith("limit:") for end in arc.ends)
    # each end lies on its limit (bisected there)
    for q_end in (arc.q[0], arc.q[-1]):
        margin = np.min(np.concatenate([q_end - LIMITS.lower, LIMITS.upper - q_end])[np.isfinite(
            np.concatenate([LIMITS.lower, LIMITS.upper]))])
        assert margin < 1e-6
    steps = np.linalg.norm(np.diff(arc.q, axis=0) / np.r_[np.ones(6), optimum.INSERTION_SCALE], axis=1)
    assert steps.max() < 1.5 * optimum.TRACE_STEP


def test_trace_closes_into_a_loop_without_limits():
    arc = trace_self_motion(ROBOT, ROBOT.psi_a, UNLIMITED)
    assert arc.closed and arc.ends == ("loop", "loop") and arc.start_index == 0
    position, orientation = pose_errors(ROBOT, arc.q, ROBOT.psi_a)
    assert position.max() <= 1e-9 and orientation.max() <= 1e-9
    gap = arc.q[-1] - arc.q[0]
    gap[[1, 3, 5]] = (gap[[1, 3, 5]] + math.pi) % (2 * math.pi) - math.pi
    gap[6] /= optimum.INSERTION_SCALE
    assert np.linalg.norm(gap) < optimum.TRACE_STEP
    # it really went round: far from the start in between
    assert np.max(np.abs(arc.q[:, 6] - ROBOT.psi_a[6])) > 0.01


# ---------------------------------------------------------------------- hold and circle
@pytest.fixture(scope="module")
def hold_cases():
    starts = sample_hold_starts(ROBOT, 3, np.random.default_rng(optimum.HOLD_STARTS_SEED))
    return starts, projected_gradient_hold(ROBOT, starts, LIMITS)


def test_hold_optimum_is_at_most_the_projected_gradient(hold_cases):
    starts, pg = hold_cases
    for k, q0 in enumerate(starts):
        result = hold_optimum(ROBOT, q0, LIMITS)
        # fair comparison: every trajectory point of the projected gradient within limits and visibility
        assert result["voi"] <= pg["best_visible_voi"][k] + 1e-12
        assert result["voi"] <= pg["final_voi"][k] + 1e-12
        q, gamma = result["q"], result["gamma"]
        assert np.all(q >= LIMITS.lower) and np.all(q <= LIMITS.upper)
        position, orientation = pose_errors(ROBOT, q, q0)
        assert position <= 1e-9 and orientation <= 1e-9
        tip, _ = ROBOT.forward_kinematics(q)
        assert cone_coordinates(tip, gamma)["angle"] <= 0.7 * BETA + 1e-9
        assert visual_occlusion_index(ROBOT, q, gamma) == pytest.approx(result["voi"], abs=1e-12)


def test_feasible_gamma_intervals_are_exact():
    tip, _ = ROBOT.forward_kinematics(ROBOT.psi_a)
    intervals = feasible_gamma_intervals(tip, 0.7)
    assert intervals
    for lo, hi in intervals:
        angles = cone_coordinates(tip, np.array([lo, hi, 0.5 * (lo + hi)]))["angle"]
        assert angles[:2] == pytest.approx([0.7 * BETA] * 2, abs=1e-9)
        assert angles[2] <= 0.7 * BETA


def test_circle_bound_holds_the_trajectory():
    result = circle_optimum(sample_dt=5.0)
    assert len(result["optimum_voi"]) == 2
    assert 0.0 <= result["optimum_mean_voi"] <= result["centring_gamma_mean_voi"] + 1e-12
    assert np.all(np.isfinite(result["optimum_voi"]))


# ---------------------------------------------------------------------- bad input and CLI
def test_bad_input_names_the_argument():
    with pytest.raises(ValueError, match="env"):
        resolve_tasks("ContinuumGym/Nope-v0")
    with pytest.raises(ValueError, match="task"):
        resolve_tasks(VIEW_TRACKING_ID, "juggling")
    with pytest.raises(ValueError, match="task 'hold'"):
        resolve_tasks(VIEW_TRACKING_ID, "hold")
    assert resolve_tasks(OCCLUSION_ID) == ("hold", "circle")
    assert sorted(resolve_tasks("all")) == ["circle", "coverage", "hold"]
    with pytest.raises(ValueError, match="grid"):
        optimum.coverage_optimum(grid=1)
    for visibility in (0.0, 1.5, -0.2):
        with pytest.raises(ValueError, match="visibility"):
            hold_optimum(ROBOT, ROBOT.psi_a, LIMITS, visibility=visibility)
    with pytest.raises(ValueError, match="q0"):
        trace_self_motion(ROBOT, ROBOT.psi_a + np.r_[np.zeros(6), 1.0], LIMITS)
    with pytest.raises(ValueError, match="effort"):
        view_tracking_optimum(coverage_grid(2), effort="lazy")
    with pytest.raises(ValueError, match="orientation_weight"):
        bounded_least_squares(np.zeros(3), np.eye(3), orientation_weight=0.0)


def _cli(argv):
    parser = argparse.ArgumentParser()
    optimum.add_arguments(parser)
    return optimum.run(parser.parse_args(argv))


def test_cli_rejects_bad_ids_and_writes_json_and_maps(tmp_path, capsys):
    assert _cli(["--env", "ContinuumGym/Nope-v0"]) != 0
    assert "ContinuumGym/ViewTracking-v0" in capsys.readouterr().err
    assert _cli(["--env", VIEW_TRACKING_ID, "--task", "circle"]) != 0
    assert _cli(["--env", VIEW_TRACKING_ID, "--grid", "1"]) != 0
    path = tmp_path / "optimum.json"
    assert _cli(["--env", VIEW_TRACKING_ID, "--grid", "2", "--global-check", "0", "--workers", "1",
                 "--json", str(path), "--out", str(tmp_path), "--no-progress"]) == 0
    data = json.loads(path.read_text())
    coverage = data["coverage"]
    assert coverage["grid"] == 2 and len(coverage["optimum_or"]) == 4
    for key in ("optimum_percent", "optimum_mean_or", "bounded_least_squares_percent", "unreachable_percent"):
        assert isinstance(coverage[key], float)
    assert "global_check" not in coverage
    assert coverage["optimum_percent"] + coverage["unreachable_percent"] == pytest.approx(100.0)
    assert (tmp_path / "optimum_coverage_maps.png").stat().st_size > 10_000


def test_shipped_cache_has_the_documented_keys():
    cache = optimum.load_optimum_cache()
    grid = optimum.cache_value(cache, "coverage.grid")
    assert isinstance(grid, int) and grid == 21
    assert len(cache["coverage"]["optimum_or"]) == grid * grid
    assert len(cache["coverage"]["bounded_least_squares_or"]) == grid * grid
    for key in ("coverage.optimum_percent", "coverage.optimum_mean_or", "coverage.bounded_least_squares_percent",
                "coverage.unreachable_percent", "circle.optimum_mean_voi"):
        assert isinstance(optimum.cache_value(cache, key), float), key
    hold = cache["hold"]
    assert hold["n_starts"] == len(hold["optimum_voi"]) == len(hold["starts"]) == optimum.HOLD_N_STARTS
    assert hold["starts_seed"] == optimum.HOLD_STARTS_SEED
    # the starts are the documented draw (the first ones suffice: the draw is sequential)
    first = sample_hold_starts(ROBOT, 3, np.random.default_rng(hold["starts_seed"]))
    assert np.allclose(np.array(hold["starts"])[:3], first, atol=1e-14)
    assert hold["fraction_optimum_le_projected_gradient"] == 1.0
    assert cache["coverage"]["optimum_percent"] >= cache["coverage"]["bounded_least_squares_percent"]
    with pytest.raises(KeyError):
        optimum.cache_value(cache, "coverage.nope")


# ---------------------------------------------------------------------- a registered variant's ceiling
VARIANT_ID = "MyTest/Occlusion4Seg-v0"


@pytest.fixture
def four_segment_variant(monkeypatch, tmp_path):
    """A registered 4-segment variant whose optimum computation is stubbed (the real one takes minutes): what the
    command does with the result is under test, not the optimum."""
    import gymnasium as gym

    from continuum_gym.evaluation import references

    gym.register(id=VARIANT_ID, entry_point="continuum_gym.envs.occlusion:OcclusionAvoidanceEnv",
                 kwargs={"robot": MultiBackboneRobot(lengths=(0.018,) * 4)})
    monkeypatch.setenv("CONTINUUM_GYM_CACHE", str(tmp_path / "cache"))
    computed = []

    def stub(spec, env_kwargs, episodes, grid, split, progress, workers):
        computed.append(env_kwargs)
        return {"hold_test": {"task_ids": list(range(episodes)), "optimum_voi": [0.05 + 0.01 * k for k in range(episodes)],
                              "optimum_mean_voi": 0.05 + 0.005 * (episodes - 1)}}

    monkeypatch.setattr(references, "_compute", stub)
    yield computed
    gym.registry.pop(VARIANT_ID)


def test_optimum_out_writes_a_variants_figure_and_says_so(four_segment_variant, tmp_path, capsys):
    out = tmp_path / "figures"
    assert _cli(["--env", VARIANT_ID, "--env-hold-tasks", "3", "--out", str(out), "--no-progress"]) == 0
    assert four_segment_variant and len(four_segment_variant[0]["robot"].lengths) == 4
    figure = out / "Occlusion4Seg_optimum_hold_test.png"
    assert figure.stat().st_size > 10_000
    assert f"wrote {figure}" in capsys.readouterr().out


def test_optimum_of_a_variant_without_a_known_optimum_says_why_and_fails(monkeypatch, tmp_path, capsys):
    import dataclasses

    from continuum_gym.envs.spec import ENV_SPECS

    spec = dataclasses.replace(ENV_SPECS[OCCLUSION_ID], env_id="MyTest/NoOptimum-v0")
    monkeypatch.setitem(ENV_SPECS, spec.env_id, spec)
    out, path = tmp_path / "figures", tmp_path / "optimum.json"
    assert _cli(["--env", spec.env_id, "--out", str(out), "--json", str(path), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "no known offline optimum" in err and "nothing written" in err and spec.env_id in err
    assert not out.exists() and not path.exists()
