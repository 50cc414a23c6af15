"""Plug-in of issue 38, Campaign 11: ViewTracking task ``mixed_hard``, a curriculum over the edge targets.

Task ids k with k % 3 == 0 are the training ``pan_tilt`` instance ``hard[(k // 3) % len(hard)]``, where ``hard``
is the id list ``vt_hard_targets.py`` wrote (the targets a policy settles near OR 0.8 on) and its path is
the environment variable ``VT_HARD_IDS``; ids with k % 3 == 1 are fresh ``pan_tilt`` instances
``HARD_SCAN_END + k // 3`` (beyond any scanned id, so the two streams do not share a target); ids with
k % 3 == 2 are ``random`` instance ``k // 3``. A third of the episodes hold an edge target, a third any
coverage-map target, a third follow a random da Vinci motion (the shipped fine-tune's ``mixed_pt2`` holds two
thirds of any target). Training split only: the list is of training ids.

Use: ``VT_HARD_IDS=hard_seed0.npy PYTHONPATH=.:scripts/optimum python scripts/optimum/vt_finetune.py ...
--task mixed_hard --import vt_hard_mix``.
"""

from __future__ import annotations

import os

import numpy as np
import numpy.typing as npt

from continuum_gym.envs import registered
from continuum_gym.envs.task_sources import TaskSource
from continuum_gym.envs.tasks import UNBOUNDED, TaskBatch, TaskContext, copy_rows, empty_batch
from continuum_gym.envs.view_tracking.tasks import view_tasks

ENV = "ContinuumGym/ViewTracking-v0"
HARD_SCAN_END = 1 << 20  # fresh pan_tilt ids start here: above any id vt_hard_targets.py scans


def _hard_ids() -> np.ndarray:
    path = os.environ.get("VT_HARD_IDS")
    if not path:
        raise RuntimeError("task mixed_hard needs VT_HARD_IDS, the path of vt_hard_targets.py's .npy of ids")
    ids = np.load(path).astype(np.int64).reshape(-1)
    if len(ids) == 0 or ids.min() < 0 or ids.max() >= HARD_SCAN_END:
        raise ValueError(f"VT_HARD_IDS={path}: needs 1 or more ids in [0, {HARD_SCAN_END})")
    return ids


class HardMix(TaskSource):
    """One edge target, one any target, one random motion in every three ids (see the module's docstring)."""

    name = "mixed_hard"

    def __init__(self) -> None:
        self._hard: np.ndarray | None = None

    def count(self, split: str, context: TaskContext) -> int:
        return UNBOUNDED

    def batch(self, split: str, task_ids: npt.ArrayLike, context: TaskContext) -> TaskBatch:
        if split != "train":
            raise ValueError(f"task mixed_hard is a training curriculum; split {split!r} is not 'train'")
        if self._hard is None:
            self._hard = _hard_ids()
        ids = np.asarray(task_ids, dtype=np.int64).reshape(-1)
        batch = empty_batch(len(ids), 6, 4)
        for phase, pick in ((0, lambda k: self._hard[(k // 3) % len(self._hard)]),
                            (1, lambda k: HARD_SCAN_END + k // 3)):
            rows = np.flatnonzero(ids % 3 == phase)
            if len(rows):
                copy_rows(batch, rows, view_tasks("pan_tilt", split, pick(ids[rows]), context))
        rand = np.flatnonzero(ids % 3 == 2)
        if len(rand):
            copy_rows(batch, rand, view_tasks("random", split, ids[rand] // 3, context))
        batch.task_id = ids.copy()
        return batch


registered.TASKS[ENV][HardMix.name] = HardMix()
