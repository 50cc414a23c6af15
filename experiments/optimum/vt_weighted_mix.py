"""Plug-in of issue 38, Campaign 6: ViewTracking task ``mixed_pt2``, a mixture weighted towards ``pan_tilt``.

Task ids k with k % 3 in (0, 1) are ``pan_tilt`` instance ``2 * (k // 3) + k % 3``, ids with k % 3 == 2 are
``random`` instance ``k // 3`` (the built-in ``mixed`` alternates the two): two thirds of the training episodes
hold a coverage-map target, one third follows a random da Vinci motion. Built from the library's own generator
(``view_tasks``), so every instance is one of the built-in families' instances, and no instance appears twice.

Use: ``continuum-gym --import vt_weighted_mix train ...`` with this directory on ``PYTHONPATH``
(``run_queue.py --import vt_weighted_mix`` does both; Campaign 6 in experiments/notebook.md).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from continuum_gym.envs import registered
from continuum_gym.envs.task_sources import TaskSource
from continuum_gym.envs.tasks import UNBOUNDED, TaskBatch, TaskContext, copy_rows, empty_batch
from continuum_gym.envs.view_tracking.tasks import view_tasks

ENV = "ContinuumGym/ViewTracking-v0"


class WeightedMix(TaskSource):
    """Two pan_tilt tasks for every random one (see the module's docstring for the numbering)."""

    name = "mixed_pt2"

    def count(self, split: str, context: TaskContext) -> int:
        return UNBOUNDED

    def batch(self, split: str, task_ids: npt.ArrayLike, context: TaskContext) -> TaskBatch:
        ids = np.asarray(task_ids, dtype=np.int64).reshape(-1)
        batch = empty_batch(len(ids), 6, 4)
        pan = np.flatnonzero(ids % 3 != 2)
        if len(pan):
            copy_rows(batch, pan, view_tasks("pan_tilt", split, 2 * (ids[pan] // 3) + ids[pan] % 3, context))
        rand = np.flatnonzero(ids % 3 == 2)
        if len(rand):
            copy_rows(batch, rand, view_tasks("random", split, ids[rand] // 3, context))
        batch.task_id = ids.copy()
        return batch


registered.TASKS[ENV][WeightedMix.name] = WeightedMix()
