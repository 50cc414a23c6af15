"""Overlap ratio of two camera frustums, OR = vol(F_a ∩ F_b) / vol(F_a) (Deng–Xu, paper-notes §2.4).

Three implementations of the same number:

* :func:`overlap_ratio` — exact, batched, compiled (numba). The volume of the convex polytope
  P = F_a ∩ F_b comes from the divergence theorem, V = 1/3 Σ_f (n_f · x_f) area_f, summed over the
  faces f of *both* frustums, where face f contributes its part inside the other frustum (its
  4-gon clipped by the other frustum's 6 half-spaces, Sutherland–Hodgman), n_f is its outward unit
  normal and x_f any point of its plane. Everything is done in F_a's camera frame, with the
  apex of F_a as origin, so F_a's four side planes pass through the origin and contribute nothing.
  A face of F_b lying in the plane of a face of F_a with the same outward normal is the same piece
  of ∂P and is counted once (F_b's copy is skipped and F_a's copy is not clipped by that plane);
  faces in a common plane with opposite normals mean P lies in that plane, so V = 0.
  Nearly coplanar faces (e.g. two cameras converged to the same pose within 1e-10 rad) are the
  ill-conditioned case of this formula: if face P is cut by plane Q and face Q by plane P
  independently, rounding moves the two cut lines apart by ~1e-17 m / angle, and the sliver between
  them is counted twice or not at all (an OR error of 2e-4 at 1e-12 rad). So face P is cut by
  Q − s·P and face Q by P − s·Q = −s·(Q − s·P) (s = sign(n_P·n_Q)), which equal Q and P on the
  respective face planes but are one and the same functional: the cuts coincide and OR stays
  exact (1e-15 against scipy for tilts from 1e-14 to 1e-4 rad).
* :func:`overlap_ratio_reference` — the polytope-library recipe of paper-notes §2.4 (scipy: Chebyshev
  centre by ``linprog``/HiGHS, ``HalfspaceIntersection``, ``ConvexHull``); one pair, slow; the
  test reference.
* :func:`overlap_ratio_monte_carlo` — fraction of uniform samples of F_a that fall inside F_b.

:func:`overlap_ratio_nb` is the compiled per-pair kernel without input checks, callable from other
numba kernels (e.g. a whole environment step).
"""

from __future__ import annotations

import threading
from collections import namedtuple

import numpy as np
from numba import njit

from continuum_gym.geometry.frustum import FACE_VERTICES, Frustum

__all__ = [
    "overlap_ratio",
    "overlap_ratio_nb",
    "overlap_ratio_in",
    "make_overlap_work",
    "OverlapWork",
]

#: Work arrays of one overlap-ratio evaluation: the frustum's camera-frame vertices (8, 3) and half-spaces
#: (6, 4), then the clipping scratch of ``_overlap_pair`` (see ``make_overlap_work``).
OverlapWork = namedtuple("OverlapWork", ["lv", "lh", "vb", "hb", "cut", "poly", "dist"])


#: Two faces are treated as coplanar when their unit normals agree to this (max abs component) ...
COPLANAR_NORMAL_TOL = 1e-12
#: ... and their plane offsets to this (m). Faces closer than this to coplanar are exact up to rounding.
COPLANAR_OFFSET_TOL = 1e-12
#: Rotation matrices must satisfy max |RᵀR − I| <= ROTATION_TOL and det R > 0.
ROTATION_TOL = 1e-6

_DEFAULT_FRUSTUM = Frustum()
_FACES = FACE_VERTICES  # numba freezes this global as a constant
_POLY_CAPACITY = 256  # a 4-gon clipped 6 times has at most 4 * 2**6 vertices (<= 10 if exactly convex)

# Error codes returned by the compiled checks (argument, problem).
_ERRORS = {
    1: ("p_a", "must be finite (no NaN or inf)"),
    2: ("R_a", "must be finite (no NaN or inf)"),
    3: ("R_a", f"must be a rotation matrix (max |R^T R - I| <= {ROTATION_TOL:g}, det R > 0)"),
    4: ("p_b", "must be finite (no NaN or inf)"),
    5: ("R_b", "must be finite (no NaN or inf)"),
    6: ("R_b", f"must be a rotation matrix (max |R^T R - I| <= {ROTATION_TOL:g}, det R > 0)"),
}


# ----------------------------------------------------------------------------------------------
# compiled kernel
# ----------------------------------------------------------------------------------------------
@njit(cache=True)
def _check_pose(p, R):
    """0 if p and R are finite and R is a proper rotation; 1 bad p; 2 non-finite R; 3 not a rotation."""
    for i in range(3):
        if not np.isfinite(p[i]):
            return 1
    for i in range(3):
        for j in range(3):
            if not np.isfinite(R[i, j]):
                return 2
    for i in range(3):
        for j in range(3):
            g = R[0, i] * R[0, j] + R[1, i] * R[1, j] + R[2, i] * R[2, j]
            if i == j:
                g -= 1.0
            if abs(g) > ROTATION_TOL:
                return 3
    det = (
        R[0, 0] * (R[1, 1] * R[2, 2] - R[1, 2] * R[2, 1])
        - R[0, 1] * (R[1, 0] * R[2, 2] - R[1, 2] * R[2, 0])
        + R[0, 2] * (R[1, 0] * R[2, 1] - R[1, 1] * R[2, 0])
    )
    if det <= 0.0:
        return 3
    return 0


@njit(cache=True)
def _local_geometry(t, near, far, verts, planes):
    """Fill the camera-frame vertices (8, 3) and half-spaces (6, 4) (order as in ``frustum.py``)."""
    a = t * near
    b = t * far
    sx = (-1.0, 1.0, 1.0, -1.0)
    sy = (-1.0, -1.0, 1.0, 1.0)
    for k in range(4):
        verts[k, 0] = sx[k] * a
        verts[k, 1] = sy[k] * a
        verts[k, 2] = near
        verts[k + 4, 0] = sx[k] * b
        verts[k + 4, 1] = sy[k] * b
        verts[k + 4, 2] = far
    c = 1.0 / np.sqrt(1.0 + t * t)
    s = t * c
    planes[:, :] = 0.0
    planes[0, 2] = -1.0
    planes[0, 3] = near
    planes[1, 2] = 1.0
    planes[1, 3] = -far
    planes[2, 0] = c
    planes[3, 0] = -c
    planes[4, 1] = c
    planes[5, 1] = -c
    for k in range(2, 6):
        planes[k, 2] = -s


@njit(cache=True)
def make_overlap_work():
    """An ``OverlapWork`` for :func:`overlap_ratio_in` (allocate once, reuse over a batch)."""
    return OverlapWork(
        np.empty((8, 3)),  # lv: the frustum's camera-frame vertices
        np.empty((6, 4)),  # lh: its camera-frame half-spaces
        np.empty((8, 3)),  # vb: vertices of b in frame a
        np.empty((6, 4)),  # hb: half-spaces of b in frame a
        np.empty((8, 6, 4)),  # cut: the 6 planes each face is clipped by (faces a-near, a-far, b0..b5)
        np.empty((2, _POLY_CAPACITY, 3)),  # ping-pong polygon buffers
        np.empty(_POLY_CAPACITY),  # signed distances
    )


@njit(cache=True)
def _overlap_pair(pa, Ra, pb, Rb, t, near, far, lv, lh, vb, hb, cut, poly, dist):
    """OR for one pair; lv, lh: camera-frame vertices/half-spaces of the frustum; the rest is workspace."""
    # pose of camera b in camera frame a: p = Ra^T (pb - pa), Rr = Ra^T Rb
    d0 = pb[0] - pa[0]
    d1 = pb[1] - pa[1]
    d2 = pb[2] - pa[2]
    p0 = Ra[0, 0] * d0 + Ra[1, 0] * d1 + Ra[2, 0] * d2
    p1 = Ra[0, 1] * d0 + Ra[1, 1] * d1 + Ra[2, 1] * d2
    p2 = Ra[0, 2] * d0 + Ra[1, 2] * d1 + Ra[2, 2] * d2
    r00 = Ra[0, 0] * Rb[0, 0] + Ra[1, 0] * Rb[1, 0] + Ra[2, 0] * Rb[2, 0]
    r01 = Ra[0, 0] * Rb[0, 1] + Ra[1, 0] * Rb[1, 1] + Ra[2, 0] * Rb[2, 1]
    r02 = Ra[0, 0] * Rb[0, 2] + Ra[1, 0] * Rb[1, 2] + Ra[2, 0] * Rb[2, 2]
    r10 = Ra[0, 1] * Rb[0, 0] + Ra[1, 1] * Rb[1, 0] + Ra[2, 1] * Rb[2, 0]
    r11 = Ra[0, 1] * Rb[0, 1] + Ra[1, 1] * Rb[1, 1] + Ra[2, 1] * Rb[2, 1]
    r12 = Ra[0, 1] * Rb[0, 2] + Ra[1, 1] * Rb[1, 2] + Ra[2, 1] * Rb[2, 2]
    r20 = Ra[0, 2] * Rb[0, 0] + Ra[1, 2] * Rb[1, 0] + Ra[2, 2] * Rb[2, 0]
    r21 = Ra[0, 2] * Rb[0, 1] + Ra[1, 2] * Rb[1, 1] + Ra[2, 2] * Rb[2, 1]
    r22 = Ra[0, 2] * Rb[0, 2] + Ra[1, 2] * Rb[1, 2] + Ra[2, 2] * Rb[2, 2]
    for k in range(8):
        x = lv[k, 0]
        y = lv[k, 1]
        z = lv[k, 2]
        vb[k, 0] = p0 + r00 * x + r01 * y + r02 * z
        vb[k, 1] = p1 + r10 * x + r11 * y + r12 * z
        vb[k, 2] = p2 + r20 * x + r21 * y + r22 * z
    for k in range(6):
        x = lh[k, 0]
        y = lh[k, 1]
        z = lh[k, 2]
        n0 = r00 * x + r01 * y + r02 * z
        n1 = r10 * x + r11 * y + r12 * z
        n2 = r20 * x + r21 * y + r22 * z
        hb[k, 0] = n0
        hb[k, 1] = n1
        hb[k, 2] = n2
        hb[k, 3] = lh[k, 3] - (n0 * p0 + n1 * p1 + n2 * p2)

    # separating planes: every vertex of one frustum outside one plane of the other -> disjoint
    for i in range(6):
        inside = False
        for k in range(8):
            if lh[i, 0] * vb[k, 0] + lh[i, 1] * vb[k, 1] + lh[i, 2] * vb[k, 2] + lh[i, 3] <= 0.0:
                inside = True
                break
        if not inside:
            return 0.0
        inside = False
        for k in range(8):
            if hb[i, 0] * lv[k, 0] + hb[i, 1] * lv[k, 1] + hb[i, 2] * lv[k, 2] + hb[i, 3] <= 0.0:
                inside = True
                break
        if not inside:
            return 0.0

    # Clip planes of each face. Face f of a (plane P = lh[f]) is cut by every plane Q = hb[k] of b,
    # applied as Q - s P with s = sign(n_Q . n_P): on the plane P this equals Q, and for a nearly
    # parallel pair (P, Q) face Q of b is cut by P - s Q = -s (Q - s P), the same functional, so the two
    # cuts agree exactly and no sliver is counted twice or missed. Coplanar faces with the same
    # outward normal are one piece of the boundary: b's copy is skipped and a's copy is not cut by
    # that plane (the row 0.x - 1 <= 0 keeps everything). Opposite normals: P ∩ Q is a plane, V = 0.
    skip_b = 0  # bit j set: face j of b is skipped
    for i in range(6):
        for j in range(6):
            dot = lh[i, 0] * hb[j, 0] + lh[i, 1] * hb[j, 1] + lh[i, 2] * hb[j, 2]
            s = 1.0 if dot >= 0.0 else -1.0
            for c in range(4):
                cut[2 + j, i, c] = lh[i, c] - s * hb[j, c]
            if i < 2:
                for c in range(4):
                    cut[i, j, c] = hb[j, c] - s * lh[i, c]
            if abs(dot) < 0.5:
                continue
            same = max(abs(lh[i, 0] - hb[j, 0]), abs(lh[i, 1] - hb[j, 1]), abs(lh[i, 2] - hb[j, 2]))
            if same <= COPLANAR_NORMAL_TOL and abs(lh[i, 3] - hb[j, 3]) <= COPLANAR_OFFSET_TOL:
                skip_b |= 1 << j
                if i < 2:
                    cut[i, j, 0] = 0.0
                    cut[i, j, 1] = 0.0
                    cut[i, j, 2] = 0.0
                    cut[i, j, 3] = -1.0
            opposite = max(abs(lh[i, 0] + hb[j, 0]), abs(lh[i, 1] + hb[j, 1]), abs(lh[i, 2] + hb[j, 2]))
            if opposite <= COPLANAR_NORMAL_TOL and abs(lh[i, 3] + hb[j, 3]) <= COPLANAR_OFFSET_TOL:
                return 0.0

    # V = 1/3 sum_f (n_f . x_f) area(face_f ∩ other); faces 0, 1: near and far of a (a's side planes
    # contain the origin, n_f . x_f = 0); faces 2..7: the six faces of b.
    total = 0.0
    for f in range(8):
        if f < 2:
            verts = lv
            face = f
            nx = lh[f, 0]
            ny = lh[f, 1]
            nz = lh[f, 2]
            h = -lh[f, 3]
        else:
            face = f - 2
            if (skip_b >> face) & 1:
                continue
            verts = vb
            nx = hb[face, 0]
            ny = hb[face, 1]
            nz = hb[face, 2]
            h = -hb[face, 3]
        for c in range(4):
            for e in range(3):
                poly[0, c, e] = verts[_FACES[face, c], e]
        m = 4
        cur = 0
        for k in range(6):
            # Sutherland–Hodgman step: keep cut[f, k] . [x, 1] <= 0
            a0 = cut[f, k, 0]
            a1 = cut[f, k, 1]
            a2 = cut[f, k, 2]
            a3 = cut[f, k, 3]
            n_out = 0
            for i in range(m):
                d = a0 * poly[cur, i, 0] + a1 * poly[cur, i, 1] + a2 * poly[cur, i, 2] + a3
                dist[i] = d
                if d > 0.0:
                    n_out += 1
            if n_out == 0:
                continue
            if n_out == m:
                m = 0
                break
            nxt = 1 - cur
            q = 0
            prev = m - 1
            dp = dist[prev]
            for i in range(m):
                dc = dist[i]
                if dc <= 0.0:
                    if dp > 0.0 and dc < 0.0:  # entering: edge prev -> i crosses the plane
                        r = dp / (dp - dc)
                        for e in range(3):
                            poly[nxt, q, e] = poly[cur, prev, e] + r * (poly[cur, i, e] - poly[cur, prev, e])
                        q += 1
                    for e in range(3):
                        poly[nxt, q, e] = poly[cur, i, e]
                    q += 1
                elif dp < 0.0:  # leaving
                    r = dp / (dp - dc)
                    for e in range(3):
                        poly[nxt, q, e] = poly[cur, prev, e] + r * (poly[cur, i, e] - poly[cur, prev, e])
                    q += 1
                prev = i
                dp = dc
            m = q
            cur = nxt
        if m < 3:
            continue
        # signed area about the outward normal (faces are counter-clockwise seen from outside)
        x0 = poly[cur, 0, 0]
        y0 = poly[cur, 0, 1]
        z0 = poly[cur, 0, 2]
        ux = poly[cur, 1, 0] - x0
        uy = poly[cur, 1, 1] - y0
        uz = poly[cur, 1, 2] - z0
        twice_area = 0.0
        for i in range(2, m):
            vx = poly[cur, i, 0] - x0
            vy = poly[cur, i, 1] - y0
            vz = poly[cur, i, 2] - z0
            twice_area += nx * (uy * vz - uz * vy) + ny * (uz * vx - ux * vz) + nz * (ux * vy - uy * vx)
            ux = vx
            uy = vy
            uz = vz
        total += h * 0.5 * twice_area

    volume_a = 4.0 * t * t * (far * far * far - near * near * near) / 3.0
    ratio = total / 3.0 / volume_a
    if ratio < 0.0:  # rounding noise of touching frustums
        return 0.0
    if ratio > 1.0:
        return 1.0
    return ratio


@njit(cache=True)
def overlap_ratio_nb(p_a, R_a, p_b, R_b, tan_half, near, far):
    """Compiled OR of one pair (p: (3,), R: (3, 3)) for a square frustum; no input checks.

    For use inside other numba kernels; Python callers should use :func:`overlap_ratio`.
    """
    # The work's arrays as locals, not a call of overlap_ratio_in with the bundle: that extra call's
    # reference counts made a single pair ~0.5 us slower.
    lv, lh, vb, hb, cut, poly, dist = make_overlap_work()
    _local_geometry(tan_half, near, far, lv, lh)
    return _overlap_pair(p_a, R_a, p_b, R_b, tan_half, near, far, lv, lh, vb, hb, cut, poly, dist)


@njit(cache=True)
def overlap_ratio_in(p_a, R_a, p_b, R_b, tan_half, near, far, work):
    """:func:`overlap_ratio_nb` with its work arrays passed (an ``OverlapWork``): same arithmetic, no allocation.

    Positions in m; for use inside other numba kernels that evaluate many pairs.
    """
    _local_geometry(tan_half, near, far, work.lv, work.lh)
    return _overlap_pair(p_a, R_a, p_b, R_b, tan_half, near, far, work.lv, work.lh, work.vb, work.hb, work.cut,
                         work.poly, work.dist)


_SINGLE_SIGNATURE = "float64(float64[::1], float64[:, ::1], float64[::1], float64[:, ::1], float64, float64, float64)"
_BATCH_SIGNATURE = (
    "Tuple((int64, int64))(float64[:, ::1], float64[:, :, ::1], float64[:, ::1], float64[:, :, ::1], "
    "float64, float64, float64, float64[::1])"
)


def _compiled(dispatcher, signature: str):
    """``dispatcher`` compiled for ``signature`` (C-contiguous writable float64 arrays) and closed to any other.

    So unusual inputs (views, read-only arrays) never trigger new compilations. On first use, not at
    import (as a signature in the decorator would): an OcclusionAvoidance user never pays its ~4.6 s of
    compiling on an empty cache. The callers keep the result in a module global (a function call per
    pair was 5 % of a single pair's 2.2 us).
    """
    with _COMPILE_LOCK:  # two threads' first calls: one compiles, the other finds it compiled
        if not dispatcher.signatures:
            dispatcher.compile(signature)
            dispatcher.disable_compile()
    return dispatcher


_COMPILE_LOCK = threading.Lock()
_single_kernel = None
_batch_kernel = None


@njit(cache=True)
def _overlap_single(p_a, R_a, p_b, R_b, tan_half, near, far):
    """OR of one pair, or −(error code) if an input is invalid."""
    code = _check_pose(p_a, R_a)
    if code != 0:
        return -float(code)
    code = _check_pose(p_b, R_b)
    if code != 0:
        return -float(code + 3)
    return overlap_ratio_nb(p_a, R_a, p_b, R_b, tan_half, near, far)


@njit(cache=True)
def _overlap_batch(p_a, R_a, p_b, R_b, tan_half, near, far, out):
    """OR of N pairs (p: (N, 3), R: (N, 3, 3)) into out (N,); returns (error code, index) or (0, -1)."""
    n = out.shape[0]
    for k in range(n):
        code = _check_pose(p_a[k], R_a[k])
        if code != 0:
            return code, k
        code = _check_pose(p_b[k], R_b[k])
        if code != 0:
            return code + 3, k
    # The work's arrays as locals: a bundle's array read inside the loop costs an atomic reference count
    # per read (~7 % of this loop when they were read there).
    lv, lh, vb, hb, cut, poly, dist = make_overlap_work()
    _local_geometry(tan_half, near, far, lv, lh)  # once: the frustum is the same for every pair
    for k in range(n):
        out[k] = _overlap_pair(p_a[k], R_a[k], p_b[k], R_b[k], tan_half, near, far, lv, lh, vb, hb, cut, poly, dist)
    return 0, -1


# ----------------------------------------------------------------------------------------------
# Python API
# ----------------------------------------------------------------------------------------------
def resolve_frustum(frustum: Frustum | None) -> Frustum:
    """``frustum``, or the paper's frustum for None (ValueError for anything else)."""
    if frustum is None:
        return _DEFAULT_FRUSTUM
    if not isinstance(frustum, Frustum):
        raise ValueError(f"frustum must be a Frustum or None; got {type(frustum).__name__}")
    return frustum


def _float_array(x, name: str) -> np.ndarray:
    if type(x) is np.ndarray and x.dtype == np.float64:
        return x
    try:
        return np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name} must be a numeric array; got {x!r}") from error


def _raise(code: int, index=None) -> None:
    name, problem = _ERRORS[int(code)]
    where = "" if index is None else f" (at flattened batch index {index})"
    raise ValueError(f"{name} {problem}{where}")


def overlap_ratio(p_a, R_a, p_b, R_b, frustum: Frustum | None = None) -> np.ndarray:
    """Exact overlap ratio OR = vol(F_a ∩ F_b) / vol(F_a) of two camera frustums (paper-notes §2.4).

    Args:
        p_a, p_b: camera positions in {w} (m), shape (..., 3).
        R_a, R_b: camera rotations ^wR_cam, shape (..., 3, 3); z is the viewing axis.
        frustum: shared frustum shape; ``None`` means ``Frustum()`` (90°, 30 mm, 120 mm).

    Returns:
        float64 array with the batch shapes of the four inputs broadcast together (a 0-d array for
        one pair), values in [0, 1].

    Raises:
        ValueError: naming the argument, for wrong shapes, NaN/inf, non-rotations or
        non-broadcastable batch shapes.
    """
    global _single_kernel, _batch_kernel
    frustum = resolve_frustum(frustum)
    p_a = _float_array(p_a, "p_a")
    R_a = _float_array(R_a, "R_a")
    p_b = _float_array(p_b, "p_b")
    R_b = _float_array(R_b, "R_b")
    if p_a.shape == (3,) and p_b.shape == (3,) and R_a.shape == (3, 3) and R_b.shape == (3, 3):
        single = _single_kernel
        if single is None:
            single = _single_kernel = _compiled(_overlap_single, _SINGLE_SIGNATURE)
        try:
            value = single(p_a, R_a, p_b, R_b, frustum.tan_half, frustum.near, frustum.far)
        except TypeError:  # views or read-only arrays: the kernel takes C-contiguous writable arrays
            value = single(
                np.array(p_a, order="C"), np.array(R_a, order="C"), np.array(p_b, order="C"),
                np.array(R_b, order="C"), frustum.tan_half, frustum.near, frustum.far,
            )
        if value < 0.0:
            _raise(-value)
        return np.array(value)
    for name, array in (("p_a", p_a), ("p_b", p_b)):
        if array.ndim < 1 or array.shape[-1] != 3:
            raise ValueError(f"{name} must have shape (..., 3); got shape {array.shape}")
    for name, array in (("R_a", R_a), ("R_b", R_b)):
        if array.ndim < 2 or array.shape[-2:] != (3, 3):
            raise ValueError(f"{name} must have shape (..., 3, 3); got shape {array.shape}")
    try:
        batch = np.broadcast_shapes(p_a.shape[:-1], R_a.shape[:-2], p_b.shape[:-1], R_b.shape[:-2])
    except ValueError as error:
        raise ValueError(
            "batch shapes of p_a, R_a, p_b, R_b do not broadcast: "
            f"{p_a.shape[:-1]}, {R_a.shape[:-2]}, {p_b.shape[:-1]}, {R_b.shape[:-2]}"
        ) from error
    n = int(np.prod(batch))

    def flat(array, tail):  # a fresh C-contiguous writable (n, *tail) copy
        return np.array(np.broadcast_to(array, batch + tail), order="C").reshape((n,) + tail)

    out = np.empty(n)
    batch_kernel = _batch_kernel
    if batch_kernel is None:
        batch_kernel = _batch_kernel = _compiled(_overlap_batch, _BATCH_SIGNATURE)
    code, index = batch_kernel(
        flat(p_a, (3,)), flat(R_a, (3, 3)), flat(p_b, (3,)), flat(R_b, (3, 3)),
        frustum.tan_half, frustum.near, frustum.far, out,
    )
    if code != 0:
        _raise(code, index)
    return out.reshape(batch)


def __getattr__(name: str):
    # The references moved to overlap_reference.py; their old import path keeps working.
    if name in ("overlap_ratio_reference", "overlap_ratio_monte_carlo", "REFERENCE_MIN_RADIUS"):
        from continuum_gym.geometry import overlap_reference

        return getattr(overlap_reference, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
