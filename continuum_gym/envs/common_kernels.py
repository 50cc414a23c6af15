"""Compiled pieces both environments' step kernels share: trajectories, clipping, clamping."""

from __future__ import annotations

import math
from collections import namedtuple

from numba import njit

#: Task instances as arrays, for both environments: a trajectory as a sum of sines (centre, amp, omega,
#: phase) of the desired tip position (occlusion) or of the da Vinci configuration (view tracking), the
#: desired tip orientation R_des (occlusion; identity otherwise), the task's duration and the episode's
#: step limit (both in control steps).
TaskArrays = namedtuple("TaskArrays", ["centre", "amp", "omega", "phase", "R_des", "duration", "limit"])


@njit(cache=True, inline="always")
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


@njit(cache=True)
def trajectory_batch(centre, amp, omega, phase, times, p_out, v_out):
    """Desired positions/velocities (N, T, dim) of N trajectories at times (T,) (s); same code as the kernels."""
    for i in range(centre.shape[0]):
        for j in range(times.shape[0]):
            trajectory_point(centre[i], amp[i], omega[i], phase[i], times[j], p_out[i, j], v_out[i, j])


@njit(cache=True, inline="always")
def clip_observation(o, limit):
    """Clip every entry of an observation row to [-limit, limit] in place (documented in the env docstrings)."""
    for j in range(o.shape[0]):
        if o[j] > limit:
            o[j] = limit
        elif o[j] < -limit:
            o[j] = -limit


@njit(cache=True, inline="always")
def clamp(value, lower, upper):
    """(value clamped to [lower, upper], whether it was clamped)."""
    if value > upper:
        return upper, True
    if value < lower:
        return lower, True
    return value, False
