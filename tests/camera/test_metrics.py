"""The pixel metrics against brute-force numpy computations."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from continuum_gym.camera import occlusion_fraction, view_centre_error
from continuum_gym.camera.model import Cameras


def cameras(n: int, k1: float = 0.0, seed: int = 0, width: int = 48, height: int = 40) -> Cameras:
    rng = np.random.default_rng(seed)
    return Cameras.from_frames(rng.uniform(-0.05, 0.05, (n, 3)), Rotation.random(n, random_state=seed).as_matrix(),
                               width, height, 0.9, k1=k1)


@pytest.mark.parametrize("k1", [0.0, -0.05, 0.3])
def test_occlusion_fraction_is_the_covered_share_of_the_circle(k1):
    rng = np.random.default_rng(1)
    cams = cameras(12, k1)
    seg = rng.integers(0, 6, (12, cams.height, cams.width, 1), dtype=np.uint8)
    seg[3] = 0  # nothing covered
    half = 0.35
    rays = cams.pixel_rays()
    inside = np.hypot(rays[..., 0], rays[..., 1]) <= math.tan(half)  # brute force: each pixel's ray angle
    robot = (seg[..., 0] >= 1) & (seg[..., 0] <= 3)
    expected = (robot & inside).sum(axis=(1, 2)) / inside.sum(axis=(1, 2))
    np.testing.assert_allclose(occlusion_fraction(seg, cams, half, 3), expected, rtol=1e-12)
    assert occlusion_fraction(seg, cams, half, 3)[3] == 0.0
    # an explicit id range: the other endoscope (id 4) alone
    other = ((seg[..., 0] == 4) & inside).sum(axis=(1, 2)) / inside.sum(axis=(1, 2))
    np.testing.assert_allclose(occlusion_fraction(seg, cams, half, (4, 4)), other, rtol=1e-12)


def test_view_centre_error_is_the_distance_from_the_principal_point():
    cams = cameras(20, seed=2)
    rng = np.random.default_rng(2)
    local = np.column_stack([rng.uniform(-0.08, 0.08, 20), rng.uniform(-0.08, 0.08, 20), rng.uniform(0.02, 0.1, 20)])
    local[0] = [0.0, 0.0, 0.05]  # on the optical axis: 0
    local[1] = [0.0, 0.0, -0.05]  # behind the camera: inf
    local[2] = [0.01, 0.0, -1e-6]  # just behind the camera plane: inf
    world = np.einsum("nij,nj->ni", cams.rotations, local) + cams.positions
    error, in_image = view_centre_error(cams, world)
    uv = cams.project(world)
    front = local[:, 2] > 0
    expected = 100.0 * np.hypot(*(uv - cams.intrinsics[:, :2, 2]).T) / cams.width
    np.testing.assert_allclose(error[front], expected[front], rtol=1e-12, atol=1e-9)
    assert error[0] == pytest.approx(0.0, abs=1e-9) and np.isinf(error[1]) and np.isinf(error[2])
    inside = (uv[:, 0] >= -0.5) & (uv[:, 0] <= cams.width - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] <= cams.height - 0.5)
    np.testing.assert_array_equal(in_image, front & inside)
    assert np.any(front & ~inside) and np.all(np.isfinite(error[front]))  # outside the image: finite, flagged
    assert np.all(error[front & ~inside] > 50.0 * min(1.0, cams.height / cams.width))


def test_metrics_refuse_what_they_cannot_measure():
    cams = cameras(2)
    with pytest.raises(ValueError, match="segmentation"):
        occlusion_fraction(np.zeros((2, 40, 48), np.uint8), cams, 0.3, 3)
    with pytest.raises(ValueError, match="cameras"):
        occlusion_fraction(np.zeros((2, 10, 10, 1), np.uint8), cams, 0.3, 3)
    with pytest.raises(ValueError, match="half_angle"):
        occlusion_fraction(np.zeros((2, 40, 48, 1), np.uint8), cams, 2.0, 3)
    with pytest.raises(ValueError, match="points"):
        view_centre_error(cams, np.zeros((3, 3)))
