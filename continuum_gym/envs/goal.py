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

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from continuum_gym.validation import choice, fraction, positive

REWARD_TYPES = ("dense", "sparse")
GOAL_DIM = 6  #: a pose: position (m, 3) and rotation vector (rad, 3)


def _pose_goal(p: np.ndarray, R: np.ndarray) -> np.ndarray:
    from continuum_gym.robots import rotation_vector

    return np.concatenate([p, rotation_vector(R)]).astype(np.float64)


def _split_goal(goal: Any, name: str, size: int = GOAL_DIM, layout: str = "position (m), rotation vector (rad)"):
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

    base_id: str = ""
    goal_dim: int = GOAL_DIM
    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 25}

    def __init__(self, reward_type: str = "dense", render_mode: str | None = None, camera: str = "external",
                 **kwargs: Any) -> None:
        self.reward_type = choice(reward_type, REWARD_TYPES, "reward_type")
        self._check_goal_kwargs(kwargs)
        self.base = gym.make(self.base_id, render_mode=render_mode, camera=camera, **kwargs).unwrapped
        self.render_mode = render_mode
        self.metadata = self.base.metadata
        goal_space = spaces.Box(-np.inf, np.inf, (self.goal_dim,), dtype=np.float64)
        self.observation_space = spaces.Dict({"observation": self.base.observation_space,
                                              "achieved_goal": goal_space, "desired_goal": goal_space})
        self.action_space = self.base.action_space

    def _check_goal_kwargs(self, kwargs: dict) -> None:  # pragma: no cover - overridden
        pass

    @property
    def core(self):
        return self.base.core

    @property
    def config(self):
        """The base env's ``EnvConfig`` (``continuum_gym.save_config`` writes it)."""
        return self.base.core.config

    def _observation(self, observation: np.ndarray, info: dict) -> dict:
        achieved, desired = self.goals(info)
        return {"observation": observation, "achieved_goal": achieved, "desired_goal": desired}

    def goals(self, info: dict) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - interface
        """(achieved_goal, desired_goal) of the current state (``info``: the base env's), each (goal_dim,)."""
        raise NotImplementedError

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        observation, info = self.base.reset(seed=seed, options=options)
        return self._observation(observation, info), info

    def step(self, action):
        observation, _, terminated, truncated, info = self.base.step(action)
        goal_observation = self._observation(observation, info)
        reward = float(self.compute_reward(goal_observation["achieved_goal"], goal_observation["desired_goal"], info))
        return goal_observation, reward, terminated, truncated, info

    def render(self):
        return self.base.render()

    def close(self) -> None:
        self.base.close()


class OcclusionAvoidanceGoalEnv(ContinuumGoalEnv):
    __doc__ = __doc__
    base_id = "ContinuumGym/OcclusionAvoidance-v0"
    goal_dim = GOAL_DIM + 1  # the pose and the state's VOI

    def __init__(self, reward_type: str = "dense", tolerance_m: float = 1e-3, tolerance_rad: float = 0.05,
                 **kwargs: Any) -> None:
        self.tolerance_m = positive(tolerance_m, "tolerance_m", "m")
        self.tolerance_rad = positive(tolerance_rad, "tolerance_rad", "rad")
        super().__init__(reward_type, **kwargs)

    def goals(self, info: dict) -> tuple[np.ndarray, np.ndarray]:
        core = self.core
        p, R = core.robot.forward_kinematics(np.ascontiguousarray(core.q[0]))
        t = core.steps[0] * core.control_dt
        p_des, _ = core.desired(0, t)
        return (np.append(_pose_goal(p, R), float(info["voi"])),
                np.append(_pose_goal(p_des, core.desired_rotation(0, t)), 0.0))

    def compute_reward(self, achieved_goal: Any, desired_goal: Any, info: Any) -> np.ndarray:
        """Reward of (achieved, desired) goal pairs of any leading shape (see the module docstring)."""
        layout = "position (m), rotation vector (rad), VOI"
        p_a, R_a, achieved = _split_goal(achieved_goal, "achieved_goal", self.goal_dim, layout)
        p_d, R_d, _ = _split_goal(desired_goal, "desired_goal", self.goal_dim, layout)
        position = np.linalg.norm(p_a - p_d, axis=-1)
        relative = np.einsum("...ji,...jk->...ik", R_a, R_d)
        orientation = np.arccos(np.clip((np.trace(relative, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0))
        if self.reward_type == "sparse":
            return -((position > self.tolerance_m) | (orientation > self.tolerance_rad)).astype(np.float64)
        return -(1e3 * position + orientation + achieved[..., GOAL_DIM])


class ViewTrackingGoalEnv(ContinuumGoalEnv):
    __doc__ = __doc__
    base_id = "ContinuumGym/ViewTracking-v0"

    def __init__(self, reward_type: str = "dense", or_threshold: float = 0.8, **kwargs: Any) -> None:
        self.or_threshold = fraction(or_threshold, "or_threshold")
        super().__init__(reward_type, **kwargs)

    def goals(self, info: dict) -> tuple[np.ndarray, np.ndarray]:
        core = self.core
        p_cam, R_cam = core.robot.forward_kinematics(np.ascontiguousarray(core.q[0]))
        p_dv, R_dv = core.davinci.forward_kinematics(core.davinci_configuration(0))
        return _pose_goal(p_cam, R_cam), _pose_goal(p_dv, R_dv)

    def compute_reward(self, achieved_goal: Any, desired_goal: Any, info: Any) -> np.ndarray:
        """Overlap ratio (dense) or its threshold indicator (sparse) of camera-pose goal pairs, batched."""
        from continuum_gym.geometry import overlap_ratio

        p_a, R_a, _ = _split_goal(achieved_goal, "achieved_goal")
        p_d, R_d, _ = _split_goal(desired_goal, "desired_goal")
        ratio = np.asarray(overlap_ratio(p_d, R_d, p_a, R_a, self.core.frustum), dtype=np.float64)
        if self.reward_type == "sparse":
            return -(ratio <= self.or_threshold).astype(np.float64)
        return ratio


GOAL_ENVS = {"ContinuumGym/OcclusionAvoidanceGoal-v0": "continuum_gym.envs.goal:OcclusionAvoidanceGoalEnv",
             "ContinuumGym/ViewTrackingGoal-v0": "continuum_gym.envs.goal:ViewTrackingGoalEnv"}
