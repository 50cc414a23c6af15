"""The rate-limited bound on a hold episode's VOI (evaluation/optimum/rate_bound.py), against closed forms,
brute force, the hold optimum and rollouts of the env that try hard to go below it."""

from pathlib import Path

import numpy as np
import pytest

import continuum_gym.agents
from continuum_gym.baselines import OcclusionLimits
from continuum_gym.envs.occlusion.tasks import hold_start_pool
from continuum_gym.envs.spec import get_spec
from continuum_gym.evaluation.methods import load_policy, policy_env_kwargs
from continuum_gym.evaluation.optimum import (
    GAMMA_RESOLUTION,
    arc_travel,
    env_hold_rate_bound,
    gamma_grid,
    hold_arc_plan,
    hold_optimum,
    hold_rate_bound,
    trace_self_motion,
)
from continuum_gym.evaluation.rollout import ZeroResidual, make_core, run_episodes
from continuum_gym.geometry import LensCone, cone_coordinates, occlusion_details
from continuum_gym.robots import MultiBackboneRobot

OCC = "ContinuumGym/OcclusionAvoidance-v0"
POLICY = (Path(continuum_gym.agents.__file__).parent / "policies" / "OcclusionAvoidance-v0"
          / "OcclusionAvoidance_ppo_arc_plan_seed0")


@pytest.fixture(scope="module")
def starts():
    lim = OcclusionLimits()
    return np.asarray(hold_start_pool("validation", float(lim.max_bend), tuple(lim.insertion)))[:4]


@pytest.mark.parametrize("closed", [False, True])
def test_arc_travel_matches_brute_force(closed):
    rng = np.random.default_rng(3)
    q = np.cumsum(rng.normal(size=(9, 3)), axis=0)
    travel = arc_travel(q, 4, closed)
    for i in range(9):
        lo, hi = sorted((4, i))
        direct = np.abs(np.diff(q[lo:hi + 1], axis=0)).sum(axis=0)
        if closed:  # the other way round: through the ends and the closing segment
            ring = np.concatenate([q[hi:], q[:lo + 1]])
            direct = np.minimum(direct, np.abs(np.diff(ring, axis=0)).sum(axis=0) + 0.0)
        np.testing.assert_allclose(travel[i], direct, atol=1e-12)


def test_bound_is_nonincreasing_and_ends_at_the_hold_optimum(starts):
    robot = MultiBackboneRobot()
    for q0 in starts[:2]:
        out = hold_rate_bound(robot, q0)
        bound = out["voi_bound"]
        assert bound.shape == (150,)
        assert np.all(np.diff(bound) <= 0)
        assert bound[-1] == pytest.approx(out["static_voi"])
        assert out["mean_voi_bound"] == pytest.approx(bound.mean())
        optimum = hold_optimum(robot, q0, OcclusionLimits())["voi"]  # refined search: at or just below the grid's
        assert optimum - 1e-9 <= out["static_voi"] <= optimum + 3e-3
        assert out["start_voi"] == pytest.approx(float(occlusion_details(robot, q0, 0.0)["voi"]))
        # the start itself is reachable at once, so the first step is never above the start's VOI
        assert bound[0] <= out["start_voi"] + 1e-12
        assert out["mean_voi_bound"] > out["static_voi"] + 1e-3  # travel costs something at the paper's rates


def test_bound_closed_forms_at_extreme_rates(starts):
    robot, q0 = MultiBackboneRobot(), starts[0]
    fast = OcclusionLimits(bend_rate=100, plane_rate=100, insertion_rate=1.0, gamma_rate=100)
    out = hold_rate_bound(robot, q0, fast, dt=0.1, steps=5)  # everything reachable in the first step
    np.testing.assert_array_equal(out["voi_bound"], np.full(5, out["static_voi"]))
    assert out["steps_to_static"] == 1
    slow = OcclusionLimits(bend_rate=1e-9, plane_rate=1e-9, insertion_rate=1e-9, gamma_rate=1e-9)
    out = hold_rate_bound(robot, q0, slow, steps=3)
    # nothing moves: only the start's cell, counted one sample wide (its arc neighbours x gamma 0, +-resolution)
    arc = trace_self_motion(robot, q0, slow)
    near = arc.q[arc.start_index - 1:arc.start_index + 2]
    res = GAMMA_RESOLUTION
    brute = occlusion_details(robot, near[:, None, :], np.array([-res, 0.0, res])[None, :])["voi"].min()
    np.testing.assert_allclose(out["voi_bound"], brute, rtol=1e-12)
    assert brute <= out["start_voi"] < brute + 5e-3


def test_env_rollouts_never_go_below_the_bound(starts):
    """The projected gradient and the shipped residual (trained to lower VOI) on the env's validation hold tasks."""
    spec = get_spec(OCC)
    bound = env_hold_rate_bound(4, "validation", workers=1, progress=False)
    assert len(bound["voi_bound"]) == 4 and bound["steps"] == 150
    model, config = load_policy(POLICY)
    # The bound holds the tip pose exactly. The projected gradient holds it closely; the residual lets the tip
    # drift by up to ~0.25 mm in its first fast steps, which buys it up to ~2e-3 VOI below the bound there.
    for policy, kwargs, margin in ((None, {}, 1e-4), (model, policy_env_kwargs(spec, config), 2.5e-3)):
        core = make_core(OCC, 4, **dict(kwargs, task="hold", task_split="validation"))
        core.reset_rows(np.arange(4), np.arange(4))
        np.testing.assert_allclose(core.q, starts)  # the bound's starts are the env's
        out = run_episodes(core, policy or ZeroResidual(core.single_action_space.shape[0]), np.arange(4),
                           record=True)
        trace = out["trace_voi"]
        assert trace.shape == (150, 4)
        assert np.all(trace.T >= np.asarray(bound["voi_bound"]) - margin)
        assert np.all(out["mean_voi"] >= np.asarray(bound["mean_voi_bound"]))


@pytest.mark.parametrize("kwargs, match", [
    ({"dt": 0.5}, r"dt must be in \(0, 0.1\]"), ({"dt": -1.0}, "dt"), ({"steps": 0}, "steps"),
    ({"gamma_resolution": 1.0}, r"gamma_resolution must be in \(0, 0.1\]"), ({"visibility": 1.5}, "visibility"),
])
def test_bad_input_names_the_parameter(starts, kwargs, match):
    with pytest.raises(ValueError, match=match):
        hold_rate_bound(MultiBackboneRobot(), starts[0], **kwargs)


def test_needs_a_seven_dof_robot():
    with pytest.raises(ValueError, match="robot: hold_rate_bound needs a 7-DoF robot"):
        hold_rate_bound(MultiBackboneRobot(lengths=(0.026, 0.020)), np.zeros(5))


def test_optimum_cli_reports_the_bound_of_the_env_hold_tasks(tmp_path, capsys):
    import argparse
    import json

    from continuum_gym.evaluation import optimum

    parser = argparse.ArgumentParser()
    optimum.add_arguments(parser)
    args = parser.parse_args(["--env", "ContinuumGym/OcclusionAvoidance-v0", "--task", "hold", "--n-starts", "1",
                              "--env-hold-tasks", "2", "--workers", "1", "--no-progress",
                              "--json", str(tmp_path / "o.json")])
    assert optimum.run(args) == 0
    out = json.loads((tmp_path / "o.json").read_text())
    bound = out["hold_test_rate_bound"]
    lim = OcclusionLimits()
    test_starts = np.asarray(hold_start_pool("test", float(lim.max_bend), tuple(lim.insertion)))[:2]
    direct = [hold_rate_bound(MultiBackboneRobot(), q0)["mean_voi_bound"] for q0 in test_starts]
    np.testing.assert_allclose(bound["mean_voi_bound"], direct, rtol=1e-12)
    # the bound on the episode mean lies above the configuration optimum of the same tasks, the plan above it
    assert np.all(np.asarray(bound["mean_voi_bound"]) > np.asarray(out["hold_test"]["optimum_voi"]))
    assert np.all(np.asarray(bound["mean_voi_plan"]) >= np.asarray(bound["mean_voi_bound"]))
    assert f"{np.mean(direct):.3f}" in capsys.readouterr().out


def test_planned_trajectory_is_feasible_and_lies_above_the_bound(starts):
    """The plan is a real trajectory (tip held, every rate within its limit, tip in view) and never beats the bound."""
    robot, lim, cone = MultiBackboneRobot(), OcclusionLimits(), LensCone()
    rates = np.asarray(lim.rate_limit)[:7]
    for q0 in starts[:2]:
        plan, bound = hold_arc_plan(robot, q0), hold_rate_bound(robot, q0)
        q = np.vstack([q0, plan["q_plan"]])
        gamma = np.r_[0.0, plan["gamma_plan"]]
        assert np.all(np.abs(np.diff(q, axis=0)) <= rates * 0.01 + 1e-12)
        assert np.all(np.abs(np.diff(gamma)) <= lim.gamma_rate * 0.01 + 1e-12)
        p0, R0 = robot.forward_kinematics(q0)
        p, R = robot.forward_kinematics(plan["q_plan"])
        assert np.abs(p - p0).max() < 1e-9 and np.abs(R - R0).max() < 1e-9
        assert np.all(cone_coordinates(p0, plan["gamma_plan"], cone)["angle"] <= 0.7 * cone.beta + 1e-12)
        direct = occlusion_details(robot, plan["q_plan"], plan["gamma_plan"], cone)["voi"]
        np.testing.assert_allclose(plan["voi_plan"], direct, rtol=1e-12)
        assert plan["mean_voi_plan"] == pytest.approx(direct.mean())
        assert np.all(plan["voi_plan"] >= bound["voi_bound"] - 1e-12)
        assert plan["target_voi"] >= bound["static_voi"] - 1e-12


def test_plan_meets_the_bound_when_rates_are_unlimited(starts):
    robot, q0 = MultiBackboneRobot(), starts[0]
    fast = OcclusionLimits(bend_rate=100, plane_rate=100, insertion_rate=1.0, gamma_rate=100)
    plan = hold_arc_plan(robot, q0, fast, dt=0.1, steps=4)
    bound = hold_rate_bound(robot, q0, fast, dt=0.1, steps=4)
    np.testing.assert_allclose(plan["voi_plan"], bound["static_voi"], rtol=1e-12)


def test_gamma_grid_passes_through_the_start():
    grid = gamma_grid(0.3, GAMMA_RESOLUTION)
    assert 0.3 in grid and np.allclose(np.diff(grid), GAMMA_RESOLUTION)
    assert grid[0] >= 0.3 - np.pi - 1e-12 and grid[-1] <= 0.3 + np.pi + 1e-12


def test_the_shipped_cache_holds_the_bound_and_plan_of_the_test_hold_tasks():
    from continuum_gym.evaluation.optimum import load_optimum_cache

    cache = load_optimum_cache()
    entry, optimum = cache["hold_test_rate_bound"], np.asarray(cache["hold_test"]["optimum_voi"])
    assert len(entry["mean_voi_bound"]) == len(optimum) == 32 and entry["split"] == "test"
    bound, plan = np.asarray(entry["mean_voi_bound"]), np.asarray(entry["mean_voi_plan"])
    assert np.all(optimum <= bound) and np.all(bound <= plan)
    lim = OcclusionLimits()
    first = np.asarray(hold_start_pool("test", float(lim.max_bend), tuple(lim.insertion)))[:2]
    robot = MultiBackboneRobot()
    np.testing.assert_allclose(bound[:2], [hold_rate_bound(robot, q0)["mean_voi_bound"] for q0 in first], rtol=1e-12)
    np.testing.assert_allclose(plan[:2], [hold_arc_plan(robot, q0)["mean_voi_plan"] for q0 in first], rtol=1e-12)


def test_evaluate_adds_the_bound_and_plan_rows_for_a_variant(tmp_path, monkeypatch):
    """A 3-segment variant (its own arc): evaluate computes its bound and plan once, per validation hold task."""
    from continuum_gym.envs.occlusion.config import OcclusionConfig
    from continuum_gym.evaluation.evaluate import evaluate_policy

    monkeypatch.setenv("CONTINUUM_GYM_CACHE", str(tmp_path))
    robot = MultiBackboneRobot(lengths=(0.028, 0.020, 0.017))
    table = evaluate_policy(lambda obs: np.zeros((obs.shape[0], 8)), OCC, env_kwargs={"robot": robot}, episodes=2,
                            split="validation", progress=False)
    optimum, bound, plan = (table[row]["mean_voi"] for row in ("offline_optimum", "rate_limited_bound",
                                                               "planned_trajectory"))
    assert bound["n_tasks"] == plan["n_tasks"] == 2
    assert optimum["mean"] <= bound["mean"] <= plan["mean"]
    config = OcclusionConfig(robot=robot)
    lim = config.limits
    starts = np.asarray(hold_start_pool("validation", float(lim.max_bend), tuple(lim.insertion), robot, config.cone))
    direct = [hold_rate_bound(robot, q0, lim, cone=config.cone)["mean_voi_bound"] for q0 in starts[:2]]
    assert bound["mean"] == pytest.approx(np.mean(direct), rel=1e-12)
