"""``MyLab/EndoscopeReach-v0``'s keyword arguments, task family and the columns its rows write (declared once)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from continuum_gym.envs.columns import NON_FINITE, Block, Columns, Episode, Layout, Value, mean
from continuum_gym.envs.config import EnvConfig, check_common, resolve_robot, spec
from continuum_gym.envs.tasks import UNBOUNDED, TaskBatch, TaskContext, empty_batch, split_rng
from continuum_gym.robots import ContinuumEndoscope


class Metric(Columns):  # a value declared once: the row writes it; info, the docs and evaluate read it from here
    DISTANCE = Value("distance of the view's target point from the goal (m)", info="distance_m", unit="m", episode=(
        Episode("final_distance_m", "final", "final distance to the goal", False, "m", "mm", 1e3),
        mean("mean_distance_m", "mean distance to the goal", unit="m", display_unit="mm", display_scale=1e3)))


class Flag(Columns):
    CLAMPED = Value("joints clamped at a limit (6,)", info="clamped_joints", kind="bits")
    TERMINATED = "never (a reach has no failure state)"
    TRUNCATED = "the task's duration is over"
    NON_FINITE = NON_FINITE  # every env's last flag: the library sets it


OBSERVATION = Layout("ReachObservation", Block("joints", "L0, phi, theta1, delta1, theta2, delta2", "m, rad", size=6),
                     Block("goal_error", "goal - target point (world)", "/ 0.05 m", size=3),
                     Block("base_command", "Jacobian-transpose command", "/ action scale", size=6))


@dataclass(frozen=True)
class ReachConfig(EnvConfig):
    """Configuration of ``MyLab/EndoscopeReach-v0`` (SI units)."""

    env_id: ClassVar[str] = "MyLab/EndoscopeReach-v0"
    baselines: ClassVar[tuple] = ("jacobian_transpose",)
    default_weights: ClassVar[dict] = {"distance": 1.0, "action": 0.01}
    task_module: ClassVar[str] = "my_reach.config"  # its tasks() and task_count() below
    trajectory_class: ClassVar[str] = "continuum_gym.envs.trajectories:TipTrajectory"  # a moving goal, recorded
    builtin_tasks: ClassVar[tuple] = ("reach",)
    object_keywords: ClassVar[tuple] = ("robot",)

    task: Any = field(default="reach", metadata=spec(doc="`reach` (a reachable goal point per episode) or a "
                                                         "`TipTrajectory` of the goal", type_name="str"))
    task_split: str = field(default="train", metadata=spec(doc="`train`, `validation` or `test`", type_name="str"))
    base_controller: str | None = field(default="jacobian_transpose", metadata=spec(
        doc="residual base: `jacobian_transpose` or `None` (pure RL)", type_name="str or None"))
    residual_scale: float = field(default=1.0, metadata=spec(unit="fraction of the action scale",
                                                             doc="residual at action 1.0 (in (0, 10])"))
    reward_weights: dict = field(default_factory=dict, metadata=spec(
        doc="weights of `distance` and `action` (defaults 1, 0.01)", type_name="dict"))
    control_dt: float = field(default=0.01, metadata=spec(unit="s", doc="control step (in (0, 0.1])"))
    substeps: int = field(default=1, metadata=spec(doc="Euler steps per control step"))
    max_episode_steps: int | None = field(default=None, metadata=spec(doc="cap on the episode length (steps)"))
    robot: Any = field(default=None, metadata=spec(doc="a `ContinuumEndoscope`; `None`: the paper's",
                                                   type_name="ContinuumEndoscope or None"))

    def __post_init__(self) -> None:
        object.__setattr__(self, "robot", resolve_robot(self.robot, ContinuumEndoscope, self.env_id))
        check_common(self)


def tasks(task: str, split: str, task_ids, context: TaskContext) -> TaskBatch:
    """``reach``: goals p_ct(q_goal) of joint values drawn within the joint limits (so reachable), 2 s each."""
    task_ids = np.asarray(task_ids, dtype=np.int64).reshape(-1)
    lower, upper = context.robot.joint_limits
    lower, upper = np.maximum(lower, -np.pi), np.minimum(upper, np.pi)  # the deltas are unbounded
    batch = empty_batch(len(task_ids), 6, 3)
    batch.task_id = task_ids.copy()
    batch.duration[:] = int(round(2.0 / context.control_dt))
    batch.start_q[:] = context.robot.case_study_start
    for i, task_id in enumerate(task_ids):  # the family's own stream of instances: 101 (the library's are small)
        batch.centre[i] = context.robot.target_point(split_rng(101, split, task_id).uniform(lower, upper))
    return batch


def task_count(task: str, split: str, context: TaskContext) -> int:
    return UNBOUNDED
