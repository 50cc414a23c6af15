"""The native vector env: a core of N rows behind ``gymnasium.vector.VectorEnv``, one compiled call per step.

Autoreset follows Gymnasium 1.x (``gymnasium.vector.AutoresetMode``):

* ``NEXT_STEP`` (default): a row that ended is reset by the next ``step``, which ignores its action
  and returns its first observation with reward 0 and ``terminated = truncated = False``;
* ``SAME_STEP``: a row that ends is reset inside the same ``step``; the observation returned is the
  new episode's first, the last one is in ``info["final_obs"]`` (an object array, ``None`` for rows
  that did not end; mask ``info["_final_obs"]``) and the last step's info in ``info["final_info"]``;
* ``DISABLED``: nothing is reset automatically; ``reset(options={"reset_mask": mask})`` resets the
  rows of ``mask``. A row that ended and was not reset is not stepped: its observation stays, its
  reward is 0 and its ``terminated``/``truncated`` stay True.

``info`` holds (N,) numpy arrays (and (N, k) for per-joint entries) with Gymnasium's ``_<key>``
masks; the weighted reward terms are ``reward_terms``, (N, n_terms), read by name. Row ``i`` of every entry equals the single
env's ``info[key]`` for the same state.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper

from continuum_gym.envs.batched import BatchedCore
from continuum_gym.envs.info import RewardTerms
from continuum_gym.envs.single import SceneOwner, check_reset_options
from continuum_gym.envs.stepping import check_actions
from continuum_gym.validation import describe, integer

if TYPE_CHECKING:
    import numpy.typing as npt
    from gymnasium import spaces

#: Keys ``reset(options=...)`` understands: task ids per row, and the rows to reset.
VECTOR_RESET_OPTIONS = ("task_ids", "reset_mask")


def row_generators(seed: Any, num_envs: int) -> list:
    """One generator per row, seeded like ``SyncVectorEnv``: seed + i, or each of a list of ints."""
    if seed is None:
        seeds: list[int | None] = [None] * num_envs
    elif isinstance(seed, (int, np.integer)) and not isinstance(seed, (bool, np.bool_)):
        seeds = [int(seed) + i for i in range(num_envs)]
    elif isinstance(seed, (list, tuple, np.ndarray)):
        seeds = [None if s is None else integer(s, "seed", low=0) for s in seed]
        if len(seeds) != num_envs:
            raise ValueError(f"seed must be an int or a list of {num_envs} ints (one per row); got {len(seeds)}")
    else:
        raise ValueError(f"seed must be None, an int >= 0 or a list of {num_envs} ints; got {describe(seed)}")
    if any(s is not None and s < 0 for s in seeds):
        raise ValueError(f"seed must be >= 0; got {seed!r}")
    return [seeding.np_random(s)[0] for s in seeds]


def autoreset_mode_of(value: Any) -> AutoresetMode:
    """An ``AutoresetMode`` from itself, its value or its name in any case ("NextStep", "same_step", "DISABLED")."""
    if isinstance(value, AutoresetMode):
        return value
    if isinstance(value, str):
        wanted = value.replace("_", "").lower()
        for mode in AutoresetMode:
            if wanted in (mode.name.replace("_", "").lower(), mode.value.lower()):
                return mode
    raise ValueError(f"autoreset_mode must be a gymnasium.vector.AutoresetMode or one of "
                     f"{[m.value for m in AutoresetMode]} (any case, e.g. 'same_step'); got {describe(value)}")


class ContinuumVectorEnv(SceneOwner, VectorEnv):
    """N robots as arrays, stepped by one compiled call (see the module docstring for autoreset and info)."""

    core_class: type = BatchedCore
    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 25,
                                "autoreset_mode": AutoresetMode.NEXT_STEP}
    single_action_space: spaces.Box  # the core's

    def __init__(self, num_envs: int = 1, max_episode_steps: int | None = None, render_mode: str | None = None,
                 camera: str = "external", pixel_occlusion: bool = False,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP, renderer: str = "pybullet",
                 **kwargs: Any) -> None:
        self.num_envs = integer(num_envs, "num_envs", low=1)
        if max_episode_steps is not None:  # else a given config's own limit stays
            kwargs["max_episode_steps"] = max_episode_steps
        self.core = self.core_class(num_envs=self.num_envs, **kwargs)
        self._check_render(self.metadata, render_mode, camera, pixel_occlusion, renderer)
        self.autoreset_mode = autoreset_mode_of(autoreset_mode)
        self.metadata = {**type(self).metadata, "autoreset_mode": self.autoreset_mode,
                         "render_fps": int(round(1.0 / self.core.control_dt))}
        self.single_observation_space = self.core.single_observation_space  # a Dict of images for an image obs_mode
        self.single_action_space = self.core.single_action_space
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, self.num_envs)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, self.num_envs)
        self._rngs = row_generators(None, self.num_envs)
        self._ended = np.zeros(self.num_envs, dtype=bool)
        self._last_terminated = np.zeros(self.num_envs, dtype=bool)  # DISABLED mode: flags of rows left ended
        self._last_truncated = np.zeros(self.num_envs, dtype=bool)
        self._needs_reset = True
        self._scene = None

    # ------------------------------------------------------------------ reset
    def reset(self, *, seed: Any = None, options: dict | None = None) -> tuple[Any, dict]:
        options = check_reset_options(options, VECTOR_RESET_OPTIONS)
        mask = options.get("reset_mask")
        if mask is None:
            rows = np.arange(self.num_envs)
        else:
            mask = np.asarray(mask)
            if mask.shape != (self.num_envs,) or mask.dtype != np.bool_:
                raise ValueError(f"options['reset_mask'] must be a bool array of shape ({self.num_envs},); got "
                                 f"{describe(options['reset_mask'])}")
            if self._needs_reset and not mask.all():
                raise ValueError("options['reset_mask'] must select every row at the first reset")
            rows = np.flatnonzero(mask)
        if seed is not None or not hasattr(self, "_seeded"):
            generators = row_generators(seed, self.num_envs)
            for row in rows:
                self._rngs[row] = generators[row]
            self._seeded = True
            if seed is not None:
                self.action_space.seed(int(np.asarray(seed).ravel()[0]))
        task_ids = options.get("task_ids")
        if task_ids is None:
            ids = np.array([self.core.sample_task_id(self._rngs[row]) for row in rows], dtype=np.int64)
        else:
            if mask is not None and np.ndim(task_ids) and len(task_ids) == self.num_envs:
                task_ids = np.asarray(task_ids, dtype=object)[rows]
            ids = self.core.check_task_ids(task_ids, len(rows), "options['task_ids']")
        self.core.reset_rows(rows, ids)
        self._ended[rows] = False
        self._last_terminated[rows] = False
        self._last_truncated[rows] = False
        self._needs_reset = False
        reset = np.zeros(self.num_envs, dtype=bool)
        reset[rows] = True
        return self.core.observations(), self._info(np.zeros(self.num_envs, dtype=bool), reset)

    # ------------------------------------------------------------------ step
    def step(self, actions: npt.ArrayLike) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict]:
        if self._needs_reset:
            raise gym.error.ResetNeeded("call reset() before step(): the vector env has not been reset")
        actions, clipped = check_actions(actions, (self.num_envs,) + self.single_action_space.shape, "actions")
        ended = self._ended.copy()
        stepping = ~ended if self.autoreset_mode != AutoresetMode.SAME_STEP else np.ones(self.num_envs, dtype=bool)
        rewards, terminated, truncated = self.core.step(actions, stepping.astype(np.uint8))
        rewards, terminated, truncated = rewards.copy(), terminated.copy(), truncated.copy()
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            return self._step_next(ended, rewards, terminated, truncated, clipped)
        if self.autoreset_mode == AutoresetMode.SAME_STEP:
            return self._step_same(rewards, terminated, truncated, clipped)
        rewards[ended] = 0.0  # DISABLED: rows that ended stay ended until reset_mask resets them
        terminated[ended] = self._last_terminated[ended]
        truncated[ended] = self._last_truncated[ended]
        self._last_terminated, self._last_truncated = terminated.copy(), truncated.copy()
        self._ended = terminated | truncated
        return self.core.observations(), rewards, terminated, truncated, self._info(clipped)

    def _step_next(self, ended, rewards, terminated, truncated, clipped):
        resetting = np.flatnonzero(ended)
        if len(resetting):
            ids = np.array([self.core.sample_task_id(self._rngs[i]) for i in resetting], dtype=np.int64)
            self.core.reset_rows(resetting, ids)
            rewards[resetting] = 0.0
            terminated[resetting] = False
            truncated[resetting] = False
        self._ended = terminated | truncated
        return self.core.observations(), rewards, terminated, truncated, self._info(clipped)

    def _step_same(self, rewards, terminated, truncated, clipped):
        ended = terminated | truncated
        obs = self.core.observations()
        if not ended.any():
            return obs, rewards, terminated, truncated, self._info(clipped)
        final_info = self._info(clipped, ended)
        final_obs = np.empty(self.num_envs, dtype=object)
        for row in np.flatnonzero(ended):
            final_obs[row] = self.core.observation(row)
        resetting = np.flatnonzero(ended)
        ids = np.array([self.core.sample_task_id(self._rngs[i]) for i in resetting], dtype=np.int64)
        self.core.reset_rows(resetting, ids)
        info = self._info(clipped)
        info.update(final_obs=final_obs, _final_obs=ended.copy(), final_info=final_info, _final_info=ended.copy())
        return self.core.observations(), rewards, terminated, truncated, info

    def _info(self, clipped: np.ndarray, mask: np.ndarray | None = None) -> dict:
        info = dict(self.core.info())
        info["reward_terms"] = self.core.reward_terms()
        info["action_clipped"] = np.asarray(clipped, dtype=bool)
        if self._pixel_occlusion:
            scene = self.scene()
            info["pixel_occlusion"] = np.array([self.core.pixel_occlusion(row, scene) for row in range(self.num_envs)])
        mask = np.ones(self.num_envs, dtype=bool) if mask is None else mask
        for key in list(info):
            info[f"_{key}"] = mask
        return info

    # ------------------------------------------------------------------ rendering
    def render(self) -> tuple[np.ndarray, ...] | None:
        """A tuple of one RGB image per row (``render_mode="rgb_array"``; about 10 ms per row)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' to make_vec()")
            return None
        return tuple(self.images(range(self.num_envs)))

    def close_extras(self, **kwargs: Any) -> None:
        self.close_scene()


class NamedRewardTerms(VectorWrapper):
    """Gives ``info["reward_terms"]`` back its term names behind Gymnasium's ``AsyncVectorEnv`` and
    ``SyncVectorEnv`` of single envs, which stack every info array into a plain (N, n_terms) array.

        envs = NamedRewardTerms(gym.make_vec(env_id, num_envs=8, vectorization_mode="async"))
        _, _, _, _, infos = envs.step(actions)
        infos["reward_terms"]["voi"]      # (8,), as from the library's own vector env

    The names are asked of the first worker once (``get_attr("reward_names")``): the workers of one
    vector env are made from the same id and keywords, so they share them.
    """

    _names: tuple[str, ...] | None = None

    def _named(self, infos: dict) -> dict:
        terms = infos.get("reward_terms")
        if terms is None or isinstance(terms, RewardTerms):
            return infos
        if self._names is None:
            self._names = tuple(self.env.get_attr("reward_names")[0])  # type: ignore[attr-defined]  # Sync/Async have it
        infos["reward_terms"] = RewardTerms(terms, self._names)
        return infos

    def step(self, actions: Any) -> tuple[Any, Any, Any, Any, dict]:
        obs, rewards, terminated, truncated, infos = self.env.step(actions)
        return obs, rewards, terminated, truncated, self._named(infos)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        obs, infos = self.env.reset(seed=seed, options=options)
        return obs, self._named(infos)


__all__ = ["ContinuumVectorEnv", "NamedRewardTerms", "row_generators", "autoreset_mode_of", "VECTOR_RESET_OPTIONS"]
