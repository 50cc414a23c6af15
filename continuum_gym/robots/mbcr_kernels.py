"""The compiled kinematics of the multi-backbone continuum robot (paper 000; paper-notes §1.2-§1.4).

Every kernel takes the robot's ``MBCRKernelArgs`` bundle (from ``MultiBackboneRobot.kernel_args()``)
and an ``MBCRWorkspace`` of scratch arrays, so baselines, geometry and environments call them inside
their own compiled loops. The ``*_batch`` and ``tip_single`` entry points are what the robot's numpy
methods call; they return False (and leave the outputs undefined) if a configuration is not finite.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit

from continuum_gym.robots.segment import (
    bend_rotation,
    bend_terms,
    segment_jacobian,
    segment_position_cs,
)

HALF_PI = 0.5 * math.pi

#: What the compiled kernels read of a robot: segment lengths (n,) in m, bending stiffness (n,) in
#: N·m/rad², and the number of samples of the straight inserted part used for VOI.
MBCRKernelArgs = namedtuple("MBCRKernelArgs", ["lengths", "stiffness", "n_insert"])
#: Scratch arrays of one robot: base frames R (n+1, 3, 3) and g (n+1, 3) of every segment, a local
#: position and rotation, one segment's (3, 2) twist columns, and (3, dof) point Jacobians.
MBCRWorkspace = namedtuple("MBCRWorkspace", ["R_base", "g_base", "p_local", "Q", "jv", "jw", "Jv", "Jw"])


@njit(cache=True)
def make_workspace(n_segments):
    """Scratch arrays for one robot of ``n_segments``; allocated once per batch call."""
    dof = 2 * n_segments + 1
    return MBCRWorkspace(np.empty((n_segments + 1, 3, 3)), np.empty((n_segments + 1, 3)), np.empty(3),
                         np.empty((3, 3)), np.empty((3, 2)), np.empty((3, 2)), np.empty((3, dof)),
                         np.empty((3, dof)))


@njit(cache=True)
def all_finite(x):
    for v in x.ravel():
        if not math.isfinite(v):
            return False
    return True


@njit(cache=True)
def frames(q, robot, ws):
    """Fill ws.R_base[j] = ^wR_j and ws.g_base[j] = ^wg_j for j = 0..n (eqs 5, 7 corrected)."""
    n = robot.lengths.shape[0]
    R_base, g_base, p_local, Q = ws.R_base, ws.g_base, ws.p_local, ws.Q
    for a in range(3):
        for b in range(3):
            R_base[0, a, b] = 1.0 if a == b else 0.0
    g_base[0, 0] = 0.0
    g_base[0, 1] = 0.0
    g_base[0, 2] = q[2 * n]
    for j in range(n):
        bend = HALF_PI - q[2 * j]
        delta = q[2 * j + 1]
        s, omc, a, b, _, _ = bend_terms(bend)  # once for the position and the rotation
        cd = math.cos(delta)
        sd = math.sin(delta)
        length = robot.lengths[j]
        p_local[0] = length * cd * a
        p_local[1] = -length * sd * a
        p_local[2] = length * b
        bend_rotation(s, omc, cd, sd, Q)
        for a in range(3):
            acc = g_base[j, a]
            for b in range(3):
                acc += R_base[j, a, b] * p_local[b]
            g_base[j + 1, a] = acc
            for b in range(3):
                acc2 = 0.0
                for c in range(3):
                    acc2 += R_base[j, a, c] * Q[c, b]
                R_base[j + 1, a, b] = acc2


@njit(cache=True)
def point_columns(q, robot, ws, segment, sigma, point, Jv, Jw, with_angular):
    """Columns of the twist of a body point (segment, sigma) at world position ``point``.

    Needs ``frames`` filled in ``ws``. Proximal segments k < segment: R_{k-1} J_{k,v} +
    (g_k - point)^ R_{k-1} J_{k,w} (eq 4 corrected, paper-notes §1.2); own segment evaluated at sigma;
    distal columns 0; insertion column e3. ``Jw`` is filled only when ``with_angular``.
    """
    R_base, g_base, jv, jw = ws.R_base, ws.g_base, ws.jv, ws.jw
    dof = q.shape[0]
    for col in range(dof):
        for a in range(3):
            Jv[a, col] = 0.0
            if with_angular:
                Jw[a, col] = 0.0
    Jv[2, dof - 1] = 1.0
    for k in range(segment + 1):
        bend = HALF_PI - q[2 * k]
        delta = q[2 * k + 1]
        s = sigma if k == segment else 1.0
        segment_jacobian(bend, delta, robot.lengths[k], s, jv, jw)
        # q holds theta = pi/2 - bend: its column is minus the bend column
        for a in range(3):
            jv[a, 0] = -jv[a, 0]
            jw[a, 0] = -jw[a, 0]
        # Lever arm from the point back to the end of this (whole) proximal segment.
        if k == segment:
            arm0 = 0.0
            arm1 = 0.0
            arm2 = 0.0
        else:
            arm0 = g_base[k + 1, 0] - point[0]
            arm1 = g_base[k + 1, 1] - point[1]
            arm2 = g_base[k + 1, 2] - point[2]
        for c in range(2):
            v0 = 0.0
            v1 = 0.0
            v2 = 0.0
            w0 = 0.0
            w1 = 0.0
            w2 = 0.0
            for b in range(3):
                v0 += R_base[k, 0, b] * jv[b, c]
                v1 += R_base[k, 1, b] * jv[b, c]
                v2 += R_base[k, 2, b] * jv[b, c]
                w0 += R_base[k, 0, b] * jw[b, c]
                w1 += R_base[k, 1, b] * jw[b, c]
                w2 += R_base[k, 2, b] * jw[b, c]
            col = 2 * k + c
            Jv[0, col] = v0 + arm1 * w2 - arm2 * w1
            Jv[1, col] = v1 + arm2 * w0 - arm0 * w2
            Jv[2, col] = v2 + arm0 * w1 - arm1 * w0
            if with_angular:
                Jw[0, col] = w0
                Jw[1, col] = w1
                Jw[2, col] = w2


@njit(cache=True)
def body_point(q, robot, ws, segment, sigma, out):
    """World position (m) of the backbone point at arc fraction ``sigma`` of ``segment`` (frames in ws)."""
    delta = q[2 * segment + 1]
    body_point_cs(q, robot, ws, segment, sigma, math.cos(delta), math.sin(delta), out)


@njit(cache=True)
def body_point_cs(q, robot, ws, segment, sigma, cd, sd, out):
    """``body_point`` given cos and sin of the segment's delta (shared by all its samples)."""
    R_base, g_base, p_local = ws.R_base, ws.g_base, ws.p_local
    bend = HALF_PI - q[2 * segment]
    segment_position_cs(sigma * bend, cd, sd, sigma * robot.lengths[segment], p_local)
    for a in range(3):
        acc = g_base[segment, a]
        for b in range(3):
            acc += R_base[segment, a, b] * p_local[b]
        out[a] = acc


@njit(cache=True)
def tip_kernel(q, robot, ws, p, R, J):
    """Tip position, rotation and 6 x dof Jacobian [v; w] in {w} (eq 2 with paper-notes §1.2) for one q."""
    frames(q, robot, ws)
    n = robot.lengths.shape[0]
    dof = q.shape[0]
    R_base, g_base, Jv, Jw = ws.R_base, ws.g_base, ws.Jv, ws.Jw
    for a in range(3):
        p[a] = g_base[n, a]
        for b in range(3):
            R[a, b] = R_base[n, a, b]
    point_columns(q, robot, ws, n - 1, 1.0, p, Jv, Jw, True)
    for a in range(3):
        for col in range(dof):
            J[a, col] = Jv[a, col]
            J[3 + a, col] = Jw[a, col]


@njit(cache=True)
def tip_batch(qs, robot, p, R, J):
    if not all_finite(qs):
        return False
    ws = make_workspace(robot.lengths.shape[0])
    for i in range(qs.shape[0]):
        tip_kernel(qs[i], robot, ws, p[i], R[i], J[i])
    return True


@njit(cache=True)
def tip_single(q, lengths, stiffness, n_insert, p, R, J):
    # Plain arrays, not the bundle: unboxing a namedtuple argument costs ~0.7 us per call.
    if not all_finite(q):
        return False
    tip_kernel(q, MBCRKernelArgs(lengths, stiffness, n_insert), make_workspace(lengths.shape[0]), p, R, J)
    return True


@njit(cache=True)
def points_kernel(q, robot, ws, segments, fractions, P, JV):
    """Positions (m, 3) and translational Jacobians (m, 3, dof) of body points, for one q."""
    frames(q, robot, ws)
    dummy = ws.Jw
    for i in range(segments.shape[0]):
        body_point(q, robot, ws, segments[i], fractions[i], P[i])
        point_columns(q, robot, ws, segments[i], fractions[i], P[i], JV[i], dummy, False)


@njit(cache=True)
def points_batch(qs, robot, segments, fractions, P, JV):
    if not all_finite(qs):
        return False
    ws = make_workspace(robot.lengths.shape[0])
    for i in range(qs.shape[0]):
        points_kernel(qs[i], robot, ws, segments, fractions, P[i], JV[i])
    return True


@njit(cache=True)
def backbone_kernel(q, robot, ws, n_per_segment, out):
    """Backbone samples from the channel exit (paper-notes §1.3 item 13).

    ``robot.n_insert`` samples from the origin toward [0, 0, q_ins] (the first at the origin, the last
    one step before the base of segment 1), then arc fractions k/n for k = 0..n on segment 1 and
    k = 1..n on the others. With q_ins = 0 the inserted samples coincide with the origin, which is
    outside every cone, so the count stays fixed and batches keep one shape.
    """
    frames(q, robot, ws)
    n = robot.lengths.shape[0]
    n_insert = robot.n_insert
    idx = 0
    for k in range(n_insert):
        out[idx, 0] = 0.0
        out[idx, 1] = 0.0
        out[idx, 2] = q[2 * n] * k / n_insert
        idx += 1
    for j in range(n):
        start = 0 if j == 0 else 1
        cd = math.cos(q[2 * j + 1])
        sd = math.sin(q[2 * j + 1])
        for k in range(start, n_per_segment + 1):
            body_point_cs(q, robot, ws, j, k / n_per_segment, cd, sd, out[idx])
            idx += 1


@njit(cache=True)
def backbone_batch(qs, robot, n_per_segment, out):
    if not all_finite(qs):
        return False
    ws = make_workspace(robot.lengths.shape[0])
    for i in range(qs.shape[0]):
        backbone_kernel(qs[i], robot, ws, n_per_segment, out[i])
    return True
