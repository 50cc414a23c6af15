"""``ContinuumGym/OcclusionAvoidanceGoal-v0``: the goal-conditioned front end (HER), see ``envs/goal.py``."""

from __future__ import annotations

from typing import Any

import numpy as np

from continuum_gym.envs import goal
from continuum_gym.envs.goal import GOAL_DIM, ContinuumGoalEnv, pose_goal, split_goal
from continuum_gym.envs.occlusion.config import OcclusionConfig
from continuum_gym.validation import positive

ENV_ID = OcclusionConfig.env_id


class OcclusionAvoidanceGoalEnv(ContinuumGoalEnv):
    __doc__ = goal.__doc__
    base_id = ENV_ID

    goal_dim = GOAL_DIM + 1  # the pose and the state's VOI
    goal_keywords = ("reward_type", "tolerance_m", "tolerance_rad")

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
        return (np.append(pose_goal(p, R), float(info["voi"])),
                np.append(pose_goal(p_des, core.desired_rotation(0, t)), 0.0))

    def compute_reward(self, achieved_goal: Any, desired_goal: Any, info: Any) -> np.ndarray:
        """Reward of (achieved, desired) goal pairs of any leading shape (see the module docstring)."""
        layout = "position (m), rotation vector (rad), VOI"
        p_a, R_a, achieved = split_goal(achieved_goal, "achieved_goal", self.goal_dim, layout)
        p_d, R_d, _ = split_goal(desired_goal, "desired_goal", self.goal_dim, layout)
        position = np.linalg.norm(p_a - p_d, axis=-1)
        relative = np.einsum("...ji,...jk->...ik", R_a, R_d)
        orientation = np.arccos(np.clip((np.trace(relative, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0))
        if self.reward_type == "sparse":
            return -((position > self.tolerance_m) | (orientation > self.tolerance_rad)).astype(np.float64)
        return -(1e3 * position + orientation + achieved[..., GOAL_DIM])


__all__ = ["OcclusionAvoidanceGoalEnv"]
