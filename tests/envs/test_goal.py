"""Goal-conditioned variants: rewards are a function of the goals, batched, and HER trains on them."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import continuum_gym  # noqa: F401  (registers the ids)

GOALS = {"ContinuumGym/OcclusionAvoidanceGoal-v0": 8, "ContinuumGym/ViewTrackingGoal-v0": 6}  # action sizes
GOAL_SIZES = {"ContinuumGym/OcclusionAvoidanceGoal-v0": 7, "ContinuumGym/ViewTrackingGoal-v0": 6}


@pytest.mark.parametrize("env_id", sorted(GOALS))
@pytest.mark.parametrize("reward_type", ["dense", "sparse"])
def test_the_reward_is_compute_reward_of_the_goals_batched_or_not(env_id, reward_type):
    env = gym.make(env_id, reward_type=reward_type, task="random")
    obs, _ = env.reset(seed=3)
    rng = np.random.default_rng(0)
    achieved, desired, infos, rewards = [], [], [], []
    for _ in range(12):
        obs, reward, _, _, info = env.step(rng.uniform(-1, 1, GOALS[env_id]).astype(np.float32))
        assert env.observation_space.contains(obs)
        achieved.append(obs["achieved_goal"])
        desired.append(obs["desired_goal"])
        infos.append(info)
        rewards.append(reward)
    batched = env.unwrapped.compute_reward(np.array(achieved), np.array(desired), np.array(infos, dtype=object))
    np.testing.assert_allclose(batched, rewards, rtol=0, atol=1e-12)
    size = GOAL_SIZES[env_id]
    grid = env.unwrapped.compute_reward(np.array(achieved).reshape(3, 4, size), np.array(desired).reshape(3, 4, size),
                                        np.array(infos, dtype=object).reshape(3, 4))
    np.testing.assert_allclose(grid.reshape(-1), rewards, rtol=0, atol=1e-12)
    if reward_type == "dense" and "ViewTracking" in env_id:  # the reward is the env's own overlap ratio
        np.testing.assert_allclose(rewards, [i["overlap_ratio"] for i in infos], rtol=0, atol=1e-9)
    if "Occlusion" in env_id:  # the achieved goal carries the state's VOI; the reward needs no info
        np.testing.assert_array_equal(np.array(achieved)[:, 6], [i["voi"] for i in infos])
        no_info = env.unwrapped.compute_reward(np.array(achieved), np.array(desired), {})
        np.testing.assert_allclose(no_info, rewards, rtol=0, atol=1e-12)
    if reward_type == "sparse":
        assert set(rewards) <= {0.0, -1.0}
    # a goal achieved exactly is the best reward there is
    best = env.unwrapped.compute_reward(np.array(desired), np.array(desired), np.array(infos, dtype=object))
    assert np.all(best >= np.array(rewards) - 1e-12)


@pytest.mark.parametrize("env_id", sorted(GOALS))
def test_goal_envs_pass_the_checker_and_refuse_bad_arguments(env_id):
    check_env(gym.make(env_id).unwrapped, skip_render_check=True)
    with pytest.raises(ValueError, match="reward_type"):
        gym.make(env_id, reward_type="shaped")
    with pytest.raises(ValueError, match="achieved_goal"):
        gym.make(env_id).unwrapped.compute_reward(np.zeros(5), np.zeros(GOAL_SIZES[env_id]), {})


def test_sac_with_hindsight_relabelling_trains_on_the_view_goal():
    from stable_baselines3 import SAC, HerReplayBuffer

    env = gym.make("ContinuumGym/ViewTrackingGoal-v0", task="random", max_episode_steps=25)
    model = SAC("MultiInputPolicy", env, replay_buffer_class=HerReplayBuffer, learning_starts=60, batch_size=32,
                replay_buffer_kwargs={"n_sampled_goal": 4, "goal_selection_strategy": "future"}, seed=0,
                device="cpu", policy_kwargs={"net_arch": [32, 32]})
    model.learn(150)
    assert model.num_timesteps == 150
    samples = model.replay_buffer.sample(64)
    # the da Vinci moves: a step's reward is that of the goal in the observation it returns (next_obs);
    # relabelled samples carry their new goal in both observations
    relabelled = env.unwrapped.compute_reward(samples.next_observations["achieved_goal"].numpy(),
                                              samples.next_observations["desired_goal"].numpy(), {})
    np.testing.assert_allclose(samples.rewards.numpy().reshape(-1), relabelled, rtol=1e-6, atol=1e-6)
    # with "future" relabelling some desired goals are goals achieved later in the episode, not the da Vinci's
    stored = model.replay_buffer.observations["desired_goal"][:150].reshape(-1, 6)
    drawn = samples.observations["desired_goal"].numpy()
    assert any(not np.any(np.all(np.isclose(goal, stored, atol=1e-6), axis=1)) for goal in drawn)


@pytest.mark.parametrize("env_id", sorted(GOALS))
def test_every_goal_id_trains_with_her_at_its_default_episodes(env_id):
    """SB3's HerReplayBuffer at its defaults (no info dicts kept) relabels episodes of the env's own length."""
    from stable_baselines3 import SAC, HerReplayBuffer

    env = gym.make(env_id)
    model = SAC("MultiInputPolicy", env, replay_buffer_class=HerReplayBuffer, learning_starts=1100, batch_size=64,
                replay_buffer_kwargs={"n_sampled_goal": 4, "goal_selection_strategy": "future"}, seed=0,
                device="cpu", policy_kwargs={"net_arch": [32, 32]})
    model.learn(1300)
    buffer = model.replay_buffer
    assert model.num_timesteps == 1300 and buffer.ep_length.max() > 0  # an episode ended before sampling
    samples = buffer.sample(128)
    relabelled = env.unwrapped.compute_reward(samples.next_observations["achieved_goal"].numpy(),
                                              samples.next_observations["desired_goal"].numpy(), {})
    np.testing.assert_allclose(samples.rewards.numpy().reshape(-1), relabelled, rtol=1e-5, atol=1e-5)
