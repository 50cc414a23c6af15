"""A batched core of one behind ``gymnasium.Env``.

``info`` has the same entries as the native vector env's, one row of them: numpy scalars (float64,
bool_, int64) and arrays, the weighted reward terms as one named array ``reward_terms`` (their sum is
the reward), and ``action_clipped``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np

from continuum_gym.envs.batched import BatchedCore
from continuum_gym.envs.pixels import fast_render
from continuum_gym.envs.stepping import check_actions
from continuum_gym.validation import boolean, choice

if TYPE_CHECKING:
    import numpy.typing as npt
    from gymnasium import spaces

    from continuum_gym.envs.config import EnvConfig
    from continuum_gym.envs.pixels import FastRender
    from continuum_gym.envs.scenes import RowScene

#: Keys ``reset(options=...)`` understands.
RESET_OPTIONS = ("task_id",)


def check_reset_options(options: Any, valid: tuple) -> dict:
    """``options`` as a dict whose keys are all in ``valid``; a named error otherwise."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise ValueError(f"options must be a dict with keys from {list(valid)}; got {type(options).__name__}")
    unknown = sorted(set(options) - set(valid))
    if unknown:
        raise ValueError(f"options has unknown key(s) {unknown}; valid keys: {list(valid)}")
    return options


def check_render_arguments(metadata: dict, core: BatchedCore, render_mode: Any, camera: Any,
                           pixel_occlusion: Any) -> tuple:
    """(render_mode, camera, pixel_occlusion) checked against the env's render modes and cameras."""
    if render_mode is not None:
        choice(render_mode, metadata["render_modes"], "render_mode")
        if not core.spec.scene:
            raise ValueError(f"render_mode={render_mode!r}: {core.spec.env_id} has no scene to draw (its EnvSpec "
                             "names none); make it without render_mode")
    if core.spec.cameras or camera != "external":
        choice(camera, core.spec.cameras, "camera")
    pixel_occlusion = boolean(pixel_occlusion, "pixel_occlusion")
    if pixel_occlusion and not core.supports_pixel_occlusion:
        raise ValueError(f"pixel_occlusion=True applies to environments with a view cone to occlude "
                         f"(OcclusionAvoidance), not to {core.spec.env_id}")
    return render_mode, camera, pixel_occlusion


class CoreOwner:
    """A front end of a batched core: ``config`` is the core's validated configuration."""

    core: BatchedCore  #: set by the front end's constructor

    @property
    def config(self) -> EnvConfig:
        """The env's ``EnvConfig`` (every keyword, validated; ``continuum_gym.save_config`` writes it)."""
        return self.core.config

    @property
    def reward_names(self) -> tuple[str, ...]:
        """Names of the weighted reward terms, in ``info["reward_terms"]`` column order."""
        return tuple(self.core.reward_names)


class SceneOwner(CoreOwner):
    """What draws ``render()``: the pybullet scene of an env's core (built on first use, released by
    ``close_scene()``, never pickled) or, with ``renderer="fast"``, the batched renderer (``envs/pixels.py``)."""

    _scene: RowScene | None = None
    _fast: FastRender | None = None
    render_mode: str | None
    camera: str
    _pixel_occlusion: bool

    def _check_render(self, metadata: dict, render_mode: Any, camera: Any, pixel_occlusion: Any,
                      renderer: Any) -> None:
        """Set ``render_mode``, ``camera``, the pixel occlusion and the renderer from the front end's keywords."""
        self.render_mode, self.camera, self._pixel_occlusion = check_render_arguments(
            metadata, self.core, render_mode, camera, pixel_occlusion)
        self._fast = fast_render(self.core, renderer, self.camera)  # the batched renderer, or None: pybullet

    def images(self, rows: Any) -> list[np.ndarray]:
        """RGB images of ``rows`` through ``camera``: the batched renderer's (one call) or the pybullet scene's."""
        if self._fast is not None:
            return list(self._fast.images(rows))
        scene = self.scene()
        return [self.core.render_row(row, scene, self.camera) for row in rows]

    def scene(self) -> RowScene:
        """The pybullet scene that renders this env's rows (built on first use; ``close()`` releases it)."""
        if self._scene is None:
            self._scene = self.core.make_scene()
        return self._scene

    def close_scene(self) -> None:
        if self._scene is not None:
            self._scene.close()
            self._scene = None

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_scene"] = None  # pybullet clients do not pickle; rebuilt on demand
        return state


class ContinuumEnv(SceneOwner, gym.Env):
    """A core of one behind ``gymnasium.Env`` (subclasses set ``core_class`` and the docstring)."""

    core_class: type = BatchedCore
    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 25}
    action_space: spaces.Box  # the core's single_action_space

    def __init__(self, render_mode: str | None = None, camera: str = "external", pixel_occlusion: bool = False,
                 renderer: str = "pybullet", **kwargs: Any) -> None:
        self.core = self.core_class(num_envs=1, **kwargs)
        self._check_render(self.metadata, render_mode, camera, pixel_occlusion, renderer)
        self.observation_space = self.core.single_observation_space  # a Dict of images for an image obs_mode
        self.action_space = self.core.single_action_space
        self.metadata = {**type(self).metadata, "render_fps": int(round(1.0 / self.core.control_dt))}
        self._scene = None
        self._needs_reset = True
        self._active = np.ones(1, dtype=np.uint8)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[Any, dict]:
        super().reset(seed=seed)
        options = check_reset_options(options, RESET_OPTIONS)
        task_id = options.get("task_id")
        if task_id is None:
            task_id = self.core.sample_task_id(self.np_random)
        self.core.reset_rows(np.array([0]), self.core.check_task_ids(task_id, 1, "options['task_id']"))
        self._needs_reset = False
        return self.core.observation(0), self._info(clipped=False)

    def step(self, action: npt.ArrayLike) -> tuple[Any, float, bool, bool, dict]:
        if self._needs_reset:
            raise gym.error.ResetNeeded("call reset() before step(): the episode has ended or never started")
        action, clipped = check_actions(action, self.action_space.shape)
        rewards, terminated, truncated = self.core.step(action, self._active)
        self._needs_reset = bool(terminated[0] or truncated[0])
        return (self.core.observation(0), float(rewards[0]), bool(terminated[0]), bool(truncated[0]),
                self._info(clipped=bool(clipped[0])))

    @property
    def episode_steps(self) -> int:
        """Control steps the current episode lasts unless it terminates earlier (its task's duration)."""
        return int(self.core.limit[0])

    def _info(self, clipped: bool) -> dict:
        info = self.core.info_row(0)
        info["reward_terms"] = self.core.reward_terms_row(0)
        info["action_clipped"] = np.bool_(clipped)
        if self._pixel_occlusion:
            info["pixel_occlusion"] = np.float64(self.core.pixel_occlusion(0, self.scene()))
        return info

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' to make()")
            return None
        return self.images([0])[0]

    def close(self) -> None:
        self.close_scene()
