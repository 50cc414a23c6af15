"""The MBCR beside the rotating angled-lens endoscope (paper 000) as a headless pybullet scene."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.geometry.lens_cone import LensCone, lens_origin, lens_rotation, resolve_cone
from continuum_gym.render.camera import fov_mask
from continuum_gym.render.meshes import (
    E3,
    disk_and_frame,
    grid_mesh,
    link,
    quat_z_to,
    quaternion,
    tube,
    wires,
)
from continuum_gym.render.scene import (
    CAMERAS_OCCLUSION,
    CAVITY,
    COLORS,
    Scene,
    corner_angle,
    external_frame,
    resolution,
)

if TYPE_CHECKING:
    from continuum_gym.robots import MultiBackboneRobot


# ====================================================================== paper 000: occlusion
class OcclusionScene(Scene):
    """The MBCR beside the rotating angled-lens endoscope (paper 000), rendered headless.

    Bodies: the robot (inserted part, ``n_segments n_per_segment`` links, a disk at each segment end; group
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

    def __init__(self, robot: MultiBackboneRobot | None = None, cone: LensCone | None = None,
                 tissue_distance: float = 0.065, robot_radius: float = 0.0015, n_per_segment: int = 8,
                 shaft_radius: float = 0.002, tissue: str | None = "view", tissue_half_size: float = 0.05,
                 circular_fov: bool = True, near: float = 1e-3, far: float = 0.3,
                 external_camera: Mapping[str, Any] | None = None, texture_seed: int = 0,
                 cache_background: bool = True) -> None:
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
        self._backgrounds: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}  # (width, height, groups) -> rgb, depth
        self.near, self.far = float(near), float(far)
        self.fov_y = 2.0 * self.cone.beta
        ext: dict[str, Any] = dict(target=(-0.012, 0.0, 0.035), distance=0.16, azimuth=-40.0, elevation=5.0, fov=45.0)
        ext.update(external_camera or {})
        self.external_camera = ext
        self._external = external_frame(ext["target"], ext["distance"], ext["azimuth"], ext["elevation"])
        super().__init__(texture_seed=texture_seed)
        try:
            self._build(shaft_radius, tissue_half_size)
        except BaseException:
            self.close()
            raise
        self.q: np.ndarray | None = None
        self.gamma: float | None = None
        self.update(self.robot.home, 0.0)

    # ------------------------------------------------------------------ build
    def _build(self, shaft_radius, tissue_half_size):
        r, n = self.robot_radius, self.n_per_segment
        # robot first: TinyRenderer draws in creation order, so the tissue behind it fails the depth test
        self._straight_length = 0.1
        self._straight = self._bodies("robot", tube(r, -self._straight_length, 0.0, sides=8, bottom="open",
                                                     top="flat"),
                                      COLORS["straight"])
        self._links = []
        last = self.robot.n_segments - 1
        for s, length in enumerate(self.robot.lengths):
            color = COLORS["segments"][s % len(COLORS["segments"])]
            if s < last:
                self._links += self._bodies("robot", link(r, length / n), color, count=n)
            else:
                if n > 1:
                    self._links += self._bodies("robot", link(r, length / n), color, count=n - 1)
                self._links += self._bodies("robot", link(r, length / n, top="flat"), color)
        self._disks = self._bodies("robot", tube(1.12 * r, -0.0004, 0.0004, sides=10, bottom="flat", top="flat"),
                                   COLORS["disk"], count=self.robot.n_segments + 1)
        self._shaft = self._bodies("shaft", tube(shaft_radius, -0.1, -2e-4, sides=16, bottom="open", top="flat"),
                                   COLORS["shaft"])
        self._lens = self._bodies("shaft", tube(0.7 * shaft_radius, -4e-4, -2e-4, sides=16, bottom="flat",
                                                 top="flat"), COLORS["lens"])
        d, beta = self.tissue_distance, self.cone.beta
        theta = 2.0 * math.pi * np.arange(64) / 64
        ring = 0.995 * d * np.stack([math.tan(beta) * np.cos(theta), math.tan(beta) * np.sin(theta),
                                     np.ones_like(theta)], axis=1)
        gen = ring[::8]
        mid = 0.5 * ring
        segments = [np.stack([np.zeros_like(gen), gen], 1), np.stack([ring, np.roll(ring, -1, 0)], 1),
                    np.stack([mid, np.roll(mid, -1, 0)], 1), [[[0, 0, 0], [0, 0, 0.995 * d]]]]
        self._cone = self._bodies("cone", wires(np.concatenate(segments), 2.5e-4), COLORS["cone"])
        self._tissue_bodies = []
        if self.tissue_mode == "view":
            # the disk inside the field of view (all the endoscope camera shades) and the rest of the square
            radius = 1.02 * d * math.tan(beta)
            disk, frame = disk_and_frame(radius, max(tissue_half_size, 1.05 * radius * math.sqrt(2.0)))
            self._tissue_bodies = [self._tissue(disk), self._tissue(frame, "tissue_frame")]
        elif self.tissue_mode == "world":
            half = tissue_half_size + d * math.sin(self.cone.alpha)
            self._tissue_bodies = [self._tissue(grid_mesh(half, half, normal_sign=-1.0,
                                                      uv_scale=half / tissue_half_size))]
            self._place(self._tissue_bodies, [[0.0, 0.0, d * math.cos(self.cone.alpha)]], [[0.0, 0.0, 0.0, 1.0]])
        self._finish(self.robot_groups)
        self._ids = self._straight + self._links + self._disks + self._shaft + self._lens + self._cone
        half = np.repeat(0.5 * np.asarray(self.robot.lengths) / n, n)
        self._half_links = half[:, None]
        disks = self.robot.n_segments + 1
        self._spheres = (self._links + self._disks, np.zeros((self.robot.n_segments * n + disks, 3)),
                         np.concatenate([half + r, np.full(disks, 1.12 * r + 4e-4)]))
        if self.tissue_mode == "view":
            self._ids += self._tissue_bodies

    # ------------------------------------------------------------------ state
    @classmethod
    def from_core(cls, core: Any) -> OcclusionScene:
        """The scene of an OcclusionAvoidance core: its robot and cone."""
        return cls(robot=core.robot, cone=core.cone)

    def show_row(self, core: Any, row: int) -> None:
        """Move the bodies to row ``row`` of ``core``: its joints and endoscope rotation."""
        self.update(core.q[row], core.gamma[row])

    def update(self, q: ArrayLike, gamma: float) -> None:
        """Move every body to configuration ``q`` (dof,) and endoscope rotation ``gamma`` (rad)."""
        self._check_open()
        q = np.asarray(q, dtype=np.float64)
        if q.shape != (self.robot.dof,):
            raise ValueError(f"q must have shape ({self.robot.dof},); got {q.shape}")
        gamma = float(gamma)
        if not math.isfinite(gamma):
            raise ValueError(f"gamma must be finite (rad); got {gamma!r}")
        n, ni = self.n_per_segment, self.robot.n_insert_samples
        P = self.robot.backbone(q, n)  # raises on non-finite q
        _, R_tip = self.robot.forward_kinematics(q)
        chords = P[ni + 1:] - P[ni:-1]
        segments = self.robot.n_segments
        ends = ni + n * np.arange(segments + 1)
        tangents = np.empty((segments + 1, 3))
        tangents[0] = E3
        tangents[1:segments] = P[ends[1:segments] + 1] - P[ends[1:segments] - 1]
        tangents[segments] = R_tip[:, 2]
        directions = np.concatenate([chords, tangents])
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        link_quats = quat_z_to(directions).tolist()
        centres = self._spheres[1]
        centres[:segments * n] = P[ni:-1] + self._half_links * directions[:segments * n]
        centres[segments * n:] = P[ends]
        p_lens = lens_origin(gamma, self.cone)
        R_lens = lens_rotation(gamma, self.cone)
        q_lens = quaternion(R_lens)
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
    def camera_pose(self, camera: str = "endoscope") -> tuple[np.ndarray, np.ndarray]:
        """(p, R) of ``camera`` in {w} (z optical axis, x image right, y image down)."""
        if camera == "endoscope":
            assert self.gamma is not None  # set by update(), which __init__ calls
            R = lens_rotation(self.gamma, self.cone) * np.array([-1.0, -1.0, 1.0])
            return lens_origin(self.gamma, self.cone), R
        if camera == "external":
            return self._external[0].copy(), self._external[1].copy()
        raise ValueError(f"camera must be one of {self.cameras}; got {camera!r}")

    def render(self, camera: str = "external", width: int = 128, height: int = 128) -> np.ndarray:
        """RGB image (height, width, 3) uint8 from ``"external"`` or ``"endoscope"``."""
        if camera == "endoscope":
            return self._endoscope(width, height, False)[0]
        if camera != "external":
            raise ValueError(f"camera must be one of {self.cameras}; got {camera!r}")
        return self._external_image(width, height, {"robot", "shaft", "tissue", "tissue_frame", "cone"})

    def endoscope_frame(self, width: int = 128, height: int = 128) -> tuple[np.ndarray, float]:
        """(endoscope RGB image (height, width, 3) uint8, pixel occlusion of that image size).

        With the cached background (``cache_background``, ``tissue="view"``) both come from one robot
        render, so the occlusion is free; it equals ``pixel_occlusion()`` for a square image.
        """
        return self._endoscope(width, height, True)

    def _endoscope(self, width, height, with_occlusion):
        width, height = resolution(width, height)
        p_cam, R_cam = self.camera_pose("endoscope")
        fov = fov_mask(width, height, self.fov_y, self.cone.beta)
        if self.circular_fov:
            # only what lies inside the circular field of view is drawn: the links whose bounding spheres
            # reach into the cone (2 pixels of slack); the rest of the image is black
            angle = self.cone.beta + 2.0 * self.fov_y / height
            tissue = {"tissue"}
        else:
            angle = corner_angle(self.fov_y, width, height)
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
            rgb[seg < 0] = CAVITY
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
            rgb[seg < 0] = CAVITY
            depth = self._last_depth.copy()
            depth[seg < 0] = np.inf
            if len(self._backgrounds) >= 8:
                self._backgrounds.clear()
            cached = self._backgrounds[key] = (rgb, depth)
        return cached

    def segmentation(self, width: int = 128, height: int = 128, fov_only: bool = False) -> np.ndarray:
        """Boolean (height, width): endoscope-image pixels showing the robot.

        The tissue is hidden, so robot parts beyond it count as well. With ``fov_only`` only the pixels
        inside the circular field of view are exact (links entirely outside the cone are not drawn).
        """
        width, height = resolution(width, height)
        p_cam, R_cam = self.camera_pose("endoscope")
        angle = self.cone.beta + 2.0 * self.fov_y / height if fov_only else corner_angle(self.fov_y, width, height)
        self._show({"robot"}, self._outside_view(p_cam, R_cam[:, 2], angle))
        _, seg = self._render(p_cam, R_cam, self.fov_y, width, height, self.near, self.far, -R_cam[:, 2],
                              segmentation=True)
        return self._robot_mask(seg)

    def fov_mask(self, width: int = 128, height: int = 128) -> np.ndarray:
        """Boolean (height, width): endoscope pixels whose ray is within beta of the view axis."""
        return fov_mask(int(width), int(height), self.fov_y, self.cone.beta)

    def pixel_occlusion(self, resolution: int = 128) -> float:
        """Fraction of the circular field of view covered by the robot at the current state (square image of
        side ``resolution``; tissue and shaft excluded, robot parts beyond the tissue included)."""
        mask = self.segmentation(resolution, resolution, fov_only=True)
        fov = self.fov_mask(resolution, resolution)
        return float(np.count_nonzero(mask & fov) / np.count_nonzero(fov))

    def __repr__(self):
        return (f"OcclusionScene(cone={self.cone!r}, tissue_distance={self.tissue_distance}, "
                f"robot_radius={self.robot_radius}, n_per_segment={self.n_per_segment}, closed={self.closed})")
