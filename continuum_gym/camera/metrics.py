"""Metrics measured in the rendered images, per row of a batch (compiled: a batch of 1024 rows costs ~1 ms).

- ``occlusion_fraction``: OcclusionAvoidance's pixel occlusion, the fraction of the circular field of view
  (pixels whose ray lies within the half-angle beta of the optical axis) that the robot covers
  (segmentation ids 1..n; the other endoscope, n + 1, does not count). The pybullet scenes' measure
  (``render.OcclusionScene.pixel_occlusion``) renders the robot without the tissue, so that robot parts
  beyond the tissue count; the same number comes from a scene built with ``tissue=False``. With the tissue
  drawn, only what the camera sees counts.
- ``view_centre_error``: ViewTracking's view-centre error (LapGym's SearchForPoint metric): the distance in
  the image between where a point (the da Vinci view's centre, ``DaVinciEndoscope.target_point``) appears and
  the principal point (where the continuum endoscope's own view centre appears), as a percentage of the
  image width. A point in front of the camera has a finite error also when it lands outside the image
  (more than 50 % across, and ``in_image`` False); a point at or behind the camera plane (camera z <= 0) has
  no image: its error is ``inf``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.camera.model import Cameras
from continuum_gym.camera.raster import fill_rays, fill_spans
from continuum_gym.robots.compiled import kernel
from continuum_gym.validation import as_finite, integer, number

__all__ = ["occlusion_fraction", "view_centre_error"]


@kernel(nogil=True, error_model="numpy")
def occlusion_rows(segmentation, K, k1, fov_tan, first_id, last_id, out):
    """Per row: the fraction of the pixels within the circular field of view with an id in [first_id, last_id]."""
    n, height, width = segmentation.shape[0], segmentation.shape[1], segmentation.shape[2]
    xs = np.empty(width)
    ys = np.empty(height)
    rays = np.empty((height, width, 2))
    spans = np.empty((height, 2), dtype=np.int64)
    for row in range(n):
        fill_rays(K[row], k1[row], width, height, xs, ys, rays)
        fill_spans(width, height, k1[row] != 0.0, xs, ys, rays, fov_tan, spans)
        inside = 0
        covered = 0
        for i in range(height):
            for j in range(spans[i, 0], spans[i, 1] + 1):
                inside += 1
                label = segmentation[row, i, j, 0]
                if first_id <= label <= last_id:
                    covered += 1
        out[row] = covered / inside if inside > 0 else 0.0


@kernel(error_model="numpy")
def centre_error_rows(points, T, K, k1, width, height, error, in_image):
    """Per row: 100 |project(point) - principal point| / width (inf at or behind the camera plane)."""
    for row in range(points.shape[0]):
        d0 = points[row, 0] - T[row, 0, 3]
        d1 = points[row, 1] - T[row, 1, 3]
        d2 = points[row, 2] - T[row, 2, 3]
        x = T[row, 0, 0] * d0 + T[row, 1, 0] * d1 + T[row, 2, 0] * d2
        y = T[row, 0, 1] * d0 + T[row, 1, 1] * d1 + T[row, 2, 1] * d2
        z = T[row, 0, 2] * d0 + T[row, 1, 2] * d1 + T[row, 2, 2] * d2
        if z <= 0.0:
            error[row] = math.inf
            in_image[row] = False
            continue
        x /= z
        y /= z
        g = 1.0 + k1[row] * (x * x + y * y)
        du = K[row, 0, 0] * x * g
        dv = K[row, 1, 1] * y * g
        u = du + K[row, 0, 2]
        v = dv + K[row, 1, 2]
        error[row] = 100.0 * math.sqrt(du * du + dv * dv) / width
        in_image[row] = -0.5 <= u <= width - 0.5 and -0.5 <= v <= height - 0.5


def occlusion_fraction(segmentation: np.ndarray, cameras: Cameras, half_angle: float,
                       robot_ids: int | tuple[int, int]) -> np.ndarray:
    """Fraction (N,) of each row's circular field of view covered by the robot.

    Args:
        segmentation: (N, H, W, 1) uint8, as ``Renderer.render`` writes it.
        cameras: the ``Cameras`` the images were taken with (``Frames.cameras``: distortion included).
        half_angle: the field of view's half-angle (rad), e.g. the lens cone's beta.
        robot_ids: n (ids 1..n count: ``Scene.n_segments``) or an inclusive (first, last) range.
    """
    seg = np.asarray(segmentation)
    if seg.dtype != np.uint8 or seg.ndim != 4 or seg.shape[3] != 1:
        raise ValueError(f"segmentation must be (N, H, W, 1) uint8; got {seg.dtype} {seg.shape}")
    if not isinstance(cameras, Cameras) or seg.shape[:3] != (cameras.num_rows, cameras.height, cameras.width):
        raise ValueError("cameras must be the Cameras of the images (one per row, their width and height)")
    half_angle = number(half_angle, "half_angle", low=0.0, high=math.pi / 2, low_open=True, high_open=True,
                        unit="rad")
    if isinstance(robot_ids, tuple):
        first, last = (integer(v, "robot_ids", low=0, high=255) for v in robot_ids)
    else:
        first, last = 1, integer(robot_ids, "robot_ids", low=1, high=255)
    out = np.empty(seg.shape[0])
    occlusion_rows(np.ascontiguousarray(seg), cameras.intrinsics, cameras.k1, math.tan(half_angle), first, last, out)
    return out


def view_centre_error(cameras: Cameras, points: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """View-centre error (N,) in % of the image width and whether each point lands in the image (N,) bool.

    Args:
        cameras: the continuum endoscope's ``Cameras`` (``scene.view("endoscope").cameras``).
        points: (N, 3) in {w} (m): each row's da Vinci view centre, ``davinci.target_point(davinci_configuration)``.

    Returns:
        (error, in_image): 100 |uv - (cx, cy)| / W, finite in front of the camera (beyond 50 % across when
        the point lands outside the image), ``inf`` at or behind the camera plane (module docstring).
    """
    if not isinstance(cameras, Cameras):
        raise ValueError(f"cameras must be Cameras; got {type(cameras).__name__}")
    P = np.ascontiguousarray(as_finite(points, (3,), "points"))
    if P.shape != (cameras.num_rows, 3):
        raise ValueError(f"points must have shape ({cameras.num_rows}, 3) (m), one per camera; got {P.shape}")
    error = np.empty(cameras.num_rows)
    in_image = np.empty(cameras.num_rows, dtype=np.bool_)
    centre_error_rows(P, cameras.poses, cameras.intrinsics, cameras.k1, cameras.width, cameras.height, error,
                      in_image)
    return error, in_image
