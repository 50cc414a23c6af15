"""Model mismatch (issue 37): nominal controller, true plant; each piece against an independent computation."""

from __future__ import annotations

import math
import pickle

import gymnasium as gym
import numpy as np
import pytest
import yaml

from continuum_gym.envs import ModelError, OcclusionConfig, ViewTrackingConfig
from continuum_gym.envs.model_error import PRESET_RANGES, value_names
from continuum_gym.envs.occlusion import OcclusionCore
from continuum_gym.envs.view_tracking import ViewTrackingCore

OA = "ContinuumGym/OcclusionAvoidance-v0"
VT = "ContinuumGym/ViewTracking-v0"


def _rollout(env_id: str, model_error, steps: int = 40, seed: int = 3, **kwargs) -> list:
    env = gym.make(env_id, model_error=model_error, **kwargs)
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    out = [obs]
    for t in range(steps):
        action = rng.uniform(-1, 1, env.action_space.shape) * (t % 3 != 0)
        obs, reward, terminated, truncated, info = env.step(action)
        out.append(np.concatenate([obs, [reward, terminated, truncated], info["base_command"]]))
        if terminated or truncated:
            obs, _ = env.reset()
            out.append(obs)
    return out


@pytest.mark.parametrize("env_id, kwargs", [
    (OA, {}), (OA, {"residual_space": "joint"}), (OA, {"base_controller": None}),
    (VT, {}), (VT, {"residual_space": "target"}), (VT, {"base_controller": None}),
])
def test_zero_error_is_none_bit_for_bit(env_id, kwargs):
    """An all-zero ModelError runs the mismatch kernel; its every value equals model_error='none''s."""
    none = _rollout(env_id, "none", **kwargs)
    zero = _rollout(env_id, ModelError(length_scale=1.0), **kwargs)
    assert len(none) == len(zero)
    for a, b in zip(none, zero):
        np.testing.assert_array_equal(a, b)


def _pure_core(error: ModelError, n: int = 1) -> ViewTrackingCore:
    core = ViewTrackingCore(n, base_controller=None, task="static", model_error=error)
    core.reset_rows(np.arange(n), np.zeros(n, dtype=np.int64))
    return core


def test_is_zero():
    assert ModelError().is_zero and ModelError(length_scale=(1.0, 1.0)).is_zero
    assert not ModelError(backlash_rad=0.01).is_zero and not ModelError(length_scale=(1.0, 0.99)).is_zero


def test_pure_lag_converges_like_exp():
    """Constant command c through a lag tau: the joint rate after n steps is c (1 - exp(-n dt / tau))."""
    tau = 0.05
    core = _pure_core(ModelError(actuator_lag_s=tau))
    dt = core.control_dt
    action = np.zeros((1, 6))
    action[0, 1] = 0.5  # stem rotation phi (pi/2 rad/s at 1.0)
    c = 0.5 * math.pi / 2
    active = np.ones(1, dtype=np.uint8)
    before = core.q[0, 1]
    for n in range(1, 30):
        core.step(action, active)
        rate = (core.q[0, 1] - before) / dt
        before = core.q[0, 1]
        assert rate == pytest.approx(c * (1.0 - math.exp(-n * dt / tau)), rel=1e-9, abs=1e-12)


def test_backlash_is_a_deadband():
    """theta1 follows its actuator through a play of width b: true = clip(true, act - b/2, act + b/2)."""
    width = 0.04
    core = _pure_core(ModelError(backlash_rad=width))
    dt = core.control_dt
    active = np.ones(1, dtype=np.uint8)
    act = true = core.q[0, 2]
    rate = 0.2 * math.pi / 2
    for n in range(40):
        direction = 1.0 if n < 15 else -1.0
        action = np.zeros((1, 6))
        action[0, 2] = 0.2 * direction
        core.step(action, active)
        act = act + direction * rate * dt
        true = min(max(true, act - width / 2), act + width / 2)
        assert core.q[0, 2] == pytest.approx(true, abs=1e-12)
        # the measured joint is the actuator's (observation entry 2 maps theta1's range to [-1, 1])
        lower, upper = core.controller.params.lower[2], core.controller.params.upper[2]
        assert core.obs[0, 2] == pytest.approx(2 * (act - lower) / (upper - lower) - 1, abs=1e-12)
    # reversing, the true angle stood still for exactly the play: b / rate seconds
    assert abs(core.q[0, 2] - act) == pytest.approx(width / 2, abs=1e-12)


@pytest.mark.parametrize("env_id, dim", [(VT, 6), (OA, 8)])
def test_delay_shifts_the_commands(env_id, dim):
    """delay_steps=k applies the undelayed command sequence k control steps later, to the bit."""
    k = 2
    actions = np.random.default_rng(0).uniform(-0.3, 0.3, (12, 1, dim))
    make = OcclusionCore if env_id == OA else ViewTrackingCore
    paths = []
    for delay in (0, k):
        core = make(1, base_controller=None, model_error=ModelError(delay_steps=delay))
        core.reset_rows(np.arange(1), np.zeros(1, dtype=np.int64))
        path = [core.q[0].copy()]
        for action in actions:
            core.step(action, np.ones(1, dtype=np.uint8))
            path.append(core.q[0].copy())
        paths.append(np.array(path))
    undelayed, delayed = paths
    np.testing.assert_array_equal(delayed[:k + 1], np.repeat(undelayed[:1], k + 1, axis=0))
    np.testing.assert_array_equal(delayed[k:], undelayed[:len(undelayed) - k])


def test_joint_noise_is_what_the_observation_sees():
    sigma = 0.01
    core = _pure_core(ModelError(joint_noise_rad=sigma), n=64)
    differences = []
    for _ in range(20):
        core.step(np.zeros((64, 6)), np.ones(64, dtype=np.uint8))
        differences.append(core.obs[:, 1] * math.pi - core.q[:, 1])  # phi, observed / pi
    differences = np.concatenate(differences)
    assert np.std(differences) == pytest.approx(sigma, rel=0.1)
    assert abs(np.mean(differences)) < 3 * sigma / math.sqrt(len(differences))


def test_length_scale_moves_the_true_tip_not_the_belief():
    """The metrics use the true robot: the tip error grows with the length error at a held pose."""
    errors = []
    for scale in (1.0, 1.05):
        core = OcclusionCore(1, base_controller=None, task="hold", task_split="test",
                             model_error=ModelError(length_scale=scale))
        core.reset_rows(np.arange(1), np.zeros(1, dtype=np.int64))
        p_true, _ = core.robot.forward_kinematics(core.q[0])
        errors.append(core.metrics[0, 1])
    assert errors[1] > errors[0] + 1e-3  # 5 % of ~65 mm of robot


def test_fixed_per_split_and_task_id():
    """Without randomisation every method faces the same robot on a task instance."""
    a = OcclusionCore(2, model_error="severe", task_split="test")
    b = OcclusionCore(1, model_error="severe", task_split="test", base_controller="minimum_norm")
    a.reset_rows(np.arange(2), np.array([5, 5]))
    b.reset_rows(np.arange(1), np.array([5]))
    np.testing.assert_array_equal(a._mismatch.values[0], a._mismatch.values[1])
    np.testing.assert_array_equal(a._mismatch.values[0], b._mismatch.values[0])
    a.reset_rows(np.arange(1), np.array([6]))
    assert not np.array_equal(a._mismatch.values[0], a._mismatch.values[1])


@pytest.mark.parametrize("preset", ["mild", "severe"])
def test_randomised_within_ranges_same_seed_same_result(preset):
    ranges = PRESET_RANGES[preset]
    env = gym.make(VT, model_error=preset, randomize_model_error=True)
    seen = []
    for seed in (1, 1, 2):
        _, info = env.reset(seed=seed)
        seen.append(np.array(info["model_error"]))
        error = info["model_error"]
        assert ranges.backlash_rad[0] <= error["backlash_rad"] <= ranges.backlash_rad[1]
        assert ranges.delay_steps[0] <= error["delay_steps"] <= ranges.delay_steps[1]
        for j in (1, 2):
            assert ranges.length_scale[0] <= abs(error[f"length_scale_{j}"] - 1) <= ranges.length_scale[1] + 1e-15
    np.testing.assert_array_equal(seen[0], seen[1])
    assert not np.array_equal(seen[0], seen[2])
    _, info = env.reset()
    assert not np.array_equal(np.array(info["model_error"]), seen[2])  # a new error per episode
    assert tuple(info["model_error"].names) == value_names(2)


@pytest.mark.parametrize("kwargs, match", [
    ({"model_error": "huge"}, "model_error must be one of"),
    ({"model_error": ModelError(backlash_rad=0.1, length_scale=(1.0, 1.0))}, "one entry per segment"),
    ({"model_error": {"backlash_rad": 0.1, "bogus": 1}}, "unknown field"),
    ({"model_error": ModelError(camera_rotation_rad=(0.01, 0, 0))}, "applies to the other environment"),
    ({"model_error": "none", "randomize_model_error": True}, "randomize_model_error=True"),
    ({"model_error": "mild", "randomize_model_error": "yes"}, "randomize_model_error"),
])
def test_bad_values_are_named(kwargs, match):
    with pytest.raises(ValueError, match=match):
        OcclusionConfig(**kwargs)


@pytest.mark.parametrize("field, value, match", [
    ("backlash_rad", -0.1, r"model_error.backlash_rad must be in \[0, 0.5\] \(rad\)"),
    ("length_scale", 2.0, r"model_error.length_scale must be in \[0.5, 1.5\]"),
    ("delay_steps", 1.5, "model_error.delay_steps"),
    ("actuator_lag_s", float("nan"), "model_error.actuator_lag_s"),
    ("camera_rotation_rad", (0.0, 0.0), "camera_rotation_rad must be 3 numbers"),
])
def test_model_error_fields_are_checked(field, value, match):
    with pytest.raises(ValueError, match=match):
        ModelError(**{field: value})


@pytest.mark.parametrize("config_class, error", [
    (OcclusionConfig, ModelError(length_scale=(1.02, 0.98, 1.0), channel_offset_m=1e-4, backlash_rad=0.02,
                                 delay_steps=1)),
    (ViewTrackingConfig, ModelError(camera_rotation_rad=(0.01, -0.02, 0.0), actuator_lag_s=0.03)),
    (ViewTrackingConfig, "severe"),
])
def test_config_round_trip_and_pickle(config_class, error):
    config = config_class(model_error=error, randomize_model_error=error == "severe")
    text = yaml.safe_dump(config.to_dict())
    assert config_class.from_dict(yaml.safe_load(text)).to_dict() == config.to_dict()
    assert pickle.loads(pickle.dumps(config)).model_error == config.model_error


@pytest.mark.parametrize("env_id", [OA, VT])
def test_pickled_core_steps_the_same(env_id):
    make = OcclusionCore if env_id == OA else ViewTrackingCore
    core = make(3, model_error="severe")
    core.reset_rows(np.arange(3), np.array([0, 1, 2]))
    actions = np.random.default_rng(1).uniform(-1, 1, (3, core.single_action_space.shape[0]))
    copy = pickle.loads(pickle.dumps(core))
    for c in (core, copy):
        c.step(actions, np.ones(3, dtype=np.uint8))
    np.testing.assert_array_equal(core.obs, copy.obs)
    np.testing.assert_array_equal(core.rewards, copy.rewards)


@pytest.mark.parametrize("env_id", [OA, VT])
@pytest.mark.parametrize("preset, randomize", [("mild", False), ("severe", False), ("severe", True)])
def test_checkers_pass(env_id, preset, randomize):
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(env_id, model_error=preset, randomize_model_error=randomize)
    check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped, warn=False)


def test_vector_env_info_names_the_error():
    env = gym.make_vec(OA, num_envs=3, vectorization_mode="vector_entry_point", model_error="mild")
    _, info = env.reset(seed=0)
    assert info["model_error"].shape == (3, len(value_names(3)))
    obs, *_, info = env.step(np.zeros((3, 8)))
    assert np.all(np.isfinite(obs)) and "backlash_rad" in info["model_error"].names
