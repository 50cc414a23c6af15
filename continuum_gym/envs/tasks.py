"""Tasks: what the robot must do in an episode, as arrays the compiled step kernels read.

A task *source* (``continuum_gym.envs.task_sources``) turns task ids into a ``TaskBatch``: start configurations and one desired trajectory
per row. A trajectory is either a sum of sines around a centre, x(t) = c + sum_k a_k sin(w_k t + phi_k)
(the papers' fixed tasks: hold has no terms, the circle two quarter-phase terms; and smooth random
ones), or a cubic spline through recorded samples (``TipTrajectory``, ``DaVinciTrajectory``).

Sources: the built-in families (``hold``, ``random``, ``mixed``, ``circle``; ``random``, ``static``,
``pan_tilt``, ``case1``, ``case2``, ``coverage``), recorded trajectories (``task=TipTrajectory(...)`` or
a list of them, one task id each) and families a user registers (``continuum_gym.registry.register_task``).

Task instances are numbered. ``task_split="train"``, ``"validation"`` and ``"test"`` draw ids from
disjoint families (every instance is generated from ``np.random.default_rng([family, split, task_id])``),
so tuning and evaluation run on held-out tasks. The papers' circle, case studies and coverage grid exist
only in the test split.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from continuum_gym.geometry.lens_cone import LensCone
from continuum_gym.robots.mbcr import MultiBackboneRobot

N_TERMS = 3
SPLIT_CODE = {"train": 0, "test": 1, "validation": 2}
#: Instances of the unbounded families (ids beyond wrap, in practice never reached).
UNBOUNDED = 10**9


@dataclass
class TaskBatch:
    """Arrays of N task instances (SI).

    Sine trajectories: x(t) = centre + sum_k amp[k] sin(omega[k] t + phase[k]); a row with
    ``n_knots > 0`` follows the cubic Hermite spline of its knots instead (times ``knot_t`` in s, values
    ``knot_x`` and slopes ``knot_m``; orientation R_des exp([r(t)]) from ``knot_r``, ``knot_rm``).
    """

    start_q: np.ndarray  # (N, dof)
    start_gamma: np.ndarray  # (N,) occlusion only (zeros otherwise)
    centre: np.ndarray  # (N, dim)
    amp: np.ndarray  # (N, K, dim)
    omega: np.ndarray  # (N, K) rad/s
    phase: np.ndarray  # (N, K) rad
    R_des: np.ndarray  # (N, 3, 3) desired tip orientation (or its start, for splines); identity otherwise
    duration: np.ndarray  # (N,) control steps
    task_id: np.ndarray  # (N,) int
    n_knots: np.ndarray  # (N,) int, 0 for sine trajectories
    knot_t: np.ndarray  # (N, M) s
    knot_x: np.ndarray  # (N, M, dim)
    knot_m: np.ndarray  # (N, M, dim) per s
    knot_r: np.ndarray  # (N, M, 3) rad
    knot_rm: np.ndarray  # (N, M, 3) rad/s

    @property
    def knot_capacity(self) -> int:
        return self.knot_t.shape[1]


_FIELD_NAMES = tuple(f.name for f in fields(TaskBatch))
_KNOT_FIELDS = frozenset(name for name in _FIELD_NAMES if name.startswith("knot_"))


def empty_batch(n: int, dof: int, dim: int, knots: int = 0) -> TaskBatch:
    # Knot arrays start empty: only recorded trajectories use them (they grow on install); at one knot
    # each they would be 14 floats per row, 0.45 MiB of a 4096-robot batch that no row reads.
    return TaskBatch(np.zeros((n, dof)), np.zeros(n), np.zeros((n, dim)), np.zeros((n, N_TERMS, dim)),
                     np.zeros((n, N_TERMS)), np.zeros((n, N_TERMS)), np.tile(np.eye(3), (n, 1, 1)),
                     np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64),
                     np.zeros((n, knots)), np.zeros((n, knots, dim)), np.zeros((n, knots, dim)),
                     np.zeros((n, knots, 3)), np.zeros((n, knots, 3)))


def row_indices(rows: np.ndarray | int | slice, source_rows: int) -> tuple[np.ndarray | int | slice, int | slice]:
    """(target, source) indices that copy ``source_rows`` rows into ``rows``.

    A single env resets one row: plain indexing copies it at a third of the cost of an index array
    (the reset's 15 task fields and 6 state arrays take ~10 us through index arrays).
    """
    if source_rows == 1 and isinstance(rows, np.ndarray) and rows.shape == (1,):
        return int(rows[0]), 0
    return rows, slice(None)


def copy_rows(target: TaskBatch, rows: np.ndarray | int | slice, source: TaskBatch) -> None:
    """target[rows] = source, knot arrays padded to the target's capacity."""
    capacity = target.knot_capacity
    rows, source_rows = row_indices(rows, len(source.task_id))
    for name in _FIELD_NAMES:
        values = getattr(source, name)
        if name in _KNOT_FIELDS and values.shape[1] < capacity:
            pad = [(0, 0)] * values.ndim
            pad[1] = (0, capacity - values.shape[1])
            values = np.pad(values, pad)
        getattr(target, name)[rows] = values[source_rows]


def interleaved(task_ids: np.ndarray, families: tuple[str, ...], draw: Callable[[str, np.ndarray], TaskBatch],
                dof: int, dim: int) -> TaskBatch:
    """A ``mixed`` family: task id k is instance ``k // len(families)`` of ``families[k % len(families)]``,
    drawn by ``draw(family, instance_ids)``."""
    batch = empty_batch(len(task_ids), dof, dim)
    for parity, name in enumerate(families):
        rows = np.flatnonzero(task_ids % len(families) == parity)
        if len(rows):
            copy_rows(batch, rows, draw(name, task_ids[rows] // len(families)))
    batch.task_id = task_ids.copy()
    return batch


def grown(batch: TaskBatch, capacity: int) -> TaskBatch:
    """A copy of ``batch`` whose knot arrays hold ``capacity`` knots."""
    out = empty_batch(len(batch.task_id), batch.start_q.shape[1], batch.centre.shape[1], capacity)
    copy_rows(out, slice(None), batch)
    return out


@dataclass(frozen=True)
class TaskContext:
    """What a task source needs to know of the environment."""

    robot: Any  # the env's robot (MultiBackboneRobot, ContinuumEndoscope, a plug-in's)
    control_dt: float
    cone: LensCone | None = None
    limits: Any = None  # OcclusionLimits (the env's limits, or None)
    grid: int = 21


def sines_through(batch: TaskBatch, i: int, start: np.ndarray, amp: np.ndarray, rng: np.random.Generator,
                  frequency_hz: tuple[float, float]) -> None:
    """Row i follows start + sum_k amp[k] (sin(w_k t + phi_k) - sin(phi_k)): random frequencies (Hz range)
    and phases, and x(0) = start exactly."""
    omega = 2 * math.pi * rng.uniform(*frequency_hz, len(amp))
    phase = rng.uniform(-math.pi, math.pi, len(amp))
    batch.amp[i] = amp
    batch.omega[i] = omega
    batch.phase[i] = phase
    batch.centre[i] = start - (amp * np.sin(phase)[:, None]).sum(axis=0)


def split_rng(family: int, split: str, task_id: int) -> np.random.Generator:
    return np.random.default_rng([family, SPLIT_CODE[split], int(task_id)])


def reach_pose(robot: MultiBackboneRobot, p: np.ndarray, R: np.ndarray, max_bend: float, insertion: tuple,
               what: str) -> np.ndarray:
    """A configuration within the limits whose tip is at pose (p (m), R), by bounded least squares.

    ``ValueError`` naming ``what`` if the best of several starts misses by more than 0.1 mm or 1e-3 rad.
    """
    from scipy.optimize import least_squares

    from continuum_gym.robots.rotations import rotation_vector

    n = robot.n_segments
    lower = np.tile([math.pi / 2 - max_bend, -3 * math.pi], n)
    upper = np.tile([math.pi / 2 + max_bend, 3 * math.pi], n)
    lower, upper = np.append(lower, insertion[0]), np.append(upper, insertion[1])

    def residual(q):
        tip, R_tip = robot.forward_kinematics(q)
        return np.concatenate([tip - p, 0.02 * rotation_vector(R @ R_tip.T)])

    best: Any = None  # scipy's OptimizeResult
    rng = np.random.default_rng(0)
    for attempt in range(12):
        q0 = np.clip(robot.home + (rng.normal(0, 0.4, robot.dof) * np.append(np.ones(2 * n), 0.01) if attempt else 0),
                     lower + 1e-9, upper - 1e-9)
        result = least_squares(residual, q0, bounds=(lower, upper), xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=400)
        if best is None or result.cost < best.cost:
            best = result
        error = residual(best.x)
        if np.linalg.norm(error[:3]) < 1e-7 and np.linalg.norm(error[3:]) < 2e-5:
            break
    error = residual(best.x)
    if np.linalg.norm(error[:3]) > 1e-4 or np.linalg.norm(error[3:]) / 0.02 > 1e-3:
        raise ValueError(f"{what}: {robot!r} cannot reach the start pose within its limits (best: "
                         f"{np.linalg.norm(error[:3]) * 1e3:.3g} mm, {np.linalg.norm(error[3:]) / 0.02:.3g} rad off)")
    q = best.x.copy()
    q[1:2 * n:2] = (q[1:2 * n:2] + math.pi) % (2 * math.pi) - math.pi
    return q


__all__ = ["TaskBatch", "TaskContext", "empty_batch", "copy_rows", "grown", "row_indices", "split_rng",
           "sines_through", "reach_pose", "SPLIT_CODE", "N_TERMS", "UNBOUNDED"]
