"""Camera frames -> pybullet view/projection matrices, and the pixel rays of a pybullet image.

Camera frame convention (OpenCV/ROS "optical" frame): position ``p`` (m) and rotation ``R`` (3x3, columns
in {w}) with ``R[:, 2]`` the optical axis (looking direction), ``R[:, 0]`` image right and ``R[:, 1]``
image *down*. pybullet's OpenGL-style matrices are built from it with ``computeViewMatrix(eye=p,
target=p + R[:, 2], up=-R[:, 1])`` and ``computeProjectionMatrixFOV`` (vertical field of view in degrees).

Pixel sampling of pybullet's TinyRenderer (examples/TinyRenderer/our_gl.cpp, TinyRendererVisualShapeConverter):
the viewport maps NDC x in [-1, 1] to [0, W] and a pixel is covered when its *integer* position lies in a
triangle, so column j samples x_ndc = 2 j / W - 1; the image is flipped vertically before it is returned,
so row i (0 = top) samples y_ndc = 2 (H - 1 - i) / H - 1. ``pixel_rays`` uses exactly these samples.

pybullet is imported lazily (inside the functions that need it). ``look_at_frame``, ``pixel_rays``, ``pixel_angles``
and ``fov_mask`` live in ``continuum_gym.camera.model`` (the batched renderer's camera model) and are re-exported.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.camera.model import fov_mask, look_at_frame, pixel_angles, pixel_rays

__all__ = [
    "camera_matrices", "view_matrix", "projection_matrix", "view_matrix_from_frame", "look_at_frame",
    "pixel_rays", "pixel_angles", "fov_mask", "quaternion_from_matrix",
]


def _as_frame(p: ArrayLike, R: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(p, dtype=np.float64).reshape(3)
    R = np.asarray(R, dtype=np.float64).reshape(3, 3)
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(R))):
        raise ValueError(f"camera frame must be finite; got p={p}, R={R}")
    return p, R


def view_matrix(p: ArrayLike, R: ArrayLike) -> tuple:
    """pybullet view matrix (16 floats, column-major) of the camera frame (p, R) (module docstring)."""
    import pybullet

    p, R = _as_frame(p, R)
    return pybullet.computeViewMatrix(
        cameraEyePosition=p.tolist(), cameraTargetPosition=(p + R[:, 2]).tolist(), cameraUpVector=(-R[:, 1]).tolist())


def projection_matrix(fov_y: float, aspect: float = 1.0, near: float = 1e-3, far: float = 0.3) -> tuple:
    """pybullet projection matrix (16 floats) for a vertical field of view ``fov_y`` (rad), near/far in m."""
    import pybullet

    if not (0.0 < fov_y < math.pi):
        raise ValueError(f"fov_y must be in (0, pi) rad; got {fov_y!r}")
    if not (0.0 < near < far):
        raise ValueError(f"need 0 < near < far (m); got near={near!r}, far={far!r}")
    return pybullet.computeProjectionMatrixFOV(fov=math.degrees(fov_y), aspect=float(aspect), nearVal=float(near),
                                               farVal=float(far))


def camera_matrices(p: ArrayLike, R: ArrayLike, fov_y: float, width: int, height: int, near: float = 1e-3,
                    far: float = 0.3) -> tuple[tuple, tuple]:
    """(view, projection) for getCameraImage: camera frame (p, R), vertical FOV ``fov_y`` (rad), image W x H."""
    return view_matrix(p, R), projection_matrix(fov_y, width / height, near, far)


def view_matrix_from_frame(p: ArrayLike, R: ArrayLike) -> np.ndarray:
    """The same view matrix as ``view_matrix`` in numpy, (4, 4) row-major (``.T.ravel()`` is pybullet's layout).

    Rows are the OpenGL eye axes in {w}: x = R[:, 0], y (up) = -R[:, 1], z (backward) = -R[:, 2].
    """
    p, R = _as_frame(p, R)
    axes = np.stack([R[:, 0], -R[:, 1], -R[:, 2]])
    V = np.eye(4)
    V[:3, :3] = axes
    V[:3, 3] = -axes @ p
    return V


def quaternion_from_matrix(R: ArrayLike) -> np.ndarray:
    """pybullet quaternion [x, y, z, w] of rotation matrices R (..., 3, 3) (Shepperd's method)."""
    R = np.asarray(R, dtype=np.float64)
    batch = R.shape[:-2]
    R = R.reshape(-1, 3, 3)
    m00, m11, m22 = R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]
    trace = m00 + m11 + m22
    cand = np.stack([trace, m00, m11, m22], axis=-1)
    k = np.argmax(cand, axis=-1)
    q = np.empty((R.shape[0], 4))
    for case in range(4):
        sel = k == case
        if not np.any(sel):
            continue
        r = R[sel]
        if case == 0:
            s = np.sqrt(1.0 + trace[sel]) * 2.0
            q[sel] = np.stack([(r[:, 2, 1] - r[:, 1, 2]) / s, (r[:, 0, 2] - r[:, 2, 0]) / s,
                               (r[:, 1, 0] - r[:, 0, 1]) / s, 0.25 * s], axis=-1)
        elif case == 1:
            s = np.sqrt(1.0 + r[:, 0, 0] - r[:, 1, 1] - r[:, 2, 2]) * 2.0
            q[sel] = np.stack([0.25 * s, (r[:, 0, 1] + r[:, 1, 0]) / s, (r[:, 0, 2] + r[:, 2, 0]) / s,
                               (r[:, 2, 1] - r[:, 1, 2]) / s], axis=-1)
        elif case == 2:
            s = np.sqrt(1.0 + r[:, 1, 1] - r[:, 0, 0] - r[:, 2, 2]) * 2.0
            q[sel] = np.stack([(r[:, 0, 1] + r[:, 1, 0]) / s, 0.25 * s, (r[:, 1, 2] + r[:, 2, 1]) / s,
                               (r[:, 0, 2] - r[:, 2, 0]) / s], axis=-1)
        else:
            s = np.sqrt(1.0 + r[:, 2, 2] - r[:, 0, 0] - r[:, 1, 1]) * 2.0
            q[sel] = np.stack([(r[:, 0, 2] + r[:, 2, 0]) / s, (r[:, 1, 2] + r[:, 2, 1]) / s, 0.25 * s,
                               (r[:, 1, 0] - r[:, 0, 1]) / s], axis=-1)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return q.reshape(batch + (4,))
