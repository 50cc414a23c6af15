"""Minari datasets of the baselines: written, loaded back equal to a fresh rollout, and clonable."""

from __future__ import annotations

import warnings

import gymnasium as gym
import minari
import numpy as np
import pytest
import torch

from continuum_gym.cli import main
from continuum_gym.evaluation.datasets import create_dataset, dataset_id

VIEW = "ContinuumGym/ViewTracking-v0"
OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"


@pytest.fixture
def root(tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    return tmp_path


def test_a_dataset_round_trips_equal_to_a_fresh_rollout(root):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        dataset = create_dataset(VIEW, "resolved_rate", split="validation", episodes=2, noise=0.3, seed=4)
    assert not [w for w in caught if "is set to None" in str(w.message)], [str(w.message) for w in caught]
    name = "continuum-gym/ViewTracking/resolved_rate-validation-noise0p3-v0"
    assert dataset.spec.dataset_id == name == dataset_id(VIEW, "resolved_rate", "validation", 0.3)
    loaded = minari.load_dataset(name)
    assert loaded.total_episodes == 2
    # The project has no public address: no metadata field points at one.
    metadata = loaded.storage.metadata
    assert metadata["author"] == {"continuum-gym"} and not {"code_permalink", "author_email"} & set(metadata)
    env = loaded.recover_environment()
    config = env.spec.kwargs["config"]  # the whole config, as EnvConfig.to_dict writes it
    assert config["base_controller"] == "resolved_rate" and config["task_split"] == "validation"
    for k, episode in enumerate(loaded.iterate_episodes()):
        obs, _ = env.reset(seed=4 + k, options={"task_id": k})
        np.testing.assert_array_equal(episode.observations[0], obs)
        rewards = []
        for action in episode.actions:  # replaying the recorded actions reproduces the episode exactly
            obs, reward, terminated, truncated, info = env.step(action)
            rewards.append(reward)
        np.testing.assert_array_equal(episode.observations[-1], obs)
        np.testing.assert_array_equal(episode.rewards, rewards)
        assert episode.truncations[-1] and not episode.terminations.any()
        np.testing.assert_allclose(episode.infos["reward_terms"][1:].sum(axis=1), episode.rewards, rtol=1e-12)
        assert 0.05 < episode.actions.std() < 0.35  # noise 0.3, a few actions clipped at +-1
    with pytest.raises(FileExistsError, match="overwrite"):
        create_dataset(VIEW, "resolved_rate", split="validation", episodes=1, noise=0.3, seed=4)


def test_behaviour_cloning_on_a_dataset_recovers_the_baseline(root):
    """BC of the noisy baseline learns the behaviour's mean residual (zero), i.e. the baseline itself.

    On the occlusion env, whose closed loop is smooth (the view-tracking loop amplifies small residuals)."""
    dataset = create_dataset(OCCLUSION, "projected_gradient", episodes=12, noise=0.2, seed=0)
    obs = torch.tensor(np.concatenate([e.observations[:-1] for e in dataset.iterate_episodes()]))
    actions = torch.tensor(np.concatenate([e.actions for e in dataset.iterate_episodes()]))
    torch.manual_seed(0)
    policy = torch.nn.Linear(32, 8)  # few parameters for the ~2 k samples: it cannot memorise the noise
    optimiser = torch.optim.Adam(policy.parameters(), lr=1e-2)
    for _ in range(400):
        loss = torch.nn.functional.mse_loss(policy(obs), actions)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    assert loss.item() == pytest.approx(0.2**2, rel=0.25)  # the noise is unpredictable: its variance remains
    env, baseline = (gym.make(OCCLUSION, base_controller="projected_gradient") for _ in range(2))
    obs, _ = env.reset(seed=9, options={"task_id": 3})
    baseline.reset(seed=9, options={"task_id": 3})
    cloned, reference, magnitudes = [], [], []
    done = False
    while not done:
        with torch.no_grad():
            a = policy(torch.tensor(obs)[None])[0].numpy()
        magnitudes.append(np.abs(a).mean())
        obs, _, terminated, truncated, info = env.step(a)
        done = terminated or truncated
        cloned.append(info["voi"])
        reference.append(baseline.step(np.zeros(8, dtype=np.float32))[4]["voi"])
    assert np.mean(magnitudes) < 0.05  # near the behaviour's zero mean (the noise alone: 0.16)
    assert np.mean(cloned) == pytest.approx(np.mean(reference), rel=0.1, abs=1e-3)


def test_the_cli_writes_datasets_and_names_bad_arguments(root, capsys):
    assert main(["dataset", "--env", VIEW, "--controller", "resolved_rate", "--episodes", "1", "--no-progress"]) == 0
    assert "continuum-gym/ViewTracking/resolved_rate-train-v0" in minari.list_local_datasets()
    assert main(["dataset", "--env", VIEW, "--controller", "nope", "--episodes", "1"]) == 2
    assert "controller" in capsys.readouterr().err
    assert main(["dataset", "--env", VIEW, "--episodes", "0"]) == 2
    assert "episodes" in capsys.readouterr().err
    assert main(["dataset", "--env", VIEW, "--controller", "resolved_rate", "--episodes", "1"]) == 2
    assert "overwrite" in capsys.readouterr().err


def test_a_dataset_of_a_recorded_task_and_another_robot_rebuilds_them(root):
    """Minari stores the env's config as plain JSON: a robot and a cone as their fields, a recorded task as its
    samples (Minari itself would flatten the objects into dicts no constructor takes; issue 54, item 2)."""
    from continuum_gym.envs import TipTrajectory
    from continuum_gym.geometry import LensCone
    from continuum_gym.robots import MultiBackboneRobot

    robot = MultiBackboneRobot(lengths=(0.018,) * 4)
    p0, R0 = robot.forward_kinematics(robot.home)
    t = np.linspace(0.0, 1.0, 11)
    path = p0 + 0.002 * np.stack([np.sin(3 * t), np.cos(3 * t) - 1, t], axis=1)
    task = TipTrajectory(t, path, np.broadcast_to(R0, (11, 3, 3)), start_q=robot.home)
    kwargs = {"robot": robot, "cone": LensCone(alpha=np.radians(45.0)), "task": task}
    create_dataset(OCCLUSION, "minimum_norm", episodes=1, seed=2, env_kwargs=kwargs)
    env = minari.load_dataset("continuum-gym/OcclusionAvoidance/minimum_norm-train-v0").recover_environment()
    config = env.unwrapped.config
    assert config.robot.lengths == robot.lengths and np.isclose(config.cone.alpha, np.radians(45.0))
    env.reset(seed=2, options={"task_id": 0})
    for time in (0.0, 0.37, 0.9):  # the rebuilt spline is the recorded one, bit for bit
        np.testing.assert_array_equal(env.unwrapped.core.desired(0, time)[0], gym.make(
            OCCLUSION, **kwargs).unwrapped.core.desired(0, time)[0])


def test_a_key_a_wrapper_adds_on_the_last_step_only_is_not_recorded(root, monkeypatch):
    # rl_zoo3, once imported in a process, patches Gymnasium's TimeLimit to add info["TimeLimit.truncated"] on the
    # step that ends an episode: the info keys then differ between steps, which Minari cannot store
    class LastStepKey(gym.wrappers.TimeLimit):
        def step(self, action):
            obs, reward, terminated, truncated, info = super().step(action)
            if terminated or truncated:
                info["TimeLimit.truncated"] = truncated
            return obs, reward, terminated, truncated, info

    monkeypatch.setattr(gym.wrappers, "TimeLimit", LastStepKey)
    dataset = create_dataset(OCCLUSION, "projected_gradient", split="validation", episodes=1,
                             env_kwargs={"task": "hold", "max_episode_steps": 3})
    episode = next(dataset.iterate_episodes())
    assert len(episode.actions) == 3 and "TimeLimit.truncated" not in episode.infos
