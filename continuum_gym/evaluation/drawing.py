"""Matplotlib 3-D drawings of the robots, the view cone and view frustums (all inputs in m, drawn in mm)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.geometry.frustum import Frustum
from continuum_gym.geometry.lens_cone import LensCone, lens_origin, lens_rotation, resolve_cone

if TYPE_CHECKING:
    from matplotlib.typing import ColorType
    from mpl_toolkits.mplot3d import Axes3D

MM = 1e3


def draw_backbone(ax: Axes3D, points: ArrayLike, color: ColorType, label: str | None = None,
                  linewidth: float = 3.0) -> None:
    """A sampled centre line (n, 3) in m."""
    pts = np.asarray(points) * MM
    ax.plot(pts[:, 0], pts[:, 1], pts[:, 2], color=color, linewidth=linewidth, label=label, solid_capstyle="round")
    ax.scatter(*pts[-1], color=color, s=18)


def draw_frame(ax: Axes3D, p: ArrayLike, R: np.ndarray, length: float = 0.008) -> None:
    """Axes of a frame (x red, y green, z blue); ``length`` in m."""
    for k, color in enumerate(("tab:red", "tab:green", "tab:blue")):
        end = (np.asarray(p) + length * R[:, k]) * MM
        start = np.asarray(p) * MM
        ax.plot([start[0], end[0]], [start[1], end[1]], [start[2], end[2]], color=color, linewidth=1.2)


def draw_cone(ax: Axes3D, gamma: float, cone: LensCone | None = None, length: float = 0.075,
              color: ColorType = "tab:orange", n: int = 24, alpha: float = 0.12) -> None:
    """The angled-lens view cone for rotation ``gamma`` (rad), ``length`` (m) along its axis."""
    cone = resolve_cone(cone)
    vertex = lens_origin(gamma, cone)
    R = lens_rotation(gamma, cone)
    radius = length * math.tan(cone.beta)
    angles = np.linspace(0, 2 * math.pi, n + 1)
    rim = vertex + length * R[:, 2] + radius * (np.outer(np.cos(angles), R[:, 0]) + np.outer(np.sin(angles), R[:, 1]))
    rim_mm = rim * MM
    v = vertex * MM
    ax.plot(rim_mm[:, 0], rim_mm[:, 1], rim_mm[:, 2], color=color, linewidth=0.8)
    for k in range(0, n, 3):
        ax.plot([v[0], rim_mm[k, 0]], [v[1], rim_mm[k, 1]], [v[2], rim_mm[k, 2]], color=color, linewidth=0.6,
                alpha=0.8)
    axis_end = (vertex + length * R[:, 2]) * MM
    ax.plot([v[0], axis_end[0]], [v[1], axis_end[1]], [v[2], axis_end[2]], color=color, linestyle="--", linewidth=0.8)
    try:
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection

        faces = [[v, rim_mm[k], rim_mm[k + 1]] for k in range(n)]
        ax.add_collection3d(Poly3DCollection(faces, color=color, alpha=alpha, linewidth=0))
    except ImportError:  # pragma: no cover - mplot3d ships with matplotlib
        pass


def draw_endoscope_shaft(ax: Axes3D, gamma: float, cone: LensCone | None = None, length: float = 0.03,
                        color: ColorType = "0.35") -> None:
    """The rigid endoscope as a line from its lens back along -z_w (m)."""
    vertex = lens_origin(gamma, resolve_cone(cone)) * MM
    ax.plot([vertex[0], vertex[0]], [vertex[1], vertex[1]], [vertex[2], vertex[2] - length * MM], color=color,
            linewidth=5, solid_capstyle="butt")


def draw_frustum(ax: Axes3D, p: ArrayLike, R: ArrayLike, color: ColorType, frustum: Frustum | None = None,
                 alpha: float = 0.08, label: str | None = None) -> None:
    """A square view frustum at camera pose (p in m, R with z the optical axis)."""
    frustum = frustum or Frustum()
    v = frustum.vertices(p, R) * MM
    edges = [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)]
    for i, (a, b) in enumerate(edges):
        ax.plot(*zip(v[a], v[b]), color=color, linewidth=0.9, label=label if i == 0 else None)
    apex = np.asarray(p) * MM
    for k in range(4):
        ax.plot(*zip(apex, v[k]), color=color, linewidth=0.5, linestyle=":")
    try:
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection

        faces = [[v[a], v[b], v[c], v[d]] for a, b, c, d in ((0, 1, 2, 3), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5),
                                                             (2, 3, 7, 6), (3, 0, 4, 7))]
        ax.add_collection3d(Poly3DCollection(faces, color=color, alpha=alpha, linewidth=0))
    except ImportError:  # pragma: no cover
        pass


def set_equal_3d(ax: Axes3D, points_mm: ArrayLike, margin: float = 5.0) -> None:
    """Equal aspect around a set of points (mm)."""
    pts = np.asarray(points_mm).reshape(-1, 3)
    centre = (pts.max(axis=0) + pts.min(axis=0)) / 2
    half = (pts.max(axis=0) - pts.min(axis=0)).max() / 2 + margin
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1, 1, 1))
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
