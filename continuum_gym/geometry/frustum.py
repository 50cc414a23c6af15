"""Square viewing frustum of a camera (Deng–Xu, paper-notes §2.4).

The frustum's apex is at the camera position ``p`` and its axis is the camera's z-axis ``R[:, 2]``.
Its cross-section is a square aligned with the camera's x and y axes, with the same full angle in
x and in y, and it is cut by the near and far planes ``z = near`` and ``z = far`` (camera frame).
In the camera frame it is the 6 half-spaces

    z >= near,  z <= far,  ±x <= t z,  ±y <= t z,       t = tan(full_angle / 2),

and its volume is V = 4 t² (far³ − near³) / 3 (2.268e-3 m³ for the paper's 90°, 30 mm, 120 mm).

Index conventions (shared with ``continuum_gym.geometry.overlap``):

* vertices 0–3 lie on the near plane and 4–7 on the far plane, each quadruple in the order
  (−,−), (+,−), (+,+), (−,+) in (x, y);
* faces and half-spaces are ordered ``near, far, +x, −x, +y, −y``; ``FACE_VERTICES[k]`` lists the
  vertices of face k counter-clockwise seen from outside (right-hand rule gives the outward normal).
"""

from __future__ import annotations

import math
from collections import namedtuple
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.validation import (
    angle_in_open_interval,
    as_rotations,
    as_vectors,
    integer,
    positive,
)

#: What the overlap kernels read of a frustum: tan of the half-angle, near and far distances (m).
FrustumKernelArgs = namedtuple("FrustumKernelArgs", ["tan_half", "near", "far"])

#: Vertex indices of the 6 faces (near, far, +x, −x, +y, −y), counter-clockwise about the outward normal.
FACE_VERTICES = np.array(
    [
        [0, 3, 2, 1],  # near, outward −z
        [4, 5, 6, 7],  # far, outward +z
        [1, 2, 6, 5],  # +x side
        [0, 4, 7, 3],  # −x side
        [2, 3, 7, 6],  # +y side
        [0, 1, 5, 4],  # −y side
    ],
    dtype=np.int64,
)


@dataclass(frozen=True)
class Frustum:
    """Square truncated viewing pyramid in SI units.

    Attributes:
        full_angle: full opening angle in x and in y (rad), in (0, π). Paper 001: 90° (paper-notes §2.4).
        near: distance of the near plane along the camera axis (m), > 0. Paper 001: 30 mm.
        far: distance of the far plane along the camera axis (m), > near. Paper 001: 120 mm.
    """

    full_angle: float = np.pi / 2
    near: float = 0.03
    far: float = 0.12

    def __post_init__(self) -> None:
        full_angle = angle_in_open_interval(self.full_angle, "full_angle", 0.0, np.pi, "(0, pi)")
        near = positive(self.near, "near", "m")
        try:
            far = float(self.far)
        except (TypeError, ValueError) as error:
            raise ValueError(f"far must be a number > near = {near} (m); got {self.far!r}") from error
        if not np.isfinite(far) or far <= near:
            raise ValueError(f"far must be finite and > near = {near} (m); got {self.far!r}")
        object.__setattr__(self, "full_angle", full_angle)
        object.__setattr__(self, "near", near)
        object.__setattr__(self, "far", far)
        object.__setattr__(self, "_tan_half", math.tan(0.5 * full_angle))

    def kernel_args(self) -> FrustumKernelArgs:
        """(tan_half, near (m), far (m)): the bundle the overlap kernels read."""
        # _tan_half: set in __post_init__ (not a dataclass field)
        return FrustumKernelArgs(self._tan_half, self.near, self.far)  # type: ignore[attr-defined]

    def to_dict(self) -> dict:
        """The constructor arguments as plain YAML/JSON values (rad, m)."""
        return {"full_angle": self.full_angle, "near": self.near, "far": self.far}

    @property
    def half_angle(self) -> float:
        """Half of ``full_angle`` (rad)."""
        return 0.5 * self.full_angle

    @property
    def tan_half(self) -> float:
        """t = tan(full_angle / 2): the half-width of the cross-section per unit depth."""
        return self._tan_half  # type: ignore[attr-defined]  # set in __post_init__ (not a dataclass field)

    @property
    def volume(self) -> float:
        """4 t² (far³ − near³) / 3 (m³)."""
        t = self.tan_half
        return 4.0 * t * t * (self.far**3 - self.near**3) / 3.0

    def local_vertices(self) -> np.ndarray:
        """The 8 vertices in the camera frame, shape (8, 3) (order in the module docstring)."""
        t = self.tan_half
        corners = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
        out = np.empty((8, 3))
        for k, depth in enumerate((self.near, self.far)):
            out[4 * k : 4 * k + 4, :2] = corners * (t * depth)
            out[4 * k : 4 * k + 4, 2] = depth
        return out

    def local_halfspaces(self) -> np.ndarray:
        """The 6 half-spaces in the camera frame, rows [n, b] with unit outward n and n·x + b <= 0, shape (6, 4)."""
        t = self.tan_half
        c = 1.0 / np.sqrt(1.0 + t * t)
        s = t * c
        return np.array(
            [
                [0.0, 0.0, -1.0, self.near],
                [0.0, 0.0, 1.0, -self.far],
                [c, 0.0, -s, 0.0],
                [-c, 0.0, -s, 0.0],
                [0.0, c, -s, 0.0],
                [0.0, -c, -s, 0.0],
            ]
        )

    def vertices(self, p: ArrayLike, R: ArrayLike) -> np.ndarray:
        """World coordinates of the 8 vertices for camera position ``p`` (..., 3) and rotation ``R`` (..., 3, 3).

        Returns shape (..., 8, 3), the batch shapes of ``p`` and ``R`` broadcast together.
        """
        p = as_vectors(p, 3, "p")
        R = as_rotations(R, "R")
        return p[..., None, :] + np.einsum("...ij,kj->...ki", R, self.local_vertices())

    def halfspaces(self, p: ArrayLike, R: ArrayLike) -> np.ndarray:
        """World half-spaces [n, b] (n unit, outward) with n·x + b <= 0 inside, shape (..., 6, 4).

        Rows are ordered near, far, +x, −x, +y, −y. ``n_w = R n`` and ``b_w = b − n_w·p``.
        """
        p = as_vectors(p, 3, "p")
        R = as_rotations(R, "R")
        local = self.local_halfspaces()
        normals = np.einsum("...ij,kj->...ki", R, local[:, :3])
        offsets = local[:, 3] - np.sum(normals * p[..., None, :], axis=-1)
        normals = np.broadcast_to(normals, offsets.shape + (3,))
        return np.concatenate([normals, offsets[..., None]], axis=-1)

    def sample_uniform(self, n: int, rng: np.random.Generator | int | None) -> np.ndarray:
        """``n`` points uniformly distributed in the frustum, in its own camera frame, shape (n, 3).

        paper-notes §2.4: z = (near³ + u (far³ − near³))^(1/3) with u ~ U(0, 1), then x, y ~ U(−t z, t z).
        ``rng`` is a ``numpy.random.Generator`` (or a seed passed to ``numpy.random.default_rng``).
        """
        n = integer(n, "n", low=1)
        rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        t = self.tan_half
        near3, far3 = self.near**3, self.far**3
        z = np.cbrt(near3 + rng.random(n) * (far3 - near3))
        xy = (2.0 * rng.random((n, 2)) - 1.0) * (t * z)[:, None]
        return np.column_stack([xy, z])
