"""What the batched renderer draws, as arrays: tubes per row, a textured plane, and one camera per view.

A ``Scene`` holds N rows (one per environment) of the same bodies in different places. Its ``views`` name the
cameras that look at it (``"endoscope"``; ViewTracking adds ``"davinci"``), each with the tube groups it shows.
The per-environment builders (``camera.occlusion``, ``camera.view_tracking``) fill it from configurations.

Segmentation ids: 0 for the background and the tissue, 1..n for the robot's segments from base to tip
(``Scene.n_segments`` = n), n + 1 for the other endoscope; ``Scene.labels`` names them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from continuum_gym.camera.model import Cameras
from continuum_gym.camera.primitives import FLAT, OPEN, ROUND
from continuum_gym.camera.raster import PLANE_CAMERA, PLANE_WORLD
from continuum_gym.camera.texture import MipPyramid
from continuum_gym.validation import as_finite, choice, integer

__all__ = ["Tubes", "TexturedPlane", "View", "Scene", "END_KINDS"]

#: Tube end kinds by name.
END_KINDS = {"open": OPEN, "flat": FLAT, "round": ROUND}


def _read_only(*arrays: np.ndarray) -> None:
    for array in arrays:
        array.flags.writeable = False


@dataclass(frozen=True)
class Tubes:
    """T tubes per row: solid cylinders from ``a`` to ``b`` with open, flat or round ends.

    Args:
        a, b: (N, T, 3) the axis ends in {w} (m); a tube of zero length is not drawn.
        u: (N, T, 3) a unit direction perpendicular to the axis toward a vertex of the tube's prism (the
            pybullet mesh's body x axis); read only for tubes with ``sides`` > 0.
        radius: (T,) circumradius (m), > 0.
        sides: (T,) sides of the regular prism the tube is drawn as (even, in [4, 64]), 0 for a round tube.
        caps: (T, 2) end kinds at a and at b: 0 open (not drawn: seen from inside), 1 flat, 2 round
            (a hemisphere of the radius, as at a joint); only the end at b may be round.
        ids: (T,) segmentation id of each tube, in [1, 255].
        colors: (T, 3) albedo in [0, 1].
        groups: (T,) group of each tube in [0, 62]: a view draws the groups it names.
    """

    a: np.ndarray
    b: np.ndarray
    u: np.ndarray
    radius: np.ndarray
    sides: np.ndarray
    caps: np.ndarray
    ids: np.ndarray
    colors: np.ndarray
    groups: np.ndarray

    def __post_init__(self) -> None:
        a = np.ascontiguousarray(as_finite(self.a, (3,), "a"))
        if a.ndim != 3:
            raise ValueError(f"a must be (N, T, 3) (m); got shape {a.shape}")
        n, t = a.shape[:2]
        b = np.ascontiguousarray(as_finite(self.b, (3,), "b"))
        u = np.ascontiguousarray(as_finite(self.u, (3,), "u"))
        for name, value in (("b", b), ("u", u)):
            if value.shape != (n, t, 3):
                raise ValueError(f"{name} must be ({n}, {t}, 3) like a; got shape {value.shape}")
        radius = np.ascontiguousarray(as_finite(self.radius, (), "radius"), dtype=np.float64)
        sides = np.ascontiguousarray(self.sides, dtype=np.int64)
        caps = np.ascontiguousarray(self.caps, dtype=np.int64)
        ids = np.ascontiguousarray(self.ids)
        colors = np.ascontiguousarray(as_finite(self.colors, (3,), "colors"), dtype=np.float64)
        groups = np.ascontiguousarray(self.groups, dtype=np.int64)
        for name, value, shape in (("radius", radius, (t,)), ("sides", sides, (t,)), ("caps", caps, (t, 2)),
                                   ("ids", ids, (t,)), ("colors", colors, (t, 3)), ("groups", groups, (t,))):
            if value.shape != shape:
                raise ValueError(f"{name} must have shape {shape} (one per tube); got {value.shape}")
        if np.any(radius <= 0):
            raise ValueError(f"radius must be > 0 (m); got {radius}")
        if np.any((sides != 0) & ((sides < 4) | (sides > 64) | (sides % 2 == 1))):
            raise ValueError(f"sides must be 0 (round) or even in [4, 64]; got {sides}")
        if np.any((caps < OPEN) | (caps > ROUND)) or np.any(caps[:, 0] == ROUND):
            raise ValueError(f"caps must be 0 open, 1 flat or 2 round (round only at b); got {caps.tolist()}")
        if not np.issubdtype(ids.dtype, np.integer) or np.any(ids < 1) or np.any(ids > 255):
            raise ValueError(f"ids must be integers in [1, 255]; got {ids}")
        if np.any(colors < 0) or np.any(colors > 1):
            raise ValueError("colors must be in [0, 1]")
        if np.any(groups < 0) or np.any(groups > 62):
            raise ValueError(f"groups must be in [0, 62]; got {groups}")
        ids = ids.astype(np.uint8)
        for name, value in (("a", a), ("b", b), ("u", u), ("radius", radius), ("sides", sides), ("caps", caps),
                            ("ids", ids), ("colors", colors), ("groups", groups)):
            object.__setattr__(self, name, value)

    @property
    def num_rows(self) -> int:
        return int(self.a.shape[0])

    @property
    def count(self) -> int:
        """T, the number of tubes per row."""
        return int(self.a.shape[1])


@dataclass(frozen=True)
class TexturedPlane:
    """A textured rectangle (the tissue), the same in every row, fixed in the world or in the camera frame.

    Args:
        frame: ``"world"`` or ``"camera"`` (then it moves with each row's camera).
        origin: (3,) its centre (m); axis_x, axis_y: (3,) unit in-plane axes; normal: (3,) unit normal of
            its front face (the side it is seen from; from behind it is not drawn, as pybullet culls it).
        half: (2,) half sizes along axis_x and axis_y (m).
        tiles_per_metre: (2,) texture repeats per metre along each axis; texture coordinates start at the
            corner origin - half_x axis_x - half_y axis_y.
        texture: the ``MipPyramid`` sampled.
    """

    frame: str
    origin: np.ndarray
    axis_x: np.ndarray
    axis_y: np.ndarray
    normal: np.ndarray
    half: np.ndarray
    tiles_per_metre: np.ndarray
    texture: MipPyramid

    def __post_init__(self) -> None:
        choice(self.frame, ("world", "camera"), "frame")
        for name in ("origin", "axis_x", "axis_y", "normal"):
            value = np.ascontiguousarray(as_finite(getattr(self, name), (3,), name).reshape(3))
            if name != "origin" and abs(np.linalg.norm(value) - 1.0) > 1e-9:
                raise ValueError(f"{name} must be a unit vector; got {value}")
            object.__setattr__(self, name, value)
        for name in ("half", "tiles_per_metre"):
            value = np.ascontiguousarray(as_finite(getattr(self, name), (2,), name).reshape(2))
            if np.any(value <= 0):
                raise ValueError(f"{name} must be > 0; got {value}")
            object.__setattr__(self, name, value)
        if not isinstance(self.texture, MipPyramid):
            raise ValueError(f"texture must be a MipPyramid; got {type(self.texture).__name__}")

    @property
    def kind(self) -> int:
        """The rasteriser's code of ``frame``."""
        return PLANE_WORLD if self.frame == "world" else PLANE_CAMERA


@dataclass(frozen=True)
class View:
    """One camera per row looking at a scene.

    Args:
        cameras: the N cameras (``Cameras``).
        groups: the tube groups it draws.
        fov_half_angle: half-angle (rad) of a circular field of view (an endoscope's round image): pixels
            whose ray lies farther from the optical axis are 0 in every modality. None: the whole image.
        plane: the textured background, or None (cavity colour at the far distance).
    """

    cameras: Cameras
    groups: tuple[int, ...]
    fov_half_angle: float | None = None
    plane: TexturedPlane | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.cameras, Cameras):
            raise ValueError(f"cameras must be Cameras; got {type(self.cameras).__name__}")
        object.__setattr__(self, "groups", tuple(integer(g, "groups", low=0, high=62) for g in self.groups))
        if self.fov_half_angle is not None and not 0.0 < self.fov_half_angle < np.pi / 2:
            raise ValueError(f"fov_half_angle must be in (0, pi/2) rad or None; got {self.fov_half_angle!r}")

    @property
    def group_mask(self) -> int:
        """The groups as a bit mask (what the rasteriser reads)."""
        return sum(1 << g for g in set(self.groups))


@dataclass(frozen=True)
class Scene:
    """N rows of tubes and the views that look at them.

    Args:
        tubes: the bodies (``Tubes``).
        views: {view name: ``View``}; every view has N cameras.
        n_segments: n, the robot's segments: ids 1..n are the robot, n + 1 the other endoscope.
        labels: {segmentation id: what it is}, for the docs and plots.
    """

    tubes: Tubes
    views: dict[str, View]
    n_segments: int
    labels: dict[int, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.tubes, Tubes):
            raise ValueError(f"tubes must be Tubes; got {type(self.tubes).__name__}")
        if not self.views:
            raise ValueError("views must name at least one View")
        for name, view in self.views.items():
            if not isinstance(view, View):
                raise ValueError(f"views[{name!r}] must be a View; got {type(view).__name__}")
            if view.cameras.num_rows != self.tubes.num_rows:
                raise ValueError(f"views[{name!r}] has {view.cameras.num_rows} cameras for {self.tubes.num_rows} rows")
        integer(self.n_segments, "n_segments", low=1, high=254)

    @property
    def num_rows(self) -> int:
        """N, the rows of the batch."""
        return self.tubes.num_rows

    def view(self, name: str) -> View:
        """The view ``name``, else a ``ValueError`` listing the views."""
        choice(name, tuple(self.views), "view")
        return self.views[name]
