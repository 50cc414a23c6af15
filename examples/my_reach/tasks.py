"""The ``reach`` family: a goal point the view can reach, drawn per (split, task id) from its own stream."""

from __future__ import annotations

import numpy as np

from continuum_gym.envs.tasks import UNBOUNDED, TaskBatch, TaskContext, empty_batch, split_rng

FAMILY = 101  #: this family's stream of task instances (the library's families use small numbers)
DURATION_S = 2.0


def tasks(task: str, split: str, task_ids, context: TaskContext) -> TaskBatch:
    """Goals p_ct(q_goal) of joint values q_goal drawn uniformly within the joint limits (so reachable)."""
    task_ids = np.asarray(task_ids, dtype=np.int64).reshape(-1)
    robot = context.robot
    lower, upper = robot.joint_limits
    lower, upper = np.maximum(lower, -np.pi), np.minimum(upper, np.pi)  # the deltas are unbounded
    batch = empty_batch(len(task_ids), 6, 3)
    batch.task_id = task_ids.copy()
    batch.duration[:] = int(round(DURATION_S / context.control_dt))
    batch.start_q[:] = robot.case_study_start
    for i, task_id in enumerate(task_ids):
        batch.centre[i] = robot.target_point(split_rng(FAMILY, split, task_id).uniform(lower, upper))
    return batch


def task_count(task: str, split: str, context: TaskContext) -> int:
    return UNBOUNDED
