"""Triangle meshes of the scenes, in numpy only (no pybullet): tubes, links, spheres, wires, grids.

Testable without pybullet; ``continuum_gym.render.scene`` turns them into pybullet shapes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

#: The world z axis.
E3 = np.array([0.0, 0.0, 1.0])


# ====================================================================== meshes (numpy only)
class Mesh:
    """Triangle mesh: vertices (n, 3), normals (n, 3), triangles (m, 3) int, optional uvs (n, 2)."""

    def __init__(self, V: ArrayLike, N: ArrayLike, T: ArrayLike, uv: ArrayLike | None = None) -> None:
        self.V = np.asarray(V, dtype=np.float64).reshape(-1, 3)
        N = np.asarray(N, dtype=np.float64).reshape(-1, 3)
        self.N = N / np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-300)
        self.T = np.asarray(T, dtype=np.int64).reshape(-1, 3)
        self.uv = None if uv is None else np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        self._orient()

    def _orient(self):
        """Counter-clockwise seen from outside (TinyRenderer culls back faces): flip triangles against normals."""
        if not len(self.T):
            return
        a, b, c = self.V[self.T[:, 0]], self.V[self.T[:, 1]], self.V[self.T[:, 2]]
        face = np.cross(b - a, c - a)
        ref = self.N[self.T].sum(axis=1)
        flip = np.einsum("ij,ij->i", face, ref) < 0
        self.T[flip] = self.T[flip][:, [0, 2, 1]]

    @staticmethod
    def merge(meshes: Sequence[Mesh]) -> Mesh:
        offsets = np.cumsum([0] + [len(m.V) for m in meshes[:-1]])
        uv = None
        if all(m.uv is not None for m in meshes):
            uv = np.concatenate([m.uv for m in meshes])
        return Mesh(np.concatenate([m.V for m in meshes]), np.concatenate([m.N for m in meshes]),
                     np.concatenate([m.T + o for m, o in zip(meshes, offsets)]), uv)


def lathe(profile: Sequence[tuple[float, float, float, float]], sides: int) -> Mesh:
    """Surface of revolution about z from a profile of (r, z, n_r, n_z); r = 0 makes a pole vertex.

    Consecutive profile entries at the same (r, z) start a new smoothing group (a hard edge).
    """
    theta = 2.0 * math.pi * np.arange(sides) / sides
    c, s = np.cos(theta), np.sin(theta)
    V: list[ArrayLike] = []  # rings of vertices (arrays) and pole vertices (nested lists)
    N: list[ArrayLike] = []
    rings: list[np.ndarray] = []
    count = 0
    for r, z, nr, nz in profile:
        if r == 0.0:
            V.append([[0.0, 0.0, z]])
            N.append([[0.0, 0.0, math.copysign(1.0, nz)]])
            rings.append(np.full(sides, count))
            count += 1
        else:
            V.append(np.stack([r * c, r * s, np.full(sides, z)], axis=1))
            N.append(np.stack([nr * c, nr * s, np.full(sides, nz)], axis=1))
            rings.append(count + np.arange(sides))
            count += sides
    T = []
    k1 = (np.arange(sides) + 1) % sides
    for (ra, za, _, _), (rb, zb, _, _), a, b in zip(profile[:-1], profile[1:], rings[:-1], rings[1:]):
        if ra == rb and za == zb:
            continue
        for tri in (np.stack([a, a[k1], b[k1]], 1), np.stack([a, b[k1], b], 1)):
            keep = (tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])
            T.append(tri[keep])
    return Mesh(np.concatenate(V), np.concatenate(N), np.concatenate(T))


def tube(radius: float, z0: float, z1: float, sides: int = 12, bottom: str = "round", top: str = "round",
         cap_rings: int = 2) -> Mesh:
    """Tube of ``radius`` along z from z0 to z1; each end "round" (hemisphere), "flat" or "open"."""
    profile = []

    def cap(z, sign, kind, opening):
        if kind == "round":
            phis = np.linspace(0.0, 0.5 * math.pi, cap_rings + 2)
            if opening:
                phis = phis[::-1]
            return [(radius * math.cos(f) if f < 0.5 * math.pi - 1e-12 else 0.0, z + sign * radius * math.sin(f),
                     math.cos(f), sign * math.sin(f)) for f in phis]
        if kind == "flat":
            pts = [(0.0, z, 0.0, sign), (radius, z, 0.0, sign), (radius, z, 1.0, 0.0)]
            return pts if opening else pts[::-1]
        return [(radius, z, 1.0, 0.0)]

    profile += cap(z0, -1.0, bottom, True)
    profile += cap(z1, +1.0, top, False)
    return lathe(profile, sides)


def link(radius: float, length: float, sides: int = 8, top: str = "round") -> Mesh:
    """A backbone link from z = 0 to ``length``: open at the bottom (inside the previous link's cap), a cone
    cap of height ``radius`` on top that closes the joint with the next link (or a flat top)."""
    return tube(radius, 0.0, length, sides=sides, bottom="open", top=top, cap_rings=0)


def sphere(radius: float, center: ArrayLike, sides: int = 10, rings: int = 3) -> Mesh:
    m = tube(radius, 0.0, 0.0, sides=sides, cap_rings=rings)
    m.V += np.asarray(center, dtype=np.float64)
    return m


def wires(segments: ArrayLike, radius: float, sides: int = 3, max_length: float = 0.01) -> Mesh:
    """Thin open prisms along line segments (k, 2, 3): a wireframe as one mesh.

    Segments are split into pieces of at most ``max_length``: TinyRenderer scans each triangle's screen
    bounding box, which for a long diagonal wire is mostly empty.
    """
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 2, 3)
    pieces = np.maximum(1, np.ceil(np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1) / max_length).astype(int))
    t0 = np.concatenate([np.arange(k) / k for k in pieces])
    t1 = np.concatenate([np.arange(1, k + 1) / k for k in pieces])
    a0, b0 = np.repeat(seg[:, 0], pieces, axis=0), np.repeat(seg[:, 1], pieces, axis=0)
    seg = np.stack([a0 + t0[:, None] * (b0 - a0), a0 + t1[:, None] * (b0 - a0)], axis=1)
    a, b = seg[:, 0], seg[:, 1]
    d = b - a
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    helper = np.where(np.abs(d[:, 2:3]) < 0.9, E3, [1.0, 0.0, 0.0])
    u = np.cross(d, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(d, u)
    theta = 2.0 * math.pi * (np.arange(sides) + 0.5) / sides
    radial = np.cos(theta)[None, :, None] * u[:, None, :] + np.sin(theta)[None, :, None] * v[:, None, :]
    V = np.concatenate([a[:, None, :] + radius * radial, b[:, None, :] + radius * radial], axis=1)  # (k, 2s, 3)
    N = np.concatenate([radial, radial], axis=1)
    i = np.arange(sides)
    j = (i + 1) % sides
    tri = np.concatenate([np.stack([i, j, sides + j], 1), np.stack([i, sides + j, sides + i], 1)])
    T = tri[None, :, :] + (2 * sides * np.arange(len(seg)))[:, None, None]
    return Mesh(V.reshape(-1, 3), N.reshape(-1, 3), T.reshape(-1, 3))


def grid_mesh(half_x: float, half_y: float, n: int = 8, normal_sign: float = -1.0, uv_scale: float = 1.0,
              two_sided: bool = False, xs: ArrayLike | None = None) -> Mesh:
    """Square grid in the plane z = 0 with uvs; normals along ``normal_sign`` z.

    ``xs`` (optional) gives the cell boundaries in x and y explicitly (then half = max |xs|).
    ``two_sided`` adds the back faces as separate triangles with flipped normals (createVisualShape's
    VISUAL_SHAPE_DOUBLE_SIDED flag does not reach TinyRenderer for meshes given by vertices); back faces
    are culled before rasterisation, so this costs nothing in a camera that sees the front.
    """
    if xs is None:
        xs, ys = np.linspace(-half_x, half_x, n + 1), np.linspace(-half_y, half_y, n + 1)
    else:
        xs = ys = np.asarray(xs, dtype=np.float64)
        half_x = half_y = float(np.max(np.abs(xs)))
    nx, ny = len(xs) - 1, len(ys) - 1
    X, Y = np.meshgrid(xs, ys, indexing="xy")
    V = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    uv = np.stack([(X.ravel() + half_x) / (2 * half_x), (Y.ravel() + half_y) / (2 * half_y)], axis=1) * uv_scale
    N = np.tile([0.0, 0.0, normal_sign], (len(V), 1))
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="xy")
    a = (j * (nx + 1) + i).ravel()
    T = np.concatenate([np.stack([a, a + 1, a + nx + 2], 1), np.stack([a, a + nx + 2, a + nx + 1], 1)])
    if two_sided:
        V, N, uv, T = np.concatenate([V, V]), np.concatenate([N, -N]), np.concatenate([uv, uv]), np.concatenate(
            [T, T + len(V)])
    return Mesh(V, N, T, uv)


def split_mesh(mesh: Mesh, inner_half: float) -> tuple[Mesh, Mesh]:
    """(triangles inside the square |x|, |y| <= inner_half, the others) of a mesh, as two meshes."""
    centre = mesh.V[mesh.T][:, :, :2].mean(axis=1)
    inside = np.all(np.abs(centre) <= inner_half, axis=1)
    return Mesh(mesh.V, mesh.N, mesh.T[inside], mesh.uv), Mesh(mesh.V, mesh.N, mesh.T[~inside], mesh.uv)


def disk_and_frame(radius: float, half: float, cells: int = 8) -> tuple[Mesh, Mesh]:
    """The square of half side ``half`` (z = 0, planar uvs, front faces toward -z) split into the grid
    cells that reach into the circle of ``radius`` (the disk) and the others (the frame).

    The disk alone covers a circular field of view of that radius, for about ``cells`` cells across it.
    """
    n = max(1, int(round(cells * half / radius / 2.0)) * 2)
    grid = grid_mesh(half, half, n, two_sided=False)
    corners = grid.V[grid.T][:, :, :2]
    # distance from the origin to each triangle (a right triangle of a cell): nearest point of its bounding box
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    nearest = np.clip(0.0, lo, hi)
    inside = np.linalg.norm(nearest, axis=1) <= radius
    return Mesh(grid.V, grid.N, grid.T[inside], grid.uv), Mesh(grid.V, grid.N, grid.T[~inside], grid.uv)


def quat_z_to(d: np.ndarray) -> np.ndarray:
    """Quaternions [x, y, z, w] (k, 4) rotating e_z onto the unit directions d (k, 3)."""
    q = np.empty((len(d), 4))
    q[:, 0] = -d[:, 1]
    q[:, 1] = d[:, 0]
    q[:, 2] = 0.0
    q[:, 3] = 1.0 + d[:, 2]
    n = np.linalg.norm(q, axis=1)
    bad = n < 1e-9
    q[bad] = [1.0, 0.0, 0.0, 0.0]
    n[bad] = 1.0
    return q / n[:, None]


def quaternion(R: np.ndarray) -> list[float]:
    """pybullet quaternion [x, y, z, w] of one rotation matrix (scalar fast path of quaternion_from_matrix)."""
    m00, m01, m02 = float(R[0, 0]), float(R[0, 1]), float(R[0, 2])
    m10, m11, m12 = float(R[1, 0]), float(R[1, 1]), float(R[1, 2])
    m20, m21, m22 = float(R[2, 0]), float(R[2, 1]), float(R[2, 2])
    trace = m00 + m11 + m22
    if trace > 0.0:
        s = 2.0 * math.sqrt(1.0 + trace)
        q = ((m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s, 0.25 * s)
    elif m00 > m11 and m00 > m22:
        s = 2.0 * math.sqrt(1.0 + m00 - m11 - m22)
        q = (0.25 * s, (m01 + m10) / s, (m02 + m20) / s, (m21 - m12) / s)
    elif m11 > m22:
        s = 2.0 * math.sqrt(1.0 + m11 - m00 - m22)
        q = ((m01 + m10) / s, 0.25 * s, (m12 + m21) / s, (m02 - m20) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + m22 - m00 - m11)
        q = ((m02 + m20) / s, (m12 + m21) / s, 0.25 * s, (m10 - m01) / s)
    n = math.sqrt(sum(x * x for x in q))
    return [x / n for x in q]


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)
