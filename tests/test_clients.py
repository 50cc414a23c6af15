"""The environments under the RL clients researchers already use, as those clients call them.

torchrl (single env, its own batched env, and its wrapper around the native vector env, each reading
the info dict), skrl's automatic wrapper detection, and sb3-contrib's TQC on the SB3 adapter.
(SB3, rl_zoo3, Ray Tune and Gymnasium's own vector envs are exercised in tests/agents and tests/envs.)
"""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium.vector import AutoresetMode

import continuum_gym  # noqa: F401  (registers the ids)
from continuum_gym.envs import ContinuumSB3VecEnv

VIEW = "ContinuumGym/ViewTracking-v0"
OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"


@pytest.fixture(autouse=True)
def quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def test_torchrl_reads_the_single_envs_info():
    from torchrl.envs import GymEnv

    env = GymEnv(VIEW, task="random")
    env.auto_register_info_dict()
    td = env.rollout(4)
    assert td["next", "overlap_ratio"].shape == (4,)
    assert td["next", "reward_terms"].shape == (4, len(env._env.unwrapped.core.reward_names))
    assert td["next", "reward_terms"].dtype == torch.float64
    reward = td["next", "reward"].reshape(-1).double()
    terms = td["next", "reward_terms"].sum(-1)
    torch.testing.assert_close(reward, terms, rtol=1e-6, atol=1e-6)  # float32 reward vs float64 terms


def test_torchrl_batches_the_env_itself_and_wraps_the_native_vector_env():
    from torchrl.envs import GymEnv, GymWrapper

    # torchrl's own vector env makes the envs in subprocesses: "module:id" imports the package there
    batched = GymEnv(f"continuum_gym:{VIEW}", num_envs=2, task="random")
    td = batched.rollout(3)
    assert td["next", "overlap_ratio"].shape == (2, 3)
    batched.close()
    native = gym.make_vec(VIEW, num_envs=2, vectorization_mode="vector_entry_point", task="random",
                          autoreset_mode=AutoresetMode.DISABLED, max_episode_steps=2)
    wrapped = GymWrapper(native)
    wrapped.auto_register_info_dict()
    td = wrapped.rollout(5, break_when_any_done=False)
    assert td["next", "overlap_ratio"].shape == (2, 5)
    assert td["next", "truncated"].reshape(2, 5)[:, 1].all()  # episodes of 2 steps, reset by torchrl


def test_skrl_detects_the_native_vector_env():
    from skrl.envs.wrappers.torch import wrap_env

    native = gym.make_vec(OCCLUSION, num_envs=2, vectorization_mode="vector_entry_point")
    env = wrap_env(native, wrapper="auto", verbose=False)
    observation, _ = env.reset()
    assert tuple(observation.shape) == (2, 32)
    observation, reward, terminated, truncated, _ = env.step(torch.zeros((2, 8)))
    assert tuple(reward.shape) == (2, 1) and torch.isfinite(reward).all()


def test_sb3_contrib_tqc_trains_on_the_adapter():
    from sb3_contrib import TQC

    venv = ContinuumSB3VecEnv(VIEW, 2, seed=0, task="random")
    model = TQC("MlpPolicy", venv, learning_starts=16, batch_size=16, buffer_size=500, seed=0, device="cpu",
                policy_kwargs={"net_arch": [16, 16], "n_critics": 2})
    model.learn(64)
    assert model.num_timesteps == 64 and model.replay_buffer.size() == 32
    actions, _ = model.predict(venv.reset(), deterministic=True)
    assert actions.shape == (2, 6) and np.all(np.abs(actions) <= 1.0)
