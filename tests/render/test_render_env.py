"""Rendering through the environments (Gymnasium's render_mode) and the ``continuum-gym render`` command."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import continuum_gym
from continuum_gym.cli import main


@pytest.mark.parametrize("env_id", continuum_gym.ENV_IDS)
@pytest.mark.parametrize("camera", ["external", "endoscope"])
def test_rgb_array_render_mode(env_id, camera):
    env = gym.make(env_id, render_mode="rgb_array", camera=camera)
    assert "rgb_array" in env.metadata["render_modes"] and env.metadata["render_fps"] == 100
    env.reset(seed=0)
    first = env.render()
    assert first.dtype == np.uint8 and first.ndim == 3 and first.shape[2] == 3
    for _ in range(20):
        env.step(env.action_space.sample())
    assert not np.array_equal(first, env.render())  # the picture follows the state
    env.close()


def test_pixel_occlusion_in_info_only_when_asked():
    env = gym.make("ContinuumGym/OcclusionAvoidance-v0", pixel_occlusion=True)
    _, info = env.reset(seed=0)
    assert 0.0 < info["pixel_occlusion"] < 1.0  # hold starts have VOI 0.2-0.3: the robot is in the image
    _, info = gym.make("ContinuumGym/OcclusionAvoidance-v0").reset(seed=0)
    assert "pixel_occlusion" not in info


def test_render_without_mode_warns_and_returns_none():
    env = gym.make("ContinuumGym/ViewTracking-v0").unwrapped
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None


def test_record_command_writes_a_gif(tmp_path):
    out = tmp_path / "episode.gif"
    assert main(["render", "--env", "ContinuumGym/OcclusionAvoidance-v0", "--out", str(out), "--steps", "6",
                 "--every", "3", "--size", "64"]) == 0
    import imageio.v2 as imageio

    frames = imageio.mimread(out)
    assert len(frames) == 2 and frames[0].shape[0] > 64


def test_record_command_rejects_bad_input(tmp_path):
    assert main(["render", "--env", "ContinuumGym/Nope-v0", "--out", str(tmp_path / "a.gif")]) == 2
    assert main(["render", "--env", "ContinuumGym/ViewTracking-v0", "--out", str(tmp_path / "a.avi")]) == 2
    assert main(["render", "--env", "ContinuumGym/ViewTracking-v0", "--policy", "no_such_policy",
                 "--out", str(tmp_path / "a.gif")]) == 2
    assert not list(tmp_path.iterdir())
