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

import math
import os
import tempfile
from collections.abc import Collection
from types import ModuleType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.camera.palette import CAVITY, COLORS
from continuum_gym.render.camera import camera_matrices, look_at_frame
from continuum_gym.render.meshes import E3, unit
from continuum_gym.render.textures import bmp_bytes, cached_texture

__all__ = ["Scene", "CAMERAS_OCCLUSION", "CAMERAS_VIEW_TRACKING", "COLORS", "CAVITY", "resolution", "corner_angle",
           "external_frame", "import_pybullet"]

CAMERAS_OCCLUSION = ("external", "endoscope")


CAMERAS_VIEW_TRACKING = ("external", "endoscope", "davinci")


def import_pybullet() -> tuple[ModuleType, ModuleType]:
    try:
        import pybullet
        from pybullet_utils import bullet_client
    except ImportError as error:  # pragma: no cover - pybullet is a dependency
        raise ImportError("continuum_gym.render needs pybullet: pip install pybullet") from error
    return pybullet, bullet_client


# ====================================================================== base scene
class Scene:
    """A private DIRECT pybullet client, body groups with visibility, and camera images."""

    #: lighting (TinyRenderer defaults are ambient 0.6, diffuse 0.35, specular 0.05)
    _light = dict(lightAmbientCoeff=0.45, lightDiffuseCoeff=0.55, lightSpecularCoeff=0.08, shadow=0)
    _light_external = dict(lightAmbientCoeff=0.7, lightDiffuseCoeff=0.45, lightSpecularCoeff=0.08, shadow=0)
    # Declared by every scene class: its cameras (a class attribute) and the external camera (in __init__).
    cameras: tuple[str, ...]
    external_camera: dict[str, Any]
    _external: tuple[np.ndarray, np.ndarray]
    # Set by every scene's constructor: the endoscope cameras' vertical field of view (rad) and clip distances (m).
    fov_y: float
    near: float
    far: float

    def __init__(self, texture_seed: int = 0, texture_size: int = 512, texture_features: float = 1.0) -> None:
        p, bullet_client = import_pybullet()
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
        self._last_depth = np.zeros((0, 0), dtype=np.float32)
        self._last_clip = (1e-3, 0.3)
        #: bounding spheres of the bodies that may be culled: (body ids, centres (k, 3), radii (k,))
        self._spheres: tuple[list[int], np.ndarray, np.ndarray] = ([], np.zeros((0, 3)), np.zeros(0))
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
                    f.write(bmp_bytes(cached_texture(self._texture_size, self._texture_seed, self._texture_features)))
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
        width, height = resolution(width, height)
        view, proj = camera_matrices(p_cam, R_cam, fov_y, width, height, near, far)
        p = self._p
        out = p.getCameraImage(width, height, viewMatrix=view, projectionMatrix=proj,
                               lightDirection=[float(x) for x in light_direction], renderer=p.ER_TINY_RENDERER,
                               flags=0 if segmentation else p.ER_NO_SEGMENTATION_MASK, physicsClientId=self._cid,
                               **(light or self._light))
        rgba = np.asarray(out[2], dtype=np.uint8).reshape(height, width, 4)
        seg = np.asarray(out[4]).reshape(height, width) if segmentation else None
        self._last_depth = np.asarray(out[3], dtype=np.float32).reshape(height, width)
        self._last_clip = (float(near), float(far))
        return rgba, seg

    def last_depth(self) -> np.ndarray:
        """Depth (height, width) float32 of the last image the scene rendered, in m along the optical axis.

        From pybullet's depth buffer z in [0, 1]: far near / (far - (far - near) z), so ``far`` where nothing was
        hit. Of the last render call: ``render("endoscope")`` with a cached background renders the robot alone.
        """
        self._check_open()
        if self._last_depth.size == 0:
            raise ValueError("no image rendered yet: call render() first")
        near, far = self._last_clip
        return (far * near / (far - (far - near) * self._last_depth.astype(np.float64))).astype(np.float32)

    def _external_image(self, width, height, groups):
        """External view: light from behind the viewer, a dark gradient where no body is hit."""
        self._show(groups)
        p_cam, R_cam = self._external
        light = unit(-R_cam[:, 2] + 0.25 * E3)
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
            rgb[seg < 0] = CAVITY
        return rgb

    def set_external_camera(self, target: ArrayLike | None = None, distance: float | None = None,
                            azimuth: float | None = None, elevation: float | None = None,
                            fov: float | None = None) -> None:
        """Move the external camera; the values given replace those of ``external_camera`` (the rest stay).

        Args:
            target: (3,) point the camera looks at, in {w} (m).
            distance: distance from the target (m), in (0, 1.5].
            azimuth: angle about z_w from +x_w (deg).
            elevation: angle above the target's horizontal plane (deg), in (-90, 90).
            fov: vertical field of view (deg), in (0, 180).
        """
        from continuum_gym.validation import as_finite, number

        self._check_open()
        ext = dict(self.external_camera)
        if target is not None:
            point = as_finite(target, (3,), "target")
            if point.shape != (3,):
                raise ValueError(f"target must be one point of shape (3,) (m); got shape {point.shape}")
            ext["target"] = tuple(float(x) for x in point)
        if distance is not None:
            ext["distance"] = number(distance, "distance", low=0.0, high=1.5, low_open=True, unit="m")
        if azimuth is not None:
            ext["azimuth"] = number(azimuth, "azimuth", unit="deg")
        if elevation is not None:
            ext["elevation"] = number(elevation, "elevation", low=-90.0, high=90.0, low_open=True, high_open=True,
                                      unit="deg")
        if fov is not None:
            ext["fov"] = number(fov, "fov", low=0.0, high=180.0, low_open=True, high_open=True, unit="deg")
        self._external = external_frame(ext["target"], ext["distance"], ext["azimuth"], ext["elevation"])
        self.external_camera = ext

    def camera_pose(self, camera: str = "endoscope") -> tuple[np.ndarray, np.ndarray]:
        """(p, R) of ``camera`` in {w}; every scene class defines it."""
        raise NotImplementedError

    def camera_image(self, camera: str, groups: Collection[str], width: int = 128,
                     height: int = 128) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """An endoscope camera's image of exactly the body ``groups`` (names of ``body_ids``), for comparisons
        with another renderer: (rgb (H, W, 3) uint8, body id of each pixel (H, W) int, -1 where nothing is
        hit, depth (H, W) float32 in m along the optical axis, ``far`` where nothing is hit).

        Unlike ``render``, nothing is culled and no background is filled in or cached.
        """
        if camera not in self.cameras or camera == "external":
            raise ValueError(f"camera must be one of {[c for c in self.cameras if c != 'external']}; got {camera!r}")
        unknown = set(groups) - set(self._groups)
        if unknown:
            raise ValueError(f"groups must be among {sorted(self._groups)}; got {sorted(unknown)}")
        p_cam, R_cam = self.camera_pose(camera)
        self._show(set(groups))
        rgba, seg = self._render(p_cam, R_cam, self.fov_y, width, height, self.near, self.far, -R_cam[:, 2],
                                 segmentation=True)
        ids = np.where(seg >= 0, seg & 0xFFFFFF, -1)
        return rgba[..., :3].copy(), ids, self.last_depth()

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

    def close(self) -> None:
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


def resolution(width: int, height: int) -> tuple[int, int]:
    w, h = int(width), int(height)
    if w != width or h != height or w < 1 or h < 1 or w > 4096 or h > 4096:
        raise ValueError(f"width and height must be integers in [1, 4096]; got {width!r} x {height!r}")
    return w, h


def corner_angle(fov_y: float, width: int, height: int) -> float:
    """Angle between the optical axis and the image corners' rays, plus 2 pixels of slack."""
    t = math.tan(0.5 * fov_y)
    return math.atan(t * math.hypot(1.0, width / height)) + 2.0 * fov_y / height


def external_frame(target: ArrayLike, distance: float, azimuth_deg: float,
                   elevation_deg: float) -> tuple[np.ndarray, np.ndarray]:
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    target = np.asarray(target, dtype=np.float64)
    eye = target + distance * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    return look_at_frame(eye, target, E3)
