"""OcclusionAvoidance's base ``arc_plan``: on hold tasks the projected gradient tracks ``hold_arc_plan``'s trajectory (computed here
independently, in the kinematics alone), other tasks are untouched to the bit, the policy pays only for its own
action, and bad values are rejected by name."""

from __future__ import annotations

import numpy as np
import pytest

from continuum_gym.baselines.arc_plan import hold_arc_plan
from continuum_gym.envs.columns import at
from continuum_gym.envs.occlusion.config import OcclusionConfig
from continuum_gym.envs.occlusion.env import OcclusionCore
from continuum_gym.envs.occlusion.outputs import OBS, Metric

GUARD = 0.69
KW = dict(task_split="validation", residual_scale=2.0, visibility_guard=GUARD)
IDS = np.arange(3)


def _run(core: OcclusionCore, ids: np.ndarray, actions=None, steps: int | None = None):
    core.reset_rows(np.arange(len(ids)), ids)
    active = np.ones(len(ids), dtype=np.uint8)
    zero = np.zeros((len(ids), core.dof + 1))
    voi, terms = [], []
    for k in range(steps or int(core.tasks.duration[0])):
        core.step(zero if actions is None else actions(k), active)
        voi.append(core.metrics[:, Metric.VOI].copy())
        terms.append(core.terms.copy())
    return np.array(voi), np.array(terms)


@pytest.fixture(scope="module")
def planned_hold():
    core = OcclusionCore(len(IDS), task="hold", base_controller="arc_plan", **KW)
    core.reset_rows(np.arange(len(IDS)), IDS)
    starts = core.q.copy()
    plans = [hold_arc_plan(core.robot, q0, core.limits, visibility=GUARD, cone=core.cone,
                           steps=int(core.tasks.duration[0])) for q0 in starts]
    return core, plans


def test_zero_action_executes_the_plan(planned_hold):
    core, plans = planned_hold
    first = at(OBS.base_command, core.robot.n_segments)
    width = core.dof + 1
    # the observation's base block at reset is the plan's first step, from the start
    expected = np.stack([np.append(p["q_plan"][0], p["gamma_plan"][0]) for p in plans])
    expected = expected - np.concatenate([core.q, core.gamma[:, None]], axis=1)
    np.testing.assert_allclose(core.obs[:, first:first + width], expected / core.control_dt / core.rate_scale_vec,
                               atol=1e-9)
    voi, terms = _run(core, IDS)
    planned = np.array([p["mean_voi_plan"] for p in plans])
    # the env's 1 ms substeps with the projected gradient underneath execute the plan to within about 2e-3 VOI
    np.testing.assert_allclose(voi.mean(axis=0), planned, atol=2e-3)
    assert np.all(terms[:, :, 4] == 0.0)  # a zero action pays no action penalty, though the kernel got the plan's
    assert np.max(core.metrics[:, Metric.TIP_ERROR]) < 2e-4


def test_plan_beats_the_projected_gradient_on_hold():
    plain = OcclusionCore(len(IDS), task="hold", **KW)
    voi_plain, _ = _run(plain, IDS)
    planned = OcclusionCore(len(IDS), task="hold", base_controller="arc_plan", **KW)
    voi_plan, _ = _run(planned, IDS)
    assert voi_plan.mean() < voi_plain.mean() - 0.02


def test_moving_targets_are_untouched_to_the_bit():
    rng = np.random.default_rng(3)
    actions = np.clip(rng.normal(0.0, 0.3, (40, 4, 8)), -1.0, 1.0)
    ids = np.arange(4)
    out = []
    for base in ("projected_gradient", "arc_plan"):
        core = OcclusionCore(4, task="random", base_controller=base, **KW)
        voi, terms = _run(core, ids, lambda k: actions[k], steps=40)
        out.append((voi, terms, core.q.copy(), core.obs.copy(), core.rewards.copy()))
    for a, b in zip(*out, strict=True):
        np.testing.assert_array_equal(a, b)


def test_the_policy_pays_for_its_own_action():
    core = OcclusionCore(2, task="hold", base_controller="arc_plan", **KW)
    action = np.full((2, 8), 0.25)
    _, terms = _run(core, IDS[:2], lambda k: action, steps=3)
    expected = -core.weights["action"] * np.sum(action ** 2, axis=1) / 8
    np.testing.assert_allclose(terms[-1][:, 4], expected, rtol=1e-12)
    np.testing.assert_allclose(core.rewards, core.terms.sum(axis=1), rtol=1e-12, atol=1e-15)


def test_mixed_tasks_plan_only_the_holds():
    core = OcclusionCore(4, task="mixed", base_controller="arc_plan", **KW)
    plain = OcclusionCore(4, task="mixed", **KW)
    ids = np.arange(4)  # even ids hold, odd ids follow a random trajectory
    voi_plan, _ = _run(core, ids, steps=30)
    voi_plain, _ = _run(plain, ids, steps=30)
    np.testing.assert_array_equal(voi_plan[:, 1::2], voi_plain[:, 1::2])
    assert not np.array_equal(voi_plan[:, 0::2], voi_plain[:, 0::2])


def test_arc_plan_is_a_base_with_its_own_residual_scale():
    """A named base of the env (a baseline row of evaluate), whose residual scale defaults to 2; the others' to 0.3."""
    assert "arc_plan" in OcclusionConfig.baselines
    assert OcclusionConfig(base_controller="arc_plan").residual_scale == 2.0
    assert OcclusionConfig(base_controller="arc_plan", residual_scale=3.0).residual_scale == 3.0
    assert OcclusionConfig().residual_scale == 0.3
    with pytest.raises(ValueError, match="arc_plan"):
        OcclusionConfig.from_kwargs(arc_plan=True)  # the 0.2 option is gone, by name


@pytest.mark.parametrize("scale", [0.3, 1.99])
def test_arc_plan_needs_the_reach_of_its_correction(scale):
    """The plan's correction of the base reaches twice the rate limits: a smaller residual scale would clip it."""
    with pytest.raises(ValueError, match="base_controller='arc_plan' needs residual_scale >= 2.*got"):
        OcclusionConfig(base_controller="arc_plan", residual_scale=scale)


def test_no_plan_under_a_model_error():
    """The plans run along the visibility guard's edge, which a mismatched tip crosses: every row keeps the base."""
    out = []
    for base in ("projected_gradient", "arc_plan"):
        core = OcclusionCore(2, task="hold", base_controller=base, model_error="mild", **KW)
        voi, terms = _run(core, IDS[:2], steps=20)
        out.append((voi, terms, core.q.copy(), core.obs.copy()))
    for a, b in zip(*out, strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_run_trained_with_the_old_option_loads_as_residual_arc_plan(tmp_path):
    """A 0.2 run's config.yml (``arc_plan: true`` beside ``base_controller: projected_gradient``) is found as
    ``residual_arc_plan`` and acts on the arc_plan base."""
    import yaml

    from continuum_gym.envs.spec import get_spec
    from continuum_gym.evaluation.methods import discover_policies, policy_env_kwargs, read_run_config

    old = {"env_id": "ContinuumGym/OcclusionAvoidance-v0", "algo": "ppo", "base_controller": "projected_gradient",
           "seed": 0, "hyperparams": {"env_kwargs": {"task": "mixed", "arc_plan": True}},
           "env_kwargs": {"task": "mixed", "arc_plan": True, "base_controller": "projected_gradient",
                          "residual_scale": 2.0},
           "env_config": {"base_controller": "projected_gradient", "residual_scale": 2.0, "arc_plan": True,
                          "visibility_guard": 0.69}}
    run = tmp_path / "OcclusionAvoidance_ppo_projected_gradient_seed0"
    run.mkdir()
    (run / "config.yml").write_text(yaml.safe_dump(old))
    (run / "model.zip").write_bytes(b"")
    assert list(discover_policies(tmp_path)["ContinuumGym/OcclusionAvoidance-v0"]) == ["residual_arc_plan"]
    config = read_run_config(run, old)
    kwargs = policy_env_kwargs(get_spec("ContinuumGym/OcclusionAvoidance-v0"), config)
    assert kwargs == {"base_controller": "arc_plan", "residual_scale": 2.0, "visibility_guard": 0.69}
    assert "arc_plan" not in config["hyperparams"]["env_kwargs"]
    # without the option the same run stays a residual on the projected gradient
    plain = {**old, "env_config": {"base_controller": "projected_gradient", "residual_scale": 2.0}}
    plain.pop("env_kwargs")
    assert read_run_config(run, plain)["env_config"]["base_controller"] == "projected_gradient"


def test_recorded_holds_are_planned_and_moving_recordings_are_not():
    """A recorded ``TipTrajectory`` whose samples all sit at its start's tip is a hold (issue 55: such rows stayed
    unplanned); the base executes hold_arc_plan's trajectory there. A recording that moves keeps the base."""
    from continuum_gym.baselines.occlusion import OcclusionLimits
    from continuum_gym.envs.occlusion.tasks import hold_start_pool
    from continuum_gym.envs.trajectories import TipTrajectory

    limits = OcclusionLimits()
    starts = np.asarray(hold_start_pool("validation", float(limits.max_bend), tuple(limits.insertion)))[:2]
    core = OcclusionCore(3, task="hold", base_controller="arc_plan", **KW)
    holds = []
    for q0 in starts:
        tip, _ = core.robot.forward_kinematics(q0)
        holds.append(TipTrajectory(times=np.array([0.0, 1.5]), positions=np.stack([tip, tip]), start_q=q0))
    tip, _ = core.robot.forward_kinematics(starts[0])
    moving = TipTrajectory(times=np.array([0.0, 1.5]), positions=np.stack([tip, tip + [0.002, 0.0, 0.0]]),
                           start_q=starts[0])
    recorded = OcclusionCore(3, task=[*holds, moving], base_controller="arc_plan", **KW)
    voi, _ = _run(recorded, np.arange(3), steps=150)
    np.testing.assert_array_equal(recorded.layers[0].on, [True, True, False])
    planned = [hold_arc_plan(recorded.robot, q0, recorded.limits, visibility=GUARD, cone=recorded.cone, steps=150)
               for q0 in starts]
    np.testing.assert_allclose(voi[:, :2].mean(axis=0), [p["mean_voi_plan"] for p in planned], atol=2e-3)
