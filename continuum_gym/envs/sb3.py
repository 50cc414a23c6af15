"""A stable-baselines3 ``VecEnv`` backed by the native batched core (same-step reset, SB3's convention).

SB3 resets a finished row inside ``step`` and returns the new episode's first observation, with the
last one in ``infos[i]["terminal_observation"]`` and ``infos[i]["TimeLimit.truncated"]``
(``common/vec_env/dummy_vec_env.py``). Gymnasium's vector env resets on the *next* step instead, so
this adapter drives the core directly rather than wrapping the Gymnasium vector env.
"""

from __future__ import annotations

import inspect
import time
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

from continuum_gym.envs.single import SceneOwner
from continuum_gym.envs.spec import get_spec, registered_kwargs
from continuum_gym.envs.stepping import check_actions
from continuum_gym.envs.vector import row_generators
from continuum_gym.validation import integer

if TYPE_CHECKING:
    from collections.abc import Sequence

    import numpy.typing as npt
    from gymnasium import spaces
    from gymnasium.envs.registration import EnvSpec as GymEnvSpec
    from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvObs, VecEnvStepReturn



def core_class(env_id: str) -> type:
    """The batched core class behind ``env_id`` (any id registered to the library's entry points)."""
    return get_spec(env_id).core_class()


class ContinuumSB3VecEnv(SceneOwner, VecEnv):
    """N environments of ``env_id`` in one process, stepped by one compiled call.

    Each row's ``info`` holds what ``DummyVecEnv`` over ``gym.make(env_id)`` wrapped in SB3's
    ``Monitor`` would give: the env's info entries (numpy scalars and arrays, ``reward_terms``,
    ``action_clipped``), and at the end of an episode ``terminal_observation``,
    ``TimeLimit.truncated`` and ``episode = {"r": return, "l": length, "t": seconds since start}``.

    Args:
        env_id: a ``ContinuumGym/`` id, or any id registered to the library's entry points (its
            registered kwargs are the defaults).
        num_envs: batch size (>= 1).
        seed: row i is seeded with seed + i (as ``SyncVectorEnv``/``DummyVecEnv`` would seed it).
        render_mode: ``"rgb_array"`` for ``render()``/``get_images()`` (e.g. ``VecVideoRecorder``).
        camera: the camera those images are taken from.
        helpers: names of the env's helpers that act on the (clipped) actions before each step
            (``envs/helpers.py``), as ``train``'s ``helpers`` key and ``evaluate`` apply them.
        renderer: ``"pybullet"`` (default) or ``"fast"`` (the batched renderer: endoscope cameras only).
        **kwargs: the environment's keyword arguments (task, task_split, base_controller, ...).
    """

    action_space: spaces.Box  # the core's single_action_space
    metadata: dict[str, Any]

    def __init__(self, env_id: str, num_envs: int, seed: Any = None, render_mode: str | None = None,
                 camera: str = "external", renderer: str = "pybullet", helpers: Any = (), **kwargs: Any) -> None:
        from continuum_gym.envs.helpers import check_helpers, make_helpers

        self.env_id = env_id
        self.env_kwargs = {**registered_kwargs(env_id), **kwargs}
        num_envs = integer(num_envs, "num_envs", low=1)
        self.helper_names = check_helpers(env_id, helpers)
        self.core = core_class(env_id)(num_envs=num_envs, **self.env_kwargs)
        self._helpers = make_helpers(env_id, self.helper_names, self.core.config)
        self._all_rows = np.ones(num_envs, dtype=np.uint8)
        self._check_render({"render_modes": ["rgb_array"]}, render_mode, camera, False, renderer)
        # the core's observation space: a Dict of images for an image obs_mode
        super().__init__(num_envs, self.core.single_observation_space, self.core.single_action_space)
        self.spec = _gym_spec(env_id)
        self.metadata = {**self.metadata, "render_fps": int(round(1.0 / self.core.control_dt))}
        self._rngs = row_generators(seed, num_envs)
        self._actions: npt.ArrayLike | None = None
        self._returns = np.zeros(num_envs)
        self._lengths = np.zeros(num_envs, dtype=np.int64)
        self._started = time.time()

    # ------------------------------------------------------------------ VecEnv API
    def reset(self) -> VecEnvObs:
        if self._seeds[0] is not None:
            self._rngs = row_generators(self._seeds, self.num_envs)
            self._reset_seeds()
        ids = np.array([self.core.sample_task_id(rng) for rng in self._rngs])
        self.core.reset_rows(np.arange(self.num_envs), ids)
        self._returns[:] = 0.0
        self._lengths[:] = 0
        return self.core.observations()

    def step_async(self, actions: np.ndarray) -> None:
        shape = (self.num_envs,) + self.action_space.shape
        if np.shape(actions) != shape:  # never reshape: (2, 16) for (4, 8) would scramble the rows
            raise ValueError(f"actions must have shape {shape} (num_envs, action dim); got {np.shape(actions)}")
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        actions, clipped = check_actions(self._actions, (self.num_envs,) + self.action_space.shape, "actions")
        if self._helpers:
            from continuum_gym.envs.helpers import apply_helpers

            # in the policy's dtype, as evaluation applies them (a float32 policy's polished actions are float32)
            given = np.asarray(self._actions).dtype
            actions = apply_helpers(self._helpers, self.core.obs, actions.astype(given if given.kind == "f" else
                                                                                 actions.dtype), self._all_rows)
        rewards, terminated, truncated = self.core.step(actions, self._all_rows)
        self._returns += rewards
        self._lengths += 1
        rewards = rewards.astype(np.float32)
        dones = terminated | truncated
        obs = self.core.observations()
        batch = dict(self.core.info())
        batch["reward_terms"] = self.core.reward_terms()
        batch["action_clipped"] = clipped
        infos = []
        for i in range(self.num_envs):
            info = {key: value[i].copy() if value.ndim > 1 else value[i] for key, value in batch.items()}
            if dones[i]:
                info["terminal_observation"] = self.core.observation(i)
                info["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
                info["episode"] = {"r": float(self._returns[i]), "l": int(self._lengths[i]),
                                   "t": round(time.time() - self._started, 6)}
            infos.append(info)
        finished = np.flatnonzero(dones)
        if len(finished):
            ids = np.array([self.core.sample_task_id(self._rngs[i]) for i in finished])
            self.core.reset_rows(finished, ids)
            obs = self.core.observations()
            self._returns[finished] = 0.0
            self._lengths[finished] = 0
        return obs, rewards, dones, infos

    def close(self) -> None:
        self.close_scene()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        owner = self.core if hasattr(self.core, attr_name) else self
        return [getattr(owner, attr_name) for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set an attribute of the core; its rows share it, so ``indices`` must select every row."""
        if sorted(self._indices(indices)) != list(range(self.num_envs)):
            raise ValueError(f"set_attr({attr_name!r}): the {self.num_envs} rows share one batched core, so the "
                             f"attribute can only be set for all of them (indices=None); got indices={indices!r}")
        setattr(self.core, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None,
                   **method_kwargs: Any) -> list[Any]:
        """Call a core method: per row (its first parameter is ``row``) or once for all rows."""
        method = getattr(self.core, method_name)
        rows = list(self._indices(indices))
        parameters = list(inspect.signature(method).parameters)
        if parameters and parameters[0] == "row":
            return [method(row, *method_args, **method_kwargs) for row in rows]
        if sorted(rows) != list(range(self.num_envs)):
            raise ValueError(f"env_method({method_name!r}) acts on the shared batched core: call it for all rows "
                             f"(indices=None); got indices={indices!r}")
        result = method(*method_args, **method_kwargs)
        return [result for _ in rows]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._indices(indices)]

    def _indices(self, indices: VecEnvIndices) -> Sequence[int]:
        if indices is None:
            return range(self.num_envs)
        rows = [indices] if isinstance(indices, (int, np.integer)) else list(indices)
        for row in rows:
            integer(row, "indices", low=0, high=self.num_envs - 1)
        return [int(row) for row in rows]

    def get_images(self) -> Sequence[np.ndarray | None]:
        """One RGB image per row (``render_mode="rgb_array"``), else Nones."""
        if self.render_mode is None:
            return [None] * self.num_envs
        return self.images(range(self.num_envs))


def _gym_spec(env_id: str) -> GymEnvSpec | None:
    from gymnasium.envs.registration import registry

    return registry.get(env_id)


def make_env(env_id: str, **kwargs: Any) -> gym.Env:
    """``gymnasium.make`` after registering the ids (for SB3's ``make_vec_env`` and rl-zoo)."""
    import continuum_gym  # noqa: F401  (registers the ids)

    return gym.make(env_id, **kwargs)
