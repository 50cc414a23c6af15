"""The public camera model: projection against independent computation, distortion round trips, conventions."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from continuum_gym.camera.model import Cameras, distort, intrinsics, k1_lower_bound, pose_matrix, undistort
from continuum_gym.render.camera import pixel_rays as pybullet_pixel_rays
from continuum_gym.render.camera import projection_matrix, view_matrix_from_frame

ROOT = Path(__file__).resolve().parents[2]


def random_cameras(n: int = 16, width: int = 64, height: int = 48, seed: int = 0, k1: float = 0.0) -> Cameras:
    rng = np.random.default_rng(seed)
    R = Rotation.random(n, random_state=seed).as_matrix()
    p = rng.uniform(-0.1, 0.1, (n, 3))
    return Cameras.from_frames(p, R, width, height, rng.uniform(0.5, 1.5), k1=k1)


def test_a_point_on_the_optical_axis_lands_on_the_principal_point():
    cams = random_cameras()
    points = cams.positions + 0.07 * cams.rotations[:, :, 2]
    uv = cams.project(points)
    np.testing.assert_allclose(uv, cams.intrinsics[:, :2, 2], atol=1e-9)
    np.testing.assert_allclose(cams.depth(points), 0.07, atol=1e-15)


def test_project_is_the_closed_form_pinhole():
    cams = random_cameras(seed=1)
    rng = np.random.default_rng(1)
    local = np.column_stack([rng.uniform(-0.02, 0.02, 16), rng.uniform(-0.02, 0.02, 16), rng.uniform(0.01, 0.2, 16)])
    world = np.einsum("nij,nj->ni", cams.rotations, local) + cams.positions  # x = R X + p
    K = cams.intrinsics
    expected = np.column_stack([K[:, 0, 0] * local[:, 0] / local[:, 2] + K[:, 0, 2],
                                K[:, 1, 1] * local[:, 1] / local[:, 2] + K[:, 1, 2]])
    np.testing.assert_allclose(cams.project(world), expected, rtol=1e-12)
    # a batch of points per row, and points shared by every row
    both = np.stack([world, world], axis=1)
    np.testing.assert_allclose(cams.project(both)[:, 1], expected, rtol=1e-12)
    assert cams.project(np.zeros(3)).shape == (16, 2)


def test_points_behind_the_camera_have_no_image():
    cams = random_cameras(seed=2)
    behind = cams.positions - 0.05 * cams.rotations[:, :, 2]
    assert np.all(np.isnan(cams.project(behind)))


def test_the_intrinsics_sample_pybullets_pixels():
    """The default principal point (W/2, H/2 - 1) gives pybullet's TinyRenderer samples; the camera frame and
    the OpenGL matrices of ``render.camera`` project a point to the same pixel."""
    width, height, fov = 64, 48, 0.9
    K = intrinsics(width, height, fov)
    cams = Cameras(K[None], pose_matrix(np.zeros(3), np.eye(3))[None], width, height)
    np.testing.assert_allclose(cams.pixel_rays()[0], pybullet_pixel_rays(width, height, fov), atol=1e-12)
    # OpenGL: clip = P V x; column = (x_ndc + 1) W / 2, row = (1 - y_ndc) H / 2 - 1 (TinyRenderer, flipped)
    rng = np.random.default_rng(3)
    p = rng.normal(0.0, 0.05, 3)
    R = Rotation.random(random_state=3).as_matrix()
    cams = Cameras(K[None], pose_matrix(p, R)[None], width, height)
    X = p + R @ np.array([0.01, -0.02, 0.1])
    P = np.array(projection_matrix(fov, width / height)).reshape(4, 4).T
    clip = P @ view_matrix_from_frame(p, R) @ np.append(X, 1.0)
    ndc = clip[:2] / clip[3]
    expected = [(ndc[0] + 1.0) * width / 2.0, (1.0 - ndc[1]) * height / 2.0 - 1.0]
    np.testing.assert_allclose(cams.project(X)[0], expected, rtol=1e-6)  # pybullet's matrices are float32
    centred = intrinsics(width, height, fov, centred=True)
    np.testing.assert_allclose(centred[:2, 2], [(width - 1) / 2, (height - 1) / 2])
    assert centred[0, 0] == K[0, 0] == pytest.approx(height / 2 / math.tan(fov / 2))


@pytest.mark.parametrize("k1", [-0.25, -0.05, 0.1, 0.8])
def test_distortion_round_trip(k1):
    rng = np.random.default_rng(4)
    limit = 0.99 * math.sqrt(-1.0 / (3.0 * k1)) if k1 < 0 else 2.0  # the invertible range
    x, y = rng.uniform(-limit, limit, (2, 500)) / math.sqrt(2.0)
    xd, yd = distort(x, y, k1)
    xu, yu = undistort(xd, yd, k1)
    np.testing.assert_allclose(xu, x, atol=1e-12)
    np.testing.assert_allclose(yu, y, atol=1e-12)
    assert np.all(np.sign(xd) == np.sign(x))


def test_distorted_pixel_rays_project_back_to_their_pixels():
    cams = random_cameras(n=3, seed=5, k1=-0.03)
    rays = cams.pixel_rays()  # (3, H, W, 3), z = 1
    world = np.einsum("nij,nhwj->nhwi", cams.rotations, 0.05 * rays) + cams.positions[:, None, None]
    uv = cams.project(world)
    columns, rows = np.meshgrid(np.arange(cams.width), np.arange(cams.height))
    np.testing.assert_allclose(uv[..., 0], np.broadcast_to(columns, uv.shape[:-1]), atol=1e-9)
    np.testing.assert_allclose(uv[..., 1], np.broadcast_to(rows, uv.shape[:-1]), atol=1e-9)


def test_the_fov_mask_is_the_ray_angle():
    cams = random_cameras(n=2, seed=6)
    half = 0.3
    rays = cams.pixel_rays()
    angle = np.arctan(np.hypot(rays[..., 0], rays[..., 1]))
    np.testing.assert_array_equal(cams.fov_mask(half), angle <= half)


def test_bad_input_is_refused_with_the_parameter_named():
    good = random_cameras(n=2)
    with pytest.raises(ValueError, match="intrinsics"):
        Cameras(np.ones((2, 3, 3)), good.poses, 64, 48)
    with pytest.raises(ValueError, match="poses"):
        Cameras(good.intrinsics, good.poses * 2.0, 64, 48)
    with pytest.raises(ValueError, match="far"):
        Cameras(good.intrinsics, good.poses, 64, 48, near=0.5, far=0.1)
    with pytest.raises(ValueError, match="k1 must be >"):
        good.with_distortion(-10.0)
    with pytest.raises(ValueError, match="width"):
        intrinsics(0, 48, 1.0)
    with pytest.raises(ValueError, match="fov_y"):
        intrinsics(64, 48, math.pi)
    assert k1_lower_bound(1.0) == pytest.approx(-4.0 / 27.0)


def test_the_docs_example_runs_as_written():
    """docs/rendering.md's worked ``project()`` example: its printed values are what the code prints."""
    page = (ROOT / "docs" / "rendering.md").read_text()
    block = re.search(r"```python\n(# worked project\(\) example.*?)```", page, re.S)
    assert block is not None, "docs/rendering.md lost its worked project() example"
    code = block.group(1)
    expected = re.findall(r"#> (.*)", code)
    assert expected
    printed: list[str] = []
    exec(compile(code, "rendering.md", "exec"), {"print": lambda *a: printed.append(" ".join(map(str, a)))})
    assert printed == expected
    # and the page's other examples run
    for other in re.findall(r"```python\n(.*?)```", page, re.S):
        if other != code:
            namespace: dict = {}
            exec(compile(other, "rendering.md", "exec"), namespace)
            assert "frames" in namespace
