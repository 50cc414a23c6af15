"""Task sources: task ids -> ``TaskBatch`` for the built-in families, recorded trajectories and
registered families, and the resolution of a config's ``task`` to one of them (see ``envs.tasks``)."""

from __future__ import annotations

import functools
import hashlib
from collections.abc import Callable, Sequence

import numpy as np

from continuum_gym.baselines.scenarios import CASE_STUDY_START
from continuum_gym.envs.tasks import (
    UNBOUNDED,
    TaskBatch,
    TaskContext,
    empty_batch,
    occlusion_task_count,
    occlusion_tasks,
    reach_pose,
    split_rng,
    view_task_count,
    view_tasks,
)
from continuum_gym.envs.trajectories import DaVinciTrajectory, TipTrajectory
from continuum_gym.validation import describe


class TaskSource:
    """Task ids -> ``TaskBatch`` for one environment; ``name`` appears in configs and tables."""

    name: str = "task"
    test_only: bool = False

    def count(self, split: str, context: TaskContext) -> int:  # pragma: no cover - interface
        raise NotImplementedError

    def batch(self, split: str, task_ids, context: TaskContext) -> TaskBatch:  # pragma: no cover - interface
        raise NotImplementedError

    def describe(self) -> str | dict:
        """What ``config.yml`` records of the task."""
        return self.name


class BuiltinTasks(TaskSource):
    """One of the papers' or the library's families."""

    def __init__(self, name: str, occlusion: bool) -> None:
        self.name, self.occlusion = name, occlusion

    @property
    def test_only(self) -> bool:
        return self.name in (("circle",) if self.occlusion else ("case1", "case2", "coverage"))

    def count(self, split: str, context: TaskContext) -> int:
        return occlusion_task_count(self.name, split) if self.occlusion else view_task_count(self.name, context.grid)

    def batch(self, split: str, task_ids, context: TaskContext) -> TaskBatch:
        return (occlusion_tasks if self.occlusion else view_tasks)(self.name, split, task_ids, context)


def trajectory_rows(trajectories: Sequence, task_ids, context: TaskContext) -> TaskBatch:
    """TaskBatch of recorded trajectories (``TipTrajectory`` or ``DaVinciTrajectory``), one per row."""
    task_ids = np.asarray(task_ids, dtype=np.int64).reshape(-1)
    occlusion = isinstance(trajectories[0], TipTrajectory)
    dof, dim = (context.robot.dof, 3) if occlusion else (6, 4)
    capacity = max(len(trajectories[int(k)].knots["t"]) for k in task_ids)
    batch = empty_batch(len(task_ids), dof, dim, capacity)
    batch.task_id = task_ids.copy()
    for i, k in enumerate(task_ids):
        trajectory = trajectories[int(k)]
        knots = trajectory.knots
        m = len(knots["t"])
        batch.n_knots[i] = m
        batch.knot_t[i, :m] = knots["t"]
        batch.knot_x[i, :m] = knots["x"]
        batch.knot_m[i, :m] = knots["m"]
        batch.knot_r[i, :m] = knots["r"]
        batch.knot_rm[i, :m] = knots["rm"]
        batch.duration[i] = max(1, int(round(trajectory.duration / context.control_dt)))
        if occlusion:
            batch.start_q[i] = occlusion_start(trajectory, context)
            batch.start_gamma[i] = float(trajectory.start_gamma)
            if knots["R0"] is not None:
                batch.R_des[i] = knots["R0"]
            else:
                batch.R_des[i] = context.robot.forward_kinematics(batch.start_q[i])[1]
        else:
            batch.start_q[i] = CASE_STUDY_START
    return batch


def occlusion_start(trajectory: TipTrajectory, context: TaskContext) -> np.ndarray:
    """The trajectory's start configuration: as given (checked against the robot), or solved at its first pose."""
    robot, limits = context.robot, context.limits
    if trajectory.start_q is not None:
        q = np.asarray(trajectory.start_q, dtype=float)
        if q.shape != (robot.dof,):
            raise ValueError(f"start_q must hold the robot's {robot.dof} joints [theta1, delta1, ..., q_ins]; got "
                             f"{q.shape[0]} values")
        return q
    return _reached_start(robot, float(limits.max_bend), tuple(limits.insertion), trajectory.knots["x"][0].tobytes(),
                          trajectory.knots["R0"].tobytes())


@functools.lru_cache(maxsize=256)
def _reached_start(robot, max_bend, insertion, p_bytes, R_bytes):
    p = np.frombuffer(p_bytes).copy()
    R = np.frombuffer(R_bytes).reshape(3, 3).copy()
    return reach_pose(robot, p, R, max_bend, insertion, "a TipTrajectory without start_q")


class RecordedTasks(TaskSource):
    """Recorded trajectories as tasks: task id k is the k-th trajectory (every split sees all of them)."""

    def __init__(self, trajectories: Sequence, kind: type, name: str = "recorded") -> None:
        trajectories = list(trajectories)
        if not trajectories:
            raise ValueError("task: a list of recorded trajectories must hold at least one")
        for k, trajectory in enumerate(trajectories):
            if not isinstance(trajectory, kind):
                raise ValueError(f"task[{k}] must be a {kind.__name__}; got {describe(trajectory)}")
        self.trajectories = trajectories
        self.name = name

    def count(self, split: str, context: TaskContext) -> int:
        return len(self.trajectories)

    def batch(self, split: str, task_ids, context: TaskContext) -> TaskBatch:
        task_ids = np.asarray(task_ids, dtype=np.int64).reshape(-1)
        if np.any(task_ids < 0) or np.any(task_ids >= len(self.trajectories)):
            raise ValueError(f"task_id must be in [0, {len(self.trajectories)}) for {len(self.trajectories)} recorded "
                             f"trajectories; got {task_ids.tolist()}")
        return trajectory_rows(self.trajectories, task_ids, context)

    def describe(self) -> dict:
        digest = hashlib.sha256()
        for trajectory in self.trajectories:
            for key in ("t", "x", "r"):
                digest.update(np.ascontiguousarray(trajectory.knots[key]).tobytes())
        return {"type": "recorded", "name": self.name, "trajectories": len(self.trajectories),
                "samples": int(sum(len(t.knots["t"]) for t in self.trajectories)), "sha256": digest.hexdigest()}


class SampledTasks(TaskSource):
    """A registered family: ``sampler(task_id, split, rng)`` returns the trajectory of each instance."""

    def __init__(self, name: str, sampler: Callable, kind: type, count: int | None = None) -> None:
        self.name, self.sampler, self.kind = name, sampler, kind
        self.instances = UNBOUNDED if count is None else int(count)
        self._seed = int.from_bytes(hashlib.sha256(name.encode()).digest()[:4], "little")

    def count(self, split: str, context: TaskContext) -> int:
        return self.instances

    def draw(self, split: str, task_id: int):
        trajectory = self.sampler(int(task_id), split, split_rng(self._seed, split, task_id))
        if not isinstance(trajectory, self.kind):
            raise ValueError(f"the sampler of task {self.name!r} must return a {self.kind.__name__}; got "
                             f"{describe(trajectory)} for task id {task_id}")
        return trajectory

    def batch(self, split: str, task_ids, context: TaskContext) -> TaskBatch:
        task_ids = np.asarray(task_ids, dtype=np.int64).reshape(-1)
        trajectories = {int(k): self.draw(split, int(k)) for k in np.unique(task_ids)}
        rows = trajectory_rows([trajectories[int(k)] for k in task_ids], np.arange(len(task_ids)), context)
        rows.task_id = task_ids.copy()
        return rows


def task_names(env_id: str, builtin: Sequence[str]) -> tuple:
    """Built-in and registered task names of an environment."""
    from continuum_gym.envs import registered

    return (*builtin, *registered.TASKS.get(env_id, {}))


def resolve_task(task: str, env_id: str, builtin: Sequence[str], occlusion: bool) -> TaskSource:
    """A task source from a config's ``task``: a name, a recorded trajectory, a list of them, or a source."""
    from continuum_gym.validation import choice

    kind = TipTrajectory if occlusion else DaVinciTrajectory
    if isinstance(task, TaskSource):
        return task
    if isinstance(task, (TipTrajectory, DaVinciTrajectory)):
        return RecordedTasks([task], kind)
    if isinstance(task, (list, tuple)):
        return RecordedTasks(task, kind)
    choice(task, task_names(env_id, builtin), "task")
    if task in builtin:
        return BuiltinTasks(task, occlusion)
    from continuum_gym.envs import registered

    return registered.TASKS[env_id][task]


__all__ = ["TaskSource", "BuiltinTasks", "RecordedTasks", "SampledTasks", "trajectory_rows", "task_names",
           "resolve_task"]
