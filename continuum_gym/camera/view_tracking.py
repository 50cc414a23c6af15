"""The ViewTracking scene for the batched renderer: the continuum endoscope and the da Vinci endoscope (paper 001).

It places every body as ``continuum_gym.render.ViewTrackingScene`` does, so that both renderers' images agree:

- the continuum endoscope (group 0): its stem (radius ``endoscope_radius``, 12 sides) from 0.2 m below {1b}
  up to it; ``n_per_segment`` links per segment along the chords of ``ContinuumEndoscope.backbone`` (each the
  segment's arc length / n_per_segment, 8 sides, round tops closing the joints); the rigid Lm cylinder; the
  camera head from the end of segment 2 to 0.2 mm behind the camera (flat top);
- the da Vinci stem (group 1): radius ``davinci_radius``, 16 sides, along the stem axis from 0.3 m behind its
  camera to 0.2 mm behind it;
- the tissue: the plane z_w = ``tissue_height`` seen from below, textured in 0.25 m tiles over a square of half
  side ``tissue_half_size``.

Two views: ``"endoscope"`` (the continuum endoscope's camera) and ``"davinci"`` (the view the surgeon asked
for), both with the frustum's full angle as vertical field of view. Both robots enter at the world origin
(the pybullet scene treats them as alternatives, not neighbours), so by default each view draws its own robot
only (behind its camera); ``show_other=True`` draws both in both views.

Segmentation ids: 1 the stem, segment 1 and the rigid cylinder; 2 segment 2 and the camera head; 3 the da Vinci.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.camera.model import Cameras, intrinsics, pose_matrix
from continuum_gym.camera.occlusion import set_tube
from continuum_gym.camera.palette import COLORS
from continuum_gym.camera.primitives import FLAT, OPEN, ROUND
from continuum_gym.camera.scene import Scene, TexturedPlane, Tubes, View
from continuum_gym.camera.texture import mip_pyramid
from continuum_gym.geometry.frustum import Frustum
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.davinci import DaVinciEndoscope, davinci_pose, stem_rotation
from continuum_gym.robots.endoscope import ContinuumEndoscope
from continuum_gym.robots.endoscope_kernels import backbone_batch, kinematics_batch
from continuum_gym.robots.mbcr_kernels import all_finite
from continuum_gym.validation import as_finite, boolean, integer, positive

__all__ = ["view_tracking_scene", "view_tracking_tube_count"]

#: Tissue texture tile (m) of the pybullet scene.
TILE = 0.25


def view_tracking_tube_count(n_per_segment: int) -> int:
    """Tubes per row: the stem, 2 n_per_segment segment links, the rigid cylinder, the camera head, the da Vinci."""
    return 1 + 2 * n_per_segment + 2 + 1


@kernel
def view_tracking_tubes(Q, Q_dv, robot, dv, n_per_segment, A, B, U, p_cam, R_cam, p_dv, R_dv):
    """Tube ends, prism directions and both cameras of every row; False on a non-finite configuration."""
    if not all_finite(Q) or not all_finite(Q_dv):
        return False
    n = n_per_segment
    P = backbone_batch(Q, robot, n)  # origin, {1b}, n samples, {2b}, n samples, camera
    kinematics_batch(Q, robot, p_cam, R_cam, np.empty((Q.shape[0], 3)), np.empty((1, 6, 6)), False)
    p_tgt = np.empty(3)
    R_stem = np.empty((3, 3))
    for row in range(Q.shape[0]):
        t = 0
        set_tube(A, B, U, row, t, P[row, 1, 0], P[row, 1, 1], P[row, 1, 2] - 0.2, 0.0, 0.0, 1.0, 0.2)
        t += 1
        for i in range(1, 2 * n + 3):
            if i <= n:
                length = robot.L1 / n
            elif i == n + 1:
                length = robot.Lm
            elif i <= 2 * n + 1:
                length = robot.L2 / n
            else:
                length = robot.Lc - 2e-4
            dx = P[row, i + 1, 0] - P[row, i, 0]
            dy = P[row, i + 1, 1] - P[row, i, 1]
            dz = P[row, i + 1, 2] - P[row, i, 2]
            norm = math.sqrt(dx * dx + dy * dy + dz * dz)
            set_tube(A, B, U, row, t, P[row, i, 0], P[row, i, 1], P[row, i, 2], dx / norm, dy / norm, dz / norm,
                     length)
            t += 1
        davinci_pose(Q_dv[row], dv, False, p_dv[row], R_dv[row], p_tgt)
        stem_rotation(Q_dv[row, 1], Q_dv[row, 2], Q_dv[row, 3], R_stem)
        zx, zy, zz = R_stem[0, 2], R_stem[1, 2], R_stem[2, 2]
        px, py, pz = p_dv[row, 0], p_dv[row, 1], p_dv[row, 2]
        A[row, t, 0], A[row, t, 1], A[row, t, 2] = px - 0.3 * zx, py - 0.3 * zy, pz - 0.3 * zz
        B[row, t, 0], B[row, t, 1], B[row, t, 2] = px - 2e-4 * zx, py - 2e-4 * zy, pz - 2e-4 * zz
        U[row, t, 0], U[row, t, 1], U[row, t, 2] = R_stem[0, 0], R_stem[1, 0], R_stem[2, 0]
    return True


def view_tracking_scene(endoscope: ContinuumEndoscope, davinci: DaVinciEndoscope, frustum: Frustum, q: ArrayLike,
                        davinci_configuration: ArrayLike, *, width: int = 64, height: int | None = None,
                        endoscope_radius: float = 0.003, davinci_radius: float = 0.004, n_per_segment: int = 6,
                        tissue_height: float | None = None, tissue_half_size: float = 1.0, show_other: bool = False,
                        faceted: bool = True, near: float = 1e-3, far: float = 1.5, texture_seed: int = 0) -> Scene:
    """The ViewTracking scene of N rows: continuum endoscope ``q`` (N, 6), da Vinci ``davinci_configuration`` (N, 4).

    Args:
        endoscope, davinci, frustum: the ``ContinuumEndoscope``, ``DaVinciEndoscope`` and ``Frustum``.
        q: continuum endoscope configurations [L0 (m), phi, theta1, delta1, theta2, delta2 (rad)].
        davinci_configuration: [L_dV (m), yaw, pitch, roll (rad)] of each row's da Vinci view
            (``ViewTrackingCore.davinci_configuration(row)``).
        width, height: image size (pixels); ``height`` None: square.
        endoscope_radius, davinci_radius: tube radii (m); n_per_segment: links per continuum segment.
        tissue_height: z_w of the tissue plane (m); None: the height of the da Vinci home view's target.
        tissue_half_size: half side of the textured square (m).
        show_other: draw both robots in both views (the pybullet scene shows each camera its own robot only).
        faceted: tubes with the silhouettes of the pybullet meshes' prisms; False: round tubes.
        near, far: clip distances of both cameras (m); texture_seed: the tissue texture's seed.
    """
    for name, value, cls in (("endoscope", endoscope, ContinuumEndoscope), ("davinci", davinci, DaVinciEndoscope),
                             ("frustum", frustum, Frustum)):
        if not isinstance(value, cls):
            raise ValueError(f"{name} must be a {cls.__name__}; got {type(value).__name__}")
    q = as_finite(q, (6,), "q")
    if q.ndim != 2:
        raise ValueError(f"q must have shape (N, 6); got {q.shape}")
    n = q.shape[0]
    q_dv = as_finite(davinci_configuration, (4,), "davinci_configuration")
    if q_dv.shape != (n, 4):
        raise ValueError(f"davinci_configuration must have shape ({n}, 4), one per row of q; got {q_dv.shape}")
    height = width if height is None else height
    n_per_segment = integer(n_per_segment, "n_per_segment", low=1, high=64)
    r = positive(endoscope_radius, "endoscope_radius", "m")
    r_dv = positive(davinci_radius, "davinci_radius", "m")
    if tissue_height is None:
        tissue_height = float(davinci.target_point(davinci.home)[2])
    h = positive(tissue_height, "tissue_height", "m")
    half = positive(tissue_half_size, "tissue_half_size", "m")
    show_other, faceted = boolean(show_other, "show_other"), boolean(faceted, "faceted")
    count = view_tracking_tube_count(n_per_segment)
    A, B, U = np.empty((n, count, 3)), np.empty((n, count, 3)), np.empty((n, count, 3))
    p_cam, R_cam, p_dv, R_dv = np.empty((n, 3)), np.empty((n, 3, 3)), np.empty((n, 3)), np.empty((n, 3, 3))
    if not view_tracking_tubes(np.ascontiguousarray(q), np.ascontiguousarray(q_dv), endoscope.kernel_args(),
                               davinci.kernel_args(), n_per_segment, A, B, U, p_cam, R_cam, p_dv, R_dv):
        raise ValueError("q and davinci_configuration must be finite")
    m = n_per_segment
    links = 2 * m + 2
    radius = np.concatenate([np.full(1 + links, r), [r_dv]])
    sides = np.concatenate([[12], np.full(links, 8), [16]]) if faceted else np.zeros(count, dtype=np.int64)
    caps = np.array([[OPEN, FLAT]] + [[OPEN, ROUND]] * (links - 1) + [[OPEN, FLAT]] * 2)
    ids = np.concatenate([[1], np.full(m + 1, 1), np.full(m + 1, 2), [3]])
    palette = COLORS["endoscope"]
    colors = np.array([palette[1][:3]] + [palette[0][:3]] * m + [palette[1][:3]] + [palette[2][:3]] * m
                      + [COLORS["camera_head"][:3], COLORS["davinci"][:3]])
    groups = np.concatenate([np.zeros(1 + links, dtype=np.int64), [1]])
    tubes = Tubes(A, B, U, radius, sides, caps, ids, colors, groups)
    K = np.broadcast_to(intrinsics(width, height, frustum.full_angle), (n, 3, 3))
    plane = TexturedPlane("world", np.array([0.0, 0.0, h]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]),
                          np.array([0.0, 0.0, -1.0]), np.full(2, half), np.full(2, 1.0 / TILE),
                          mip_pyramid(512, texture_seed, 2.5))
    views = {
        "endoscope": View(Cameras(K, pose_matrix(p_cam, R_cam), width, height, near, far),
                          (0, 1) if show_other else (0,), None, plane),
        "davinci": View(Cameras(K, pose_matrix(p_dv, R_dv), width, height, near, far),
                        (0, 1) if show_other else (1,), None, plane),
    }
    labels = {0: "background and tissue", 1: "stem, segment 1 and rigid cylinder", 2: "segment 2 and camera head",
              3: "da Vinci endoscope"}
    return Scene(tubes, views, 2, labels)
