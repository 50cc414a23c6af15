"""Registered reward terms see the joint rates the robot applied (base and residual, after the limits).

Checked against what the step must have done, computed independently of the rates' own code: the
baseline's cached command (what a zero residual applies, read before the step), the residual's closed
form without a baseline, a joint held at its limit (no motion), the endoscope angle across +-pi (the
short way round), and the compiled and numpy paths against each other.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from numba import njit

import continuum_gym  # noqa: F401  (registers the ids)
from continuum_gym.envs.view_tracking import ACTION_SCALE
from continuum_gym.registry import register_reward_term, unregister

OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"


@njit(cache=True)
def first_rate(metrics, flags, action, rates, params):
    return rates[int(params[0])]


@pytest.fixture
def rate_terms():
    """Compiled ``rate_<k>`` and numpy ``rates_np`` terms (weight 1) reading the applied rates, per env."""
    added = []

    def register(env: str, columns: int):
        for k in range(columns):
            register_reward_term(f"rate_{k}", first_rate, env=env, params=[k], replace=True)
            added.append((f"rate_{k}", env))
        register_reward_term("rates_np", lambda metrics, actions, rates: rates.sum(axis=1), env=env, compiled=False,
                             replace=True)
        added.append(("rates_np", env))

    yield register
    for name, env in added:
        unregister(name, env)


def _rates(info, columns: int) -> np.ndarray:
    return np.array([info["reward_terms"][f"rate_{k}"] for k in range(columns)], dtype=float)


def test_a_zero_residual_applies_the_baselines_command(rate_terms):
    rate_terms(OCCLUSION, 8)
    env = gym.make(OCCLUSION, substeps=1, task="hold")
    env.reset(seed=3)
    core = env.unwrapped.core
    for _ in range(5):
        command = core.base_cmd[0].copy()  # the command the next step applies (cached by the last observe)
        _, _, _, _, info = env.step(np.zeros(8, dtype=np.float32))
        rates = _rates(info, 8)
        assert not np.any(info["clamped_joints"]) and not info["rate_saturated"]
        np.testing.assert_allclose(rates, command, rtol=1e-9, atol=1e-12)
        assert info["reward_terms"]["rates_np"] == pytest.approx(rates.sum(), rel=1e-12, abs=1e-15)


def test_without_a_baseline_the_rates_are_the_scaled_action_and_stop_at_a_joint_limit(rate_terms):
    rate_terms(VIEW, 6)
    env = gym.make(VIEW, base_controller=None, task="static")
    env.reset(seed=0)
    action = np.array([0.1, -0.2, 0.05, 0.0, 0.15, -0.1], dtype=np.float32)
    _, _, _, _, info = env.step(action)
    expected = action.astype(float) * ACTION_SCALE  # pure RL: the action times its per-joint rate scale
    assert not info["rate_saturated"]
    np.testing.assert_allclose(_rates(info, 6), expected, rtol=1e-9)
    # Push joint 1 against its upper limit: once there it no longer moves, whatever the action asks.
    push = np.zeros(6, dtype=np.float32)
    push[1] = 1.0
    for _ in range(400):
        _, _, terminated, truncated, info = env.step(push)
        if info["clamped_joints"][1]:
            break
    assert info["clamped_joints"][1]
    env.step(push)
    _, _, _, _, info = env.step(push)
    assert _rates(info, 6)[1] == 0.0


def test_the_endoscope_rate_goes_the_short_way_across_pi(rate_terms):
    rate_terms(OCCLUSION, 8)
    env = gym.make(OCCLUSION, substeps=1, task="hold", visibility_guard=None, base_controller=None)
    env.reset(seed=0)
    core = env.unwrapped.core
    core.gamma[0] = np.pi - 1e-4  # next to the wrap: a positive rate crosses to -pi
    core.observe_rows([0])
    action = np.zeros(8, dtype=np.float32)
    action[7] = 1.0
    _, _, _, _, info = env.step(action)
    assert core.gamma[0] < 0.0  # it crossed
    rate = _rates(info, 8)[7]
    # Pure RL: a full action asks for the rotation's rate scale (at most its limit), not about -2 pi / dt.
    np.testing.assert_allclose(rate, min(core.rate_scale_vec[-1], core.limits.gamma_rate), rtol=1e-9)


def test_the_vector_env_gives_every_row_its_rates(rate_terms):
    rate_terms(VIEW, 6)
    venv = gym.make_vec(VIEW, num_envs=4, vectorization_mode="vector_entry_point", task="static")
    venv.reset(seed=1)
    core = venv.unwrapped.core
    commands = core.base_cmd.copy()
    _, _, _, _, infos = venv.step(np.zeros((4, 6), dtype=np.float32))
    rates = np.stack([infos["reward_terms"][f"rate_{k}"] for k in range(6)], axis=1)
    np.testing.assert_allclose(rates, commands, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(infos["reward_terms"]["rates_np"], rates.sum(axis=1), rtol=1e-12, atol=1e-15)
