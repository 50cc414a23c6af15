"""Compiled pieces both environments' step kernels share: desired trajectories, clipping, clamping."""

from __future__ import annotations

import math
from collections import namedtuple
from typing import TYPE_CHECKING

import numpy as np

from continuum_gym.envs.row_claims import atomic_add
from continuum_gym.envs.trajectories import hermite_point
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.rotations import rotation_exp

if TYPE_CHECKING:
    from continuum_gym.envs.tasks import TaskBatch

#: Task instances as arrays, for both environments (see ``envs.tasks.TaskBatch``): a trajectory of the
#: desired tip position (occlusion) or of the da Vinci configuration (view tracking), either a sum of
#: sines (centre, amp, omega, phase) or, where ``n_knots > 0``, a cubic Hermite spline (knot times,
#: values, slopes; for the orientation rotation vectors relative to R_des); the desired tip orientation
#: R_des; the task's duration and the episode's step limit (both in control steps).
#: ``active`` value of a row the step kernels observe at its state instead of stepping (``observe_rows``).
OBSERVE_ONLY = 2

TaskArrays = namedtuple("TaskArrays", ["centre", "amp", "omega", "phase", "R_des", "duration", "limit", "n_knots",
                                       "knot_t", "knot_x", "knot_m", "knot_r", "knot_rm"])


def task_arrays(batch: TaskBatch, limit: np.ndarray) -> TaskArrays:
    """The kernel bundle of a ``TaskBatch`` (the same arrays, not copies) and the episode step limits."""
    return TaskArrays(batch.centre, batch.amp, batch.omega, batch.phase, batch.R_des, batch.duration, limit,
                      batch.n_knots, batch.knot_t, batch.knot_x, batch.knot_m, batch.knot_r, batch.knot_rm)


@kernel(inline="always")
def at(block_start, n_segments):
    """Index of an observation block's first entry (``Layout.offsets()``'s ``(per_segment, constant)``) for a
    robot of ``n_segments`` (``columns.at`` in Python)."""
    return block_start[0] * n_segments + block_start[1]


@kernel(inline="always")
def trajectory_point(centre, amp, omega, phase, t, p, v):
    """x(t) = c + sum a_k sin(w_k t + phi_k) and its derivative, into p and v."""
    for a in range(p.shape[0]):
        p[a] = centre[a]
        v[a] = 0.0
    for k in range(omega.shape[0]):
        s = math.sin(omega[k] * t + phase[k])
        c = math.cos(omega[k] * t + phase[k])
        for a in range(p.shape[0]):
            p[a] += amp[k, a] * s
            v[a] += amp[k, a] * omega[k] * c


@kernel(inline="always")
def desired_point(tasks, i, t, p, v):
    """Row i's desired position (or da Vinci configuration) and its rate at time t (s), into p and v."""
    n = tasks.n_knots[i]
    if n == 0:
        trajectory_point(tasks.centre[i], tasks.amp[i], tasks.omega[i], tasks.phase[i], t, p, v)
    else:
        hermite_point(tasks.knot_t[i], tasks.knot_x[i], tasks.knot_m[i], n, t, p, v)


@kernel(inline="always")
def desired_rotation(tasks, i, t, w, w_rate, turn, out):
    """Row i's desired orientation at time t: R_des for sine tasks, R_des exp([r(t)]) for splines.

    Returns the array that holds it (``tasks.R_des[i]`` itself or ``out``); w, w_rate (3,), turn (3, 3) scratch.
    """
    n = tasks.n_knots[i]
    if n == 0:
        return tasks.R_des[i]
    hermite_point(tasks.knot_t[i], tasks.knot_r[i], tasks.knot_rm[i], n, t, w, w_rate)
    rotation_exp(w, turn)
    R0 = tasks.R_des[i]
    for a in range(3):
        for b in range(3):
            out[a, b] = R0[a, 0] * turn[0, b] + R0[a, 1] * turn[1, b] + R0[a, 2] * turn[2, b]
    return out


@kernel
def rotation_at(tasks, row, t, out):
    """Row's desired orientation at time t into out (3, 3) (the kernels' own computation)."""
    w, w_rate, turn = np.empty(3), np.empty(3), np.empty((3, 3))
    R = desired_rotation(tasks, row, t, w, w_rate, turn, out)
    for a in range(3):
        for b in range(3):
            out[a, b] = R[a, b]


@kernel
def trajectory_batch(tasks, rows, times, p_out, v_out):
    """Desired positions/velocities (len(rows), T, dim) of task rows at times (T,) (s); same code as the kernels."""
    for k in range(rows.shape[0]):
        for j in range(times.shape[0]):
            desired_point(tasks, rows[k], times[j], p_out[k, j], v_out[k, j])


@kernel(inline="always")
def clip_observation(o, limit):
    """Clip every entry of an observation row to [-limit, limit] in place (documented in the env docstrings)."""
    for j in range(o.shape[0]):
        if o[j] > limit:
            o[j] = limit
        elif o[j] < -limit:
            o[j] = -limit


@kernel(inline="always")
def clamp(value, lower, upper):
    """(value clamped to [lower, upper], whether it was clamped)."""
    if value > upper:
        return upper, True
    if value < lower:
        return lower, True
    return value, False


@kernel(inline="always")
def finite_values(values):
    """Whether every entry of the 1-D array ``values`` is finite (no NaN, no inf)."""
    for k in range(values.shape[0]):
        if not math.isfinite(values[k]):
            return False
    return True


@kernel(inline="always")
def mark_non_finite(i, q, out, column):
    """Row i's non-finite flag (``flags[i, column]``): 1 where its joints q, its cached baseline command, its
    observation or its metrics hold a NaN or an inf, else 0; each flagged row is counted in ``out.faults[0]``.

    A plug-in's NaN (a controller's command, a robot's kinematics) reaches the state, and from there every value
    of the row; without this flag it would be scored (a NaN configuration has a VOI of 0, the best value). The
    observation is checked before it is read by anyone, and the count lets the front end find such rows with one
    read per step (``envs/faults.py`` raises or ends the episode).
    """
    bad = not (finite_values(q) and finite_values(out.base_cmd[i]) and finite_values(out.obs[i])
               and finite_values(out.metrics[i]))
    out.flags[i, column] = 1 if bad else 0
    if bad:
        atomic_add(out.faults, 0, 1)


@kernel(inline="always")
def mark_non_finite_reward(i, out, column):
    """Flag row i (as ``mark_non_finite``) if its reward is not finite."""
    if not math.isfinite(out.rewards[i]):
        if out.flags[i, column] == 0:
            atomic_add(out.faults, 0, 1)
        out.flags[i, column] = 1
