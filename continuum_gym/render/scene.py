"""Headless pybullet scenes of the two tasks: what the endoscope sees and an external view.

Every scene owns a private ``pybullet_utils.bullet_client.BulletClient(pybullet.DIRECT)`` (several scenes
coexist in one process) and renders with pybullet's CPU TinyRenderer. Bodies are built once from the
kinematics and moved per step with ``resetBasePositionAndOrientation`` (``update``); nothing is rebuilt.

Geometry (SI units, m):

- a robot link is a low-poly tube mesh whose body frame sits at the link's start sample with z along the
  chord to the next sample; its length is the (constant) arc length between samples, so a bent link
  overlaps its neighbours by a few microns and the rounded ends close the joints;
- straight parts of variable length (the MBCR's inserted part, the continuum endoscope's stem, the
  da Vinci stem) are one long tube whose top end follows the kinematics and whose rest runs back below
  the entry plane z_w = 0 (outside every camera's view);
- overlays (view cone, frusta, target points) are one wire mesh per camera in that camera's frame, shown
  only in the external view;
- the tissue is a one-sided textured grid mesh (procedural reddish noise with vessels) facing the
  cameras: an external camera behind it sees through it (TinyRenderer culls back faces).

TinyRenderer has no alpha blending, so overlays are drawn as thin wires, and a body is hidden by
setting its alpha to 0 (TinyRenderer then skips it entirely).

Camera frames follow ``continuum_gym.render.camera`` (z optical axis, x image right, y image down).
"""

from __future__ import annotations

import functools
import math
import os
import tempfile

import numpy as np

from continuum_gym.geometry.lens_cone import lens_origin, lens_rotation, resolve_cone
from continuum_gym.render.camera import camera_matrices, fov_mask, look_at_frame

__all__ = ["OcclusionScene", "ViewTrackingScene", "tissue_texture", "CAMERAS_OCCLUSION", "CAMERAS_VIEW_TRACKING"]

CAMERAS_OCCLUSION = ("external", "endoscope")
CAMERAS_VIEW_TRACKING = ("external", "endoscope", "davinci")

_E3 = np.array([0.0, 0.0, 1.0])


def _pybullet():
    try:
        import pybullet
        from pybullet_utils import bullet_client
    except ImportError as error:  # pragma: no cover - pybullet is a dependency
        raise ImportError("continuum_gym.render needs pybullet: pip install pybullet") from error
    return pybullet, bullet_client


# ====================================================================== meshes (numpy only)
class _Mesh:
    """Triangle mesh: vertices (n, 3), normals (n, 3), triangles (m, 3) int, optional uvs (n, 2)."""

    def __init__(self, V, N, T, uv=None):
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
    def merge(meshes):
        offsets = np.cumsum([0] + [len(m.V) for m in meshes[:-1]])
        uv = None
        if all(m.uv is not None for m in meshes):
            uv = np.concatenate([m.uv for m in meshes])
        return _Mesh(np.concatenate([m.V for m in meshes]), np.concatenate([m.N for m in meshes]),
                     np.concatenate([m.T + o for m, o in zip(meshes, offsets)]), uv)


def _lathe(profile, sides):
    """Surface of revolution about z from a profile of (r, z, n_r, n_z); r = 0 makes a pole vertex.

    Consecutive profile entries at the same (r, z) start a new smoothing group (a hard edge).
    """
    theta = 2.0 * math.pi * np.arange(sides) / sides
    c, s = np.cos(theta), np.sin(theta)
    V, N, rings = [], [], []
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
    return _Mesh(np.concatenate(V), np.concatenate(N), np.concatenate(T))


def _tube(radius, z0, z1, sides=12, bottom="round", top="round", cap_rings=2):
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
    return _lathe(profile, sides)


def _link(radius, length, sides=8, top="round"):
    """A backbone link from z = 0 to ``length``: open at the bottom (inside the previous link's cap), a cone
    cap of height ``radius`` on top that closes the joint with the next link (or a flat top)."""
    return _tube(radius, 0.0, length, sides=sides, bottom="open", top=top, cap_rings=0)


def _sphere(radius, center, sides=10, rings=3):
    m = _tube(radius, 0.0, 0.0, sides=sides, cap_rings=rings)
    m.V += np.asarray(center, dtype=np.float64)
    return m


def _wires(segments, radius, sides=3, max_length=0.01):
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
    helper = np.where(np.abs(d[:, 2:3]) < 0.9, _E3, [1.0, 0.0, 0.0])
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
    return _Mesh(V.reshape(-1, 3), N.reshape(-1, 3), T.reshape(-1, 3))


def _grid(half_x, half_y, n=8, normal_sign=-1.0, uv_scale=1.0, two_sided=False, xs=None):
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
    return _Mesh(V, N, T, uv)


def _split(mesh, inner_half):
    """(triangles inside the square |x|, |y| <= inner_half, the others) of a mesh, as two meshes."""
    centre = mesh.V[mesh.T][:, :, :2].mean(axis=1)
    inside = np.all(np.abs(centre) <= inner_half, axis=1)
    return _Mesh(mesh.V, mesh.N, mesh.T[inside], mesh.uv), _Mesh(mesh.V, mesh.N, mesh.T[~inside], mesh.uv)


def _disk_and_frame(radius, half, cells=8):
    """The square of half side ``half`` (z = 0, planar uvs, front faces toward -z) split into the grid
    cells that reach into the circle of ``radius`` (the disk) and the others (the frame).

    The disk alone covers a circular field of view of that radius, for about ``cells`` cells across it.
    """
    n = max(1, int(round(cells * half / radius / 2.0)) * 2)
    grid = _grid(half, half, n, two_sided=False)
    corners = grid.V[grid.T][:, :, :2]
    # distance from the origin to each triangle (a right triangle of a cell): nearest point of its bounding box
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    nearest = np.clip(0.0, lo, hi)
    inside = np.linalg.norm(nearest, axis=1) <= radius
    return _Mesh(grid.V, grid.N, grid.T[inside], grid.uv), _Mesh(grid.V, grid.N, grid.T[~inside], grid.uv)


def _quat_z_to(d):
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


def _quat(R):
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


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


# ====================================================================== texture
def _fractal(rng, size, slope, k_min=0.0, k_max=np.inf):
    f = np.fft.fftfreq(size) * size
    k = np.hypot(f[:, None], f[None, :])
    k[0, 0] = 1.0
    gain = k ** (-slope) * ((k >= k_min) & (k <= k_max))
    gain[0, 0] = 0.0
    out = np.real(np.fft.ifft2(np.fft.fft2(rng.standard_normal((size, size))) * gain))
    return (out - out.mean()) / (out.std() + 1e-12)


@functools.lru_cache(maxsize=4)
def _texture_cached(size, seed, features):
    image = _tissue_texture(size, seed, features)
    image.flags.writeable = False
    return image


def tissue_texture(size: int = 512, seed: int = 0, features: float = 1.0) -> np.ndarray:
    """Tileable (periodic) reddish mucosa texture (size, size, 3) uint8: fractal blotches, grain, dark vessels.

    ``features`` scales the number of blotches and vessels per tile (1: a few vessels per tile).
    """
    return _texture_cached(int(size), int(seed), float(features)).copy()


def _tissue_texture(size, seed, features):
    rng = np.random.default_rng(seed)
    f = features
    blotch = _fractal(rng, size, 1.8, k_max=f * size / 8)
    grain = _fractal(rng, size, 0.6, k_min=size / 16)
    vessels = np.zeros((size, size))
    for scale, width, weight in ((3.0, 0.035, 0.9), (8.0, 0.05, 0.6)):
        field = _fractal(rng, size, 1.5, k_min=f * scale * 0.5, k_max=f * scale * 3)
        patch = np.clip(_fractal(rng, size, 2.0, k_max=f * 6) * 0.8 + 0.2, 0.0, 1.0)
        vessels = np.maximum(vessels, weight * patch * np.exp(-(field / width) ** 2))
    base = np.array([0.80, 0.36, 0.32])
    vessel = np.array([0.42, 0.05, 0.10])
    shade = 1.0 + 0.10 * blotch[..., None] + 0.05 * grain[..., None]
    color = base * shade
    color[..., 1:] *= (1.0 - 0.15 * np.clip(blotch, 0, None))[..., None]
    color = color * (1.0 - vessels[..., None]) + vessel * vessels[..., None]
    return np.clip(color * 255.0, 0, 255).astype(np.uint8)


def _bmp(image) -> bytes:
    """24-bit uncompressed BMP of an (h, w, 3) uint8 RGB image (pybullet's stb_image reads it; writing it
    takes a millisecond where PNG encoding takes ~150 ms)."""
    h, w, _ = image.shape
    row = (3 * w + 3) // 4 * 4
    pixels = np.zeros((h, row), dtype=np.uint8)
    pixels[:, :3 * w] = image[::-1, :, ::-1].reshape(h, 3 * w)  # bottom-up rows, BGR
    size = 54 + pixels.size
    header = (b"BM" + size.to_bytes(4, "little") + b"\0\0\0\0" + (54).to_bytes(4, "little")
              + (40).to_bytes(4, "little") + w.to_bytes(4, "little") + h.to_bytes(4, "little")
              + (1).to_bytes(2, "little") + (24).to_bytes(2, "little") + b"\0" * 4
              + pixels.size.to_bytes(4, "little") + (2835).to_bytes(4, "little") * 2 + b"\0" * 8)
    return header + pixels.tobytes()


# ====================================================================== base scene
class _Scene:
    """A private DIRECT pybullet client, body groups with visibility, and camera images."""

    #: lighting (TinyRenderer defaults are ambient 0.6, diffuse 0.35, specular 0.05)
    _light = dict(lightAmbientCoeff=0.45, lightDiffuseCoeff=0.55, lightSpecularCoeff=0.08, shadow=0)
    _light_external = dict(lightAmbientCoeff=0.7, lightDiffuseCoeff=0.45, lightSpecularCoeff=0.08, shadow=0)

    def __init__(self, texture_seed=0, texture_size=512, texture_features=1.0):
        p, bullet_client = _pybullet()
        self._p = p
        self._client = bullet_client.BulletClient(connection_mode=p.DIRECT)
        self._cid = self._client._client
        self._pid = os.getpid()
        self._groups: dict = {}
        self._colors: dict = {}
        self._hidden: set = set()
        self._texture_seed = int(texture_seed)
        self._texture_size = int(texture_size)
        self._texture_features = float(texture_features)
        self._texture = None
        self._lut = np.zeros(1, dtype=bool)
        self._spheres = ([], np.zeros((0, 3)), np.zeros(0))
        self.closed = False

    # ------------------------------------------------------------------ building
    def _shape(self, mesh, rgba, specular=(0.2, 0.2, 0.2)):
        p = self._p
        kwargs = dict(vertices=mesh.V.tolist(), indices=mesh.T.ravel().tolist(), normals=mesh.N.tolist(),
                      rgbaColor=list(rgba), specularColor=list(specular), physicsClientId=self._cid)
        if mesh.uv is not None:
            kwargs["uvs"] = mesh.uv.tolist()
        return p.createVisualShape(p.GEOM_MESH, **kwargs)

    def _bodies(self, group, mesh, rgba, count=1, **shape_kwargs):
        shape = self._shape(mesh, rgba, **shape_kwargs)
        p = self._p
        if count == 1:
            ids = [p.createMultiBody(baseMass=0.0, baseVisualShapeIndex=shape, physicsClientId=self._cid)]
        else:
            ids = list(p.createMultiBody(baseMass=0.0, baseVisualShapeIndex=shape,
                                         batchPositions=[[0.0, 0.0, -1.0 - 0.01 * i] for i in range(count)],
                                         physicsClientId=self._cid))
        self._groups.setdefault(group, []).extend(ids)
        for i in ids:
            self._colors[i] = list(rgba)
        return ids

    def _texture_id(self):
        if self._texture is None:
            fd, path = tempfile.mkstemp(suffix=".bmp", prefix="continuum_gym_tissue_")
            try:
                with os.fdopen(fd, "wb") as f:
                    f.write(_bmp(_texture_cached(self._texture_size, self._texture_seed, self._texture_features)))
                self._texture = self._p.loadTexture(path, physicsClientId=self._cid)
            finally:
                os.remove(path)
        return self._texture

    def _tissue(self, mesh, group="tissue"):
        (body,) = self._bodies(group, mesh, (1.0, 1.0, 1.0, 1.0), specular=(0.6, 0.6, 0.6))
        self._p.changeVisualShape(body, -1, textureUniqueId=self._texture_id(), physicsClientId=self._cid)
        return body

    def _finish(self, robot_groups):
        """Lookup table body id -> robot (segmentation mask); call after all bodies exist."""
        ids = [i for ids in self._groups.values() for i in ids]
        self._lut = np.zeros(max(ids) + 2, dtype=bool)
        for group in robot_groups:
            self._lut[np.asarray(self._groups[group]) + 1] = True

    # ------------------------------------------------------------------ state
    def _place(self, ids, positions, quaternions):
        reset = self._p.resetBasePositionAndOrientation
        cid = self._cid
        positions = positions.tolist() if isinstance(positions, np.ndarray) else positions
        quaternions = quaternions.tolist() if isinstance(quaternions, np.ndarray) else quaternions
        for body, pos, orn in zip(ids, positions, quaternions):
            reset(body, pos, orn, physicsClientId=cid)

    def _show(self, visible_groups, culled=()):
        """Make exactly the bodies of ``visible_groups`` visible, except the ids in ``culled``.

        A hidden body has alpha 0, which TinyRenderer skips entirely; only bodies whose state changes are
        touched (one changeVisualShape each).
        """
        self._check_open()
        change = self._p.changeVisualShape
        hidden = self._hidden
        for group, ids in self._groups.items():
            show_group = group in visible_groups
            for body in ids:
                hide = not show_group or body in culled
                if hide == (body in hidden):
                    continue
                rgba = list(self._colors[body])
                if hide:
                    rgba[3] = 0.0
                    hidden.add(body)
                else:
                    hidden.discard(body)
                change(body, -1, rgbaColor=rgba, physicsClientId=self._cid)

    def _outside_view(self, p_cam, axis, half_angle):
        """Body ids of the bounding spheres (``self._spheres``) entirely outside the cone (p_cam, axis, angle)."""
        ids, centres, radii = self._spheres
        if not len(ids):
            return set()
        v = centres - p_cam
        dist = np.linalg.norm(v, axis=1)
        cos_angle = (v @ axis) / np.maximum(dist, 1e-300)
        angle = np.arccos(np.clip(cos_angle, -1.0, 1.0))
        slack = np.arcsin(np.clip(radii / np.maximum(dist, 1e-300), 0.0, 1.0))
        outside = (dist > radii) & (angle > half_angle + slack)
        return {ids[i] for i in np.flatnonzero(outside)}

    def _render(self, p_cam, R_cam, fov_y, width, height, near, far, light_direction, segmentation=False,
                light=None):
        self._check_open()
        width, height = _resolution(width, height)
        view, proj = camera_matrices(p_cam, R_cam, fov_y, width, height, near, far)
        p = self._p
        out = p.getCameraImage(width, height, viewMatrix=view, projectionMatrix=proj,
                               lightDirection=[float(x) for x in light_direction], renderer=p.ER_TINY_RENDERER,
                               flags=0 if segmentation else p.ER_NO_SEGMENTATION_MASK, physicsClientId=self._cid,
                               **(light or self._light))
        rgba = np.asarray(out[2], dtype=np.uint8).reshape(height, width, 4)
        seg = np.asarray(out[4]).reshape(height, width) if segmentation else None
        self._last_depth = np.asarray(out[3], dtype=np.float32).reshape(height, width)
        return rgba, seg

    def _external_image(self, width, height, groups):
        """External view: light from behind the viewer, a dark gradient where no body is hit."""
        self._show(groups)
        p_cam, R_cam = self._external
        light = _unit(-R_cam[:, 2] + 0.25 * _E3)
        rgba, seg = self._render(p_cam, R_cam, math.radians(self.external_camera["fov"]), width, height, 0.01, 2.0,
                                 light, segmentation=True, light=self._light_external)
        rgb = rgba[..., :3].copy()
        h = rgb.shape[0]
        ramp = np.linspace(0.0, 1.0, h)[:, None, None]
        background = ((1.0 - ramp) * np.array([58, 64, 78]) + ramp * np.array([18, 20, 26])).astype(np.uint8)
        empty = seg < 0
        rgb[empty] = np.broadcast_to(background, rgb.shape)[empty]
        return rgb

    def _camera_image(self, p_cam, R_cam, fov_y, width, height, near, far, fill_background=True):
        """Endoscope image: a head light at the camera; rays that hit nothing (TinyRenderer clears to white)
        are dark, as an unlit cavity."""
        rgba, seg = self._render(p_cam, R_cam, fov_y, width, height, near, far, -R_cam[:, 2],
                                 segmentation=fill_background)
        rgb = rgba[..., :3].copy()
        if fill_background:
            rgb[seg < 0] = _CAVITY
        return rgb

    def _robot_mask(self, seg):
        seg = np.where(seg >= 0, seg & 0xFFFFFF, -1)
        seg = np.clip(seg + 1, 0, len(self._lut) - 1)
        return self._lut[seg]

    @property
    def body_ids(self) -> dict:
        """{group name: tuple of pybullet body ids}; fixed for the lifetime of the scene."""
        return {group: tuple(ids) for group, ids in self._groups.items()}

    @property
    def client_id(self) -> int:
        """The physicsClientId of the scene's private DIRECT connection."""
        return self._cid

    # ------------------------------------------------------------------ lifetime
    def _check_open(self):
        if self.closed:
            raise RuntimeError(f"{type(self).__name__} is closed")

    def close(self):
        """Disconnect the private pybullet client (idempotent)."""
        if getattr(self, "closed", True):
            return
        self.closed = True
        client = getattr(self, "_client", None)
        if client is not None and getattr(client, "_client", -1) >= 0 and os.getpid() == self._pid:
            try:
                self._p.disconnect(physicsClientId=self._cid)
            except Exception:  # noqa: BLE001 - interpreter shutdown or already gone
                pass
            client._client = -1

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:  # noqa: BLE001
            pass


def _resolution(width, height):
    w, h = int(width), int(height)
    if w != width or h != height or w < 1 or h < 1 or w > 4096 or h > 4096:
        raise ValueError(f"width and height must be integers in [1, 4096]; got {width!r} x {height!r}")
    return w, h


def _corner_angle(fov_y, width, height):
    """Angle between the optical axis and the image corners' rays, plus 2 pixels of slack."""
    t = math.tan(0.5 * fov_y)
    return math.atan(t * math.hypot(1.0, width / height)) + 2.0 * fov_y / height


def _external_frame(target, distance, azimuth_deg, elevation_deg):
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    target = np.asarray(target, dtype=np.float64)
    eye = target + distance * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    return look_at_frame(eye, target, _E3)


#: colour of rays that hit nothing in an endoscope image (an unlit cavity)
_CAVITY = (14, 8, 8)

_COLORS = {
    "straight": (0.55, 0.57, 0.62, 1.0),
    "segments": ((0.80, 0.80, 0.84, 1.0), (0.62, 0.78, 0.90, 1.0), (0.90, 0.82, 0.55, 1.0)),
    "disk": (0.25, 0.27, 0.30, 1.0),
    "shaft": (0.12, 0.12, 0.14, 1.0),
    "lens": (0.20, 0.45, 0.85, 1.0),
    "cone": (1.0, 0.85, 0.10, 1.0),
    "endoscope": ((0.35, 0.75, 0.45, 1.0), (0.25, 0.45, 0.30, 1.0), (0.30, 0.65, 0.80, 1.0)),
    "camera_head": (0.10, 0.10, 0.12, 1.0),
    "davinci": (0.55, 0.58, 0.66, 1.0),
    "frustum_endoscope": (0.20, 0.95, 0.35, 1.0),
    "frustum_davinci": (0.25, 0.55, 1.00, 1.0),
}


# ====================================================================== paper 000: occlusion
class OcclusionScene(_Scene):
    """The MBCR beside the rotating angled-lens endoscope (paper 000), rendered headless.

    Bodies: the robot (inserted part, ``3 n_per_segment`` links, 4 disks at the segment ends; group
    ``"robot"``), the endoscope shaft along -z_w from the lens with a lens window (``"shaft"``), the view
    cone as a wireframe to the working distance (``"cone"``, external view only) and a textured tissue
    surface (``"tissue"``: the disk the circular field of view sees, and ``"tissue_frame"``: the rest of
    the square, shown in the external view and in square endoscope images).

    Each render draws only what its camera needs (hidden bodies have alpha 0): endoscope images and
    ``pixel_occlusion`` skip the robot links whose bounding spheres lie outside the cone.

    Args:
        robot: ``MultiBackboneRobot`` (default: the paper's).
        cone: ``LensCone`` (default: the paper's, literal lens model).
        tissue_distance: distance of the tissue from the lens along the view axis (m).
        robot_radius: outer radius of the robot (disk radius, m); the robot is drawn as a tube of this radius.
        n_per_segment: links per segment.
        shaft_radius: endoscope shaft radius (m).
        tissue: ``"view"`` (perpendicular to the view axis, follows gamma), ``"world"`` (fixed plane
            z_w = tissue_distance cos(alpha), which every view axis meets at tissue_distance) or None.
        tissue_half_size: half the side of the tissue square (m) (``"world"`` adds d sin(alpha)).
        circular_fov: black out endoscope-image pixels outside the cone (as a real endoscope image).
        cache_background: with ``tissue="view"`` the tissue is fixed in the lens frame, so the endoscope
            sees the same tissue image at every q and gamma: render it once per image size (with depth)
            and per frame render only the robot, composited where it is in front of the tissue. The
            image equals a full render up to TinyRenderer's specular term, which uses world z.
        near, far: clip planes of the endoscope camera (m).
        external_camera: dict of ``target`` (m), ``distance`` (m), ``azimuth``, ``elevation`` (deg, about z_w
            from +x_w and above the target) and ``fov`` (deg, vertical) of the external view.
        texture_seed: seed of the procedural tissue texture.

    The endoscope camera sits at ``lens_origin(gamma)`` looking along the view axis with vertical field of
    view 2 beta (the circular field of view is the inscribed disk of a square image); its frame is the lens
    frame turned half a turn about the view axis, so the image rotates with gamma and the robot's channel
    (at -y_lens) is at the bottom of the image.
    """

    cameras = CAMERAS_OCCLUSION
    robot_groups = ("robot",)

    def __init__(self, robot=None, cone=None, tissue_distance=0.065, robot_radius=0.0015, n_per_segment=8,
                 shaft_radius=0.002, tissue="view", tissue_half_size=0.05, circular_fov=True, near=1e-3, far=0.3,
                 external_camera=None, texture_seed=0, cache_background=True):
        from continuum_gym.robots import MultiBackboneRobot

        self.robot = MultiBackboneRobot() if robot is None else robot
        if not isinstance(self.robot, MultiBackboneRobot):
            raise ValueError(f"robot must be a MultiBackboneRobot; got {type(robot).__name__}")
        self.cone = resolve_cone(cone)
        for name, value in (("tissue_distance", tissue_distance), ("robot_radius", robot_radius),
                            ("shaft_radius", shaft_radius), ("tissue_half_size", tissue_half_size),
                            ("near", near), ("far", far)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0 (m); got {value!r}")
        if int(n_per_segment) != n_per_segment or n_per_segment < 1:
            raise ValueError(f"n_per_segment must be an integer >= 1; got {n_per_segment!r}")
        if tissue not in ("view", "world", None):
            raise ValueError(f"tissue must be 'view', 'world' or None; got {tissue!r}")
        if not near < far:
            raise ValueError(f"need near < far; got {near!r}, {far!r}")
        self.tissue_distance = float(tissue_distance)
        self.robot_radius = float(robot_radius)
        self.n_per_segment = int(n_per_segment)
        self.tissue_mode = tissue
        self.circular_fov = bool(circular_fov)
        self.cache_background = bool(cache_background)
        self._backgrounds = {}
        self.near, self.far = float(near), float(far)
        self.fov_y = 2.0 * self.cone.beta
        ext = dict(target=(-0.012, 0.0, 0.035), distance=0.16, azimuth=-40.0, elevation=5.0, fov=45.0)
        ext.update(external_camera or {})
        self.external_camera = ext
        self._external = _external_frame(ext["target"], ext["distance"], ext["azimuth"], ext["elevation"])
        super().__init__(texture_seed=texture_seed)
        try:
            self._build(shaft_radius, tissue_half_size)
        except BaseException:
            self.close()
            raise
        self.q = None
        self.gamma = None
        self.update(self.robot.psi_a, 0.0)

    # ------------------------------------------------------------------ build
    def _build(self, shaft_radius, tissue_half_size):
        r, n = self.robot_radius, self.n_per_segment
        # robot first: TinyRenderer draws in creation order, so the tissue behind it fails the depth test
        self._straight_length = 0.1
        self._straight = self._bodies("robot", _tube(r, -self._straight_length, 0.0, sides=8, bottom="open",
                                                     top="flat"),
                                      _COLORS["straight"])
        self._links = []
        for s, length in enumerate(self.robot.lengths):
            color = _COLORS["segments"][s]
            if s < 2:
                self._links += self._bodies("robot", _link(r, length / n), color, count=n)
            else:
                if n > 1:
                    self._links += self._bodies("robot", _link(r, length / n), color, count=n - 1)
                self._links += self._bodies("robot", _link(r, length / n, top="flat"), color)
        self._disks = self._bodies("robot", _tube(1.12 * r, -0.0004, 0.0004, sides=10, bottom="flat", top="flat"),
                                   _COLORS["disk"], count=4)
        self._shaft = self._bodies("shaft", _tube(shaft_radius, -0.1, -2e-4, sides=16, bottom="open", top="flat"),
                                   _COLORS["shaft"])
        self._lens = self._bodies("shaft", _tube(0.7 * shaft_radius, -4e-4, -2e-4, sides=16, bottom="flat",
                                                 top="flat"), _COLORS["lens"])
        d, beta = self.tissue_distance, self.cone.beta
        theta = 2.0 * math.pi * np.arange(64) / 64
        ring = 0.995 * d * np.stack([math.tan(beta) * np.cos(theta), math.tan(beta) * np.sin(theta),
                                     np.ones_like(theta)], axis=1)
        gen = ring[::8]
        mid = 0.5 * ring
        segments = [np.stack([np.zeros_like(gen), gen], 1), np.stack([ring, np.roll(ring, -1, 0)], 1),
                    np.stack([mid, np.roll(mid, -1, 0)], 1), [[[0, 0, 0], [0, 0, 0.995 * d]]]]
        self._cone = self._bodies("cone", _wires(np.concatenate(segments), 2.5e-4), _COLORS["cone"])
        self._tissue_bodies = []
        if self.tissue_mode == "view":
            # the disk inside the field of view (all the endoscope camera shades) and the rest of the square
            radius = 1.02 * d * math.tan(beta)
            disk, frame = _disk_and_frame(radius, max(tissue_half_size, 1.05 * radius * math.sqrt(2.0)))
            self._tissue_bodies = [self._tissue(disk), self._tissue(frame, "tissue_frame")]
        elif self.tissue_mode == "world":
            half = tissue_half_size + d * math.sin(self.cone.alpha)
            self._tissue_bodies = [self._tissue(_grid(half, half, normal_sign=-1.0,
                                                      uv_scale=half / tissue_half_size))]
            self._place(self._tissue_bodies, [[0.0, 0.0, d * math.cos(self.cone.alpha)]], [[0.0, 0.0, 0.0, 1.0]])
        self._finish(self.robot_groups)
        self._ids = self._straight + self._links + self._disks + self._shaft + self._lens + self._cone
        half = np.repeat(0.5 * np.asarray(self.robot.lengths) / n, n)
        self._half_links = half[:, None]
        self._spheres = (self._links + self._disks, np.zeros((3 * n + 4, 3)),
                         np.concatenate([half + r, np.full(4, 1.12 * r + 4e-4)]))
        if self.tissue_mode == "view":
            self._ids += self._tissue_bodies

    # ------------------------------------------------------------------ state
    def update(self, q, gamma) -> None:
        """Move every body to configuration ``q`` (7,) and endoscope rotation ``gamma`` (rad)."""
        self._check_open()
        q = np.asarray(q, dtype=np.float64)
        if q.shape != (7,):
            raise ValueError(f"q must have shape (7,); got {q.shape}")
        gamma = float(gamma)
        if not math.isfinite(gamma):
            raise ValueError(f"gamma must be finite (rad); got {gamma!r}")
        n, ni = self.n_per_segment, self.robot.n_insert_samples
        P = self.robot.backbone(q, n)  # raises on non-finite q
        _, R_tip = self.robot.forward_kinematics(q)
        chords = P[ni + 1:] - P[ni:-1]
        ends = ni + n * np.arange(4)
        tangents = np.empty((4, 3))
        tangents[0] = _E3
        tangents[1:3] = P[ends[1:3] + 1] - P[ends[1:3] - 1]
        tangents[3] = R_tip[:, 2]
        directions = np.concatenate([chords, tangents])
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        link_quats = _quat_z_to(directions).tolist()
        centres = self._spheres[1]
        centres[:3 * n] = P[ni:-1] + self._half_links * directions[:3 * n]
        centres[3 * n:] = P[ends]
        p_lens = lens_origin(gamma, self.cone)
        R_lens = lens_rotation(gamma, self.cone)
        q_lens = _quat(R_lens)
        lens = p_lens.tolist()
        positions = [P[ni].tolist()] + P[ni:-1].tolist() + P[ends].tolist() + [lens, lens, lens]
        quats = [[0.0, 0.0, 0.0, 1.0]] + link_quats + [[0.0, 0.0, 0.0, 1.0], q_lens, q_lens]
        ids = self._ids
        if self.tissue_mode == "view":
            p_tissue = (p_lens + self.tissue_distance * R_lens[:, 2]).tolist()
            positions += [p_tissue, p_tissue]
            quats += [q_lens, q_lens]
        self._place(ids, positions, quats)
        self.q = q.copy()
        self.gamma = gamma

    # ------------------------------------------------------------------ cameras
    def camera_pose(self, camera="endoscope"):
        """(p, R) of ``camera`` in {w} (z optical axis, x image right, y image down)."""
        if camera == "endoscope":
            R = lens_rotation(self.gamma, self.cone) * np.array([-1.0, -1.0, 1.0])
            return lens_origin(self.gamma, self.cone), R
        if camera == "external":
            return self._external[0].copy(), self._external[1].copy()
        raise ValueError(f"camera must be one of {self.cameras}; got {camera!r}")

    def render(self, camera="external", width=128, height=128) -> np.ndarray:
        """RGB image (height, width, 3) uint8 from ``"external"`` or ``"endoscope"``."""
        if camera == "endoscope":
            return self._endoscope(width, height, False)[0]
        if camera != "external":
            raise ValueError(f"camera must be one of {self.cameras}; got {camera!r}")
        return self._external_image(width, height, {"robot", "shaft", "tissue", "tissue_frame", "cone"})

    def endoscope_frame(self, width=128, height=128):
        """(endoscope RGB image (height, width, 3) uint8, pixel occlusion of that image size).

        With the cached background (``cache_background``, ``tissue="view"``) both come from one robot
        render, so the occlusion is free; it equals ``pixel_occlusion()`` for a square image.
        """
        return self._endoscope(width, height, True)

    def _endoscope(self, width, height, with_occlusion):
        width, height = _resolution(width, height)
        p_cam, R_cam = self.camera_pose("endoscope")
        fov = fov_mask(width, height, self.fov_y, self.cone.beta)
        if self.circular_fov:
            # only what lies inside the circular field of view is drawn: the links whose bounding spheres
            # reach into the cone (2 pixels of slack); the rest of the image is black
            angle = self.cone.beta + 2.0 * self.fov_y / height
            tissue = {"tissue"}
        else:
            angle = _corner_angle(self.fov_y, width, height)
            tissue = {"tissue", "tissue_frame"}
        culled = self._outside_view(p_cam, R_cam[:, 2], angle)
        if self.cache_background and self.tissue_mode == "view":
            background, background_depth = self._background(width, height, tissue)
            self._show({"robot"}, culled)
            rgba, seg = self._render(p_cam, R_cam, self.fov_y, width, height, self.near, self.far, -R_cam[:, 2],
                                     segmentation=True)
            robot = self._robot_mask(seg)
            in_front = robot & (self._last_depth < background_depth)
            rgb = background.copy()
            rgb[in_front] = rgba[..., :3][in_front]
            occlusion = float(np.count_nonzero(robot & fov) / np.count_nonzero(fov))
        else:
            self._show({"robot", "shaft"} | tissue, culled)
            rgba, seg = self._render(p_cam, R_cam, self.fov_y, width, height, self.near, self.far, -R_cam[:, 2],
                                     segmentation=True)
            rgb = rgba[..., :3].copy()
            rgb[seg < 0] = _CAVITY
            occlusion = None
        if self.circular_fov:
            rgb[~fov] = 0
        if occlusion is None and with_occlusion:
            robot = self.segmentation(width, height, fov_only=True)
            occlusion = float(np.count_nonzero(robot & fov) / np.count_nonzero(fov))
        return rgb, occlusion

    def _background(self, width, height, groups):
        """Tissue-only endoscope image and depth, cached per size: with the tissue fixed in the lens frame
        (``tissue="view"``) the endoscope sees the same tissue at every q and gamma."""
        key = (width, height, tuple(sorted(groups)))
        cached = self._backgrounds.get(key)
        if cached is None:
            p_cam, R_cam = self.camera_pose("endoscope")
            self._show(groups)
            rgba, seg = self._render(p_cam, R_cam, self.fov_y, width, height, self.near, self.far, -R_cam[:, 2],
                                     segmentation=True)
            rgb = rgba[..., :3].copy()
            rgb[seg < 0] = _CAVITY
            depth = self._last_depth.copy()
            depth[seg < 0] = np.inf
            if len(self._backgrounds) >= 8:
                self._backgrounds.clear()
            cached = self._backgrounds[key] = (rgb, depth)
        return cached

    def segmentation(self, width=128, height=128, fov_only=False) -> np.ndarray:
        """Boolean (height, width): endoscope-image pixels showing the robot.

        The tissue is hidden, so robot parts beyond it count as well. With ``fov_only`` only the pixels
        inside the circular field of view are exact (links entirely outside the cone are not drawn).
        """
        width, height = _resolution(width, height)
        p_cam, R_cam = self.camera_pose("endoscope")
        angle = self.cone.beta + 2.0 * self.fov_y / height if fov_only else _corner_angle(self.fov_y, width, height)
        self._show({"robot"}, self._outside_view(p_cam, R_cam[:, 2], angle))
        _, seg = self._render(p_cam, R_cam, self.fov_y, width, height, self.near, self.far, -R_cam[:, 2],
                              segmentation=True)
        return self._robot_mask(seg)

    def fov_mask(self, width=128, height=128) -> np.ndarray:
        """Boolean (height, width): endoscope pixels whose ray is within beta of the view axis."""
        return fov_mask(int(width), int(height), self.fov_y, self.cone.beta)

    def pixel_occlusion(self, resolution=128) -> float:
        """Fraction of the circular field of view covered by the robot at the current state (square image of
        side ``resolution``; tissue and shaft excluded, robot parts beyond the tissue included)."""
        mask = self.segmentation(resolution, resolution, fov_only=True)
        fov = self.fov_mask(resolution, resolution)
        return float(np.count_nonzero(mask & fov) / np.count_nonzero(fov))

    def __repr__(self):
        return (f"OcclusionScene(cone={self.cone!r}, tissue_distance={self.tissue_distance}, "
                f"robot_radius={self.robot_radius}, n_per_segment={self.n_per_segment}, closed={self.closed})")


# ====================================================================== paper 001: view tracking
class ViewTrackingScene(_Scene):
    """The continuum endoscope and the da Vinci endoscope (paper 001) with their view frusta.

    Bodies: the continuum endoscope (stem, ``n_per_segment`` links per segment, the rigid cylinder and the
    camera head; group ``"endoscope"``), the da Vinci stem through the remote centre (``"davinci"``), a
    wire frustum plus target point per camera (``"frustum_endoscope"``, ``"frustum_davinci"``, external
    view only) and a fixed textured tissue plane z_w = ``tissue_height`` (``"tissue"``).

    Both robots start at the world origin, so they are alternatives rather than neighbours: each camera's
    image hides the other robot. Camera images have the frustum's full angle as vertical field of view
    and use the robots' camera frames as x right, y down.

    Args:
        endoscope: ``ContinuumEndoscope``; davinci: ``DaVinciEndoscope``; frustum: ``Frustum`` (defaults: the paper's).
        endoscope_radius, davinci_radius: tube radii (m).
        n_per_segment: links per continuum segment.
        tissue_height: z_w of the tissue plane (m); default: the da Vinci home target's height.
        tissue_half_size: half the side of the tissue square (m); the texture tile is 0.25 m.
        near, far: clip planes of both endoscope cameras (m).
        external_camera: as for ``OcclusionScene``.
        texture_seed: seed of the tissue texture.
    """

    cameras = CAMERAS_VIEW_TRACKING
    robot_groups = ("endoscope",)

    def __init__(self, endoscope=None, davinci=None, frustum=None, endoscope_radius=0.003, davinci_radius=0.004,
                 n_per_segment=6, tissue_height=None, tissue_half_size=1.0, near=1e-3, far=1.5,
                 external_camera=None, texture_seed=0):
        from continuum_gym.geometry.frustum import Frustum
        from continuum_gym.robots import ContinuumEndoscope, DaVinciEndoscope

        self.endoscope = ContinuumEndoscope() if endoscope is None else endoscope
        self.davinci = DaVinciEndoscope() if davinci is None else davinci
        self.frustum = Frustum() if frustum is None else frustum
        if not isinstance(self.endoscope, ContinuumEndoscope):
            raise ValueError(f"endoscope must be a ContinuumEndoscope; got {type(endoscope).__name__}")
        if not isinstance(self.davinci, DaVinciEndoscope):
            raise ValueError(f"davinci must be a DaVinciEndoscope; got {type(davinci).__name__}")
        if not isinstance(self.frustum, Frustum):
            raise ValueError(f"frustum must be a Frustum; got {type(frustum).__name__}")
        if int(n_per_segment) != n_per_segment or n_per_segment < 1:
            raise ValueError(f"n_per_segment must be an integer >= 1; got {n_per_segment!r}")
        if tissue_height is None:
            tissue_height = float(self.davinci.target_point(self.davinci.home)[2])
        for name, value in (("endoscope_radius", endoscope_radius), ("davinci_radius", davinci_radius),
                            ("tissue_height", tissue_height), ("tissue_half_size", tissue_half_size),
                            ("near", near), ("far", far)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0 (m); got {value!r}")
        if not near < far:
            raise ValueError(f"need near < far; got {near!r}, {far!r}")
        self.n_per_segment = int(n_per_segment)
        self.tissue_height = float(tissue_height)
        self.near, self.far = float(near), float(far)
        self.fov_y = float(self.frustum.full_angle)
        ext = dict(target=(0.0, 0.04, 0.10), distance=0.30, azimuth=-50.0, elevation=-25.0, fov=45.0)
        ext.update(external_camera or {})
        self.external_camera = ext
        self._external = _external_frame(ext["target"], ext["distance"], ext["azimuth"], ext["elevation"])
        super().__init__(texture_seed=texture_seed, texture_size=512, texture_features=2.5)
        try:
            self._build(float(endoscope_radius), float(davinci_radius), float(tissue_half_size))
        except BaseException:
            self.close()
            raise
        self.q = None
        self.q_davinci = None
        self.update(self.endoscope.home, self.davinci.home)

    def _build(self, r, r_dv, tissue_half_size):
        e, n = self.endoscope, self.n_per_segment
        colors = _COLORS["endoscope"]
        self._stem_length = 0.2
        self._stem = self._bodies("endoscope", _tube(r, -self._stem_length, 0.0, bottom="open", top="flat"),
                                  colors[1])
        self._links = self._bodies("endoscope", _link(r, e.L1 / n), colors[0], count=n)
        self._links += self._bodies("endoscope", _link(r, e.Lm), colors[1])
        self._links += self._bodies("endoscope", _link(r, e.L2 / n), colors[2], count=n)
        self._links += self._bodies("endoscope", _link(r, e.Lc - 2e-4, top="flat"), _COLORS["camera_head"])
        self._davinci = self._bodies("davinci", _tube(r_dv, -0.3, -2e-4, sides=16, bottom="open", top="flat"),
                                     _COLORS["davinci"])
        self._frusta = {}
        for name, Le in (("endoscope", e.Le), ("davinci", self.davinci.Le)):
            v = self.frustum.local_vertices()
            edges = [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)]
            segments = [v[list(edge)] for edge in edges] + [np.stack([np.zeros(3), v[k]]) for k in range(4)]
            segments.append(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, Le]]))
            mesh = _Mesh.merge([_wires(np.stack(segments), 4e-4), _sphere(0.0025, [0.0, 0.0, Le])])
            self._frusta[name] = self._bodies(f"frustum_{name}", mesh, _COLORS[f"frustum_{name}"])
        # a central patch (all the external view shows) and the rest of the plane (for the cameras' rays)
        half, inner = tissue_half_size, min(0.3, 0.5 * tissue_half_size)
        xs = np.concatenate([[-half], np.linspace(-inner, inner, 9), [half]])
        patch, rest = _split(_grid(0, 0, xs=xs, normal_sign=-1.0, uv_scale=2.0 * half / 0.25), inner)
        self._tissue_bodies = [self._tissue(patch), self._tissue(rest, "tissue_frame")]
        self._place(self._tissue_bodies, [[0.0, 0.0, self.tissue_height]] * 2, [[0.0, 0.0, 0.0, 1.0]] * 2)
        self._finish(("endoscope",))
        self._ids = self._stem + self._links + self._davinci + self._frusta["endoscope"] + self._frusta["davinci"]

    def update(self, q, q_davinci) -> None:
        """Move the continuum endoscope to ``q`` (6,) and the da Vinci endoscope to ``q_davinci`` (4,)."""
        self._check_open()
        q = np.asarray(q, dtype=np.float64)
        q_dv = np.asarray(q_davinci, dtype=np.float64)
        if q.shape != (6,):
            raise ValueError(f"q must have shape (6,); got {q.shape}")
        if q_dv.shape != (4,):
            raise ValueError(f"q_davinci must have shape (4,); got {q_dv.shape}")
        n = self.n_per_segment
        B = self.endoscope.backbone(q, n)  # raises on non-finite q
        p_cam, R_cam = self.endoscope.forward_kinematics(q)
        p_dv, R_dv = self.davinci.forward_kinematics(q_dv)
        if not np.all(np.isfinite(q_dv)):
            raise ValueError(f"q_davinci must be finite; got {q_dv}")
        R_stem = self.davinci.stem_rotation(q_dv)
        directions = B[2:] - B[1:-1]
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        positions = [B[1].tolist()] + B[1:-1].tolist() + [p_dv.tolist(), p_cam.tolist(), p_dv.tolist()]
        quats = ([[0.0, 0.0, 0.0, 1.0]] + _quat_z_to(directions).tolist()
                 + [_quat(R_stem), _quat(R_cam), _quat(R_dv)])
        self._place(self._ids, positions, quats)
        self.q, self.q_davinci = q.copy(), q_dv.copy()
        self._poses = {"endoscope": (p_cam, R_cam), "davinci": (p_dv, R_dv)}

    def camera_pose(self, camera="endoscope"):
        """(p, R) of ``camera`` in {w} (z optical axis, x image right, y image down)."""
        if camera in ("endoscope", "davinci"):
            p, R = self._poses[camera]
            return p.copy(), R.copy()
        if camera == "external":
            return self._external[0].copy(), self._external[1].copy()
        raise ValueError(f"camera must be one of {self.cameras}; got {camera!r}")

    def render(self, camera="external", width=128, height=128) -> np.ndarray:
        """RGB image (height, width, 3) uint8 from ``"external"``, ``"endoscope"`` or ``"davinci"``."""
        p_cam, R_cam = self.camera_pose(camera)
        if camera == "external":
            return self._external_image(width, height, {"endoscope", "davinci", "frustum_endoscope",
                                                        "frustum_davinci", "tissue"})
        self._show({camera, "tissue", "tissue_frame"})  # the camera's own robot (behind it), not the other one
        return self._camera_image(p_cam, R_cam, self.fov_y, width, height, self.near, self.far)

    def __repr__(self):
        return (f"ViewTrackingScene(endoscope={self.endoscope!r}, davinci={self.davinci!r}, "
                f"frustum={self.frustum!r}, closed={self.closed})")
