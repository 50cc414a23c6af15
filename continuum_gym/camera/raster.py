"""The compiled rasteriser: rows [start, stop) of a batch of scenes into rgb / depth / segmentation buffers.

What a row's image holds, in drawing order:

1. the **background**: a textured plane (the tissue) hit in closed form along each pixel's ray, or the cavity
   colour at the far distance where a ray misses it. A plane fixed in the camera frame (OcclusionAvoidance's
   tissue) looks the same in every row with the same intrinsics: ``render_background`` draws it once and rows
   copy it;
2. **tubes** (the robots' links, disks and shafts): solid finite cylinders or regular prisms with open, flat or
   round (hemispherical) ends, each tested only over the pixels of its screen-space bounding box (ray - tube
   in closed form, ``primitives.draw_tube``), z-buffered against what is drawn, shaded as they are drawn:
   albedo x (ambient + diffuse cos), the light at the camera (an endoscope's own light);
3. optional pixel noise.

Tubes are drawn as pybullet draws its meshes when asked (``sides`` > 0), so the two renderers' masks agree to a
fraction of a pixel; ``sides = 0`` draws a round tube. Pixels outside the circular field of view
(``fov_tan`` > 0) are 0 in every modality. Every row is computed by the same code whatever thread runs it:
results do not depend on the number of threads.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from continuum_gym.camera.primitives import (
    ROUND,
    distorted_span,
    draw_plane,
    draw_tube,
    effective_radius,
    gaussian_like,
    prism_planes,
    shade,
    tube_box,
    undistort_radius,
)
from continuum_gym.robots.compiled import kernel

__all__ = ["CameraArgs", "TubeArgs", "PlaneArgs", "TextureArgs", "ShadeArgs", "OutputArgs", "CacheArgs",
           "render_rows", "render_background", "PLANE_NONE", "PLANE_WORLD", "PLANE_CAMERA"]

#: Plane kinds: none, fixed in the world frame, fixed in the camera frame.
PLANE_NONE, PLANE_WORLD, PLANE_CAMERA = 0, 1, 2

#: Per-row cameras: K (N, 3, 3) px, world-from-camera T (N, 4, 4), k1 (N,), clip distances (m), image size.
CameraArgs = namedtuple("CameraArgs", ["K", "T", "k1", "near", "far", "width", "height"])
#: Tubes: ends a, b (N, T, 3) in {w} (m), prism vertex direction u (N, T, 3); per tube radius (T,) m, sides (T,),
#: end kinds (T, 2) [at a, at b], segmentation ids (T,) uint8, albedo (T, 3) in [0, 1], group (T,).
TubeArgs = namedtuple("TubeArgs", ["a", "b", "u", "radius", "sides", "caps", "ids", "colors", "groups"])
#: The textured plane: kind, origin, in-plane axes x and y and front normal (3,) each in its frame, half sizes
#: (2,) m, texture tiles per metre (2,).
PlaneArgs = namedtuple("PlaneArgs", ["kind", "origin", "axis_x", "axis_y", "normal", "half", "tiles_per_metre"])
#: A mip pyramid (``texture.MipPyramid``): texels (M, 3) float32 and packed (M,) uint32, first texel (L,) and side
#: (L,) of each level.
TextureArgs = namedtuple("TextureArgs", ["texels", "packed", "offsets", "sizes"])
#: Light and noise per row: ambient (N,), diffuse (N,), noise seeds (N,) uint64, noise std (0-255 units),
#: tan of the circular field of view's half-angle (0: none).
ShadeArgs = namedtuple("ShadeArgs", ["ambient", "diffuse", "seeds", "noise_std", "fov_tan"])
#: Output buffers (N, H, W, 3) uint8, (N, H, W, 1) float32, (N, H, W, 1) uint8 and whether each is written
#: (an unused one may be a (1, 1, 1, k) placeholder).
OutputArgs = namedtuple("OutputArgs", ["rgb", "depth", "segmentation", "want_rgb", "want_depth",
                                       "want_segmentation"])
#: A background drawn once (``render_background``): rgb (H, W, 3) uint8 under the light (ambient, diffuse),
#: depth (H, W, 1) float32, albedo (H, W, 3) in [0, 255], cosine (H, W), and the rows (N,) that copy it.
CacheArgs = namedtuple("CacheArgs", ["rgb", "depth", "albedo", "cosine", "ambient", "diffuse", "rows"])


# ---------------------------------------------------------------------- per-row pieces
@kernel(inline="always")
def fill_rays(K, k1, width, height, xs, ys, rays):
    """Each pixel sample's undistorted ray (x, y): xs (W,), ys (H,) without distortion, rays (H, W, 2) with."""
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    for j in range(width):
        xs[j] = (j - cx) / fx
    for i in range(height):
        ys[i] = (i - cy) / fy
    if k1 != 0.0:
        for i in range(height):
            for j in range(width):
                r_d = math.sqrt(xs[j] * xs[j] + ys[i] * ys[i])
                s = 1.0 if r_d == 0.0 else undistort_radius(r_d, k1) / r_d
                rays[i, j, 0] = xs[j] * s
                rays[i, j, 1] = ys[i] * s


@kernel(inline="always")
def fill_inv_norm(K, k1, distorted, xs, ys, rays, key, inv_norm):
    """1 / |ray| of every pixel into inv_norm (H, W), unless it holds them already for these intrinsics (``key``)."""
    if not distorted and key[0] == K[0, 0] and key[1] == K[1, 1] and key[2] == K[0, 2] and key[3] == K[1, 2] \
            and key[4] == 0.0:
        return
    for i in range(inv_norm.shape[0]):
        for j in range(inv_norm.shape[1]):
            x, y = (rays[i, j, 0], rays[i, j, 1]) if distorted else (xs[j], ys[i])
            inv_norm[i, j] = 1.0 / math.sqrt(x * x + y * y + 1.0)
    key[0], key[1], key[2], key[3], key[4] = K[0, 0], K[1, 1], K[0, 2], K[1, 2], k1


@kernel(inline="always")
def fill_spans(width, height, distorted, xs, ys, rays, fov_tan, spans):
    """First and last column (inclusive) of each image row inside the circular field of view (all: fov_tan <= 0):
    the pixels whose ray (x, y) has x^2 + y^2 <= fov_tan^2. A row's are contiguous (a disk is convex, the radial
    map monotone); without distortion they are found from the circle's chord, then checked pixel by pixel."""
    limit = fov_tan * fov_tan
    for i in range(height):
        if fov_tan <= 0.0:
            spans[i, 0] = 0
            spans[i, 1] = width - 1
            continue
        first = width
        last = -1
        if distorted:
            for j in range(width):
                if rays[i, j, 0] ** 2 + rays[i, j, 1] ** 2 <= limit:
                    first = min(first, j)
                    last = j
        else:
            y2 = ys[i] * ys[i]
            if y2 <= limit:
                # xs is increasing: start from the chord's ends and move to the exact samples
                fx = 1.0 / (xs[1] - xs[0]) if width > 1 else 1.0
                half = math.sqrt(limit - y2)
                first = min(max(int(math.ceil((-half - xs[0]) * fx)), 0), width - 1)
                while first > 0 and xs[first - 1] ** 2 + y2 <= limit:
                    first -= 1
                while first < width and xs[first] ** 2 + y2 > limit:
                    first += 1
                last = min(max(int(math.floor((half - xs[0]) * fx)), 0), width - 1)
                while last < width - 1 and xs[last + 1] ** 2 + y2 <= limit:
                    last += 1
                while last >= 0 and xs[last] ** 2 + y2 > limit:
                    last -= 1
        spans[i, 0] = first
        spans[i, 1] = last


@kernel(inline="always")
def plane_in_camera(plane, R, p, o, ex, ey, n):
    """The plane's origin, axes and front normal in the camera frame (R, p: the camera's world pose) into o, ex,
    ey, n; returns whether the camera sees its front face."""
    for a in range(3):
        if plane.kind == PLANE_WORLD:
            o[a] = (R[0, a] * (plane.origin[0] - p[0]) + R[1, a] * (plane.origin[1] - p[1])
                    + R[2, a] * (plane.origin[2] - p[2]))
            ex[a] = R[0, a] * plane.axis_x[0] + R[1, a] * plane.axis_x[1] + R[2, a] * plane.axis_x[2]
            ey[a] = R[0, a] * plane.axis_y[0] + R[1, a] * plane.axis_y[1] + R[2, a] * plane.axis_y[2]
            n[a] = R[0, a] * plane.normal[0] + R[1, a] * plane.normal[1] + R[2, a] * plane.normal[2]
        else:
            o[a] = plane.origin[a]
            ex[a] = plane.axis_x[a]
            ey[a] = plane.axis_y[a]
            n[a] = plane.normal[a]
    return plane.kind != PLANE_NONE and o[0] * n[0] + o[1] * n[1] + o[2] * n[2] < 0.0


@kernel(inline="always")
def to_camera(R, p, x):
    """World point x (3,) in the camera frame: R^T (x - p)."""
    d0 = x[0] - p[0]
    d1 = x[1] - p[1]
    d2 = x[2] - p[2]
    return (R[0, 0] * d0 + R[1, 0] * d1 + R[2, 0] * d2, R[0, 1] * d0 + R[1, 1] * d1 + R[2, 1] * d2,
            R[0, 2] * d0 + R[1, 2] * d1 + R[2, 2] * d2)


@kernel(inline="always")
def zero_outside(spans, width, want_rgb, rgb, row, zbuf, zrow, seg, srow):
    """Pixels outside the circular field of view: 0 in every modality."""
    for i in range(spans.shape[0]):
        lo = min(spans[i, 0], width)
        hi = max(spans[i, 1], lo - 1)
        for part in range(2):
            for j in range(0, lo) if part == 0 else range(hi + 1, width):
                zbuf[zrow, i, j, 0] = 0.0
                seg[srow, i, j, 0] = 0
                if want_rgb:
                    rgb[row, i, j, 0] = 0
                    rgb[row, i, j, 1] = 0
                    rgb[row, i, j, 2] = 0


# ---------------------------------------------------------------------- entry points
@kernel(nogil=True, error_model="numpy")
def render_rows(start, stop, camera, tubes, visible_groups, plane, texture, shade_args, cache, out):
    """Render rows [start, stop): background, the tubes of ``visible_groups`` (a bit mask of tube groups), noise;
    into ``out``. Thread-safe for disjoint row ranges (the scratch arrays are the call's own)."""
    height, width = camera.height, camera.width
    near, far = camera.near, camera.far
    want_rgb = out.want_rgb
    rgb = out.rgb
    # depth and segmentation double as the z-buffer and the id buffer: the caller's, or scratch of one row
    zbuf = out.depth if out.want_depth else np.empty((1, height, width, 1), dtype=np.float32)
    seg = out.segmentation if out.want_segmentation else np.empty((1, height, width, 1), dtype=np.uint8)
    xs = np.empty(width)
    ys = np.empty(height)
    rays = np.empty((height, width, 2))
    inv_norm = np.empty((height, width))
    norm_key = np.full(5, np.nan)  # the (fx, fy, cx, cy, k1) inv_norm was filled for
    spans = np.empty((height, 2), dtype=np.int64)
    m = np.empty((64, 3))
    candidates = np.empty(width, dtype=np.bool_)
    o, ex, ey, nrm = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    no_store = np.empty((0, 0, 3))
    n_tubes = tubes.radius.shape[0]
    for row in range(start, stop):
        zrow = row if out.want_depth else 0
        srow = row if out.want_segmentation else 0
        K = camera.K[row]
        T = camera.T[row]
        k1 = camera.k1[row]
        R = T[:3, :3]
        p = T[:3, 3]
        distorted = k1 != 0.0
        ambient = shade_args.ambient[row]
        diffuse = shade_args.diffuse[row]
        fill_rays(K, k1, width, height, xs, ys, rays)
        fill_spans(width, height, distorted, xs, ys, rays, shade_args.fov_tan, spans)
        fill_inv_norm(K, k1, distorted, xs, ys, rays, norm_key, inv_norm)
        if cache.rows[row]:
            # flat copies: numba's copy of an (H, W, 3) array goes element by element through its index
            zbuf[zrow].reshape(-1)[:] = cache.depth.reshape(-1)
            seg[srow].reshape(-1)[:] = 0
            if want_rgb:
                if ambient == cache.ambient and diffuse == cache.diffuse:
                    rgb[row].reshape(-1)[:] = cache.rgb.reshape(-1)
                else:
                    for i in range(height):
                        for j in range(width):
                            c = cache.cosine[i, j]
                            gain = 1.0 if c < 0.0 else ambient + diffuse * c
                            for ch in range(3):
                                rgb[row, i, j, ch] = shade(cache.albedo[i, j, ch] * gain)
        else:
            visible = plane_in_camera(plane, R, p, o, ex, ey, nrm)
            draw_plane(xs, ys, distorted, rays, inv_norm, spans, near, far, visible, o, ex, ey, nrm, plane.half,
                       plane.tiles_per_metre, texture, K[0, 0], ambient, diffuse, want_rgb, rgb, row,
                       zbuf, zrow, seg, srow, no_store, no_store[:, :, 0])
            zero_outside(spans, width, want_rgb, rgb, row, zbuf, zrow, seg, srow)
        fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
        for t in range(n_tubes):
            if not (visible_groups >> tubes.groups[t]) & 1:
                continue
            a0, a1, a2 = to_camera(R, p, tubes.a[row, t])
            b0, b1, b2 = to_camera(R, p, tubes.b[row, t])
            L = math.sqrt((b0 - a0) ** 2 + (b1 - a1) ** 2 + (b2 - a2) ** 2)
            r = tubes.radius[t]
            if L <= 0.0:
                continue
            x0, x1, y0, y1 = tube_box(a0, a1, a2, b0, b1, b2, r, tubes.caps[t, 1] == ROUND, near, far)
            if x0 > x1 or y0 > y1:
                continue
            if distorted:
                xd0, xd1 = distorted_span(x0, x1, y0, y1, k1)
                yd0, yd1 = distorted_span(y0, y1, x0, x1, k1)
                x0, x1, y0, y1 = xd0, xd1, yd0, yd1
            j0 = max(0, int(math.ceil(fx * x0 + cx - 1e-6)))
            j1 = min(width - 1, int(math.floor(fx * x1 + cx + 1e-6)))
            i0 = max(0, int(math.ceil(fy * y0 + cy - 1e-6)))
            i1 = min(height - 1, int(math.floor(fy * y1 + cy + 1e-6)))
            if j0 > j1 or i0 > i1:
                continue
            u = tubes.u[row, t]
            # the prism's vertex direction in the camera frame
            u0 = R[0, 0] * u[0] + R[1, 0] * u[1] + R[2, 0] * u[2]
            u1 = R[0, 1] * u[0] + R[1, 1] * u[1] + R[2, 1] * u[2]
            u2 = R[0, 2] * u[0] + R[1, 2] * u[1] + R[2, 2] * u[2]
            w0, w1, w2 = (b0 - a0) / L, (b1 - a1) / L, (b2 - a2) / L
            sides = tubes.sides[t]
            nv = prism_planes(sides, w0, w1, w2, u0, u1, u2, m)
            r_cap = effective_radius(r, sides, w0, w1, w2, u0, u1, u2, 0.5 * (a0 + b0), 0.5 * (a1 + b1),
                                     0.5 * (a2 + b2))
            draw_tube(i0, i1, j0, j1, xs, ys, distorted, rays, spans, near, far, a0, a1, a2, b0, b1, b2, r, nv, m,
                      r_cap, tubes.caps[t, 0], tubes.caps[t, 1], tubes.ids[t], 255.0 * tubes.colors[t, 0],
                      255.0 * tubes.colors[t, 1], 255.0 * tubes.colors[t, 2], ambient, diffuse, want_rgb, rgb, row,
                      zbuf, zrow, seg, srow, candidates)
        if want_rgb and shade_args.noise_std > 0.0:
            seed = shade_args.seeds[row]
            for i in range(height):
                for j in range(spans[i, 0], spans[i, 1] + 1):
                    for ch in range(3):
                        noise = shade_args.noise_std * gaussian_like(seed, (i * width + j) * 3 + ch)
                        rgb[row, i, j, ch] = shade(rgb[row, i, j, ch] + noise)


@kernel(nogil=True, error_model="numpy")
def render_background(K, near, far, width, height, fov_tan, plane, texture, ambient, diffuse, rgb, depth, albedo,
                      cosine):
    """The image of a plane fixed in the frame of an undistorted camera with intrinsics K: rgb (H, W, 3) uint8 under
    the light (ambient, diffuse), depth (H, W, 1), and the unshaded albedo (H, W, 3) and cosine (H, W) for other
    lights; 0 outside the circular field of view (``fov_tan`` > 0)."""
    xs = np.empty(width)
    ys = np.empty(height)
    rays = np.empty((1, 1, 2))
    spans = np.empty((height, 2), dtype=np.int64)
    fill_rays(K, 0.0, width, height, xs, ys, rays)
    fill_spans(width, height, False, xs, ys, rays, fov_tan, spans)
    inv_norm = np.empty((height, width))
    fill_inv_norm(K, 0.0, False, xs, ys, rays, np.full(5, np.nan), inv_norm)
    o, ex, ey, n = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    visible = plane_in_camera(plane, np.eye(3), np.zeros(3), o, ex, ey, n)
    rgb4 = rgb.reshape((1, height, width, 3))
    depth4 = depth.reshape((1, height, width, 1))
    seg4 = np.empty((1, height, width, 1), dtype=np.uint8)
    albedo[:] = 0.0
    cosine[:] = -1.0
    draw_plane(xs, ys, False, rays, inv_norm, spans, near, far, visible, o, ex, ey, n, plane.half,
               plane.tiles_per_metre, texture, K[0, 0], ambient, diffuse, True, rgb4, 0, depth4, 0, seg4, 0, albedo,
               cosine)
    zero_outside(spans, width, True, rgb4, 0, depth4, 0, seg4, 0)
