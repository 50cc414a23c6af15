"""``ContinuumGym/ViewTrackingGoal-v0``: the goal-conditioned front end (HER), see ``envs/goal.py``."""

from __future__ import annotations

from typing import Any

import numpy as np

from continuum_gym.envs import goal
from continuum_gym.envs.goal import ContinuumGoalEnv, pose_goal, split_goal
from continuum_gym.envs.view_tracking.config import ViewTrackingConfig
from continuum_gym.validation import fraction

ENV_ID = ViewTrackingConfig.env_id


class ViewTrackingGoalEnv(ContinuumGoalEnv):
    __doc__ = goal.__doc__
    base_id = ENV_ID
    goal_keywords = ("reward_type", "or_threshold")

    def __init__(self, reward_type: str = "dense", or_threshold: float = 0.8, **kwargs: Any) -> None:
        self.or_threshold = fraction(or_threshold, "or_threshold")
        super().__init__(reward_type, **kwargs)

    def goals(self, info: dict) -> tuple[np.ndarray, np.ndarray]:
        core = self.core
        p_cam, R_cam = core.robot.forward_kinematics(np.ascontiguousarray(core.q[0]))
        p_dv, R_dv = core.davinci.forward_kinematics(core.davinci_configuration(0))
        return pose_goal(p_cam, R_cam), pose_goal(p_dv, R_dv)

    def compute_reward(self, achieved_goal: Any, desired_goal: Any, info: Any) -> np.ndarray:
        """Overlap ratio (dense) or its threshold indicator (sparse) of camera-pose goal pairs, batched."""
        from continuum_gym.geometry import overlap_ratio

        p_a, R_a, _ = split_goal(achieved_goal, "achieved_goal")
        p_d, R_d, _ = split_goal(desired_goal, "desired_goal")
        ratio = np.asarray(overlap_ratio(p_d, R_d, p_a, R_a, self.core.frustum), dtype=np.float64)
        if self.reward_type == "sparse":
            return -(ratio <= self.or_threshold).astype(np.float64)
        return ratio


__all__ = ["ViewTrackingGoalEnv"]
