"""Image observations (issue 56): an observation layer over a batched core's state, rendered by ``camera``.

The environments' physics never sees a pixel. A batched core whose ``config.obs_mode`` is an image mode holds a
``PixelObserver`` (``core.pixels``, made once by ``BatchedCore``): a step or a reset marks the rows it changed, and
the next read of the observations or of ``info`` builds the analytic scene of those rows from the core's state
(its true joints, the endoscope's rotation, the true robot under a model error) and renders it with
``camera.Renderer`` into preallocated buffers: one compiled call per view and batch, threaded. The core's
``single_observation_space`` is then the ``Dict`` of the images and ``observations()`` / ``observation(row)`` return
them, so every front end (``single.py``, ``vector.py``, ``sb3.py``, and ``goal.py`` over the single env) observes
images through the same two calls it makes for the state; no env and no front end has code of its own for them.

The layer reads the core only through what every core keeps: ``num_envs``, ``config``, ``q``,
``sensed_joints()``, ``base_cmd``, ``steps``, ``control_dt``, ``spec.env_id`` and the env-specific state its
``PixelSpec`` names (``gamma``, ``davinci_configuration(row)``). What differs per environment (the scene, the
views, the ``state`` entry, the pixel metric) is a ``PixelSpec`` in the env's package (``envs/occlusion/pixels.py``,
``envs/view_tracking/pixels.py``), named by the env's ``EnvSpec`` (``pixels="module:NAME"``, which ``register_env``
passes to ``register_pixels``) so that nothing compiled is imported until an image mode is used.

Vocabulary (ManiSkill's): ``obs_mode`` is ``"state"`` (the flat ``Box`` the env always had, bit for bit),
``"rgb"``, ``"depth"``, ``"segmentation"``, ``"rgbd"`` or ``"rgb+depth+segmentation"``; ``image_size`` is an int
(square) or (H, W), 64 by default. An image observation is a ``Dict``: ``rgb`` (H, W, 3) uint8, ``depth``
(H, W, 1) float32 (m along the optical axis), ``segmentation`` (H, W, 1) uint8 ids, and ``state``, what a real
system measures (joints as its sensors read them, the endoscope's rotation, the base controller's command).
A second view (ViewTracking's da Vinci, the view the surgeon asked for) adds the same keys with a prefix
(``goal_rgb``, ...).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from continuum_gym.envs.obs_modes import (
    DEFAULT_IMAGE_SIZE,
    MAX_IMAGE_SIDE,
    MIN_IMAGE_SIDE,
    MODE_MODALITIES,
    OBS_MODES,
    OBSERVATION_KEYWORDS,
    check_image_size,
    check_obs_mode,
    image_shape,
)
from continuum_gym.validation import choice

if TYPE_CHECKING:
    from gymnasium import spaces

    from continuum_gym.camera import Frames, Scene
    from continuum_gym.envs.declared import EpisodeMetric, Metric

#: Bound of the ``state`` entry's values (SI units): far beyond any joint, rotation or rate of the robots, finite
#: so that the checkers accept the space; values beyond it (a diverging plug-in) are clipped to it.
STATE_LIMIT = 1e6


@dataclass(frozen=True)
class PixelSpec:
    """What one environment's image observations are made of (registered with ``register_pixels``).

    Args:
        env_id: the environment's id.
        views: (scene view, key prefix) pairs: ``("endoscope", "")`` gives ``rgb`` ..., ``("davinci", "goal_")``
            gives ``goal_rgb`` ...
        max_id: ``max_id(core) -> int``, the largest segmentation id (n + 1: the other endoscope).
        far: the far clip of every view (m): the depth of a ray that meets nothing, the depth space's bound.
        state_names: the ``state`` entry's columns (with units), for the docs.
        state: ``state(core) -> (N, k)`` float: what a real system measures.
        scene: ``scene(core, rows, height, width) -> camera.Scene`` of the given rows' true state.
        metrics: ``metrics(core, rows, scene, frames) -> {info key: (len(rows),) float64}``, the pixel
            metrics; ``frames`` maps each view to its ``camera.Frames`` (rows of ``rows`` only).
        metric_modalities: what the metrics need rendered in the first view beyond the observation.
        table_metrics: the evaluation table's columns of the pixel metrics (``evaluate --pixel-metrics``).
        episode_metrics: their reductions from the per-step info values.
    """

    env_id: str
    views: tuple[tuple[str, str], ...]
    max_id: Callable[[Any], int]
    far: float
    state_names: tuple[str, ...]
    state: Callable[[Any], np.ndarray]
    scene: Callable[[Any, np.ndarray, int, int], Scene]
    metrics: Callable[[Any, np.ndarray, Scene, dict[str, Frames]], dict[str, np.ndarray]]
    metric_modalities: tuple[str, ...] = ()
    table_metrics: tuple[Metric, ...] = ()
    episode_metrics: tuple[EpisodeMetric, ...] = ()


#: env id -> "module:NAME" of its ``PixelSpec`` (filled by ``register_env`` from ``EnvSpec.pixels``, or by
#: ``register_pixels``; loaded on first use).
PIXEL_SPECS: dict[str, str | PixelSpec] = {}


def register_pixels(env_id: str, reference: str | PixelSpec) -> None:
    """Give ``env_id`` image observations: its ``PixelSpec`` or the ``"module:NAME"`` it is imported from."""
    PIXEL_SPECS[env_id] = reference


def pixel_spec(env_id: str) -> PixelSpec:
    """The ``PixelSpec`` of an environment (its module imported now); ``ValueError`` if it has none."""
    from continuum_gym.plugins import load_object

    entry = PIXEL_SPECS.get(env_id)
    if entry is None:
        raise ValueError(f"obs_mode: {env_id} has no image observations (only 'state': its EnvSpec names no pixels); "
                         f"environments with images: {sorted(PIXEL_SPECS)}")
    if isinstance(entry, str):
        entry = PIXEL_SPECS[env_id] = load_object(entry)
    assert isinstance(entry, PixelSpec), f"{env_id}'s pixel spec is not a PixelSpec"
    return entry


def observation_space(spec: PixelSpec, obs_mode: str, height: int, width: int, state_dim: int,
                      max_id: int) -> spaces.Dict:
    """The ``Dict`` space of one row's image observation."""
    from gymnasium import spaces

    entries: dict[str, spaces.Space] = {}
    for _, prefix in spec.views:
        for modality in MODE_MODALITIES[obs_mode]:
            if modality == "rgb":
                entries[prefix + "rgb"] = spaces.Box(0, 255, (height, width, 3), np.uint8)
            elif modality == "depth":
                entries[prefix + "depth"] = spaces.Box(0.0, spec.far, (height, width, 1), np.float32)
            else:
                entries[prefix + "segmentation"] = spaces.Box(0, max_id, (height, width, 1), np.uint8)
    entries["state"] = spaces.Box(-STATE_LIMIT, STATE_LIMIT, (state_dim,), np.float32)
    return spaces.Dict(entries)


class PixelObserver:
    """Renders the rows of a core into preallocated image buffers: the core's image observations (``core.pixels``).

    Rows marked ``stale`` (the core marks the rows a step or a reset changed) are rendered at the next read
    (``observations``, ``observation``, ``info``, ``info_row``), each once; ``update`` renders at once.

    Args:
        core: the batched core (any env with a registered ``PixelSpec``).
        obs_mode: one of ``OBS_MODES`` (None: the core's ``config.obs_mode``); ``"state"`` observes no image
            but still measures the pixel metrics (``evaluate --pixel-metrics``).
        image_size: int or (H, W) (None: the core's ``config.image_size``).
        threads: the renderer's threads (None: 1 when torch is loaded, else numba's count).
    """

    def __init__(self, core: Any, obs_mode: str | None = None, image_size: int | tuple[int, int] | None = None,
                 threads: int | None = None) -> None:
        from continuum_gym.camera import Renderer, allocate_frames

        self.core = core
        self.spec = pixel_spec(core.spec.env_id)
        self.obs_mode = check_obs_mode(core.config.obs_mode if obs_mode is None else obs_mode)
        self.image_size = check_image_size(core.config.image_size if image_size is None else image_size)
        self.height, self.width = image_shape(self.image_size)
        self.renderer = Renderer(threads=threads)
        self.observed = MODE_MODALITIES[self.obs_mode]
        self.state_dim = int(self.spec.state(core).shape[1])
        self.space = observation_space(self.spec, self.obs_mode, self.height, self.width, self.state_dim,
                                       self.spec.max_id(core))
        n = core.num_envs
        first = self.spec.views[0][0]
        self._modalities = {view: tuple(m for m in ("rgb", "depth", "segmentation") if m in self.observed
                                        or (view == first and m in self.spec.metric_modalities))
                            for view, _ in self.spec.views}
        self._buffers = {view: allocate_frames(n, self.width, self.height, modalities) if modalities else {}
                         for view, modalities in self._modalities.items()}
        self.state = np.zeros((n, self.state_dim), dtype=np.float32)
        self.metrics: dict[str, np.ndarray] = {}
        self._stale = np.ones(n, dtype=bool)  # rows changed since they were last rendered

    # ------------------------------------------------------------------ rendering
    def stale(self, rows: Any = None) -> None:
        """Mark ``rows`` (indices or an (N,) bool mask; None: all) as changed: they are rendered at the next read."""
        if rows is None:
            self._stale[:] = True
        else:
            self._stale[rows] = True

    def refresh(self) -> None:
        """Render the rows marked stale, if any (all of them in one call when every row is)."""
        if self._stale.any():
            self.update(None if self._stale.all() else np.flatnonzero(self._stale))

    def update(self, rows: Any = None) -> None:
        """Render ``rows`` (None: all) from the core's current state, and measure their pixel metrics."""
        n = self.core.num_envs
        whole = rows is None or (len(rows) == n and np.array_equal(np.asarray(rows), np.arange(n)))
        index = np.arange(n) if whole else np.asarray(rows, dtype=np.int64)
        np.clip(self.spec.state(self.core), -STATE_LIMIT, STATE_LIMIT, out=self.state, casting="same_kind")
        if len(index) == 0:
            return
        self._stale[index] = False
        scene = self.spec.scene(self.core, index, self.height, self.width)
        frames = {}
        for view, modalities in self._modalities.items():
            if whole or not modalities:
                out = self._buffers[view] if modalities else None
                frames[view] = self.renderer.render(scene, view, modalities, out=out) if modalities \
                    else _camera_frames(scene, view)
            else:
                rendered = self.renderer.render(scene, view, modalities)
                for modality in modalities:
                    self._buffers[view][modality][index] = getattr(rendered, modality)
                frames[view] = rendered
        values = self.spec.metrics(self.core, index, scene, frames)
        for key, value in values.items():
            target = self.metrics.get(key)
            if target is None:
                target = self.metrics[key] = np.zeros(n, dtype=np.asarray(value).dtype)
            target[index] = value

    # ------------------------------------------------------------------ observations
    def observations(self, copy: bool = True) -> dict[str, np.ndarray]:
        """Every row's observation {key: (N, ...)}: fresh arrays (``copy``) or the buffers themselves."""
        self.refresh()
        out: dict[str, np.ndarray] = {}
        for view, prefix in self.spec.views:
            for modality in self.observed:
                array = self._buffers[view][modality]
                out[prefix + modality] = array.copy() if copy else array
        out["state"] = self.state.copy() if copy else self.state
        return out

    def observation(self, row: int) -> dict[str, np.ndarray]:
        """One row's observation {key: array}: fresh arrays."""
        return {key: value[row].copy() for key, value in self.observations(copy=False).items()}

    def info_row(self, row: int) -> dict[str, Any]:
        """One row's pixel metrics as numpy scalars (the single env's ``info`` entries)."""
        self.refresh()
        return {key: value[row] for key, value in self.metrics.items()}

    def info(self) -> dict[str, np.ndarray]:
        """Every row's pixel metrics {key: (N,) float64} (copies)."""
        self.refresh()
        return {key: value.copy() for key, value in self.metrics.items()}

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["renderer"] = None  # its caches are rebuilt on demand
        return state

    def __setstate__(self, state: dict) -> None:
        from continuum_gym.camera import Renderer

        self.__dict__.update(state)
        self.renderer = Renderer()


def _camera_frames(scene: Scene, view: str) -> Frames:
    """The cameras of a view without rendering it (a metric that only projects points needs no image)."""
    from continuum_gym.camera import Frames

    return Frames(None, None, None, scene.view(view).cameras)


def make_observer(core: Any) -> PixelObserver | None:
    """A ``PixelObserver`` of the core's configured ``obs_mode``, or None for ``"state"`` (``BatchedCore``'s hook)."""
    mode = getattr(core.config, "obs_mode", "state")
    return None if mode == "state" else PixelObserver(core)


def stack_rows(observations: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Dict observations of single rows as one batch {key: (len, ...)}."""
    return {key: np.stack([o[key] for o in observations]) for key in observations[0]}


# ---------------------------------------------------------------------- the true robot (model error)
def mismatch_groups(core: Any, rows: np.ndarray) -> list[tuple[np.ndarray, tuple[np.ndarray, np.ndarray] | None]]:
    """The rows grouped by their true robot: [(positions in ``rows``, (length scales, calibration) or None)].

    Without a model error there is one group of nominal rows (None). Under one, rows whose segment
    length scales and mounting calibration (``MismatchState.arrays``) are equal share a group, so each group's
    scene is one compiled call.
    """
    mismatch = getattr(core, "_mismatch", None)
    if mismatch is None:
        return [(np.arange(len(rows)), None)]
    scale, calib = mismatch.arrays.scale[rows], mismatch.arrays.calib[rows]
    keys = np.concatenate([scale, calib], axis=1)
    unique, inverse = np.unique(keys, axis=0, return_inverse=True)
    inverse = np.asarray(inverse).reshape(-1)
    groups = []
    for g in range(unique.shape[0]):
        members = np.flatnonzero(inverse == g)
        s, c = scale[members[0]], calib[members[0]]
        nominal = bool(np.all(s == 1.0) and np.all(c == 0.0))
        groups.append((members, None if nominal else (s, c)))
    return groups


def with_rows(scene: Scene, members: np.ndarray, a: np.ndarray, b: np.ndarray, u: np.ndarray,
              rotations: dict[str, tuple[np.ndarray, np.ndarray]]) -> Scene:
    """``scene`` with the tubes of rows ``members`` replaced by (a, b, u) and their cameras' poses by
    ``rotations`` {view: (p (m, 3), R (m, 3, 3))}: another robot (a model error's true one) in those rows."""
    from dataclasses import replace

    from continuum_gym.camera import Cameras, pose_matrix

    tubes = scene.tubes
    A, B, U = tubes.a.copy(), tubes.b.copy(), tubes.u.copy()
    A[members], B[members], U[members] = a, b, u
    views = {}
    for name, view in scene.views.items():
        cameras = view.cameras
        if name in rotations:
            poses = cameras.poses.copy()
            poses[members] = pose_matrix(*rotations[name])
            cameras = Cameras(cameras.intrinsics, poses, cameras.width, cameras.height, cameras.near, cameras.far,
                              cameras.k1)
        views[name] = replace(view, cameras=cameras)
    return replace(scene, tubes=replace(tubes, a=A, b=B, u=U), views=views)


def cameras(env: Any, view: str = "endoscope") -> Any:
    """Every row's camera of ``view`` at an env's current state: the public camera model (``camera.Cameras``).

    ``intrinsics`` (N, 3, 3) in pixels, ``poses`` (N, 4, 4) world-from-camera (OpenCV axes: z the optical axis,
    x image right, y image down), ``project(points)`` -> pixel coordinates (u, v) = (column, row), at the env's
    ``image_size`` (docs/rendering.md, "Camera conventions"). ``env``: any front end (or a core), in any
    ``obs_mode``; ``view``: ``"endoscope"``, or ViewTracking's ``"davinci"``.
    """
    inner = getattr(env, "unwrapped", env)
    core = getattr(inner, "core", inner)
    spec = pixel_spec(core.spec.env_id)
    height, width = image_shape(check_image_size(getattr(core.config, "image_size", DEFAULT_IMAGE_SIZE)))
    return spec.scene(core, np.arange(core.num_envs), height, width).view(view).cameras


# ---------------------------------------------------------------------- render_mode="rgb_array" of the endoscope cameras
#: Who draws ``render()``: the pybullet scene (every camera, overlays) or the batched renderer (endoscope cameras).
RENDERERS = ("pybullet", "fast")
#: ``render()``'s image side (pixels), the pybullet scenes' default.
RENDER_SIZE = 128


class FastRender:
    """``render()`` of an endoscope camera by the batched renderer: the rgb of the rows' true state, 128x128."""

    def __init__(self, core: Any, camera: str) -> None:
        from continuum_gym.camera import Renderer

        self.core, self.camera = core, camera
        self.spec = pixel_spec(core.spec.env_id)
        self.renderer = Renderer()

    def images(self, rows: Any = None) -> np.ndarray:
        """RGB images (len(rows), 128, 128, 3) uint8 of ``rows`` (None: all)."""
        index = np.arange(self.core.num_envs) if rows is None else np.asarray(rows, dtype=np.int64).reshape(-1)
        scene = self.spec.scene(self.core, index, RENDER_SIZE, RENDER_SIZE)
        rgb = self.renderer.render(scene, self.camera, ("rgb",)).rgb
        assert rgb is not None
        return rgb

    def __getstate__(self) -> dict:
        return {**self.__dict__, "renderer": None}

    def __setstate__(self, state: dict) -> None:
        from continuum_gym.camera import Renderer

        self.__dict__.update(state, renderer=Renderer())


def fast_render(core: Any, renderer: Any, camera: str) -> FastRender | None:
    """The batched renderer of ``render()`` for ``renderer="fast"`` (None for ``"pybullet"``), checked: it draws the
    endoscope cameras (``"endoscope"``, ViewTracking's ``"davinci"``) only."""
    choice(renderer, RENDERERS, "renderer")
    if renderer == "pybullet":
        return None
    views = tuple(view for view, _ in pixel_spec(core.spec.env_id).views)
    if camera not in views:
        raise ValueError(f"renderer='fast' draws the endoscope cameras {list(views)}; camera={camera!r} needs "
                         "renderer='pybullet' (the external view and the overlays are pybullet's)")
    return FastRender(core, camera)


__all__ = ["OBS_MODES", "MODE_MODALITIES", "OBSERVATION_KEYWORDS", "DEFAULT_IMAGE_SIZE", "MIN_IMAGE_SIDE",
           "MAX_IMAGE_SIDE", "STATE_LIMIT",
           "check_obs_mode", "check_image_size", "image_shape", "PixelSpec", "PIXEL_SPECS", "register_pixels",
           "pixel_spec", "observation_space", "PixelObserver", "make_observer", "stack_rows", "mismatch_groups",
           "with_rows", "cameras", "RENDERERS", "FastRender", "fast_render"]
