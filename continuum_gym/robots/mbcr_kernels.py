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

from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.segment import (
    bend_rotation,
    bend_terms,
    segment_jacobian_terms,
)

HALF_PI = 0.5 * math.pi

#: What the compiled kernels read of a robot: segment lengths (n,) in m, bending stiffness (n,) in
#: N·m/rad², and the number of samples of the straight inserted part used for VOI.
MBCRKernelArgs = namedtuple("MBCRKernelArgs", ["lengths", "stiffness", "n_insert"])
#: Scratch arrays of one robot: base frames R (n+1, 3, 3) and g (n+1, 3) of every segment, a local
#: position and rotation, one segment's (3, 2) twist columns, (3, dof) point Jacobians, and what
#: ``frames`` keeps of each segment: cos / sin of delta (n, 2) and the world-frame twist
#: columns of the whole segment, linear V (n + 1, 3, 2) and angular W (n + 1, 3, 2), theta column first
#: (the last row holds one body point's own, partial segment).
MBCRWorkspace = namedtuple("MBCRWorkspace", ["R_base", "g_base", "p_local", "Q", "jv", "jw", "Jv", "Jw",
                                             "cs", "V", "W"])


@kernel
def make_workspace(n_segments):
    """Scratch arrays for one robot of ``n_segments``; allocated once per batch call."""
    dof = 2 * n_segments + 1
    return MBCRWorkspace(np.empty((n_segments + 1, 3, 3)), np.empty((n_segments + 1, 3)), np.empty(3),
                         np.empty((3, 3)), np.empty((3, 2)), np.empty((3, 2)), np.empty((3, dof)),
                         np.empty((3, dof)), np.empty((n_segments, 2)), np.empty((n_segments + 1, 3, 2)),
                         np.empty((n_segments + 1, 3, 2)))


@kernel
def all_finite(x):
    for v in x.ravel():
        if not math.isfinite(v):
            return False
    return True


@kernel
def frames(q, robot, ws):
    """Fill ws.R_base[j] = ^wR_j and ws.g_base[j] = ^wg_j for j = 0..n (eqs 5, 7 corrected), ws.cs, and every
    whole segment's world twist columns in ws.V, ws.W.

    The columns are what all point Jacobians share: a point then needs only its own segment's terms
    (``point_columns_framed``); the proximal segments' columns are the same for every point, up to the
    lever arm. They cost no transcendental beyond the frames' own.
    """
    fill_frames(q, robot, ws)


# Reference counts: a compiled function that calls another (not inlined) one keeps an atomic
# incref / decref of every array it was passed, bundles included, because the call may raise; those
# would be a large share of an occlusion step. So the kernels called per substep are leaves, their helpers
# inlined ("always"), and they pass the workspace's arrays and row indices rather than row views.
@kernel(inline="always")
def fill_frames(q, robot, ws):
    """``frames`` inlined into the caller, which stays a leaf."""
    lengths = robot.lengths
    n = lengths.shape[0]
    R_base, g_base, p_local, Q, jv, jw, cs, V, W = ws.R_base, ws.g_base, ws.p_local, ws.Q, ws.jv, ws.jw, ws.cs, \
        ws.V, ws.W
    for a in range(3):
        for b in range(3):
            R_base[0, a, b] = 1.0 if a == b else 0.0
    g_base[0, 0] = 0.0
    g_base[0, 1] = 0.0
    g_base[0, 2] = q[2 * n]
    for j in range(n):
        bend = HALF_PI - q[2 * j]
        delta = q[2 * j + 1]
        s, omc, a, b, da, db = bend_terms(bend)  # once for the position, the rotation and the columns
        cd = math.cos(delta)
        sd = math.sin(delta)
        cs[j, 0] = cd
        cs[j, 1] = sd
        length = lengths[j]
        segment_jacobian_terms(s, omc, a, da, db, cd, sd, length, 1.0, jv, jw)
        rotate_columns(R_base, j, jv, jw, V, W, j)
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


@kernel(inline="always")
def rotate_columns(R_base, j, jv, jw, V, W, row):
    """V[row] = R_j jv, W[row] = R_j jw for one segment's (3, 2) twist columns, the theta column negated
    (q holds theta = pi/2 - bend: its column is minus the bend column)."""
    # The negation is done in registers: negated in place (jv[a, 0] = -jv[a, 0]), the compiler flips one
    # byte of each double in memory, and the 8-byte reload just after cannot be forwarded from that store
    # (a store-forwarding stall, which perf shows as the hottest instruction of the step). R * (-x) is -(R * x)
    # exactly: the same bits.
    for c in range(2):
        v0 = 0.0
        v1 = 0.0
        v2 = 0.0
        w0 = 0.0
        w1 = 0.0
        w2 = 0.0
        for b in range(3):
            jv_b = -jv[b, c] if c == 0 else jv[b, c]
            jw_b = -jw[b, c] if c == 0 else jw[b, c]
            v0 += R_base[j, 0, b] * jv_b
            v1 += R_base[j, 1, b] * jv_b
            v2 += R_base[j, 2, b] * jv_b
            w0 += R_base[j, 0, b] * jw_b
            w1 += R_base[j, 1, b] * jw_b
            w2 += R_base[j, 2, b] * jw_b
        V[row, 0, c] = v0
        V[row, 1, c] = v1
        V[row, 2, c] = v2
        W[row, 0, c] = w0
        W[row, 1, c] = w1
        W[row, 2, c] = w2


@kernel
def point_columns(q, robot, ws, segment, sigma, point, Jv, Jw, with_angular):
    """Columns of the twist of a body point (segment, sigma) at world position ``point``.

    Needs ``frames`` filled in ``ws``. Proximal segments k < segment: R_{k-1} J_{k,v} +
    (g_k - point)^ R_{k-1} J_{k,w} (eq 4 corrected, paper-notes §1.2); own segment evaluated at sigma;
    distal columns 0; insertion column e3. ``Jw`` is filled only when ``with_angular``.
    """
    s, omc, a, _, da, db = bend_terms(sigma * (HALF_PI - q[2 * segment]))
    point_columns_framed(robot.lengths, ws.R_base, ws.g_base, ws.cs, ws.jv, ws.jw, ws.V, ws.W, q.shape[0], segment,
                         sigma, point[0], point[1], point[2], s, omc, a, da, db, Jv, Jw, with_angular)


@kernel(inline="always")
def point_columns_framed(lengths, R_base, g_base, cs, jv, jw, V, W, dof, segment, sigma, px, py, pz, s, omc, a, da,
                         db, Jv, Jw, with_angular):
    """``point_columns`` on the workspace's arrays, given the bend terms at sigma * bend of the point's own
    segment (its position needs them too); the last row of V, W is the own segment's scratch."""
    for col in range(dof):
        for r in range(3):
            Jv[r, col] = 0.0
            if with_angular:
                Jw[r, col] = 0.0
    Jv[2, dof - 1] = 1.0
    for k in range(segment):
        # Lever arm from the point back to the end of this (whole) proximal segment.
        add_columns(V, W, k, g_base[k + 1, 0] - px, g_base[k + 1, 1] - py, g_base[k + 1, 2] - pz, 2 * k, Jv, Jw,
                    with_angular)
    row = segment
    if sigma != 1.0:
        segment_jacobian_terms(s, omc, a, da, db, cs[segment, 0], cs[segment, 1], lengths[segment], sigma, jv, jw)
        row = V.shape[0] - 1
        rotate_columns(R_base, segment, jv, jw, V, W, row)
    add_columns(V, W, row, 0.0, 0.0, 0.0, 2 * segment, Jv, Jw, with_angular)


@kernel(inline="always")
def add_columns(V, W, row, arm0, arm1, arm2, col0, Jv, Jw, with_angular):
    """Columns col0, col0 + 1 of a point's twist from a segment's world columns and the lever arm (m)."""
    for c in range(2):
        w0 = W[row, 0, c]
        w1 = W[row, 1, c]
        w2 = W[row, 2, c]
        col = col0 + c
        Jv[0, col] = V[row, 0, c] + arm1 * w2 - arm2 * w1
        Jv[1, col] = V[row, 1, c] + arm2 * w0 - arm0 * w2
        Jv[2, col] = V[row, 2, c] + arm0 * w1 - arm1 * w0
        if with_angular:
            Jw[0, col] = w0
            Jw[1, col] = w1
            Jw[2, col] = w2


@kernel
def body_point(q, robot, ws, segment, sigma, out):
    """World position (m) of the backbone point at arc fraction ``sigma`` of ``segment`` (frames in ws)."""
    delta = q[2 * segment + 1]
    body_point_cs(q, robot, ws, segment, sigma, math.cos(delta), math.sin(delta), out)


@kernel
def body_point_cs(q, robot, ws, segment, sigma, cd, sd, out):
    """``body_point`` given cos and sin of the segment's delta (shared by all its samples)."""
    _, _, a, b, _, _ = bend_terms(sigma * (HALF_PI - q[2 * segment]))
    out[0], out[1], out[2] = point_in_world(ws.R_base, ws.g_base, segment, sigma * robot.lengths[segment], cd, sd,
                                            a, b)


@kernel(inline="always")
def point_in_world(R_base, g_base, segment, length, cd, sd, a, b):
    """World position (m) of the point of ``segment`` at arc length ``length`` (m) from its base, given
    cos / sin of delta and the shape factors a, b at its bend (eq 8 of paper 000, then the base frame)."""
    p0 = length * cd * a
    p1 = -length * sd * a
    p2 = length * b
    x = g_base[segment, 0] + R_base[segment, 0, 0] * p0 + R_base[segment, 0, 1] * p1 + R_base[segment, 0, 2] * p2
    y = g_base[segment, 1] + R_base[segment, 1, 0] * p0 + R_base[segment, 1, 1] * p1 + R_base[segment, 1, 2] * p2
    z = g_base[segment, 2] + R_base[segment, 2, 0] * p0 + R_base[segment, 2, 1] * p1 + R_base[segment, 2, 2] * p2
    return x, y, z


@kernel(borrows=True)
def tip_kernel(q, robot, ws, p, R, J):
    """Tip position, rotation and 6 x dof Jacobian [v; w] in {w} (eq 2 with paper-notes §1.2) for one q.

    Leaves the ``frames`` of q in ws, which ``points_kernel_framed`` reuses."""
    fill_frames(q, robot, ws)
    lengths = robot.lengths
    n = lengths.shape[0]
    dof = q.shape[0]
    R_base, g_base, Jv, Jw = ws.R_base, ws.g_base, ws.Jv, ws.Jw
    for a in range(3):
        p[a] = g_base[n, a]
        for b in range(3):
            R[a, b] = R_base[n, a, b]
    # sigma = 1: the own segment's columns are the whole segment's, so its bend terms are not read.
    point_columns_framed(lengths, R_base, g_base, ws.cs, ws.jv, ws.jw, ws.V, ws.W, dof, n - 1, 1.0, p[0], p[1], p[2],
                         0.0, 0.0, 0.0, 0.0, 0.0, Jv, Jw, True)
    for a in range(3):
        for col in range(dof):
            J[a, col] = Jv[a, col]
            J[3 + a, col] = Jw[a, col]


@kernel
def tip_batch(qs, robot, p, R, J):
    if not all_finite(qs):
        return False
    ws = make_workspace(robot.lengths.shape[0])
    for i in range(qs.shape[0]):
        tip_kernel(qs[i], robot, ws, p[i], R[i], J[i])
    return True


@kernel
def tip_single(q, lengths, stiffness, n_insert, p, R, J):
    # Plain arrays, not the bundle: unboxing a namedtuple argument costs ~0.7 us per call.
    if not all_finite(q):
        return False
    tip_kernel(q, MBCRKernelArgs(lengths, stiffness, n_insert), make_workspace(lengths.shape[0]), p, R, J)
    return True


@kernel
def points_kernel(q, robot, ws, segments, fractions, P, JV):
    """Positions (m, 3) and translational Jacobians (m, 3, dof) of body points, for one q."""
    fill_frames(q, robot, ws)
    points_kernel_framed(q, robot, ws, segments, fractions, P, JV)


@kernel(inline="always")
def points_kernel_framed(q, robot, ws, segments, fractions, P, JV):
    """``points_kernel`` with the ``frames`` of q already in ws (as ``tip_kernel`` leaves it)."""
    lengths = robot.lengths
    R_base, g_base, cs, jv, jw, V, W, dummy = ws.R_base, ws.g_base, ws.cs, ws.jv, ws.jw, ws.V, ws.W, ws.Jw
    dof = q.shape[0]
    for i in range(segments.shape[0]):
        segment = segments[i]
        sigma = fractions[i]
        # One set of bend terms at sigma * bend for the point's position and its own segment's columns.
        s, omc, a, b, da, db = bend_terms(sigma * (HALF_PI - q[2 * segment]))
        px, py, pz = point_in_world(R_base, g_base, segment, sigma * lengths[segment], cs[segment, 0],
                                    cs[segment, 1], a, b)
        P[i, 0] = px
        P[i, 1] = py
        P[i, 2] = pz
        point_columns_framed(lengths, R_base, g_base, cs, jv, jw, V, W, dof, segment, sigma, px, py, pz, s, omc, a,
                             da, db, JV[i], dummy, False)


@kernel
def positions_batch(qs, robot, segments, fractions, P):
    """Positions only (N, m, 3) of body points: ``points_kernel_framed``'s arithmetic without the Jacobians.

    A small kernel of its own, so that what needs positions only (the hold-start search of every
    OcclusionAvoidance process) does not compile the Jacobian kernel on an empty cache (~2.8 s).
    """
    if not all_finite(qs):
        return False
    ws = make_workspace(robot.lengths.shape[0])
    lengths = robot.lengths
    R_base, g_base, cs = ws.R_base, ws.g_base, ws.cs
    for n in range(qs.shape[0]):
        q = qs[n]
        fill_frames(q, robot, ws)
        for i in range(segments.shape[0]):
            segment = segments[i]
            sigma = fractions[i]
            _, _, a, b, _, _ = bend_terms(sigma * (HALF_PI - q[2 * segment]))
            P[n, i, 0], P[n, i, 1], P[n, i, 2] = point_in_world(R_base, g_base, segment, sigma * lengths[segment],
                                                                cs[segment, 0], cs[segment, 1], a, b)
    return True


@kernel
def points_batch(qs, robot, segments, fractions, P, JV):
    if not all_finite(qs):
        return False
    ws = make_workspace(robot.lengths.shape[0])
    for i in range(qs.shape[0]):
        points_kernel(qs[i], robot, ws, segments, fractions, P[i], JV[i])
    return True


@kernel(borrows=True)
def backbone_kernel(q, robot, ws, n_per_segment, out):
    """Backbone samples from the channel exit (paper-notes §1.3 item 13).

    ``robot.n_insert`` samples from the origin toward [0, 0, q_ins] (the first at the origin, the last
    one step before the base of segment 1), then arc fractions k/n for k = 0..n on segment 1 and
    k = 1..n on the others. With q_ins = 0 the inserted samples coincide with the origin, which is
    outside every cone, so the count stays fixed and batches keep one shape.
    """
    fill_frames(q, robot, ws)
    lengths = robot.lengths
    n = lengths.shape[0]
    n_insert = robot.n_insert
    R_base, g_base, cs = ws.R_base, ws.g_base, ws.cs
    idx = 0
    for k in range(n_insert):
        out[idx, 0] = 0.0
        out[idx, 1] = 0.0
        out[idx, 2] = q[2 * n] * k / n_insert
        idx += 1
    for j in range(n):
        start = 0 if j == 0 else 1
        bend = HALF_PI - q[2 * j]
        for k in range(start, n_per_segment + 1):
            sigma = k / n_per_segment
            _, _, a, b, _, _ = bend_terms(sigma * bend)
            out[idx, 0], out[idx, 1], out[idx, 2] = point_in_world(R_base, g_base, j, sigma * lengths[j], cs[j, 0],
                                                                   cs[j, 1], a, b)
            idx += 1


@kernel
def backbone_batch(qs, robot, n_per_segment, out):
    if not all_finite(qs):
        return False
    ws = make_workspace(robot.lengths.shape[0])
    for i in range(qs.shape[0]):
        backbone_kernel(qs[i], robot, ws, n_per_segment, out[i])
    return True
