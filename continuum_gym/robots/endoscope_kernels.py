"""The compiled kinematics of the two-segment continuum endoscope (paper 001; paper-notes §2.2-§2.3).

``endoscope_kinematics`` takes the robot's ``EndoscopeKernelArgs`` (from
``ContinuumEndoscope.kernel_args()``) and an ``EndoscopeWorkspace``, so baselines and environments call
it inside their own compiled loops; the ``*_batch`` / ``kinematics_single`` entry points are what the
robot's numpy methods call.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.segment import (
    bend_rotation,
    bend_terms,
)

DOF = 6
#: What the compiled kernels read of the endoscope: its lengths (m).
EndoscopeKernelArgs = namedtuple("EndoscopeKernelArgs", ["L1", "Lm", "L2", "Lc", "Le"])
#: Scratch of one evaluation: the two segment rotations and w_R_1e (3 x 3 each).
EndoscopeWorkspace = namedtuple("EndoscopeWorkspace", ["R1", "W1", "R2"])


@kernel
def make_endoscope_workspace():
    """Scratch arrays of ``endoscope_kinematics``."""
    return EndoscopeWorkspace(np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)))


@kernel(inline="always")
def endoscope_kinematics(q, robot, ws, p_cam, w_R_cam, p_ct, J, with_jacobian):
    """Eqs (3), (4), (7), (8) and, if ``with_jacobian``, eq (9) for one configuration.

    ``robot`` is ``ContinuumEndoscope.kernel_args()`` (lengths in m), ``ws`` an ``EndoscopeWorkspace``.
    Writes the camera position ``p_cam`` (m), the camera / target rotation ``w_R_cam = w_R_2e``, the
    target point ``p_ct`` (m) and the 6x6 twist Jacobian ``J`` of ct in {w} (rows [v; w], columns L0,
    phi, theta1, delta1, theta2, delta2).
    """
    R1, W1, R2 = ws.R1, ws.W1, ws.R2
    L1 = robot.L1
    Lm = robot.Lm
    L2 = robot.L2
    Lc = robot.Lc
    Le = robot.Le
    L0 = q[0]
    cp = math.cos(q[1])
    sp = math.sin(q[1])
    cd1 = math.cos(q[3])
    sd1 = math.sin(q[3])
    cd2 = math.cos(q[5])
    sd2 = math.sin(q[5])
    s1, omc1, a1, b1, da1, db1 = bend_terms(q[2])
    s2, omc2, a2, b2, da2, db2 = bend_terms(q[4])

    # segment 1 in {1b}: eq (3) as L*[c_d a, -s_d a, b], eq (4) corrected
    bend_rotation(s1, omc1, cd1, sd1, R1)
    p1x = L1 * cd1 * a1
    p1y = -L1 * sd1 * a1
    p1z = L1 * b1
    # w_R_1e = Rz(phi) 1b_R_1e  (= w_R_2b, since 1e_R_2b = I)
    for j in range(3):
        W1[0, j] = cp * R1[0, j] - sp * R1[1, j]
        W1[1, j] = sp * R1[0, j] + cp * R1[1, j]
        W1[2, j] = R1[2, j]
    # w_p_1e = [0, 0, L0] + Rz(phi) 1b_p_1e;  w_p_2b = w_p_1e + Lm z_1e
    e1x = cp * p1x - sp * p1y
    e1y = sp * p1x + cp * p1y
    e1z = L0 + p1z
    b2x = e1x + Lm * W1[0, 2]
    b2y = e1y + Lm * W1[1, 2]
    b2z = e1z + Lm * W1[2, 2]
    # segment 2 in {2b}
    bend_rotation(s2, omc2, cd2, sd2, R2)
    p2x = L2 * cd2 * a2
    p2y = -L2 * sd2 * a2
    p2z = L2 * b2
    # w_R_2e = w_R_2b 2b_R_2e;  w_p_2e = w_p_2b + w_R_2b 2b_p_2e
    for i in range(3):
        for j in range(3):
            w_R_cam[i, j] = W1[i, 0] * R2[0, j] + W1[i, 1] * R2[1, j] + W1[i, 2] * R2[2, j]
    e2x = b2x + W1[0, 0] * p2x + W1[0, 1] * p2y + W1[0, 2] * p2z
    e2y = b2y + W1[1, 0] * p2x + W1[1, 1] * p2y + W1[1, 2] * p2z
    e2z = b2z + W1[2, 0] * p2x + W1[2, 1] * p2y + W1[2, 2] * p2z
    # camera at Lc and target point ct at Lc + Le along z_2e (eq 8)
    Lt = Lc + Le
    p_cam[0] = e2x + Lc * w_R_cam[0, 2]
    p_cam[1] = e2y + Lc * w_R_cam[1, 2]
    p_cam[2] = e2z + Lc * w_R_cam[2, 2]
    ctx = e2x + Lt * w_R_cam[0, 2]
    cty = e2y + Lt * w_R_cam[1, 2]
    ctz = e2z + Lt * w_R_cam[2, 2]
    p_ct[0] = ctx
    p_ct[1] = cty
    p_ct[2] = ctz
    if not with_jacobian:
        return

    # ---- eq (9) with paper-notes §2.2 / §2.3 item 3, assembled directly in {w} ----
    # column L0: J0v = e3, J0w = 0
    J[0, 0] = 0.0
    J[1, 0] = 0.0
    J[2, 0] = 1.0
    J[3, 0] = 0.0
    J[4, 0] = 0.0
    J[5, 0] = 0.0
    # column phi: w = e3, v = e3 x (w_R_1b 1b_p_ct) with 1b_p_ct the vector {1b} -> ct
    J[0, 1] = -cty
    J[1, 1] = ctx
    J[2, 1] = 0.0
    J[3, 1] = 0.0
    J[4, 1] = 0.0
    J[5, 1] = 1.0
    # columns theta1, delta1: w_R_1b T1 and w_R_1b J1w, T1 = J1v - (1b_R_1e 1e_p_ct)^ J1w
    rx = ctx - e1x
    ry = cty - e1y
    rz = ctz - e1z
    # eq (5), (6) in {1b}
    vtx = L1 * cd1 * da1
    vty = -L1 * sd1 * da1
    vtz = L1 * db1
    vdx = -L1 * sd1 * a1
    vdy = -L1 * cd1 * a1
    wtx = sd1
    wty = cd1
    wdx = cd1 * s1
    wdy = -sd1 * s1
    wdz = -omc1
    # rotate by Rz(phi)
    Wtx = cp * wtx - sp * wty
    Wty = sp * wtx + cp * wty
    Wdx = cp * wdx - sp * wdy
    Wdy = sp * wdx + cp * wdy
    Wdz = wdz
    J[0, 2] = cp * vtx - sp * vty + (Wty * rz)
    J[1, 2] = sp * vtx + cp * vty - (Wtx * rz)
    J[2, 2] = vtz + (Wtx * ry - Wty * rx)
    J[3, 2] = Wtx
    J[4, 2] = Wty
    J[5, 2] = 0.0
    J[0, 3] = cp * vdx - sp * vdy + (Wdy * rz - Wdz * ry)
    J[1, 3] = sp * vdx + cp * vdy + (Wdz * rx - Wdx * rz)
    J[2, 3] = Wdx * ry - Wdy * rx
    J[3, 3] = Wdx
    J[4, 3] = Wdy
    J[5, 3] = Wdz
    # columns theta2, delta2: w_R_2b T2 and w_R_2b J2w, T2 = J2v - (2b_R_2e 2e_p_ct)^ J2w
    rx = ctx - e2x
    ry = cty - e2y
    rz = ctz - e2z
    vtx = L2 * cd2 * da2
    vty = -L2 * sd2 * da2
    vtz = L2 * db2
    vdx = -L2 * sd2 * a2
    vdy = -L2 * cd2 * a2
    wtx = sd2
    wty = cd2
    wdx = cd2 * s2
    wdy = -sd2 * s2
    wdz = -omc2
    for i in range(3):
        Wt = W1[i, 0] * wtx + W1[i, 1] * wty
        Wd = W1[i, 0] * wdx + W1[i, 1] * wdy + W1[i, 2] * wdz
        J[3 + i, 4] = Wt
        J[3 + i, 5] = Wd
        J[i, 4] = W1[i, 0] * vtx + W1[i, 1] * vty + W1[i, 2] * vtz
        J[i, 5] = W1[i, 0] * vdx + W1[i, 1] * vdy
    Wtx = J[3, 4]
    Wty = J[4, 4]
    Wtz = J[5, 4]
    Wdx = J[3, 5]
    Wdy = J[4, 5]
    Wdz = J[5, 5]
    J[0, 4] += Wty * rz - Wtz * ry
    J[1, 4] += Wtz * rx - Wtx * rz
    J[2, 4] += Wtx * ry - Wty * rx
    J[0, 5] += Wdy * rz - Wdz * ry
    J[1, 5] += Wdz * rx - Wdx * rz
    J[2, 5] += Wdx * ry - Wdy * rx


@kernel(inline="always")
def require_finite(q):
    for j in range(q.shape[0]):
        if not math.isfinite(q[j]):
            raise ValueError("q must be finite (no NaN or inf)")


@kernel
def kinematics_batch(Q, robot, p_cam, w_R_cam, p_ct, J, with_jacobian):
    """Rows of Q (n, 6) into p_cam (n, 3), w_R_cam (n, 3, 3), p_ct (n, 3) and, if ``with_jacobian``,
    J (n, 6, 6) (else J is (1, 6, 6) and unused)."""
    for k in range(Q.shape[0]):
        require_finite(Q[k])
    ws = make_endoscope_workspace()
    for k in range(Q.shape[0]):
        endoscope_kinematics(Q[k], robot, ws, p_cam[k], w_R_cam[k], p_ct[k], J[k if with_jacobian else 0],
                             with_jacobian)


@kernel
def kinematics_single(q, L1, Lm, L2, Lc, Le, p_cam, w_R_cam, p_ct, J, with_jacobian):
    # Plain floats, not the bundle: unboxing a namedtuple argument costs ~0.7 us per call.
    require_finite(q)
    endoscope_kinematics(q, EndoscopeKernelArgs(L1, Lm, L2, Lc, Le), make_endoscope_workspace(), p_cam, w_R_cam,
                         p_ct, J, with_jacobian)


# placeholder for J when only forward kinematics are asked for (never written)
UNUSED_JACOBIAN = np.empty((1, 6, 6))


@kernel
def backbone_batch(Q, robot, m):
    """Centre line samples (n, 2m + 4, 3) in m: origin, {1b}, m points of segment 1, {2b}, m points of
    segment 2, camera."""
    n = Q.shape[0]
    npts = 2 * m + 4
    out = np.empty((n, npts, 3))
    L1 = robot.L1
    Lm = robot.Lm
    L2 = robot.L2
    Lc = robot.Lc
    R1 = np.empty((3, 3))
    R2 = np.empty((3, 3))
    W1 = np.empty((3, 3))
    for k in range(n):
        require_finite(Q[k])
    for k in range(n):
        L0 = Q[k, 0]
        cp = math.cos(Q[k, 1])
        sp = math.sin(Q[k, 1])
        cd1 = math.cos(Q[k, 3])
        sd1 = math.sin(Q[k, 3])
        cd2 = math.cos(Q[k, 5])
        sd2 = math.sin(Q[k, 5])
        out[k, 0, 0] = 0.0
        out[k, 0, 1] = 0.0
        out[k, 0, 2] = 0.0
        out[k, 1, 0] = 0.0
        out[k, 1, 1] = 0.0
        out[k, 1, 2] = L0
        # segment 1, fractions 1/m .. 1 of the arc (arc of length f L1 bending f theta1)
        for i in range(1, m + 1):
            f = i / m
            s, omc, a, b, da, db = bend_terms(f * Q[k, 2])
            px = f * L1 * cd1 * a
            py = -f * L1 * sd1 * a
            pz = f * L1 * b
            out[k, 1 + i, 0] = cp * px - sp * py
            out[k, 1 + i, 1] = sp * px + cp * py
            out[k, 1 + i, 2] = L0 + pz
        s1, omc1, a1, b1, da1, db1 = bend_terms(Q[k, 2])
        bend_rotation(s1, omc1, cd1, sd1, R1)
        for j in range(3):
            W1[0, j] = cp * R1[0, j] - sp * R1[1, j]
            W1[1, j] = sp * R1[0, j] + cp * R1[1, j]
            W1[2, j] = R1[2, j]
        # rigid cylinder to {2b}
        bx = out[k, 1 + m, 0] + Lm * W1[0, 2]
        by = out[k, 1 + m, 1] + Lm * W1[1, 2]
        bz = out[k, 1 + m, 2] + Lm * W1[2, 2]
        out[k, 2 + m, 0] = bx
        out[k, 2 + m, 1] = by
        out[k, 2 + m, 2] = bz
        for i in range(1, m + 1):
            f = i / m
            s, omc, a, b, da, db = bend_terms(f * Q[k, 4])
            px = f * L2 * cd2 * a
            py = -f * L2 * sd2 * a
            pz = f * L2 * b
            for r in range(3):
                out[k, 2 + m + i, r] = (
                    out[k, 2 + m, r] + W1[r, 0] * px + W1[r, 1] * py + W1[r, 2] * pz
                )
        s2, omc2, a2, b2, da2, db2 = bend_terms(Q[k, 4])
        bend_rotation(s2, omc2, cd2, sd2, R2)
        for r in range(3):
            z = W1[r, 0] * R2[0, 2] + W1[r, 1] * R2[1, 2] + W1[r, 2] * R2[2, 2]
            out[k, npts - 1, r] = out[k, npts - 2, r] + Lc * z
    return out
