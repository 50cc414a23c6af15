"""ViewTracking's built-in task families: ``random``, ``static``, ``pan_tilt``, ``mixed`` and the paper's
``case1``, ``case2`` and ``coverage`` grid.

See ``envs/tasks.py`` for what a task is and how instances are numbered per split.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from continuum_gym.baselines.scenarios import CASE_STUDIES, CASE_STUDY_START, COVERAGE_INSERTION, coverage_grid
from continuum_gym.envs.tasks import (
    N_TERMS,
    UNBOUNDED,
    TaskBatch,
    TaskContext,
    empty_batch,
    interleaved,
    sines_through,
    split_rng,
)
from continuum_gym.envs.view_tracking.config import TASKS, TEST_ONLY  # noqa: F401  (named in config.py: light)

VIEW_DURATION_S = {"random": 6.0, "static": 10.0, "pan_tilt": 10.0, "case1": 10.0, "case2": 10.0, "coverage": 10.0}


def view_tasks(task: str, split: str, task_ids: npt.ArrayLike, context: TaskContext) -> TaskBatch:
    """TaskBatch of a built-in view-tracking family (trajectories of q_davinci = [L_dV, yaw, pitch, roll])."""
    task_ids = np.asarray(task_ids, dtype=np.int64).reshape(-1)
    n = len(task_ids)
    if task == "mixed":  # even ids a pan_tilt target (the coverage map's), odd ids a random motion
        return interleaved(task_ids, ("pan_tilt", "random"), lambda name, ids: view_tasks(name, split, ids, context),
                           6, 4)
    batch = empty_batch(n, 6, 4)
    batch.task_id = task_ids.copy()
    batch.duration[:] = int(round(VIEW_DURATION_S[task] / context.control_dt))
    batch.start_q[:] = CASE_STUDY_START
    if task in CASE_STUDIES:
        batch.centre[:] = CASE_STUDIES[task]
        return batch
    if task == "coverage":
        points = coverage_grid(context.grid, COVERAGE_INSERTION)
        if np.any(task_ids < 0) or np.any(task_ids >= len(points)):
            raise ValueError(f"coverage task ids must be in [0, {len(points)}) for grid={context.grid}")
        batch.centre[:] = points[task_ids]
        return batch
    for i, task_id in enumerate(task_ids):
        rng = split_rng(2, split, task_id)
        if task == "static":
            batch.centre[i] = [rng.uniform(0.05, 0.08), rng.uniform(-math.pi / 3, math.pi / 3),
                               rng.uniform(-math.pi / 3, math.pi / 3), rng.uniform(-math.pi / 6, math.pi / 6)]
        elif task == "pan_tilt":  # the coverage map's distribution, drawn at random instead of on its grid
            batch.centre[i] = [COVERAGE_INSERTION, rng.uniform(-math.pi / 3, math.pi / 3),
                               rng.uniform(-math.pi / 3, math.pi / 3), 0.0]
        else:  # random: smooth pan/tilt/roll/zoom around a moderate start view
            start = np.array([rng.uniform(0.055, 0.075), rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.3),
                              rng.uniform(-0.5, 0.5)])
            amp = rng.uniform(0, 1, (N_TERMS, 4)) * np.array([0.004, 0.25, 0.25, 0.25])
            sines_through(batch, i, start, amp, rng, (0.05, 0.2))
    return batch


def view_task_count(task: str, grid: int = 21) -> int:
    if task in CASE_STUDIES:
        return 1
    if task == "coverage":
        return grid * grid
    return UNBOUNDED


def tasks(task: str, split: str, task_ids: npt.ArrayLike, context: TaskContext) -> TaskBatch:
    """The ``TaskBatch`` of a built-in family (``BuiltinTasks`` calls this)."""
    return view_tasks(task, split, task_ids, context)


def task_count(task: str, split: str, context: TaskContext) -> int:
    """Number of distinct instances of a built-in family."""
    return view_task_count(task, context.grid)


__all__ = ["TASKS", "TEST_ONLY", "view_tasks", "view_task_count", "tasks", "task_count"]
