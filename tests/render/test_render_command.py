"""``continuum-gym render``: the views side by side, ``.png`` stills, the external camera, supersampling, gaps."""

from __future__ import annotations

import gymnasium as gym
import imageio.v2 as imageio
import numpy as np
import pytest

from continuum_gym.cli import main
from continuum_gym.envs.benchmark import benchmark_of
from continuum_gym.envs.spec import get_spec

OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"


def _reference(env_id, steps, size, external_camera=None, seed=0):
    """Each camera's image of the state after ``steps`` zero actions, rendered directly through the scene."""
    spec = get_spec(env_id)
    env = gym.make(env_id, task=benchmark_of(spec).record_task, task_split="test", render_mode="rgb_array")
    env.reset(seed=seed)
    for _ in range(steps):
        env.step(np.zeros(env.action_space.shape, np.float32))
    core, scene = env.unwrapped.core, env.unwrapped.scene()
    if external_camera:
        scene.set_external_camera(**external_camera)
    images = {camera: core.render_row(0, scene, camera, size) for camera in spec.cameras}
    env.close()
    return images


def _render(tmp_path, name, *argv):
    out = tmp_path / name
    assert main(["render", *argv, "--out", str(out), "--no-progress"]) == 0
    return out


def test_png_still_is_every_camera_side_by_side_with_gaps_and_plot(tmp_path):
    size, gap = 48, 3
    out = _render(tmp_path, "still.png", "--env", OCCLUSION, "--steps", "5", "--size", str(size), "--gap", str(gap))
    frame = imageio.imread(out)
    plot = max(size // 4, 24)
    assert frame.shape == (size + plot, 2 * size + gap, 3)
    reference = _reference(OCCLUSION, 5, size)
    np.testing.assert_array_equal(frame[:size, :size], reference["external"])
    assert np.all(frame[:size, size:size + gap] == 255)
    np.testing.assert_array_equal(frame[:size, size + gap:], reference["endoscope"])
    assert not np.array_equal(reference["external"], reference["endoscope"])


def test_view_tracking_frames_are_three_views_wide_without_the_plot(tmp_path):
    size = 32
    out = _render(tmp_path, "still.png", "--env", VIEW, "--steps", "3", "--size", str(size), "--no-plot")
    frame = imageio.imread(out)
    assert frame.shape == (size, 3 * size, 3)
    reference = _reference(VIEW, 3, size)
    for k, camera in enumerate(("external", "endoscope", "davinci")):
        np.testing.assert_array_equal(frame[:, k * size:(k + 1) * size], reference[camera], err_msg=camera)


def test_external_camera_flags_move_the_external_view_only(tmp_path):
    size = 40
    camera = dict(azimuth=30.0, elevation=20.0, distance=0.2, target=(0.0, 0.01, 0.03))
    out = _render(tmp_path, "moved.png", "--env", OCCLUSION, "--steps", "2", "--size", str(size), "--no-plot",
                  "--azimuth", "30", "--elevation", "20", "--distance", "0.2", "--target", "0", "0.01", "0.03")
    frame = imageio.imread(out)
    moved, default = _reference(OCCLUSION, 2, size, camera), _reference(OCCLUSION, 2, size)
    np.testing.assert_array_equal(frame[:, :size], moved["external"])
    assert not np.array_equal(moved["external"], default["external"])
    np.testing.assert_array_equal(frame[:, size:], default["endoscope"])


def test_supersample_averages_blocks_of_the_larger_render(tmp_path):
    size, k = 24, 2
    out = _render(tmp_path, "smooth.png", "--env", OCCLUSION, "--steps", "2", "--size", str(size), "--no-plot",
                  "--supersample", str(k))
    frame = imageio.imread(out)
    assert frame.shape == (size, 2 * size, 3)
    large = _reference(OCCLUSION, 2, size * k)
    expected = [np.rint(large[c].reshape(size, k, size, k, 3).mean(axis=(1, 3))).astype(np.uint8)
                for c in ("external", "endoscope")]
    np.testing.assert_array_equal(frame, np.concatenate(expected, axis=1))


def test_gif_frames_read_back_close_to_the_renders(tmp_path):
    size = 40
    common = ["--env", OCCLUSION, "--size", str(size), "--gap", "2", "--steps", "6"]
    gif = _render(tmp_path, "episode.gif", *common, "--every", "3")
    still = imageio.imread(_render(tmp_path, "last.png", *common))
    frames = imageio.mimread(gif)
    assert len(frames) == 2 and frames[-1].shape[:2] == still.shape[:2]
    # one palette for all frames and differences stored as transparency: the last frame, composited over
    # the first, is still the render of the last step up to the palette's rounding
    assert np.abs(frames[-1][..., :3].astype(int) - still).mean() < 4.0
    assert not np.array_equal(frames[0], frames[-1])


BAD = [
    ("--supersample", ["0"]), ("--supersample", ["5"]), ("--supersample", ["abc"]),
    ("--gap", ["-1"]), ("--gap", ["1000"]), ("--gap", ["abc"]),
    ("--azimuth", ["nan"]), ("--azimuth", ["inf"]), ("--azimuth", ["abc"]),
    ("--elevation", ["90"]), ("--elevation", ["-90"]), ("--elevation", ["nan"]),
    ("--distance", ["0"]), ("--distance", ["-0.1"]), ("--distance", ["2"]), ("--distance", ["nan"]),
    ("--target", ["nan", "0", "0"]), ("--target", ["0", "0"]), ("--target", ["0", "inf", "0"]),
    ("--out", ["x.jpg"]), ("--size", ["2048", "--supersample", "3"]),
]


@pytest.mark.parametrize("flag,values", BAD, ids=lambda x: str(x))
def test_bad_values_exit_2_naming_the_flag_and_write_nothing(flag, values, tmp_path, capsys):
    argv = ["render", "--env", OCCLUSION, "--steps", "2", "--no-progress"]
    if flag != "--out":
        argv += ["--out", str(tmp_path / "out.png")]
    argv += [flag, *values]
    try:
        code = main(argv)
    except SystemExit as exit_:  # argparse's own refusal
        code = exit_.code
    err = capsys.readouterr().err
    assert code == 2, err
    assert "continuum-gym render" in err and "Traceback" not in err
    assert flag in err, err
    assert not list(tmp_path.iterdir())


def test_set_external_camera_validates_and_keeps_the_other_values():
    from continuum_gym.render import OcclusionScene

    with OcclusionScene() as scene:
        before = dict(scene.external_camera)
        p0, _ = scene.camera_pose("external")
        scene.set_external_camera(azimuth=before["azimuth"] + 90.0)
        assert scene.external_camera == {**before, "azimuth": before["azimuth"] + 90.0}
        p1, R1 = scene.camera_pose("external")
        target = np.asarray(before["target"])
        assert np.isclose(np.linalg.norm(p1 - target), before["distance"]) and not np.allclose(p0, p1)
        np.testing.assert_allclose(R1[:, 2], (target - p1) / np.linalg.norm(target - p1), atol=1e-12)
        for kwargs, name in ((dict(distance=0.0), "distance"), (dict(elevation=90.0), "elevation"),
                             (dict(fov=180.0), "fov"), (dict(target=(0.0, np.nan, 0.0)), "target"),
                             (dict(target=[[0.0, 0.0, 0.0]] * 2), "target"), (dict(azimuth="north"), "azimuth")):
            with pytest.raises(ValueError, match=name):
                scene.set_external_camera(**kwargs)
        assert scene.external_camera["azimuth"] == before["azimuth"] + 90.0  # a refused call changes nothing
