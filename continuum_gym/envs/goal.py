"""Goal-conditioned variants for hindsight relabelling (HER), in the Gymnasium-Robotics convention.

``ContinuumGym/OcclusionAvoidanceGoal-v0`` and ``ContinuumGym/ViewTrackingGoal-v0`` are the same
environments (same dynamics, tasks, residual action, keyword arguments) with a ``Dict`` observation
``{"observation", "achieved_goal", "desired_goal"}`` and a reward that is a function of the goals,
``compute_reward(achieved_goal, desired_goal, info)``, vectorised over any leading batch shape.

* OcclusionAvoidanceGoal: the goal is a tip pose ``[p (m, 3), rotation vector (rad, 3)]``: achieved
  the tip's, desired the task's at the current time. ``reward_type="dense"``: minus (position error
  in mm + orientation error in rad + VOI of the step); ``"sparse"``: 0 when within ``tolerance_m``
  (default 1 mm) and ``tolerance_rad`` (0.05 rad), else -1. VOI is a property of the state, read from
  ``info["voi"]``, so relabelled transitions keep it.
* ViewTrackingGoal: the goal is a camera pose ``[p (m, 3), rotation vector (rad, 3)]``: achieved the
  continuum endoscope's camera, desired the da Vinci's. The reward is the exact overlap ratio of the
  two view frustums (dense) or 0 when it exceeds ``or_threshold`` (0.8), else -1 (sparse).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from continuum_gym.validation import choice, fraction, positive

REWARD_TYPES = ("dense", "sparse")
GOAL_DIM = 6


def _pose_goal(p: np.ndarray, R: np.ndarray) -> np.ndarray:
    from continuum_gym.robots import rotation_vector

    return np.concatenate([p, rotation_vector(R)]).astype(np.float64)


def _split_goal(goal: Any, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(positions (..., 3), rotations (..., 3, 3)) of goals (..., 6)."""
    from scipy.spatial.transform import Rotation

    goal = np.asarray(goal, dtype=np.float64)
    if goal.shape[-1:] != (GOAL_DIM,):
        raise ValueError(f"{name} must have shape (..., {GOAL_DIM}) [position (m), rotation vector (rad)]; got "
                         f"{goal.shape}")
    flat = goal.reshape(-1, GOAL_DIM)
    rotations = Rotation.from_rotvec(flat[:, 3:]).as_matrix().reshape(goal.shape[:-1] + (3, 3))
    return goal[..., :3], rotations


def _info_values(info: Any, key: str, shape: tuple) -> np.ndarray:
    """``info[key]`` of one info dict, or of each of an array/list of them (HER passes a batch)."""
    if isinstance(info, dict):
        return np.broadcast_to(np.asarray(info[key], dtype=np.float64), shape)
    return np.array([item[key] for item in np.asarray(info, dtype=object).reshape(-1)], dtype=np.float64).reshape(shape)


class ContinuumGoalEnv(gym.Env):
    """A goal-conditioned front end of a ``ContinuumGym/`` env (subclasses set ``base_id``)."""

    base_id: str = ""
    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 25}

    def __init__(self, reward_type: str = "dense", render_mode: str | None = None, camera: str = "external",
                 **kwargs: Any) -> None:
        self.reward_type = choice(reward_type, REWARD_TYPES, "reward_type")
        self._check_goal_kwargs(kwargs)
        self.base = gym.make(self.base_id, render_mode=render_mode, camera=camera, **kwargs).unwrapped
        self.render_mode = render_mode
        self.metadata = self.base.metadata
        goal_space = spaces.Box(-np.inf, np.inf, (GOAL_DIM,), dtype=np.float64)
        self.observation_space = spaces.Dict({"observation": self.base.observation_space,
                                              "achieved_goal": goal_space, "desired_goal": goal_space})
        self.action_space = self.base.action_space

    def _check_goal_kwargs(self, kwargs: dict) -> None:  # pragma: no cover - overridden
        pass

    @property
    def core(self):
        return self.base.core

    def _observation(self, observation: np.ndarray) -> dict:
        achieved, desired = self.goals()
        return {"observation": observation, "achieved_goal": achieved, "desired_goal": desired}

    def goals(self) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - interface
        """(achieved_goal, desired_goal) of the current state, each (6,)."""
        raise NotImplementedError

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        observation, info = self.base.reset(seed=seed, options=options)
        return self._observation(observation), info

    def step(self, action):
        observation, _, terminated, truncated, info = self.base.step(action)
        goal_observation = self._observation(observation)
        reward = float(self.compute_reward(goal_observation["achieved_goal"], goal_observation["desired_goal"], info))
        return goal_observation, reward, terminated, truncated, info

    def render(self):
        return self.base.render()

    def close(self) -> None:
        self.base.close()


class OcclusionAvoidanceGoalEnv(ContinuumGoalEnv):
    __doc__ = __doc__
    base_id = "ContinuumGym/OcclusionAvoidance-v0"

    def __init__(self, reward_type: str = "dense", tolerance_m: float = 1e-3, tolerance_rad: float = 0.05,
                 **kwargs: Any) -> None:
        self.tolerance_m = positive(tolerance_m, "tolerance_m", "m")
        self.tolerance_rad = positive(tolerance_rad, "tolerance_rad", "rad")
        super().__init__(reward_type, **kwargs)

    def goals(self) -> tuple[np.ndarray, np.ndarray]:
        core = self.core
        p, R = core.robot.forward_kinematics(np.ascontiguousarray(core.q[0]))
        t = core.steps[0] * core.control_dt
        p_des, _ = core.desired(0, t)
        return _pose_goal(p, R), _pose_goal(p_des, core.desired_rotation(0, t))

    def compute_reward(self, achieved_goal: Any, desired_goal: Any, info: Any) -> np.ndarray:
        """Reward of (achieved, desired) goal pairs of any leading shape (see the module docstring)."""
        p_a, R_a = _split_goal(achieved_goal, "achieved_goal")
        p_d, R_d = _split_goal(desired_goal, "desired_goal")
        position = np.linalg.norm(p_a - p_d, axis=-1)
        relative = np.einsum("...ji,...jk->...ik", R_a, R_d)
        orientation = np.arccos(np.clip((np.trace(relative, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0))
        if self.reward_type == "sparse":
            return -((position > self.tolerance_m) | (orientation > self.tolerance_rad)).astype(np.float64)
        voi = _info_values(info, "voi", position.shape)
        return -(1e3 * position + orientation + voi)


class ViewTrackingGoalEnv(ContinuumGoalEnv):
    __doc__ = __doc__
    base_id = "ContinuumGym/ViewTracking-v0"

    def __init__(self, reward_type: str = "dense", or_threshold: float = 0.8, **kwargs: Any) -> None:
        self.or_threshold = fraction(or_threshold, "or_threshold")
        super().__init__(reward_type, **kwargs)

    def goals(self) -> tuple[np.ndarray, np.ndarray]:
        core = self.core
        p_cam, R_cam = core.robot.forward_kinematics(np.ascontiguousarray(core.q[0]))
        p_dv, R_dv = core.davinci.forward_kinematics(core.davinci_configuration(0))
        return _pose_goal(p_cam, R_cam), _pose_goal(p_dv, R_dv)

    def compute_reward(self, achieved_goal: Any, desired_goal: Any, info: Any) -> np.ndarray:
        """Overlap ratio (dense) or its threshold indicator (sparse) of camera-pose goal pairs, batched."""
        from continuum_gym.geometry import overlap_ratio

        p_a, R_a = _split_goal(achieved_goal, "achieved_goal")
        p_d, R_d = _split_goal(desired_goal, "desired_goal")
        ratio = np.asarray(overlap_ratio(p_d, R_d, p_a, R_a, self.core.frustum), dtype=np.float64)
        if self.reward_type == "sparse":
            return -(ratio <= self.or_threshold).astype(np.float64)
        return ratio


GOAL_ENVS = {"ContinuumGym/OcclusionAvoidanceGoal-v0": "continuum_gym.envs.goal:OcclusionAvoidanceGoalEnv",
             "ContinuumGym/ViewTrackingGoal-v0": "continuum_gym.envs.goal:ViewTrackingGoalEnv"}
