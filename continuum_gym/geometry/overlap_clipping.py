"""The compiled clipping behind the exact overlap ratio (``geometry.overlap``; paper-notes §2.4).

The volume of the convex polytope P = F_a ∩ F_b comes from the divergence theorem, V = 1/3 Σ_f (n_f · x_f)
area_f, summed over the faces f of *both* frustums, where face f contributes its part inside the other
frustum (its 4-gon clipped by the other frustum's 6 half-spaces, Sutherland–Hodgman), n_f is its outward
unit normal and x_f any point of its plane. Everything is done in F_a's camera frame, with the apex of F_a
as origin, so F_a's four side planes pass through the origin and contribute nothing. A face of F_b lying in
the plane of a face of F_a with the same outward normal is the same piece of ∂P and is counted once (F_b's
copy is skipped and F_a's copy is not clipped by that plane); faces in a common plane with opposite normals
mean P lies in that plane, so V = 0. Nearly coplanar faces (e.g. two cameras converged to the same pose
within 1e-10 rad) are the ill-conditioned case of this formula: if face P is cut by plane Q and face Q by
plane P independently, rounding moves the two cut lines apart by ~1e-17 m / angle, and the sliver between
them is counted twice or not at all (an OR error of 2e-4 at 1e-12 rad). So face P is cut by Q − s·P and face
Q by P − s·Q = −s·(Q − s·P) (s = sign(n_P·n_Q)), which equal Q and P on the respective face planes but are
one and the same functional: the cuts coincide and OR stays exact (1e-15 against scipy for tilts from 1e-14
to 1e-4 rad).

:func:`overlap_ratio_nb` (fresh work arrays) and :func:`overlap_ratio_in` (an ``OverlapWork`` passed) are
the per-pair kernels without input checks, for other numba kernels; ``overlap.overlap_ratio`` is the
checked, batched Python API.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from continuum_gym.geometry.frustum import FACE_VERTICES
from continuum_gym.robots.compiled import kernel

__all__ = ["OverlapWork", "make_overlap_work", "local_geometry", "overlap_pair", "overlap_ratio_nb", "overlap_ratio_in",
           "overlap_ratio_inline", "COPLANAR_NORMAL_TOL", "COPLANAR_OFFSET_TOL"]

#: Work arrays of one overlap-ratio evaluation: the frustum's camera-frame vertices (8, 3) and half-spaces
#: (6, 4), then the clipping scratch of ``overlap_pair`` (see ``make_overlap_work``).
OverlapWork = namedtuple("OverlapWork", ["lv", "lh", "vb", "hb", "cut", "poly", "dist"])

#: Two faces are treated as coplanar when their unit normals agree to this (max abs component) ...
COPLANAR_NORMAL_TOL = 1e-12
#: ... and their plane offsets to this (m). Faces closer than this to coplanar are exact up to rounding.
COPLANAR_OFFSET_TOL = 1e-12

_FACES = FACE_VERTICES  # numba freezes this global as a constant
_POLY_CAPACITY = 256  # a 4-gon clipped 6 times has at most 4 * 2**6 vertices (<= 10 if exactly convex)


@kernel(borrows=True)
def local_geometry(t, near, far, verts, planes):
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


@kernel
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


@kernel(borrows=True)
def overlap_pair(pa, Ra, pb, Rb, t, near, far, lv, lh, vb, hb, cut, poly, dist):
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


@kernel
def overlap_ratio_nb(p_a, R_a, p_b, R_b, tan_half, near, far):
    """Compiled OR of one pair (p: (3,), R: (3, 3)) for a square frustum; no input checks.

    For use inside other numba kernels; Python callers should use :func:`overlap_ratio`.
    """
    # The work's arrays as locals, not a call of overlap_ratio_in with the bundle: that extra call's
    # reference counts would make a single pair ~0.5 us slower.
    lv, lh, vb, hb, cut, poly, dist = make_overlap_work()
    local_geometry(tan_half, near, far, lv, lh)
    return overlap_pair(p_a, R_a, p_b, R_b, tan_half, near, far, lv, lh, vb, hb, cut, poly, dist)


@kernel(borrows=True)
def overlap_ratio_in(p_a, R_a, p_b, R_b, tan_half, near, far, work):
    """:func:`overlap_ratio_nb` with its work arrays passed (an ``OverlapWork``): same arithmetic, no allocation.

    Positions in m; for use inside other numba kernels that evaluate many pairs.
    """
    return overlap_ratio_inline(p_a, R_a, p_b, R_b, tan_half, near, far, work)


@kernel(inline="always")
def overlap_ratio_inline(p_a, R_a, p_b, R_b, tan_half, near, far, work):
    """``overlap_ratio_in`` inlined into a borrowing caller (a call would pass every array of ``work``)."""
    local_geometry(tan_half, near, far, work.lv, work.lh)
    return overlap_pair(p_a, R_a, p_b, R_b, tan_half, near, far, work.lv, work.lh, work.vb, work.hb, work.cut,
                         work.poly, work.dist)
