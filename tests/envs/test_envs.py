"""The environments against Gymnasium's and SB3's checkers, the baselines they wrap, and themselves."""

from __future__ import annotations

import copy
import math
import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import continuum_gym
from continuum_gym.baselines import DimensionReduced, ProjectedGradient
from continuum_gym.envs.occlusion import (
    OcclusionAvoidanceEnv,
    OcclusionAvoidanceVectorEnv,
)
from continuum_gym.envs.occlusion.tasks import hold_start_pool
from continuum_gym.envs.view_tracking import ViewTrackingEnv, ViewTrackingVectorEnv

OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"


def test_registry_lists_every_id():
    assert continuum_gym.ENV_IDS == [OCCLUSION, VIEW]
    for env_id in continuum_gym.ENV_IDS:
        spec = gym.spec(env_id)
        assert isinstance(spec.entry_point, str) and isinstance(spec.vector_entry_point, str)
        assert spec.max_episode_steps is None  # every task truncates itself at its own duration


@pytest.mark.parametrize("env_id", continuum_gym.ENV_IDS)
def test_gymnasium_and_sb3_checkers_pass(env_id):
    gym_check_env(gym.make(env_id).unwrapped, skip_render_check=True)
    sb3_check_env(gym.make(env_id), warn=True)


@pytest.mark.parametrize("env_id", continuum_gym.ENV_IDS)
def test_make_with_module_prefix(env_id):
    env = gym.make(f"continuum_gym:{env_id}")
    obs, _ = env.reset(seed=1)
    assert env.observation_space.contains(obs)


def _rollout(env, seed, steps, actions):
    obs, info = env.reset(seed=seed)
    out = [obs]
    for k in range(steps):
        obs, reward, terminated, truncated, info = env.step(actions[k])
        out.append(np.append(obs, [reward, terminated, truncated]))
        if terminated or truncated:
            obs, info = env.reset()
            out.append(obs)
    return out


@pytest.mark.parametrize("env_id", continuum_gym.ENV_IDS)
def test_same_seed_same_trajectory_and_copies(env_id):
    rng = np.random.default_rng(0)
    env = gym.make(env_id, max_episode_steps=40)
    actions = rng.uniform(-1, 1, (100,) + env.action_space.shape)
    first = _rollout(env, 3, 100, actions)
    second = _rollout(gym.make(env_id, max_episode_steps=40), 3, 100, actions)
    assert all(np.array_equal(a, b) for a, b in zip(first, second))
    other = _rollout(gym.make(env_id, max_episode_steps=40), 4, 100, actions)
    assert not all(np.array_equal(a, b) for a, b in zip(first, other))
    # Pickled and deep-copied envs continue identically.
    env.reset(seed=5)
    env.step(actions[0])
    clones = [copy.deepcopy(env), pickle.loads(pickle.dumps(env))]
    for k in range(1, 10):
        expected = env.step(actions[k])[0]
        for clone in clones:
            assert np.array_equal(clone.step(actions[k])[0], expected)


@pytest.mark.parametrize("env_id, kwargs", [
    (OCCLUSION, {"base_controller": None}),
    (OCCLUSION, {"task": "random", "residual_space": "joint", "residual_scale": 1.0}),
    (VIEW, {"base_controller": None}),
    (VIEW, {"task": "random"}),
])
def test_observations_stay_in_their_space_under_extreme_actions(env_id, kwargs):
    env = gym.make(env_id, **kwargs)
    rng = np.random.default_rng(1)
    obs, _ = env.reset(seed=0)
    hit_limit = False
    for k in range(600):
        push = np.sign(rng.uniform(-1, 1, env.action_space.shape))
        action = push if k % 50 < 40 else np.zeros(env.action_space.shape)
        if k % 100 < 10:  # push the first bend (and the stem) hard toward a limit
            action[0] = -1.0 if env_id == OCCLUSION else 1.0
            action[2] = 1.0
        obs, reward, terminated, truncated, info = env.step(action.astype(np.float32))
        assert env.observation_space.contains(obs), (k, obs)
        assert np.isfinite(reward)
        hit_limit |= bool(np.any(info["clamped_joints"]))
        if terminated or truncated:
            obs, _ = env.reset()
    if env_id == VIEW and kwargs.get("base_controller", "x") is None:
        assert hit_limit  # the rollout did reach joint limits (occlusion: see the next test)


def test_joint_limits_are_reached_and_reported():
    env = OcclusionAvoidanceEnv(base_controller=None, task="hold")
    env.reset(seed=0)
    core = env.core
    core.q[0, 0] = core.limits.lower[0] + 0.005  # bend of segment 1 just inside its limit
    _, _, _, _, info = env.step(np.array([-1, 0, 0, 0, 0, 0, 0, 0], dtype=np.float32))
    assert info["clamped_joints"][0] and core.q[0, 0] == core.limits.lower[0]
    assert not info["clamped_joints"][1:].any()


def test_near_straight_configuration_is_handled():
    env = OcclusionAvoidanceEnv(task="hold")
    env.reset(seed=0)
    core = env.unwrapped.core
    core.q[0] = [math.pi / 2, 0.3, math.pi / 2 + 1e-9, -0.2, math.pi / 2, 1.0, 0.01]
    core.tasks.centre[0], core.tasks.R_des[0] = core.robot.forward_kinematics(core.q[0])
    for _ in range(5):
        obs, reward, *_ = env.step(np.zeros(8, dtype=np.float32))
        assert env.observation_space.contains(obs) and np.isfinite(reward)


# ---------------------------------------------------------------- zero residual == baseline
@pytest.mark.parametrize("task", ["hold", "circle"])
def test_zero_residual_reproduces_the_projected_gradient_exactly(task):
    env = OcclusionAvoidanceEnv(task=task, task_split="test")
    env.reset(seed=2)
    core = env.core
    q0, gamma0 = core.q[0].copy(), float(core.gamma[0])
    steps = 60
    qs, gammas = [q0.copy()], [gamma0]
    for _ in range(steps):
        env.step(np.zeros(8, dtype=np.float32))
        qs.append(core.q[0].copy())
        gammas.append(float(core.gamma[0]))
    sub_dt = core.control_dt / core.substeps
    times = np.array([k * core.control_dt + s * sub_dt for k in range(steps) for s in range(core.substeps)])
    desired = [core.desired(0, t) for t in times]
    p, v = np.array([d[0] for d in desired]), np.array([d[1] for d in desired])
    R = np.broadcast_to(core.tasks.R_des[0], (len(times), 3, 3))
    q_ref, g_ref = ProjectedGradient(limits=core.limits, cone=core.cone).rollout(q0, gamma0, p, R, v, dt=sub_dt)
    assert np.array_equal(np.array(qs), q_ref[::core.substeps])
    assert np.array_equal(np.array(gammas), g_ref[::core.substeps])


@pytest.mark.parametrize("residual_space", ["joint", "target"])
def test_zero_residual_reproduces_dimension_reduced_exactly(residual_space):
    env = ViewTrackingEnv(task="case2", task_split="test", residual_space=residual_space)
    env.reset(seed=0)
    core = env.core
    history = [core.q[0].copy()]
    for _ in range(100):
        env.step(np.zeros(6, dtype=np.float32))
        history.append(core.q[0].copy())
    target = core.davinci.target_pose(core.davinci_configuration(0))
    solved = DimensionReduced().solve(history[0], target, max_steps=100, record=True)
    n = int(solved["steps"]) + 1
    assert n > 50
    assert np.array_equal(np.array(history)[:n], solved["history"][:n])


def test_target_residual_is_dimension_reduced_towards_the_moved_target():
    """A constant target-space action: the env's steps are DR's own steps towards the shifted, turned target."""
    from scipy.spatial.transform import Rotation

    env = ViewTrackingEnv(task="case2", task_split="test", residual_space="target", residual_scale=0.5)
    env.reset(seed=0)
    core = env.core
    action = np.array([0.4, -0.3, 0.2, 0.1, -0.2, 0.3], dtype=np.float32)
    history = [core.q[0].copy()]
    for _ in range(100):
        env.step(action)
        history.append(core.q[0].copy())
    p, R = core.davinci.target_pose(core.davinci_configuration(0))
    a = action.astype(np.float64) * 0.5
    moved = (p + 0.02 * a[:3], Rotation.from_rotvec(0.5 * a[3:]).as_matrix() @ R)
    solved = DimensionReduced().solve(history[0], moved, max_steps=100, record=True)
    # The moved frame is built by scipy here and by the kernel's Rodrigues there: equal to rounding, which the
    # IK near its limits amplifies after ~50 steps; before that the two paths agree to 1e-10.
    np.testing.assert_allclose(np.array(history)[:50], solved["history"][:50], rtol=0, atol=1e-10)
    # It did go somewhere else than the unmoved baseline would.
    plain = DimensionReduced().solve(history[0], (p, R), max_steps=100)
    assert np.abs(plain["q"] - history[-1]).max() > 1e-3


def test_rotation_exp_matches_scipy_and_inverts_the_log():
    from scipy.spatial.transform import Rotation

    from continuum_gym.robots.rotations import rotation_exp, rotation_log

    rng = np.random.default_rng(0)
    directions = rng.normal(size=(200, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    vectors = np.concatenate([directions * rng.uniform(0, 3.1, (200, 1)),  # the log's range: angles below pi
                              rng.normal(size=(20, 3)) * 1e-10, np.zeros((1, 3))])
    out, back = np.empty((3, 3)), np.empty(3)
    for w in vectors:
        rotation_exp(w, out)
        np.testing.assert_allclose(out, Rotation.from_rotvec(w).as_matrix(), rtol=0, atol=1e-14)
        rotation_log(out, back)
        np.testing.assert_allclose(back, w, rtol=0, atol=1e-12)


# ---------------------------------------------------------------- rewards and info
@pytest.mark.parametrize("env_id", continuum_gym.ENV_IDS)
def test_reward_is_the_sum_of_weighted_terms(env_id):
    env = gym.make(env_id)
    env.reset(seed=0)
    rng = np.random.default_rng(2)
    for _ in range(20):
        _, reward, _, _, info = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
        assert reward == pytest.approx(sum(info["reward_terms"].values()), rel=1e-12, abs=1e-12)
    # Doubling one weight doubles that term and nothing else.
    name = "voi" if env_id == OCCLUSION else "overlap"
    pair = [gym.make(env_id, reward_weights={name: w}) for w in (1.0, 2.0)]
    infos = []
    for e in pair:
        e.reset(seed=0)
        infos.append(e.step(np.zeros(e.action_space.shape, dtype=np.float32))[4])
    assert infos[1]["reward_terms"][name] == pytest.approx(2 * infos[0]["reward_terms"][name])


def test_overlap_bonus_pays_exactly_when_the_coverage_criterion_holds():
    env = ViewTrackingEnv(task="case2", task_split="test", reward_weights={"overlap_bonus": 2.5})
    env.reset(seed=0)
    seen = set()
    for _ in range(150):
        _, _, _, _, info = env.step(np.zeros(6, dtype=np.float32))
        above = info["overlap_ratio"] > 0.8
        assert info["reward_terms"]["overlap_bonus"] == (2.5 if above else 0.0)
        seen.add(bool(above))
    assert seen == {True, False}  # the episode crosses the threshold, so both branches were checked


def test_pan_tilt_task_draws_the_coverage_distribution_off_its_grid():
    from continuum_gym.baselines.scenarios import COVERAGE_INSERTION, coverage_grid

    centres = {}
    for split in ("train", "test"):
        env = ViewTrackingEnv(task="pan_tilt", task_split=split)
        rows = []
        for task_id in range(200):
            env.reset(options={"task_id": task_id})
            rows.append(env.core.tasks.centre[0].copy())
        centres[split] = np.array(rows)
    for rows in centres.values():
        assert np.all(rows[:, 0] == COVERAGE_INSERTION) and np.all(rows[:, 3] == 0.0)
        assert np.all(np.abs(rows[:, 1:3]) <= math.pi / 3) and np.abs(rows[:, 1:3]).max() > 0.9 * math.pi / 3
    grid = coverage_grid(21)
    for rows in centres.values():
        assert np.abs(rows[:, None, 1:3] - grid[None, :, 1:3]).max(axis=-1).min() > 1e-9  # never a grid point
    assert np.abs(centres["train"][:, None] - centres["test"][None]).max(axis=-1).min() > 1e-9


def test_view_tracking_mixed_task_interleaves_pan_tilt_targets_and_random_motions():
    """Even ids are pan_tilt instance id // 2, odd ids random instance id // 2: every field, the duration included."""
    from dataclasses import fields

    mixed = ViewTrackingEnv(task="mixed", task_split="validation")
    singles = {name: ViewTrackingEnv(task=name, task_split="validation") for name in ("pan_tilt", "random")}
    for task_id in range(6):
        mixed.reset(options={"task_id": task_id})
        single = singles["pan_tilt" if task_id % 2 == 0 else "random"]
        single.reset(options={"task_id": task_id // 2})
        assert int(mixed.core.tasks.task_id[0]) == task_id
        for field in fields(mixed.core.tasks):
            if field.name != "task_id":
                np.testing.assert_array_equal(getattr(mixed.core.tasks, field.name)[0],
                                              getattr(single.core.tasks, field.name)[0], err_msg=field.name)
        obs_mixed = mixed.step(np.zeros(mixed.action_space.shape, dtype=np.float32))[0]
        obs_single = single.step(np.zeros(single.action_space.shape, dtype=np.float32))[0]
        np.testing.assert_array_equal(obs_mixed, obs_single)
    assert mixed.core.tasks.duration[0] != singles["pan_tilt"].core.tasks.duration[0]  # id 5: a 6 s random motion


def test_observe_target_appends_the_da_vinci_configuration_and_changes_nothing_else():
    plain = ViewTrackingEnv(task="random")
    extended = ViewTrackingEnv(task="random", observe_target=True)
    assert extended.observation_space.shape == (27,)
    gym_check_env(extended, skip_render_check=True)
    sb3_check_env(ViewTrackingEnv(task="random", observe_target=True), warn=True)
    obs_a, _ = plain.reset(seed=4)
    obs_b, _ = extended.reset(seed=4)
    rng = np.random.default_rng(0)
    for _ in range(60):
        np.testing.assert_array_equal(obs_a, obs_b[:22])
        q_dv = extended.unwrapped.core.davinci_configuration(0)
        expected = [(q_dv[0] - 0.05) / 0.05, q_dv[1] / (math.pi / 3), q_dv[2] / (math.pi / 3), math.sin(q_dv[3]),
                    math.cos(q_dv[3])]
        np.testing.assert_allclose(obs_b[22:], expected, atol=1e-6)
        action = rng.uniform(-1, 1, 6).astype(np.float32)
        obs_a, reward_a, *_ = plain.step(action)
        obs_b, reward_b, *_ = extended.step(action)
        assert reward_a == reward_b


def test_occlusion_info_reports_metrics_and_saturation():
    env = OcclusionAvoidanceEnv(base_controller=None, task="hold")
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.ones(8, dtype=np.float32) * 3.0)
    assert info["action_clipped"]
    for key in ("voi", "tip_error_m", "orientation_error_rad", "tip_view_fraction", "tip_in_view", "clamped_joints",
                "rate_saturated", "gamma", "base_command"):
        assert key in info
    assert 0 <= info["voi"] <= 1 and info["clamped_joints"].shape == (7,)


# ---------------------------------------------------------------- visibility guard
@pytest.mark.parametrize("direction", [1.0, -1.0])
def test_visibility_guard_keeps_the_tip_in_view_and_says_so(direction):
    """A residual that spins the endoscope as fast as it can: the guard stops it at its bound, not before."""
    action = np.zeros(8, dtype=np.float32)
    action[7] = direction
    fractions = {}
    for guard in (0.69, None):
        env = OcclusionAvoidanceEnv(task="hold", task_split="test", residual_scale=1.0, visibility_guard=guard)
        env.reset(seed=3)
        seen, flagged = [], []
        for _ in range(60):
            _, _, terminated, truncated, info = env.step(action)
            seen.append(info["tip_view_fraction"])
            flagged.append(info["visibility_guarded"])
        fractions[guard] = np.array(seen)
        if guard is None:
            assert not any(flagged)
        else:
            assert any(flagged)
    assert fractions[None].max() > 0.9  # unguarded, the tip leaves the view
    # Guarded: held at the bound (the tip moves within a substep, hence the small slack) ...
    assert fractions[0.69].max() <= 0.69 + 1e-3
    # ... and pushed right up to it: the guard cuts the residual, not the whole rotation.
    assert fractions[0.69][-10:].min() > 0.685


def test_guard_gamma_rate_keeps_the_largest_feasible_share_of_the_residual():
    from continuum_gym.envs.occlusion.guard import guard_gamma_rate, view_fraction_at

    core = OcclusionAvoidanceEnv(task="hold").core
    prm = core.controller.params.cone
    rng = np.random.default_rng(0)
    shares = np.linspace(0.0, 1.0, 20001)
    checked = 0
    for _ in range(200):
        tip = core.robot.forward_kinematics(core.q[0] + rng.normal(0, 0.05, 7))[0]
        gamma, base_rate, residual_rate, dt = rng.uniform(-np.pi, np.pi), rng.normal(0, 1), rng.normal(0, 3), 0.05
        rate, guarded = guard_gamma_rate(tip, gamma, base_rate, residual_rate, dt, 0.69, prm)
        bound = max(0.69, view_fraction_at(tip, gamma + base_rate * dt, prm))
        feasible = [view_fraction_at(tip, gamma + (base_rate + a * residual_rate) * dt, prm) <= bound for a in shares]
        if feasible[-1]:
            assert not guarded and rate == base_rate + residual_rate
            continue
        checked += 1
        # Brute force: the first infeasible share on a fine scan (the fraction is monotone over so small a turn).
        first_out = shares[np.argmin(feasible)]
        assert guarded
        assert view_fraction_at(tip, gamma + rate * dt, prm) <= bound
        assert abs((rate - base_rate) / residual_rate - first_out) <= 1e-4
    assert checked > 20


# ---------------------------------------------------------------- splits
def test_train_validation_and_test_tasks_are_disjoint():
    pools = {split: hold_start_pool(split, math.pi / 2, (0.0, 0.04)) for split in ("train", "validation", "test")}
    for a, b in (("train", "test"), ("train", "validation"), ("validation", "test")):
        distances = np.linalg.norm(pools[a][:, None] - pools[b][None], axis=-1)
        assert distances.min() > 1e-6, (a, b)
    a = ViewTrackingEnv(task="static", task_split="train")
    b = ViewTrackingEnv(task="static", task_split="test")
    a.reset(options={"task_id": 7})
    b.reset(options={"task_id": 7})
    assert not np.array_equal(a.core.tasks.centre, b.core.tasks.centre)


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize("env_id, kwargs, name", [
    (OCCLUSION, {"task": "orbit"}, "task"),
    (OCCLUSION, {"task": "circle", "task_split": "train"}, "circle"),
    (OCCLUSION, {"task_split": "dev"}, "task_split"),
    (OCCLUSION, {"base_controller": "dimension_reduced"}, "base_controller"),
    (OCCLUSION, {"lens_model": "fisheye"}, "lens_model"),
    (OCCLUSION, {"reward_weights": {"voi": -1.0}}, "reward_weights"),
    (OCCLUSION, {"reward_weights": {"occlusion": 1.0}}, "reward_weights"),
    (OCCLUSION, {"reward_weights": {"voi": "high"}}, "reward_weights"),
    (OCCLUSION, {"residual_space": "task"}, "residual_space"),
    (OCCLUSION, {"max_bend": -0.5}, "max_bend"),
    (OCCLUSION, {"substeps": 0}, "substeps"),
    (OCCLUSION, {"control_dt": 0.0}, "control_dt"),
    (OCCLUSION, {"visibility_guard": 1.5}, "visibility_guard"),
    (VIEW, {"task": "coverage"}, "coverage"),
    (VIEW, {"base_controller": "projected_gradient"}, "base_controller"),
    (VIEW, {"residual_scale": -0.1}, "residual_scale"),
    (VIEW, {"rate_limits": [1, 1, 1]}, "rate_limits"),
    (VIEW, {"residual_space": "nullspace"}, "residual_space"),
    (VIEW, {"residual_space": "target", "base_controller": None}, "residual_space"),
    (VIEW, {"observe_target": "yes"}, "observe_target"),
])
def test_bad_keywords_raise(env_id, kwargs, name):
    with pytest.raises(ValueError, match=name):
        gym.make(env_id, **kwargs)


@pytest.mark.parametrize("env_id", continuum_gym.ENV_IDS)
def test_bad_actions_raise(env_id):
    env = gym.make(env_id).unwrapped
    env.reset(seed=0)
    dim = env.action_space.shape[0]
    for bad in (np.full(dim, np.nan), np.full(dim, np.inf), np.zeros(dim + 1), np.zeros((2, dim))):
        with pytest.raises(ValueError, match="action"):
            env.step(bad)
    before = env.core.obs.copy()
    assert np.array_equal(before, env.core.obs)  # a rejected action leaves no trace


# ---------------------------------------------------------------- vector envs
@pytest.mark.parametrize("env_id, vector_class", [(OCCLUSION, OcclusionAvoidanceVectorEnv),
                                                   (VIEW, ViewTrackingVectorEnv)])
def test_native_vector_env_equals_single_envs(env_id, vector_class):
    n = 4
    venv = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", max_episode_steps=7)
    assert isinstance(venv, vector_class)
    singles = [gym.make(env_id, max_episode_steps=7) for _ in range(n)]
    obs, _ = venv.reset(seed=10)
    single_obs = [env.reset(seed=10 + i)[0] for i, env in enumerate(singles)]
    assert np.array_equal(obs, np.array(single_obs))
    rng = np.random.default_rng(3)
    pending_reset = [False] * n
    for _ in range(20):
        actions = rng.uniform(-1, 1, (n,) + singles[0].action_space.shape).astype(np.float32)
        obs, rewards, terminated, truncated, _ = venv.step(actions)
        for i, env in enumerate(singles):
            if pending_reset[i]:  # next-step autoreset: this step returns the reset observation
                expected_obs, _ = env.reset()
                assert np.array_equal(obs[i], expected_obs) and rewards[i] == 0.0
                assert not terminated[i] and not truncated[i]
                pending_reset[i] = False
                continue
            o, r, te, tr, _ = env.step(actions[i])
            assert np.array_equal(obs[i], o) and rewards[i] == r and terminated[i] == te and truncated[i] == tr
            pending_reset[i] = te or tr
    assert venv.observation_space.shape == (n,) + singles[0].observation_space.shape


def test_sb3_adapter_resets_in_the_same_step():
    from continuum_gym.envs.sb3 import ContinuumSB3VecEnv

    venv = ContinuumSB3VecEnv(VIEW, 3, max_episode_steps=5)
    venv.seed(0)
    obs = venv.reset()
    for _ in range(5):
        obs, rewards, dones, infos = venv.step(np.zeros((3, 6), dtype=np.float32))
    assert dones.all()
    assert all("terminal_observation" in info and info["TimeLimit.truncated"] for info in infos)
    assert not np.array_equal(obs[0], infos[0]["terminal_observation"])
    assert np.all(obs[:, 21] == 0.0)  # elapsed-time feature of a fresh episode
    with pytest.raises(ValueError, match="unknown env"):
        ContinuumSB3VecEnv("ContinuumGym/Nope-v0", 2)


@pytest.mark.slow
@pytest.mark.parametrize("env_id", continuum_gym.ENV_IDS)
def test_short_ppo_run_trains_saves_and_loads(env_id, tmp_path):
    from stable_baselines3 import PPO

    from continuum_gym.envs.sb3 import ContinuumSB3VecEnv

    venv = ContinuumSB3VecEnv(env_id, 8, seed=0)
    model = PPO("MlpPolicy", venv, n_steps=64, batch_size=128, n_epochs=2, seed=0, device="cpu")
    model.learn(2048)
    model.save(tmp_path / "model")
    loaded = PPO.load(tmp_path / "model", device="cpu")
    obs = venv.reset()
    assert np.array_equal(model.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0])


@pytest.mark.slow
def test_rl_zoo_trains_with_the_shipped_yaml(tmp_path):
    import subprocess
    import sys
    from pathlib import Path

    import rl_zoo3  # noqa: F401  (a test extra: missing, the test fails rather than skips)
    conf = Path(continuum_gym.__file__).parent / "agents" / "hyperparams" / "zoo_ppo.yml"
    result = subprocess.run([sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo", "--env", VIEW, "--gym-packages",
                             "continuum_gym", "--conf-file", str(conf), "-n", "2048", "--log-folder", str(tmp_path),
                             "--eval-freq", "-1"], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    assert list(tmp_path.glob("ppo/ContinuumGym-ViewTracking-v0_1/*.zip"))


@pytest.mark.parametrize("env_id, k", [("ContinuumGym/OcclusionAvoidance-v0", 8), ("ContinuumGym/ViewTracking-v0", 6)])
def test_the_step_entry_point_and_the_dispatcher_agree(env_id, k):
    """The core calls its kernel's compiled entry point directly; arrays of another layout take numba's
    dispatcher instead. Both must step the same rows to the same bits, and a pickled core again."""
    from continuum_gym.evaluation.rollout import make_core

    rng = np.random.default_rng(0)
    actions = np.ascontiguousarray(rng.uniform(-1, 1, (3, 4, k))[:, 0, :])  # (3, k) float64, C order
    cores = [make_core(env_id, 3, task="random") for _ in range(3)]
    for core in cores:
        core.reset_rows(np.arange(3), np.arange(3))
    cores[2] = pickle.loads(pickle.dumps(cores[2]))
    active = np.ones(3, dtype=np.uint8)
    strided = np.asfortranarray(actions)  # another layout: the dispatcher path
    for _ in range(5):
        cores[0].step(actions.copy(), active)
        cores[1].step(strided, active.astype(np.uint8))
        cores[2].step(actions.copy(), active)
    assert cores[0]._step_call.entry is not None
    for other in cores[1:]:
        np.testing.assert_array_equal(cores[0].obs, other.obs)
        np.testing.assert_array_equal(cores[0].rewards, other.rewards)


@pytest.mark.parametrize("env_id", ["ContinuumGym/OcclusionAvoidance-v0", "ContinuumGym/ViewTracking-v0"])
def test_observing_rows_through_the_step_kernel_touches_only_those_rows(env_id):
    """observe_rows runs the step kernel with its rows marked OBSERVE_ONLY: those rows get the observation
    of their state (the same bits whichever other rows are observed with them, pickled or not); every other
    row, and every step counter, reward and flag, stays as it was."""
    from continuum_gym.evaluation.rollout import make_core

    cores = [make_core(env_id, 4, task="random") for _ in range(3)]
    shift = 0.01 * np.random.default_rng(1).standard_normal(cores[0].q.shape)
    for core in cores:
        core.reset_rows(np.arange(4), np.arange(4))
        active = np.ones(4, dtype=np.uint8)
        core.step(np.zeros((4,) + core.single_action_space.shape), active)
        core.q += shift
    cores[2] = pickle.loads(pickle.dumps(cores[2]))
    before = {name: getattr(cores[0], name).copy() for name in ("obs", "steps", "rewards", "flags", "terms")}
    cores[0].observe_rows(np.array([1, 3]))
    cores[1].observe_rows(np.arange(4))
    cores[2].observe_rows([3, 1])
    assert not cores[0]._observe_mask.any()
    for name in ("steps", "rewards", "flags", "terms"):
        np.testing.assert_array_equal(getattr(cores[0], name), before[name])
    np.testing.assert_array_equal(cores[0].obs[[0, 2]], before["obs"][[0, 2]])
    assert not np.array_equal(cores[0].obs[[1, 3]], before["obs"][[1, 3]])  # the shifted state was observed
    for other in cores[1:]:
        np.testing.assert_array_equal(cores[0].obs[[1, 3]], other.obs[[1, 3]])
        np.testing.assert_array_equal(cores[0].base_cmd[[1, 3]], other.base_cmd[[1, 3]])


def test_episodes_last_their_tasks_duration_with_no_registered_cut():
    """No TimeLimit: a 15 s recording at control_dt 5 ms runs its 3000 steps, and says so up front."""
    from continuum_gym.envs import TipTrajectory
    from continuum_gym.robots import MultiBackboneRobot

    robot = MultiBackboneRobot()
    p0, R0 = robot.forward_kinematics(robot.psi_a)
    t = np.linspace(0.0, 15.0, 4)
    recording = TipTrajectory(t, np.broadcast_to(p0, (4, 3)), np.broadcast_to(R0, (4, 3, 3)), start_q=robot.psi_a)
    env = gym.make(OCCLUSION, task=recording, control_dt=0.005, substeps=5)
    env.reset(seed=0)
    assert env.unwrapped.episode_steps == 3000
    steps, done = 0, False
    while not done:
        _, _, terminated, truncated, _ = env.step(np.zeros(8, dtype=np.float32))
        steps += 1
        done = terminated or truncated
    assert steps == 3000 and truncated and not terminated
    short = gym.make(OCCLUSION, task="hold")
    short.reset(seed=0)
    assert short.unwrapped.episode_steps == 150


@pytest.mark.parametrize("env_id", ["ContinuumGym/OcclusionAvoidance-v0", "ContinuumGym/ViewTracking-v0"])
def test_actions_of_any_layout_step_the_same_compiled_kernel(env_id):
    """A Fortran-ordered or strided action batch is copied to C order: the same bits, and no new
    specialisation of the step kernel (which would compile it again, ~25-60 s)."""
    envs = [gym.make_vec(env_id, num_envs=4, vectorization_mode="vector_entry_point") for _ in range(2)]
    for venv in envs:
        venv.reset(seed=3)
    kernel = envs[0].core._step_call.kernel
    rng = np.random.default_rng(1)
    k = envs[0].single_action_space.shape[0]
    envs[0].step(np.zeros((4, k)))
    envs[1].step(np.zeros((4, k)))
    signatures = len(kernel.signatures)  # other tests in this process may have compiled other layouts
    for layout in ("F", "strided", "F"):
        actions = rng.uniform(-1, 1, (4, k))
        other = np.asfortranarray(actions) if layout == "F" else np.repeat(actions, 2, axis=1)[:, ::2]
        assert not other.flags.c_contiguous
        results = envs[0].step(actions), envs[1].step(other)
        for mine, theirs in zip(results[0][:3], results[1][:3]):
            np.testing.assert_array_equal(mine, theirs)
    assert len(kernel.signatures) == signatures


def test_the_guard_limits_only_the_residuals_rotation_as_documented():
    """Issue 54, item 5: what the guard guarantees is stated exactly. A joint residual that walks the tip out of
    the view, with no endoscope residual, is not stopped (the guard never acts), as the docstring says."""
    from continuum_gym.envs.occlusion.guard import view_fraction_at

    doc = OcclusionAvoidanceEnv.__doc__
    assert "limits **only the\n    residual's endoscope rotation**" in doc and "nor the joint residual" in doc
    env = OcclusionAvoidanceEnv(task="hold", task_split="test", residual_space="joint", residual_scale=2.0)
    env.reset(seed=3)
    core, cone = env.core, env.core.controller.params.cone

    def fraction(q):
        return view_fraction_at(core.robot.forward_kinematics(q)[0], float(core.gamma[0]), cone)

    seen, guarded = [], []
    for _ in range(150):  # ascend the tip's view fraction through the joints alone (finite differences)
        q = core.q[0].copy()
        grad = np.array([(fraction(q + 1e-6 * e) - fraction(q - 1e-6 * e)) / 2e-6 for e in np.eye(7)])
        action = np.append(np.sign(grad), 0.0).astype(np.float32)
        _, _, terminated, truncated, info = env.step(action)
        seen.append(info["tip_view_fraction"])
        guarded.append(info["visibility_guarded"])
        if terminated or truncated:
            break
    assert max(seen) > 0.69 + 0.02 and not any(guarded)
