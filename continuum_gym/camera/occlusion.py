"""The OcclusionAvoidance scene for the batched renderer: the MBCR beside the angled endoscope (paper 000).

It places every body as ``continuum_gym.render.OcclusionScene`` does, so that the two renderers' masks and
depths agree (``tests/camera``):

- the inserted straight part: a tube of the robot radius from 0.1 m below the base of segment 1 up to it
  (open bottom, flat top), prism of 8 sides, unrotated;
- ``n_per_segment`` links per segment from each backbone sample along the chord to the next, each the
  segment's arc length / n_per_segment long (a few microns over the chord) with a round top closing the
  joint (flat on the tip), prisms of 8 sides turned by ``quat_z_to`` of the chord;
- a disk at each segment end (radius 1.12 r, 0.8 mm thick, 10 sides) along the backbone tangent;
- the endoscope shaft (radius ``shaft_radius``, 16 sides) from 0.1 m behind the lens to 0.2 mm behind it;
- the tissue: the plane ``tissue_distance`` along the view axis, perpendicular to it, fixed in the lens frame
  (the same image at every q and gamma), textured over a square of half side ``tissue_half_size`` (one texture
  tile across it).

The camera sits at ``lens_origin(gamma)`` looking along the view axis, its frame the lens frame turned half a
turn about that axis (``OcclusionScene.camera_pose``); a square image with vertical field of view 2 beta and the
circular field of view (half-angle beta) inscribed in it.

Segmentation ids: the straight part and segment 1 are 1, segment k is k (its disk at the far end too), the
endoscope shaft n + 1 (never in its own view).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.camera.model import Cameras, intrinsics, pose_matrix
from continuum_gym.camera.palette import COLORS
from continuum_gym.camera.primitives import FLAT, OPEN, ROUND
from continuum_gym.camera.scene import Scene, TexturedPlane, Tubes, View
from continuum_gym.camera.texture import mip_pyramid
from continuum_gym.geometry.lens_cone import LensCone, lens_to_world_direction_cs, resolve_cone
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.mbcr import MultiBackboneRobot
from continuum_gym.robots.mbcr_kernels import all_finite, backbone_kernel, make_workspace
from continuum_gym.validation import as_finite, boolean, integer, positive

__all__ = ["occlusion_scene", "occlusion_tube_count", "OcclusionLayout"]

#: The scene's body layout: how many links per segment, the robot radius and the shaft radius (m).
OcclusionLayout = namedtuple("OcclusionLayout", ["n_per_segment", "robot_radius", "shaft_radius"])


def occlusion_tube_count(n_segments: int, n_per_segment: int) -> int:
    """Tubes per row: the straight part, the links, a disk per segment end, the shaft."""
    return 1 + n_segments * n_per_segment + n_segments + 1 + 1


@kernel(inline="always")
def z_to_x_axis(dx, dy, dz, out):
    """The body x axis of ``quat_z_to(d)`` (the minimal rotation taking e_z to the unit d): R e_x."""
    if 1.0 + dz < 1e-9:  # quat_z_to's fallback: half a turn about x
        out[0], out[1], out[2] = 1.0, 0.0, 0.0
        return
    k = 1.0 / (1.0 + dz)
    out[0] = 1.0 - dx * dx * k
    out[1] = -dx * dy * k
    out[2] = -dx


@kernel(inline="always")
def set_tube(A, B, U, row, t, ax, ay, az, dx, dy, dz, length):
    """Tube t of a row from (ax, ay, az) along the unit (dx, dy, dz) for ``length`` (m), prism turned as pybullet's."""
    A[row, t, 0], A[row, t, 1], A[row, t, 2] = ax, ay, az
    B[row, t, 0], B[row, t, 1], B[row, t, 2] = ax + length * dx, ay + length * dy, az + length * dz
    z_to_x_axis(dx, dy, dz, U[row, t])


@kernel
def occlusion_tubes(Q, G, robot, d_o, alpha, model, n_per_segment, A, B, U, p_cam, R_cam):
    """Tube ends (N, T, 3), prism directions and the endoscope cameras of every row; False on a non-finite q."""
    if not all_finite(Q) or not all_finite(G):
        return False
    n_seg = robot.lengths.shape[0]
    ni = robot.n_insert
    ws = make_workspace(n_seg)
    P = np.empty((ni + n_seg * n_per_segment + 1, 3))
    ca, sa = math.cos(alpha), math.sin(alpha)
    for row in range(Q.shape[0]):
        backbone_kernel(Q[row], robot, ws, n_per_segment, P)
        t = 0
        # the inserted straight part, unrotated, ending at the base of segment 1
        set_tube(A, B, U, row, t, P[ni, 0], P[ni, 1], P[ni, 2] - 0.1, 0.0, 0.0, 1.0, 0.1)
        t += 1
        for s in range(n_seg):
            length = robot.lengths[s] / n_per_segment
            for k in range(n_per_segment):
                i = ni + s * n_per_segment + k
                dx = P[i + 1, 0] - P[i, 0]
                dy = P[i + 1, 1] - P[i, 1]
                dz = P[i + 1, 2] - P[i, 2]
                norm = math.sqrt(dx * dx + dy * dy + dz * dz)
                set_tube(A, B, U, row, t, P[i, 0], P[i, 1], P[i, 2], dx / norm, dy / norm, dz / norm, length)
                t += 1
        for j in range(n_seg + 1):
            c = ni + j * n_per_segment
            if j == 0:
                dx, dy, dz = 0.0, 0.0, 1.0
            elif j == n_seg:
                dx, dy, dz = ws.R_base[n_seg, 0, 2], ws.R_base[n_seg, 1, 2], ws.R_base[n_seg, 2, 2]
            else:
                dx = P[c + 1, 0] - P[c - 1, 0]
                dy = P[c + 1, 1] - P[c - 1, 1]
                dz = P[c + 1, 2] - P[c - 1, 2]
            norm = math.sqrt(dx * dx + dy * dy + dz * dz)
            dx, dy, dz = dx / norm, dy / norm, dz / norm
            set_tube(A, B, U, row, t, P[c, 0] - 4e-4 * dx, P[c, 1] - 4e-4 * dy, P[c, 2] - 4e-4 * dz, dx, dy, dz, 8e-4)
            t += 1
        # the lens frame ^wR_lens = Rz(gamma) Ry(-alpha) and its origin (both lens models)
        cg, sg = math.cos(G[row]), math.sin(G[row])
        for col in range(3):
            e0 = 1.0 if col == 0 else 0.0
            e1 = 1.0 if col == 1 else 0.0
            e2 = 1.0 if col == 2 else 0.0
            x, y, z = lens_to_world_direction_cs(e0, e1, e2, cg, sg, ca, sa)
            sign = -1.0 if col < 2 else 1.0  # the camera frame: the lens frame half a turn about the view axis
            R_cam[row, 0, col], R_cam[row, 1, col], R_cam[row, 2, col] = sign * x, sign * y, sign * z
        if model == 1:
            p_cam[row, 0], p_cam[row, 1] = 0.0, d_o
        else:
            p_cam[row, 0], p_cam[row, 1] = -sg * d_o, cg * d_o
        p_cam[row, 2] = 0.0
        zx, zy, zz = R_cam[row, 0, 2], R_cam[row, 1, 2], R_cam[row, 2, 2]
        # the shaft, along -z_lens from the lens; its prism's x axis is the lens frame's (-x_camera)
        A[row, t, 0], A[row, t, 1], A[row, t, 2] = p_cam[row, 0] - 0.1 * zx, p_cam[row, 1] - 0.1 * zy, -0.1 * zz
        B[row, t, 0], B[row, t, 1], B[row, t, 2] = (p_cam[row, 0] - 2e-4 * zx, p_cam[row, 1] - 2e-4 * zy,
                                                    -2e-4 * zz)
        U[row, t, 0], U[row, t, 1], U[row, t, 2] = -R_cam[row, 0, 0], -R_cam[row, 1, 0], -R_cam[row, 2, 0]
    return True


def occlusion_scene(robot: MultiBackboneRobot, cone: LensCone | None, q: ArrayLike, gamma: ArrayLike, *,
                    width: int = 64, height: int | None = None, tissue: bool = True, tissue_distance: float = 0.065,
                    tissue_half_size: float = 0.05, robot_radius: float = 0.0015, shaft_radius: float = 0.002,
                    n_per_segment: int = 8, circular_fov: bool = True, faceted: bool = True, near: float = 1e-3,
                    far: float = 0.3, texture_seed: int = 0) -> Scene:
    """The OcclusionAvoidance scene of N rows: robot ``q`` (N, dof), endoscope rotations ``gamma`` (N,) (rad).

    Args:
        robot: the ``MultiBackboneRobot``; cone: its ``LensCone`` (None: the paper's).
        width, height: image size (pixels); ``height`` None: square (the pybullet scene's framing: vertical
            field of view 2 beta, the circular field of view inscribed in a square image).
        tissue: draw the tissue plane. Without it, robot parts beyond it are seen too, as pybullet's
            ``pixel_occlusion`` counts them (it renders without the tissue).
        tissue_distance: the tissue's distance from the lens along the view axis (m).
        tissue_half_size: half side of the textured square (m); at least the square the image sees.
        robot_radius, shaft_radius: tube radii (m); n_per_segment: links per segment.
        circular_fov: 0 outside the circular field of view (a real endoscope image), else the whole square.
        faceted: tubes with the silhouettes of the pybullet scene's 8-, 10- and 16-sided meshes (masks agree
            with it); False: round tubes of the nominal radii.
        near, far: clip distances (m); texture_seed: seed of the tissue texture (pybullet's default 0).

    Returns:
        A ``Scene`` with one view, ``"endoscope"``. Group 0 is the robot, group 1 the shaft.
    """
    if not isinstance(robot, MultiBackboneRobot):
        raise ValueError(f"robot must be a MultiBackboneRobot; got {type(robot).__name__}")
    cone = resolve_cone(cone)
    q = as_finite(q, (robot.dof,), "q")
    if q.ndim != 2:
        raise ValueError(f"q must have shape (N, {robot.dof}); got {q.shape}")
    n = q.shape[0]
    gamma = as_finite(gamma, (), "gamma").reshape(-1)
    if gamma.shape != (n,):
        raise ValueError(f"gamma must have shape ({n},) (rad), one per row of q; got {np.shape(gamma)}")
    height = width if height is None else height
    n_per_segment = integer(n_per_segment, "n_per_segment", low=1, high=64)
    r = positive(robot_radius, "robot_radius", "m")
    shaft = positive(shaft_radius, "shaft_radius", "m")
    d = positive(tissue_distance, "tissue_distance", "m")
    half = positive(tissue_half_size, "tissue_half_size", "m")
    tissue = boolean(tissue, "tissue")
    circular_fov = boolean(circular_fov, "circular_fov")
    faceted = boolean(faceted, "faceted")
    K = intrinsics(width, height, 2.0 * cone.beta)
    segments = robot.n_segments
    count = occlusion_tube_count(segments, n_per_segment)
    A, B, U = np.empty((n, count, 3)), np.empty((n, count, 3)), np.empty((n, count, 3))
    p_cam, R_cam = np.empty((n, 3)), np.empty((n, 3, 3))
    if not occlusion_tubes(np.ascontiguousarray(q), np.ascontiguousarray(gamma), robot.kernel_args(), cone.d_o,
                           cone.alpha, cone.model_code, n_per_segment, A, B, U, p_cam, R_cam):
        raise ValueError("q and gamma must be finite")
    links = segments * n_per_segment
    radius = np.concatenate([[r], np.full(links, r), np.full(segments + 1, 1.12 * r), [shaft]])
    sides = np.concatenate([[8], np.full(links, 8), np.full(segments + 1, 10), [16]]) if faceted \
        else np.zeros(count, dtype=np.int64)
    caps = np.array([[OPEN, FLAT]] + [[OPEN, ROUND]] * (links - 1) + [[OPEN, FLAT]]
                    + [[FLAT, FLAT]] * (segments + 1) + [[OPEN, FLAT]])
    link_ids = np.repeat(np.arange(1, segments + 1), n_per_segment)
    ids = np.concatenate([[1], link_ids, [1], np.arange(1, segments + 1), [segments + 1]])
    seg_colors = COLORS["segments"]
    colors = np.array([COLORS["straight"][:3]] + [seg_colors[(i - 1) % len(seg_colors)][:3] for i in link_ids]
                      + [COLORS["disk"][:3]] * (segments + 1) + [COLORS["shaft"][:3]])
    groups = np.zeros(count, dtype=np.int64)
    groups[-1] = 1
    tubes = Tubes(A, B, U, radius, sides, caps, ids, colors, groups)
    cameras = Cameras(np.broadcast_to(K, (n, 3, 3)), pose_matrix(p_cam, R_cam), width, height, near, far)
    plane = None
    if tissue:
        # fixed in the camera frame: the camera's x and y are the lens frame's negated, and the pybullet mesh's
        # texture coordinates run along the lens frame's x and y
        plane = TexturedPlane("camera", np.array([0.0, 0.0, d]), np.array([-1.0, 0.0, 0.0]),
                              np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, -1.0]),
                              np.full(2, _tissue_half(d, cone.beta, half)),
                              np.full(2, 0.5 / _tissue_half(d, cone.beta, half)), mip_pyramid(512, texture_seed, 1.0))
    view = View(cameras, (0, 1), cone.beta if circular_fov else None, plane)
    labels = {0: "background and tissue", 1: "straight part and segment 1"}
    labels.update({k: f"segment {k}" for k in range(2, segments + 1)})
    labels[segments + 1] = "endoscope shaft"
    return Scene(tubes, {"endoscope": view}, segments, labels)


def _tissue_half(d: float, beta: float, half: float) -> float:
    """Half side of the pybullet scene's tissue square: at least 1.05 sqrt(2) times the disk it sees."""
    return max(half, 1.05 * 1.02 * d * math.tan(beta) * math.sqrt(2.0))

