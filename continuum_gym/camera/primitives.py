"""The rasteriser's inline pieces: a tube and a textured plane drawn into one image, shading, noise.

Everything here is inlined into ``raster.render_rows``. An image is drawn into a row of 4-d buffers
``(rows, H, W, channels)``: rgb uint8, depth float32 (the z-buffer), segmentation uint8, each with the row
it writes (a scratch buffer has one row).

Pixel samples and rays follow ``continuum_gym.camera.model``: pixel (i, j) has the ray (x, y, 1) in the camera
frame, (x, y) = (xs[j], ys[i]) without distortion or ``rays[i, j]`` with, so a hit's depth is its ray parameter.
"""

from __future__ import annotations

import math

import numpy as np

from continuum_gym.robots.compiled import kernel

__all__ = ["OPEN", "FLAT", "ROUND", "gaussian_like", "undistort_radius", "distorted_span", "tube_box",
           "effective_radius", "prism_planes", "draw_tube", "draw_plane", "shade"]

#: Tube end kinds.
OPEN, FLAT, ROUND = 0, 1, 2

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_MASK16 = np.uint64(0xFFFF)
_S30, _S27, _S31 = np.uint64(30), np.uint64(27), np.uint64(31)
_S16, _S32, _S48 = np.uint64(16), np.uint64(32), np.uint64(48)
#: sum of four uniform 16-bit integers: its mean and standard deviation
_SUM_MEAN = 2.0 * 65535.0
_SUM_STD = 65536.0 / math.sqrt(3.0)


@kernel(inline="always")
def gaussian_like(seed, index):
    """An approximately standard normal number from (seed, index): splitmix64, then the sum of its four 16-bit
    parts (Irwin-Hall, n = 4: mean 0, variance 1, tails cut at +-3.46). Counter-based: any order, any thread."""
    z = seed + np.uint64(index) * _GOLDEN
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    z = z ^ (z >> _S31)
    s = float(z & _MASK16) + float((z >> _S16) & _MASK16) + float((z >> _S32) & _MASK16) + float(z >> _S48)
    return (s - _SUM_MEAN) / _SUM_STD


@kernel(inline="always")
def shade(value):
    """A colour channel in [0, 255] (float) as uint8, rounded."""
    return np.uint8(min(max(value + 0.5, 0.0), 255.0))


@kernel(inline="always")
def undistort_radius(r_d, k1):
    """r with r (1 + k1 r^2) = r_d (Newton from r_d, as the model's ``undistort``)."""
    r = r_d
    for _ in range(8):
        r = r - (r + k1 * r * r * r - r_d) / (1.0 + 3.0 * k1 * r * r)
    return r


@kernel(inline="always")
def distorted_span(lo, hi, other_lo, other_hi, k1):
    """Range of x (1 + k1 (x^2 + y^2)) over the box x in [lo, hi], y in [other_lo, other_hi] (an invertible k1):
    the extremes lie at the corners or where the box crosses y = 0 (the map is monotone in x)."""
    y_near = 0.0 if other_lo <= 0.0 <= other_hi else min(abs(other_lo), abs(other_hi))
    y_far = max(abs(other_lo), abs(other_hi))
    out_lo = math.inf
    out_hi = -math.inf
    for x in (lo, hi):
        for y in (y_near, y_far):
            v = x * (1.0 + k1 * (x * x + y * y))
            out_lo = min(out_lo, v)
            out_hi = max(out_hi, v)
    return out_lo, out_hi


@kernel(inline="always")
def sphere_range(c, cz, r):
    """Range of x / z over a sphere of radius r at (c, ., cz), cz > r: its tangent planes through the origin."""
    q = cz * cz - r * r
    s = r * math.sqrt(max(c * c + q, 0.0))
    return (c * cz - s) / q, (c * cz + s) / q


@kernel(inline="always")
def clipped_prism_box(a0, a1, a2, b0, b1, b2, r, near):
    """Normalised-coordinate box (x0, x1, y0, y1) of the part in front of z = near of the octagonal prism
    circumscribing the tube from a to b of radius r (x0 > x1 if none): the image of a convex polytope in z > 0
    is the hull of its vertices' images, and the clipped prism's vertices are its own in front and the points
    where its edges cross z = near."""
    L = math.sqrt((b0 - a0) ** 2 + (b1 - a1) ** 2 + (b2 - a2) ** 2)
    w0, w1, w2 = (b0 - a0) / L, (b1 - a1) / L, (b2 - a2) / L
    # e1, e2: unit vectors across the axis
    if abs(w0) < 0.9:
        e0, e1_, e2_ = 0.0, w2, -w1  # w x x
    else:
        e0, e1_, e2_ = -w2, 0.0, w0  # w x y
    norm = math.sqrt(e0 * e0 + e1_ * e1_ + e2_ * e2_)
    e0, e1_, e2_ = e0 / norm, e1_ / norm, e2_ / norm
    f0, f1, f2 = w1 * e2_ - w2 * e1_, w2 * e0 - w0 * e2_, w0 * e1_ - w1 * e0
    big = r / math.cos(math.pi / 8.0)
    x0 = math.inf
    x1 = -math.inf
    y0 = math.inf
    y1 = -math.inf
    root = math.sqrt(0.5)
    c1, s1 = 1.0, 0.0
    for _ in range(8):
        c0, s0 = c1, s1  # cos and sin of k pi / 4 for the k-th corner, by rotation
        c1, s1 = root * (c0 - s0), root * (s0 + c0)
        o0 = big * (c0 * e0 + s0 * f0)
        o1 = big * (c0 * e1_ + s0 * f1)
        o2 = big * (c0 * e2_ + s0 * f2)
        q0 = big * (c1 * e0 + s1 * f0)
        q1 = big * (c1 * e1_ + s1 * f1)
        q2 = big * (c1 * e2_ + s1 * f2)
        # this vertex at both ends, its lateral edge, and the ring edges to the next vertex
        for edge in range(3):
            if edge == 0:
                p0, p1, p2, d0, d1, d2 = a0 + o0, a1 + o1, a2 + o2, b0 - a0, b1 - a1, b2 - a2
            elif edge == 1:
                p0, p1, p2, d0, d1, d2 = a0 + o0, a1 + o1, a2 + o2, q0 - o0, q1 - o1, q2 - o2
            else:
                p0, p1, p2, d0, d1, d2 = b0 + o0, b1 + o1, b2 + o2, q0 - o0, q1 - o1, q2 - o2
            for end in range(2):
                v0, v1, v2 = p0 + end * d0, p1 + end * d1, p2 + end * d2
                if v2 >= near:
                    x0, x1 = min(x0, v0 / v2), max(x1, v0 / v2)
                    y0, y1 = min(y0, v1 / v2), max(y1, v1 / v2)
            if (p2 - near) * (p2 + d2 - near) < 0.0:
                t = (near - p2) / d2
                v0, v1 = p0 + t * d0, p1 + t * d1
                x0, x1 = min(x0, v0 / near), max(x1, v0 / near)
                y0, y1 = min(y0, v1 / near), max(y1, v1 / near)
    return x0, x1, y0, y1


@kernel(inline="always")
def tube_box(a0, a1, a2, b0, b1, b2, r, round_b, near, far):
    """Normalised-coordinate box (x0, x1, y0, y1) holding the image of a tube (camera-frame ends a, b, radius r,
    a sphere of radius <= r at b if ``round_b``), or x0 > x1 when it lies outside [near, far].

    With both end spheres in front: the union of their exact images (the tube lies in their convex hull, and
    perspective keeps convex hulls); else the box of the clipped circumscribing prism (``clipped_prism_box``,
    the end at b moved out by r for a round end). An end disk of radius r perpendicular to the unit axis w
    reaches r sqrt(1 - w_z^2) along z.
    """
    L = math.sqrt((b0 - a0) ** 2 + (b1 - a1) ** 2 + (b2 - a2) ** 2)
    ez = r * math.sqrt(max(0.0, 1.0 - ((b2 - a2) / L) ** 2))
    bz = r if round_b else ez
    if max(a2 + ez, b2 + bz) < near or min(a2 - ez, b2 - bz) > far:
        return 1.0, 0.0, 1.0, 0.0
    if min(a2, b2) > 1.001 * r + 1e-9:
        xa0, xa1 = sphere_range(a0, a2, r)
        xb0, xb1 = sphere_range(b0, b2, r)
        ya0, ya1 = sphere_range(a1, a2, r)
        yb0, yb1 = sphere_range(b1, b2, r)
        return min(xa0, xb0), max(xa1, xb1), min(ya0, yb0), max(ya1, yb1)
    if round_b:
        b0, b1, b2 = b0 + r * (b0 - a0) / L, b1 + r * (b1 - a1) / L, b2 + r * (b2 - a2) / L
    return clipped_prism_box(a0, a1, a2, b0, b1, b2, r, near)


@kernel(inline="always")
def effective_radius(r, sides, wx, wy, wz, ux, uy, uz, mx, my, mz):
    """Silhouette half-width of a regular prism (circumradius r, ``sides``, vertex direction u, unit axis w) seen
    from the origin toward its point m (r for sides = 0): r cos(delta), delta the angle from the silhouette
    direction w x m to the nearest vertex. End-on (no silhouette direction): its mean width."""
    if sides <= 0:
        return r
    sx = wy * mz - wz * my
    sy = wz * mx - wx * mz
    sz = wx * my - wy * mx
    norm = math.sqrt(sx * sx + sy * sy + sz * sz)
    step = 2.0 * math.pi / sides
    if norm < 1e-12 * math.sqrt(mx * mx + my * my + mz * mz):
        return r * math.sin(0.5 * step) / (0.5 * step)
    vx = wy * uz - wz * uy  # v = w x u
    vy = wz * ux - wx * uz
    vz = wx * uy - wy * ux
    phi = math.atan2(sx * vx + sy * vy + sz * vz, sx * ux + sy * uy + sz * uz)
    off = phi % step
    return r * math.cos(min(off, step - off))


@kernel(inline="always")
def prism_planes(sides, wx, wy, wz, ux, uy, uz, m):
    """The vectors that draw a prism of an even number of ``sides`` (vertex direction u, unit axis w), into m (64, 3):
    rows k < sides / 2, m_k = v_k x w for the vertex directions v_k = cos(2 pi k / sides) u + sin(2 pi k / sides)
    (w x u) (the other half are their negatives); rows 32 + k, the unit normals of the faces between v_k and
    v_{k+1} (the other faces' are their negatives). Returns sides / 2 (0 for a round tube)."""
    if sides <= 0:
        return 0
    vx = wy * uz - wz * uy
    vy = wz * ux - wx * uz
    vz = wx * uy - wy * ux
    count = sides // 2
    step_c, step_s = math.cos(2.0 * math.pi / sides), math.sin(2.0 * math.pi / sides)
    half_c, half_s = math.cos(math.pi / sides), math.sin(math.pi / sides)
    c, s = 1.0, 0.0  # cos and sin of 2 pi k / sides, by rotation (a few ulps from the trigonometric values)
    for k in range(count):
        px, py, pz = c * ux + s * vx, c * uy + s * vy, c * uz + s * vz
        m[k, 0] = py * wz - pz * wy
        m[k, 1] = pz * wx - px * wz
        m[k, 2] = px * wy - py * wx
        fc, fs = c * half_c - s * half_s, s * half_c + c * half_s
        m[32 + k, 0] = fc * ux + fs * vx
        m[32 + k, 1] = fc * uy + fs * vy
        m[32 + k, 2] = fc * uz + fs * vz
        c, s = c * step_c - s * step_s, s * step_c + c * step_s
    return count


@kernel(inline="always")
def tube_candidate(x, y, a0, a1, a2, w0, w1, w2, aw, circumscribed, L, b0, b1, b2, bb, round_cap):
    """Whether the ray (x, y, 1) meets the finite round tube from a along the unit w for L
    (|a_perp|^2 - r^2 = ``circumscribed``) or, if ``round_cap`` is 1, the sphere at b (|b|^2 - r_cap^2 = ``bb``):
    what a tube can cover. Polynomial, without branches, divisions or roots (a loop of it vectorises).

    The ray meets the infinite tube for t in B / A +- sqrt(disc) / A, where the axis coordinate is
    s = t (d . w) - a . w: A s = S +- |d . w| sqrt(disc) with S = B (d . w) - (a . w) A. That range meets [0, L]
    when S >= -|d . w| sqrt(disc) and S - L A <= |d . w| sqrt(disc), compared in squares.
    """
    dw = x * w0 + y * w1 + w2
    d2 = x * x + y * y + 1.0
    A = d2 - dw * dw
    B = x * a0 + y * a1 + a2 - dw * aw
    disc = B * B - A * circumscribed
    S = B * dw - aw * A
    reach = dw * dw * disc
    above = S - L * A
    tube = (disc >= 0.0) & ((S >= 0.0) | (S * S <= reach)) & ((above <= 0.0) | (above * above <= reach))
    e = x * b0 + y * b1 + b2
    return tube | ((e * e - d2 * bb >= 0.0) & (round_cap > 0.0))


@kernel(error_model="numpy", borrows=True)
def draw_tube(i0, i1, j0, j1, xs, ys, distorted, rays, spans, near, far, a0, a1, a2, b0, b1, b2, r, nv, m, r_cap,
              cap_a, cap_b, seg_id, red, green, blue, ambient, diffuse, want_rgb, rgb, row, zbuf, zrow, seg, srow,
              candidates):
    """Z-buffer one tube (camera-frame ends a, b, circumradius r) over the pixels [i0, i1] x [j0, j1].

    A prism (``nv`` > 0 vertex directions v_k, given as m_k = v_k x w, w the unit axis) is drawn, for each pixel's
    ray d, as the cylinder whose radius is the prism's support across the ray, h = r max_k |d . m_k| / |w x d|:
    a ray meets the infinite prism exactly when it meets that cylinder (its projection across the axis is a
    line, which meets a centrally symmetric polygon when its distance from the centre is at most the polygon's
    support along its normal); where it does, the ray's entry is found across the prism's slabs (``m[32:]``), so
    depth is the prism's. ``nv`` = 0: a round tube, h = r. A round end at b is a sphere of radius ``r_cap``.
    Each image row is done in two passes: which pixels the circumscribed round tube (or the round end) covers,
    without branches (vectorised, into ``candidates`` (W,) bool), then those pixels exactly. ``red``, ``green``,
    ``blue`` are the albedo x 255. It only borrows its arrays (no reference counting: it is called per tube).
    """
    L = math.sqrt((b0 - a0) ** 2 + (b1 - a1) ** 2 + (b2 - a2) ** 2)
    w0, w1, w2 = (b0 - a0) / L, (b1 - a1) / L, (b2 - a2) / L
    aw = a0 * w0 + a1 * w1 + a2 * w2
    a_perp2 = a0 * a0 + a1 * a1 + a2 * a2 - aw * aw
    r2 = r * r
    apothem = r * math.cos(math.pi / (2 * nv)) if nv > 0 else r
    round_cap = cap_b == 2
    bb = b0 * b0 + b1 * b1 + b2 * b2 - r_cap * r_cap
    round_cap_flag = 1.0 if round_cap else 0.0
    circumscribed = a_perp2 - r2
    for i in range(i0, i1 + 1):
        lo = max(j0, spans[i, 0])
        hi = min(j1, spans[i, 1])
        y = ys[i]
        # candidates, without branches (vectorised): the pixels whose ray meets the circumscribed round tube or
        # the round end
        if distorted:
            for j in range(lo, hi + 1):
                candidates[j] = tube_candidate(rays[i, j, 0], rays[i, j, 1], a0, a1, a2, w0, w1, w2, aw, circumscribed,
                                               L, b0, b1, b2, bb, round_cap_flag)
        else:
            for j in range(lo, hi + 1):
                candidates[j] = tube_candidate(xs[j], y, a0, a1, a2, w0, w1, w2, aw, circumscribed, L, b0, b1, b2,
                                               bb, round_cap_flag)
        for j in range(lo, hi + 1):
            if not candidates[j]:
                continue
            if distorted:
                x = rays[i, j, 0]
                y = rays[i, j, 1]
            else:
                x = xs[j]
            dw = x * w0 + y * w1 + w2
            da = x * a0 + y * a1 + a2
            d2 = x * x + y * y + 1.0
            A = d2 - dw * dw
            B = da - dw * aw
            if nv > 0:
                support = 0.0
                for k in range(nv):
                    support = max(support, abs(x * m[k, 0] + y * m[k, 1] + m[k, 2]))
                hA = r2 * support * support  # h^2 A
            else:
                hA = r2 * A
            disc = B * B - A * a_perp2 + hA
            e = 0.0
            disc_s = -1.0
            if round_cap:
                e = x * b0 + y * b1 + b2
                disc_s = e * e - d2 * bb
            if disc < 0.0 and disc_s < 0.0:
                continue
            best = math.inf
            kind = 0
            face = -1
            if disc >= 0.0:
                # the solid tube: inside the infinite tube and between the end planes
                if nv > 0:
                    # the prism: the latest entry and earliest exit across its slabs |(X - a) . f_k| <= apothem
                    t0 = -math.inf
                    t1 = math.inf
                    for k in range(nv):
                        dm = x * m[32 + k, 0] + y * m[32 + k, 1] + m[32 + k, 2]
                        am = a0 * m[32 + k, 0] + a1 * m[32 + k, 1] + a2 * m[32 + k, 2]
                        ta = (am - apothem) / dm
                        tb = (am + apothem) / dm
                        if min(ta, tb) > t0:
                            t0 = min(ta, tb)
                            face = k
                        t1 = min(t1, max(ta, tb))
                elif A > 1e-14 * d2:
                    sq = math.sqrt(disc)
                    t0 = (B - sq) / A
                    t1 = (B + sq) / A
                else:  # along the axis, inside its radius
                    t0 = -math.inf
                    t1 = math.inf
                if dw > 0.0:
                    tin = aw / dw
                    tout = (aw + L) / dw
                    cap_in = cap_a
                elif dw < 0.0:
                    tin = (aw + L) / dw
                    tout = aw / dw
                    cap_in = cap_b
                else:
                    tin = -math.inf if 0.0 <= -aw <= L else math.inf
                    tout = math.inf
                    cap_in = OPEN
                enter = max(t0, tin)
                if enter <= min(t1, tout) and enter >= near:
                    if t0 >= tin:
                        best = t0
                        kind = 1
                    elif cap_in == FLAT:  # an open end shows the tube's inside: back faces, not drawn
                        best = tin
                        kind = 2
            if disc_s >= 0.0:
                ts = (e - math.sqrt(disc_s)) / d2
                if near <= ts < best:
                    best = ts
                    kind = 3
            if kind == 0 or best > far or best >= zbuf[zrow, i, j, 0]:
                continue
            zbuf[zrow, i, j, 0] = best
            seg[srow, i, j, 0] = seg_id
            if want_rgb:
                # cosine between the surface normal and the ray (the light is at the camera)
                if kind == 1 and face >= 0:
                    c = abs(x * m[32 + face, 0] + y * m[32 + face, 1] + m[32 + face, 2])
                elif kind == 1:
                    s = best * dw - aw
                    c = abs(best * d2 - da - s * dw) / r
                elif kind == 3:
                    c = abs(best * d2 - e) / r_cap
                else:
                    c = abs(dw)
                gain = ambient + diffuse * c / math.sqrt(d2)
                rgb[row, i, j, 0] = shade(red * gain)
                rgb[row, i, j, 1] = shade(green * gain)
                rgb[row, i, j, 2] = shade(blue * gain)


@kernel(inline="always")
def mip_level(footprint, last):
    """The mip level whose texels best match a footprint of ``footprint`` level-0 texels: floor(log2), in
    [0, last] (compares, not a logarithm: the loop over a row of pixels vectorises)."""
    level = (np.int64(footprint >= 2.0) + np.int64(footprint >= 4.0) + np.int64(footprint >= 8.0)
             + np.int64(footprint >= 16.0) + np.int64(footprint >= 32.0) + np.int64(footprint >= 64.0)
             + np.int64(footprint >= 128.0) + np.int64(footprint >= 256.0))
    return min(level, last)


@kernel(inline="always")
def plane_hit(x, y, inv_norm, visible, num, n0, n1, n2, ex0, ex1, ex2, ey0, ey1, ey2, ox, oy, hx, hy, tx_m, ty_m, near,
              far, size0, last, footprint_scale):
    """(depth, cosine, texel index) where the ray (x, y, 1) (of length 1 / ``inv_norm``) meets the plane's front
    face (normal n, axes ex, ey in the camera frame) within [near, far] and its rectangle, else (far, -1, the cavity
    texel: the pyramid's last).
    Scalars only, one division and no branches: a loop of it over a row of pixels vectorises."""
    nd = x * n0 + y * n1 + n2
    inv = 1.0 / nd
    t = num * inv
    lx = t * (x * ex0 + y * ex1 + ex2) - ox
    ly = t * (x * ey0 + y * ey1 + ey2) - oy
    d2 = x * x + y * y + 1.0
    hit = visible & (nd < 0.0) & (t >= near) & (t <= far) & (abs(lx) <= hx) & (abs(ly) <= hy)
    level = mip_level(-num * d2 * inv * inv * footprint_scale, last)  # t |d|^2 / |n . d| in level-0 texels
    size = size0 >> level
    u = min(max((lx + hx) * tx_m * size, 0.0), 1e9)  # >= 0: truncation is floor
    v = min(max((ly + hy) * ty_m * size, 0.0), 1e9)
    # level l starts at 2 size0^2 - (2 size0^2 >> l) (``MipPyramid``: a shift, not a read of the offsets or a
    # division, either of which keeps the loop from vectorising); texture rows run against v (pybullet's
    # TinyRenderer reads the image bottom up)
    total = 2 * size0 * size0
    k = total - (total >> level) + ((-1 - np.int64(v)) & (size - 1)) * size + (np.int64(u) & (size - 1))
    return (t if hit else far), (-nd * inv_norm if hit else -1.0), (k if hit else total - 1)


@kernel(error_model="numpy")
def draw_plane(xs, ys, distorted, rays, inv_norm, spans, near, far, visible, o, ex, ey, n, half, tiles, texture, fx,
               ambient, diffuse, want_rgb, rgb, row, zbuf, zrow, seg, srow, albedo, cosine):
    """Background of one image: the plane's texture where a ray meets its front face within [near, far] and its
    rectangle, else the cavity colour (unlit; the pyramid's last texel) at depth ``far``. ``inv_norm`` (H, W):
    1 / |ray| of each pixel. With ``albedo`` (H, W, 3) and ``cosine`` (H, W) of the image's size, the unshaded
    colour (in [0, 255]) and the cosine (-1: unlit) are stored as well.

    The texel is read from the mip level whose texels match the pixel's footprint on the plane (t |d|^2 /
    |n . d| / f metres). Each image row is done in two passes: the geometry of every pixel, without branches (it
    vectorises), then the texture reads (packed 8-bit texels, the light in fixed point) and the writes.
    """
    keep = albedo.shape[0] == zbuf.shape[1]
    height, width = zbuf.shape[1], zbuf.shape[2]
    num = o[0] * n[0] + o[1] * n[1] + o[2] * n[2]  # < 0: the camera is on the front side
    ox = o[0] * ex[0] + o[1] * ex[1] + o[2] * ex[2]
    oy = o[0] * ey[0] + o[1] * ey[1] + o[2] * ey[2]
    hx, hy = half[0], half[1]
    tx_m, ty_m = tiles[0], tiles[1]
    footprint_scale = max(tx_m, ty_m) * texture.sizes[0] / fx
    last = texture.sizes.shape[0] - 1
    size0 = texture.sizes[0]
    packed = texture.packed
    depth_row = np.empty(width)
    cos_row = np.empty(width)
    texel_row = np.empty(width, dtype=np.int64)
    n0, n1, n2 = n[0], n[1], n[2]
    ex0, ex1, ex2 = ex[0], ex[1], ex[2]
    ey0, ey1, ey2 = ey[0], ey[1], ey[2]
    for i in range(height):
        lo = spans[i, 0]
        hi = spans[i, 1]
        if distorted:
            for j in range(lo, hi + 1):
                depth_row[j], cos_row[j], texel_row[j] = plane_hit(
                    rays[i, j, 0], rays[i, j, 1], inv_norm[i, j], visible, num, n0, n1, n2, ex0, ex1, ex2, ey0, ey1,
                    ey2, ox, oy, hx, hy, tx_m, ty_m, near, far, size0, last, footprint_scale)
        else:
            y = ys[i]
            for j in range(lo, hi + 1):
                depth_row[j], cos_row[j], texel_row[j] = plane_hit(
                    xs[j], y, inv_norm[i, j], visible, num, n0, n1, n2, ex0, ex1, ex2, ey0, ey1, ey2, ox, oy, hx, hy,
                    tx_m, ty_m, near, far, size0, last, footprint_scale)
        for j in range(lo, hi + 1):  # simple loops: each vectorises
            zbuf[zrow, i, j, 0] = depth_row[j]
        for j in range(lo, hi + 1):
            seg[srow, i, j, 0] = 0
        if want_rgb:
            for j in range(lo, hi + 1):
                # one read of the packed texel; the light in 8-bit fixed point (the cavity is unlit)
                texel = np.int64(packed[texel_row[j]])
                c = cos_row[j]
                gain = np.int64((ambient + diffuse * c) * 256.0 + 0.5) if c >= 0.0 else np.int64(256)
                rgb[row, i, j, 0] = np.uint8(min(((texel & 255) * gain + 128) >> 8, 255))
                rgb[row, i, j, 1] = np.uint8(min((((texel >> 8) & 255) * gain + 128) >> 8, 255))
                rgb[row, i, j, 2] = np.uint8(min((((texel >> 16) & 255) * gain + 128) >> 8, 255))
        if keep:
            for j in range(lo, hi + 1):
                for ch in range(3):
                    albedo[i, j, ch] = 255.0 * texture.texels[texel_row[j], ch]
                cosine[i, j] = cos_row[j]
