"""The continuum endoscope and the da Vinci endoscope (paper 001) as a headless pybullet scene."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.render.meshes import (
    Mesh,
    grid_mesh,
    link,
    quat_z_to,
    quaternion,
    sphere,
    split_mesh,
    tube,
    wires,
)
from continuum_gym.render.scene import (
    CAMERAS_VIEW_TRACKING,
    COLORS,
    Scene,
    external_frame,
)

if TYPE_CHECKING:
    from continuum_gym.geometry.frustum import Frustum
    from continuum_gym.robots import ContinuumEndoscope, DaVinciEndoscope


# ====================================================================== paper 001: view tracking
class ViewTrackingScene(Scene):
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

    def __init__(self, endoscope: ContinuumEndoscope | None = None, davinci: DaVinciEndoscope | None = None,
                 frustum: Frustum | None = None, endoscope_radius: float = 0.003, davinci_radius: float = 0.004,
                 n_per_segment: int = 6, tissue_height: float | None = None, tissue_half_size: float = 1.0,
                 near: float = 1e-3, far: float = 1.5, external_camera: Mapping[str, Any] | None = None,
                 texture_seed: int = 0) -> None:
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
        ext: dict[str, Any] = dict(target=(0.0, 0.04, 0.10), distance=0.30, azimuth=-50.0, elevation=-25.0, fov=45.0)
        ext.update(external_camera or {})
        self.external_camera = ext
        self._external = external_frame(ext["target"], ext["distance"], ext["azimuth"], ext["elevation"])
        super().__init__(texture_seed=texture_seed, texture_size=512, texture_features=2.5)
        try:
            self._build(float(endoscope_radius), float(davinci_radius), float(tissue_half_size))
        except BaseException:
            self.close()
            raise
        self.q: np.ndarray | None = None
        self.q_davinci: np.ndarray | None = None
        self.update(self.endoscope.home, self.davinci.home)

    def _build(self, r, r_dv, tissue_half_size):
        e, n = self.endoscope, self.n_per_segment
        colors = COLORS["endoscope"]
        self._stem_length = 0.2
        self._stem = self._bodies("endoscope", tube(r, -self._stem_length, 0.0, bottom="open", top="flat"),
                                  colors[1])
        self._links = self._bodies("endoscope", link(r, e.L1 / n), colors[0], count=n)
        self._links += self._bodies("endoscope", link(r, e.Lm), colors[1])
        self._links += self._bodies("endoscope", link(r, e.L2 / n), colors[2], count=n)
        self._links += self._bodies("endoscope", link(r, e.Lc - 2e-4, top="flat"), COLORS["camera_head"])
        self._davinci = self._bodies("davinci", tube(r_dv, -0.3, -2e-4, sides=16, bottom="open", top="flat"),
                                     COLORS["davinci"])
        self._frusta = {}
        for name, Le in (("endoscope", e.Le), ("davinci", self.davinci.Le)):
            v = self.frustum.local_vertices()
            edges = [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)]
            segments = [v[list(edge)] for edge in edges] + [np.stack([np.zeros(3), v[k]]) for k in range(4)]
            segments.append(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, Le]]))
            mesh = Mesh.merge([wires(np.stack(segments), 4e-4), sphere(0.0025, [0.0, 0.0, Le])])
            self._frusta[name] = self._bodies(f"frustum_{name}", mesh, COLORS[f"frustum_{name}"])
        # a central patch (all the external view shows) and the rest of the plane (for the cameras' rays)
        half, inner = tissue_half_size, min(0.3, 0.5 * tissue_half_size)
        xs = np.concatenate([[-half], np.linspace(-inner, inner, 9), [half]])
        patch, rest = split_mesh(grid_mesh(0, 0, xs=xs, normal_sign=-1.0, uv_scale=2.0 * half / 0.25), inner)
        self._tissue_bodies = [self._tissue(patch), self._tissue(rest, "tissue_frame")]
        self._place(self._tissue_bodies, [[0.0, 0.0, self.tissue_height]] * 2, [[0.0, 0.0, 0.0, 1.0]] * 2)
        self._finish(("endoscope",))
        self._ids = self._stem + self._links + self._davinci + self._frusta["endoscope"] + self._frusta["davinci"]

    @classmethod
    def from_core(cls, core: Any) -> ViewTrackingScene:
        """The scene of a ViewTracking core: its continuum endoscope, da Vinci and frustum."""
        return cls(endoscope=core.robot, davinci=core.davinci, frustum=core.frustum)

    def show_row(self, core: Any, row: int) -> None:
        """Move the bodies to row ``row`` of ``core``: its joints and the da Vinci's configuration."""
        self.update(core.q[row], core.davinci_configuration(row))

    def update(self, q: ArrayLike, q_davinci: ArrayLike) -> None:
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
        quats = ([[0.0, 0.0, 0.0, 1.0]] + quat_z_to(directions).tolist()
                 + [quaternion(R_stem), quaternion(R_cam), quaternion(R_dv)])
        self._place(self._ids, positions, quats)
        self.q, self.q_davinci = q.copy(), q_dv.copy()
        self._poses = {"endoscope": (p_cam, R_cam), "davinci": (p_dv, R_dv)}

    def camera_pose(self, camera: str = "endoscope") -> tuple[np.ndarray, np.ndarray]:
        """(p, R) of ``camera`` in {w} (z optical axis, x image right, y image down)."""
        if camera in ("endoscope", "davinci"):
            p, R = self._poses[camera]
            return p.copy(), R.copy()
        if camera == "external":
            return self._external[0].copy(), self._external[1].copy()
        raise ValueError(f"camera must be one of {self.cameras}; got {camera!r}")

    def render(self, camera: str = "external", width: int = 128, height: int = 128) -> np.ndarray:
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
