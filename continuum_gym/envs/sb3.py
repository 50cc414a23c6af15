"""A stable-baselines3 ``VecEnv`` backed by the native batched core (same-step reset, SB3's convention).

SB3 resets a finished row inside ``step`` and returns the new episode's first observation, with the
last one in ``infos[i]["terminal_observation"]`` and ``infos[i]["TimeLimit.truncated"]``
(``common/vec_env/dummy_vec_env.py``). Gymnasium's vector env resets on the *next* step instead, so
this adapter drives the core directly rather than wrapping the Gymnasium vector env.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

from continuum_gym.envs.batched import check_actions, row_generators
from continuum_gym.envs.spec import get_spec, registered_kwargs


def core_class(env_id: str) -> type:
    """The batched core class behind ``env_id`` (any id registered to the library's entry points)."""
    return get_spec(env_id).core_class()


class ContinuumSB3VecEnv(VecEnv):
    """N environments of ``env_id`` in one process, stepped by one compiled call.

    Args:
        env_id: a ``ContinuumGym/`` id.
        num_envs: batch size.
        seed: row i is seeded with seed + i (as ``SyncVectorEnv``/``DummyVecEnv`` would seed it).
        **kwargs: the environment's keyword arguments (task, task_split, base_controller, ...).
    """

    def __init__(self, env_id: str, num_envs: int, seed=None, **kwargs):
        self.env_id = env_id
        self.env_kwargs = {**registered_kwargs(env_id), **kwargs}
        self.core = core_class(env_id)(num_envs=num_envs, **self.env_kwargs)
        self.render_mode = None
        super().__init__(num_envs, self.core.single_observation_space, self.core.single_action_space)
        self._rngs = row_generators(seed, num_envs)
        self._actions = None

    # ------------------------------------------------------------------ VecEnv API
    def reset(self):
        if self._seeds[0] is not None:
            self._rngs = row_generators(self._seeds, self.num_envs)
            self._reset_seeds()
        ids = np.array([self.core.sample_task_id(rng) for rng in self._rngs])
        self.core.reset_rows(np.arange(self.num_envs), ids)
        return self.core.obs.astype(np.float32)

    def step_async(self, actions):
        self._actions = actions

    def step_wait(self):
        actions, clipped = check_actions(np.asarray(self._actions).reshape(self.num_envs, -1),
                                         (self.num_envs,) + self.action_space.shape, "actions")
        rewards, terminated, truncated = self.core.step(actions, np.ones(self.num_envs, dtype=np.uint8))
        rewards = rewards.astype(np.float32)
        dones = terminated | truncated
        obs = self.core.obs.astype(np.float32)
        metrics = self.core.info()
        infos = []
        for i in range(self.num_envs):
            info = {key: value[i] for key, value in metrics.items() if value.ndim == 1}
            info["action_clipped"] = bool(clipped[i])
            if dones[i]:
                info["terminal_observation"] = obs[i].copy()
                info["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            infos.append(info)
        finished = np.flatnonzero(dones)
        if len(finished):
            ids = np.array([self.core.sample_task_id(self._rngs[i]) for i in finished])
            self.core.reset_rows(finished, ids)
            obs[finished] = self.core.obs[finished]
        return obs, rewards, dones, infos

    def close(self):
        pass

    def get_attr(self, attr_name, indices=None):
        owner = self.core if hasattr(self.core, attr_name) else self
        return [getattr(owner, attr_name) for _ in self._indices(indices)]

    def set_attr(self, attr_name, value, indices=None):
        setattr(self.core, attr_name, value)

    def env_method(self, method_name, *method_args, indices=None, **method_kwargs):
        return [getattr(self.core, method_name)(*method_args, **method_kwargs) for _ in self._indices(indices)]

    def env_is_wrapped(self, wrapper_class, indices=None):
        return [False for _ in self._indices(indices)]

    def _indices(self, indices):
        if indices is None:
            return range(self.num_envs)
        if isinstance(indices, int):
            return [indices]
        return indices

    def get_images(self):
        return [None] * self.num_envs


def make_env(env_id: str, **kwargs) -> gym.Env:
    """``gymnasium.make`` after registering the ids (for SB3's ``make_vec_env`` and rl-zoo)."""
    import continuum_gym  # noqa: F401  (registers the ids)

    return gym.make(env_id, **kwargs)
