"""Goal-conditioned variants for hindsight relabelling (HER), in the Gymnasium-Robotics convention.

``ContinuumGym/OcclusionAvoidanceGoal-v0`` and ``ContinuumGym/ViewTrackingGoal-v0`` are the same
environments (same dynamics, tasks, residual action, keyword arguments) with a ``Dict`` observation
``{"observation", "achieved_goal", "desired_goal"}`` and a reward that is a function of the goals,
``compute_reward(achieved_goal, desired_goal, info)``, vectorised over any leading batch shape.

* OcclusionAvoidanceGoal: the goal is a tip pose and an occlusion ``[p (m, 3), rotation vector (rad, 3),
  VOI]``: achieved the tip's pose and the VOI of the state, desired the task's pose at the current time
  and VOI 0. ``reward_type="dense"``: minus (position error in mm + orientation error in rad + the
  achieved VOI); ``"sparse"``: 0 when within ``tolerance_m`` (default 1 mm) and ``tolerance_rad``
  (0.05 rad), else -1. VOI is a property of the state that a pose does not determine, so the achieved
  goal carries it: relabelled transitions keep it, and ``compute_reward`` needs no ``info`` (SB3's
  ``HerReplayBuffer`` passes empty ones unless ``copy_info_dict=True``). The desired VOI is not scored.
* ViewTrackingGoal: the goal is a camera pose ``[p (m, 3), rotation vector (rad, 3)]``: achieved the
  continuum endoscope's camera, desired the da Vinci's. The reward is the exact overlap ratio of the
  two view frustums (dense) or 0 when it exceeds ``or_threshold`` (0.8), else -1 (sparse).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from continuum_gym.validation import choice

if TYPE_CHECKING:
    import numpy.typing as npt

    from continuum_gym.envs.batched import BatchedCore
    from continuum_gym.envs.config import EnvConfig
    from continuum_gym.envs.single import ContinuumEnv

REWARD_TYPES = ("dense", "sparse")
GOAL_DIM = 6  #: a pose: position (m, 3) and rotation vector (rad, 3)


def pose_goal(p: np.ndarray, R: np.ndarray) -> np.ndarray:
    from continuum_gym.robots import rotation_vector

    return np.concatenate([p, rotation_vector(R)]).astype(np.float64)


def split_goal(goal: Any, name: str, size: int = GOAL_DIM, layout: str = "position (m), rotation vector (rad)"
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(positions (..., 3), rotations (..., 3, 3), the goal array) of goals (..., size) that start with a pose."""
    from scipy.spatial.transform import Rotation

    goal = np.asarray(goal, dtype=np.float64)
    if goal.shape[-1:] != (size,):
        raise ValueError(f"{name} must have shape (..., {size}) [{layout}]; got {goal.shape}")
    flat = goal[..., :GOAL_DIM].reshape(-1, GOAL_DIM)
    rotations = Rotation.from_rotvec(flat[:, 3:]).as_matrix().reshape(goal.shape[:-1] + (3, 3))
    return goal[..., :3], rotations, goal


class ContinuumGoalEnv(gym.Env):
    """A goal-conditioned front end of a ``ContinuumGym/`` env (subclasses set ``base_id``)."""

    base_id: str = ""  #: the id of the env this is the goal-conditioned front end of
    #: the front end's own keywords (not the env's config): ``goal_kwargs()`` reads them back as attributes
    goal_keywords: tuple[str, ...] = ("reward_type",)
    goal_dim: int = GOAL_DIM
    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 25}

    if TYPE_CHECKING:  # defined by every subclass
        def compute_reward(self, achieved_goal: Any, desired_goal: Any, info: Any) -> np.ndarray: ...

    def __init__(self, reward_type: str = "dense", render_mode: str | None = None, camera: str = "external",
                 **kwargs: Any) -> None:
        self.reward_type = choice(reward_type, REWARD_TYPES, "reward_type")
        self._check_goal_kwargs(kwargs)
        self.base = cast("ContinuumEnv",
                         gym.make(self.base_id, render_mode=render_mode, camera=camera, **kwargs).unwrapped)
        self.render_mode = render_mode
        self.metadata = self.base.metadata
        goal_space = spaces.Box(-np.inf, np.inf, (self.goal_dim,), dtype=np.float64)
        base_space = self.base.observation_space
        # an image obs_mode (envs/pixels.py): the images beside the goals, the measured state as "observation"
        # (one flat Dict: SB3's HER buffer takes no nested spaces)
        images = dict(base_space.spaces) if isinstance(base_space, spaces.Dict) else {}
        observed = images.pop("state") if images else base_space
        self.observation_space = spaces.Dict({"observation": observed, **images,
                                              "achieved_goal": goal_space, "desired_goal": goal_space})
        self.action_space = self.base.action_space

    def goal_kwargs(self) -> dict:
        """The keywords of this front end itself (reward type, tolerances), to make it again (``save_config``)."""
        return {name: getattr(self, name) for name in self.goal_keywords}

    def _check_goal_kwargs(self, kwargs: dict) -> None:  # pragma: no cover - overridden
        pass

    @property
    def core(self) -> BatchedCore:
        return self.base.core

    @property
    def config(self) -> EnvConfig:
        """The base env's ``EnvConfig`` (``continuum_gym.save_config`` writes it)."""
        return self.base.core.config

    def _observation(self, observation: Any, info: dict) -> dict:
        achieved, desired = self.goals(info)
        if isinstance(observation, dict):  # images and the measured state
            images = {key: value for key, value in observation.items() if key != "state"}
            return {"observation": observation["state"], **images, "achieved_goal": achieved, "desired_goal": desired}
        return {"observation": observation, "achieved_goal": achieved, "desired_goal": desired}

    def goals(self, info: dict) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - interface
        """(achieved_goal, desired_goal) of the current state (``info``: the base env's), each (goal_dim,)."""
        raise NotImplementedError

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict[str, np.ndarray], dict]:
        super().reset(seed=seed)
        observation, info = self.base.reset(seed=seed, options=options)
        return self._observation(observation, info), info

    def step(self, action: npt.ArrayLike) -> tuple[dict[str, np.ndarray], float, bool, bool, dict]:
        observation, _, terminated, truncated, info = self.base.step(action)
        goal_observation = self._observation(observation, info)
        reward = float(self.compute_reward(goal_observation["achieved_goal"], goal_observation["desired_goal"], info))
        return goal_observation, reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        return self.base.render()

    def close(self) -> None:
        self.base.close()


__all__ = ["ContinuumGoalEnv", "REWARD_TYPES", "GOAL_DIM", "pose_goal", "split_goal"]
