"""Two-segment continuum endoscope of Deng, Xu et al. (paper 001), corrected per paper-notes §2.

Configuration ``q = [L0, phi, theta1, delta1, theta2, delta2]`` in SI units: ``L0`` in m (stem
insertion), every angle in rad. ``theta = 0`` is a straight segment (Xu's convention, paper-notes §2.1);
the bending direction of segment t in {tb} is ``(cos delta, -sin delta, 0)``.

Frames (paper Fig. 2c): {w} at the incision; {1b} = {w} translated by ``[0, 0, L0]`` and rotated
``Rz(phi)``; segment 1 from {1b} to {1e}; a rigid multi-lumen cylinder of length ``Lm`` from {1e}
to {2b}; segment 2 from {2b} to {2e}. The camera sits ``Lc`` along ``z_2e`` from {2e} with
``w_R_cam = w_R_2e`` (its z-axis is the viewing axis); the visual target point ct sits
``Lc + Le`` along ``z_2e`` and ``w_R_ct = w_R_2e`` as well.

All lengths are in metres. The kinematics accept any finite ``q``; joint limits are only data.

The hot path (forward kinematics + Jacobian) is one numba kernel that loops over a flattened
batch, so a batched result equals the looped single results bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .validation import as_configuration, positive

__all__ = [
    "ContinuumEndoscope",
    "SERIES_THRESHOLD",
    "endoscope_segment_pose",
    "endoscope_segment_jacobian",
]

#: |theta| below which the series of paper-notes §2.2 replace the closed forms of eqs (3), (5).
SERIES_THRESHOLD = 2e-3

_DOF = 6


# ----------------------------------------------------------------------------------------------
# Scalar building blocks (compiled; inlined into the batch kernels)
# ----------------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _bend_terms(theta):
    """Return ``s, omc, a, b, da, db`` of a bending angle ``theta`` (rad).

    ``s = sin(theta)``, ``omc = 1 - cos(theta)`` (via the half angle, no cancellation),
    ``a = (1 - cos)/theta``, ``b = sin/theta`` and their derivatives ``da``, ``db`` in theta.
    Below ``SERIES_THRESHOLD`` the series of paper-notes §2.2 are used, so all are exact and finite
    at theta = 0.
    """
    sh = math.sin(0.5 * theta)
    ch = math.cos(0.5 * theta)
    s = 2.0 * sh * ch
    omc = 2.0 * sh * sh
    if abs(theta) < SERIES_THRESHOLD:
        t2 = theta * theta
        a = theta * (0.5 - t2 * (1.0 / 24.0 - t2 / 720.0))
        b = 1.0 - t2 * (1.0 / 6.0 - t2 / 120.0)
        da = 0.5 - t2 * (1.0 / 8.0 - t2 / 144.0)
        db = -theta * (1.0 / 3.0 - t2 * (1.0 / 30.0 - t2 / 840.0))
    else:
        a = omc / theta
        b = s / theta
        da = (s - a) / theta  # sin/theta - (1 - cos)/theta^2
        db = (1.0 - omc - b) / theta  # cos/theta - sin/theta^2
    return s, omc, a, b, da, db


@njit(cache=True, inline="always")
def _segment_rotation(s, omc, cd, sd, R):
    """Write ``tb_R_te = Rz(-delta) Ry(theta) Rz(delta)`` (eq 4 corrected, paper-notes §2.3 item 2) into R."""
    R[0, 0] = 1.0 - omc * cd * cd
    R[0, 1] = omc * cd * sd
    R[0, 2] = s * cd
    R[1, 0] = omc * cd * sd
    R[1, 1] = 1.0 - omc * sd * sd
    R[1, 2] = -s * sd
    R[2, 0] = -s * cd
    R[2, 1] = s * sd
    R[2, 2] = 1.0 - omc


@njit(cache=True, inline="always")
def _kinematics_one(q, geom, p_cam, w_R_cam, p_ct, J, with_jacobian, R1, W1, R2):
    """Eqs (3), (4), (7), (8) and, if ``with_jacobian``, eq (9) for one configuration.

    ``geom = [L1, Lm, L2, Lc, Le]`` (m). Writes the camera position ``p_cam`` (m), the camera /
    target rotation ``w_R_cam = w_R_2e``, the target point ``p_ct`` (m) and the 6x6 twist Jacobian
    ``J`` of ct in {w} (rows [v; w], columns L0, phi, theta1, delta1, theta2, delta2).
    ``R1``, ``W1``, ``R2`` are 3x3 scratch arrays.
    """
    L1 = geom[0]
    Lm = geom[1]
    L2 = geom[2]
    Lc = geom[3]
    Le = geom[4]
    L0 = q[0]
    cp = math.cos(q[1])
    sp = math.sin(q[1])
    cd1 = math.cos(q[3])
    sd1 = math.sin(q[3])
    cd2 = math.cos(q[5])
    sd2 = math.sin(q[5])
    s1, omc1, a1, b1, da1, db1 = _bend_terms(q[2])
    s2, omc2, a2, b2, da2, db2 = _bend_terms(q[4])

    # segment 1 in {1b}: eq (3) as L*[c_d a, -s_d a, b], eq (4) corrected
    _segment_rotation(s1, omc1, cd1, sd1, R1)
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
    _segment_rotation(s2, omc2, cd2, sd2, R2)
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


@njit(cache=True, inline="always")
def _require_finite(q):
    for j in range(q.shape[0]):
        if not math.isfinite(q[j]):
            raise ValueError("q must be finite (no NaN or inf)")


@njit(cache=True)
def _kinematics_into_1(q, geom, p_cam, w_R_cam, p_ct, J, with_jacobian):
    """One configuration q (6,) into p_cam (3,), w_R_cam (3, 3), p_ct (3,) and, if ``with_jacobian``,
    J (6, 6)."""
    _require_finite(q)
    R1 = np.empty((3, 3))
    W1 = np.empty((3, 3))
    R2 = np.empty((3, 3))
    _kinematics_one(q, geom, p_cam, w_R_cam, p_ct, J, with_jacobian, R1, W1, R2)


@njit(cache=True)
def _kinematics_into(Q, geom, p_cam, w_R_cam, p_ct, J, with_jacobian):
    """Batch version of ``_kinematics_into_1``: Q (n, 6); J (n, 6, 6) if ``with_jacobian``, else unused."""
    for k in range(Q.shape[0]):
        _require_finite(Q[k])
    R1 = np.empty((3, 3))
    W1 = np.empty((3, 3))
    R2 = np.empty((3, 3))
    for k in range(Q.shape[0]):
        _kinematics_one(
            Q[k], geom, p_cam[k], w_R_cam[k], p_ct[k], J[k if with_jacobian else 0], with_jacobian, R1, W1, R2
        )


# placeholders for J when only forward kinematics are asked for (never written)
_UNUSED_J_1 = np.empty((6, 6))
_UNUSED_J_N = np.empty((1, 6, 6))


@njit(cache=True)
def _backbone_batch(Q, geom, m):
    """Centre line samples (n, 2m + 4, 3) in m: origin, {1b}, m points of segment 1, {2b}, m points of
    segment 2, camera."""
    n = Q.shape[0]
    npts = 2 * m + 4
    out = np.empty((n, npts, 3))
    L1 = geom[0]
    Lm = geom[1]
    L2 = geom[2]
    Lc = geom[3]
    R1 = np.empty((3, 3))
    R2 = np.empty((3, 3))
    W1 = np.empty((3, 3))
    for k in range(n):
        _require_finite(Q[k])
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
            s, omc, a, b, da, db = _bend_terms(f * Q[k, 2])
            px = f * L1 * cd1 * a
            py = -f * L1 * sd1 * a
            pz = f * L1 * b
            out[k, 1 + i, 0] = cp * px - sp * py
            out[k, 1 + i, 1] = sp * px + cp * py
            out[k, 1 + i, 2] = L0 + pz
        s1, omc1, a1, b1, da1, db1 = _bend_terms(Q[k, 2])
        _segment_rotation(s1, omc1, cd1, sd1, R1)
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
            s, omc, a, b, da, db = _bend_terms(f * Q[k, 4])
            px = f * L2 * cd2 * a
            py = -f * L2 * sd2 * a
            pz = f * L2 * b
            for r in range(3):
                out[k, 2 + m + i, r] = (
                    out[k, 2 + m, r] + W1[r, 0] * px + W1[r, 1] * py + W1[r, 2] * pz
                )
        s2, omc2, a2, b2, da2, db2 = _bend_terms(Q[k, 4])
        _segment_rotation(s2, omc2, cd2, sd2, R2)
        for r in range(3):
            z = W1[r, 0] * R2[0, 2] + W1[r, 1] * R2[1, 2] + W1[r, 2] * R2[2, 2]
            out[k, npts - 1, r] = out[k, npts - 2, r] + Lc * z
    return out


# ----------------------------------------------------------------------------------------------
# Single-segment functions (numpy, broadcasting) — eqs (3)–(6)
# ----------------------------------------------------------------------------------------------
def _bend_terms_np(theta):
    theta = np.asarray(theta, dtype=np.float64)
    sh = np.sin(0.5 * theta)
    s = 2.0 * sh * np.cos(0.5 * theta)
    omc = 2.0 * sh * sh
    small = np.abs(theta) < SERIES_THRESHOLD
    safe = np.where(small, 1.0, theta)
    t2 = theta * theta
    a = np.where(small, theta * (0.5 - t2 * (1.0 / 24.0 - t2 / 720.0)), omc / safe)
    b = np.where(small, 1.0 - t2 * (1.0 / 6.0 - t2 / 120.0), s / safe)
    da = np.where(small, 0.5 - t2 * (1.0 / 8.0 - t2 / 144.0), (s - a) / safe)
    db = np.where(
        small, -theta * (1.0 / 3.0 - t2 * (1.0 / 30.0 - t2 / 840.0)), (1.0 - omc - b) / safe
    )
    return s, omc, a, b, da, db


def _segment_args(theta, delta, length):
    length = positive(length, "length", "m")
    theta = np.asarray(theta, dtype=np.float64)
    delta = np.asarray(delta, dtype=np.float64)
    if not (np.all(np.isfinite(theta)) and np.all(np.isfinite(delta))):
        raise ValueError("theta and delta must be finite (rad)")
    theta, delta = np.broadcast_arrays(theta, delta)
    return theta, delta, length


def endoscope_segment_pose(theta, delta, length):
    """Pose of {te} in {tb} of one constant-curvature segment (eqs 3 and 4, paper-notes §2.3 item 2).

    ``theta`` (rad, 0 = straight), ``delta`` (rad) broadcast together; ``length`` in m.
    Returns ``tb_p_te`` (..., 3) in m and ``tb_R_te = Rz(-delta) Ry(theta) Rz(delta)`` (..., 3, 3).
    Exact and finite at theta = 0 (series of paper-notes §2.2 below ``SERIES_THRESHOLD``).
    """
    theta, delta, length = _segment_args(theta, delta, length)
    s, omc, a, b, _, _ = _bend_terms_np(theta)
    cd, sd = np.cos(delta), np.sin(delta)
    tb_p_te = length * np.stack([cd * a, -sd * a, b], axis=-1)
    tb_R_te = np.stack(
        [
            np.stack([1.0 - omc * cd * cd, omc * cd * sd, s * cd], axis=-1),
            np.stack([omc * cd * sd, 1.0 - omc * sd * sd, -s * sd], axis=-1),
            np.stack([-s * cd, s * sd, 1.0 - omc], axis=-1),
        ],
        axis=-2,
    )
    return tb_p_te, tb_R_te


def endoscope_segment_jacobian(theta, delta, length):
    """Twist Jacobian of {te}'s origin in {tb} per [theta, delta] rate (eqs 5 and 6, as printed).

    Returns (..., 6, 2): rows [J_tv (m/rad); J_tw (rad/rad)], columns theta, delta. ``length`` in m.
    Below ``SERIES_THRESHOLD`` uses the series of paper-notes §2.2 (exact and finite at theta = 0).
    """
    theta, delta, length = _segment_args(theta, delta, length)
    s, omc, a, _, da, db = _bend_terms_np(theta)
    cd, sd = np.cos(delta), np.sin(delta)
    zero = np.zeros_like(theta)
    rows = [
        [length * cd * da, -length * sd * a],
        [-length * sd * da, -length * cd * a],
        [length * db, zero],
        [sd, cd * s],
        [cd, -sd * s],
        [zero, -omc],
    ]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


# ----------------------------------------------------------------------------------------------
# Robot class
# ----------------------------------------------------------------------------------------------
class ContinuumEndoscope:
    """6-DoF two-segment continuum endoscope (paper 001, Fig. 2c, Table II; paper-notes §2).

    Parameters (all lengths in m, each must be finite and > 0):
        L1: length of segment 1 (default 0.020).
        Lm: length of the rigid multi-lumen cylinder between the segments (default 0.006).
        L2: length of segment 2 (default 0.030).
        Lc: camera offset along z_2e from the end of segment 2 (default 0.020).
        Le: effective view distance, camera to target point ct (default 0.120).

    ``q = [L0 (m), phi, theta1, delta1, theta2, delta2 (rad)]``; every method accepts shape (6,)
    or (..., 6) and returns matching leading dimensions.
    """

    dof = _DOF
    joint_names = ("L0", "phi", "theta1", "delta1", "theta2", "delta2")

    def __init__(self, L1=0.020, Lm=0.006, L2=0.030, Lc=0.020, Le=0.120):
        self._geom = np.array(
            [
                positive(L1, "L1", "m"),
                positive(Lm, "Lm", "m"),
                positive(L2, "L2", "m"),
                positive(Lc, "Lc", "m"),
                positive(Le, "Le", "m"),
            ]
        )
        self._geom.flags.writeable = False
        # Table II / paper-notes §2.1: L0 in m; phi hard limit; deltas unlimited (wrapped by controllers)
        self._lower = np.array([0.0, -np.pi, 0.0, -np.inf, 0.0, -np.inf])
        self._upper = np.array([0.100, np.pi, np.pi / 4, np.inf, np.pi / 2, np.inf])
        self._lower.flags.writeable = False
        self._upper.flags.writeable = False

    # -- parameters ---------------------------------------------------------------------------
    L1 = property(lambda self: float(self._geom[0]), doc="Segment 1 length (m).")
    Lm = property(lambda self: float(self._geom[1]), doc="Rigid cylinder length (m).")
    L2 = property(lambda self: float(self._geom[2]), doc="Segment 2 length (m).")
    Lc = property(lambda self: float(self._geom[3]), doc="Camera offset from the end of segment 2 (m).")
    Le = property(lambda self: float(self._geom[4]), doc="View distance camera -> target point (m).")

    @property
    def geometry(self):
        """Read-only float64 array ``[L1, Lm, L2, Lc, Le]`` (m): the ``geom`` argument of the kernels.

        Compiled controllers call ``_kinematics_one(q, geom, p_cam, w_R_cam, p_ct, J, with_jacobian,
        R1, W1, R2)`` with it inside their own loops.
        """
        return self._geom

    @property
    def joint_limits(self):
        """``(lower, upper)``, each shape (6,): L0 in m, angles in rad; deltas are ±inf.

        Table II / paper-notes §2.1: L0 in [0, 0.1] m, phi in [-pi, pi] (hard), theta1 in [0, pi/4],
        theta2 in [0, pi/2]. Fresh copies.
        """
        return self._lower.copy(), self._upper.copy()

    # -- named configurations -----------------------------------------------------------------
    @property
    def straight(self):
        """All zeros: stem not inserted (L0 = 0 m), both segments straight."""
        return np.zeros(_DOF)

    @property
    def case_study_start(self):
        """Psi0 of the case studies (paper-notes §2.1): [0.008 m, 0, 0.3857, -1.57, 0.7828, 1.57]."""
        return np.array([0.008, 0.0, 0.3857, -1.57, 0.7828, 1.57])

    home = case_study_start

    @property
    def named_configurations(self):
        """``{"straight": ..., "home": ..., "case_study_start": ...}`` (fresh arrays)."""
        return {
            "straight": self.straight,
            "home": self.home,
            "case_study_start": self.case_study_start,
        }

    # -- input handling ----------------------------------------------------------------------
    @staticmethod
    def _array(q):
        """``q`` as a float64 array of shape (..., 6), C-contiguous and writeable (finiteness is
        checked in the kernels; every error is raised by ``as_configuration`` so it names q)."""
        try:
            array = np.asarray(q, dtype=np.float64)
        except (TypeError, ValueError):
            as_configuration(q, _DOF)  # raises with a message naming q
            raise
        if array.ndim == 0 or array.shape[-1] != _DOF:
            as_configuration(array, _DOF)  # raises
        flags = array.flags
        if not (flags.c_contiguous and flags.writeable):
            array = np.array(array, order="C")
        return array

    def _run(self, q, with_jacobian):
        """reshape -> kernel -> reshape: ``(p_cam, w_R_cam, p_ct, J or None)`` with q's leading shape."""
        array = self._array(q)
        lead = array.shape[:-1]
        p_cam = np.empty(lead + (3,))
        w_R_cam = np.empty(lead + (3, 3))
        p_ct = np.empty(lead + (3,))
        J = np.empty(lead + (6, 6)) if with_jacobian else None
        try:
            if array.ndim == 1:
                _kinematics_into_1(
                    array,
                    self._geom,
                    p_cam,
                    w_R_cam,
                    p_ct,
                    J if with_jacobian else _UNUSED_J_1,
                    with_jacobian,
                )
            else:
                _kinematics_into(
                    array.reshape(-1, _DOF),
                    self._geom,
                    p_cam.reshape(-1, 3),
                    w_R_cam.reshape(-1, 3, 3),
                    p_ct.reshape(-1, 3),
                    J.reshape(-1, 6, 6) if with_jacobian else _UNUSED_J_N,
                    with_jacobian,
                )
        except ValueError:
            as_configuration(array, _DOF)  # raises "q must be finite ..."
            raise
        return p_cam, w_R_cam, p_ct, J

    # -- kinematics ----------------------------------------------------------------------------
    def forward_kinematics(self, q):
        """Camera frame in {w}: ``(p (..., 3) in m, R (..., 3, 3))``.

        Eqs (3), (4), (7), (8) with paper-notes §2.2 and §2.3 item 2. The camera sits ``Lc`` along z_2e
        from the end of segment 2; ``R = w_R_ct = w_R_2e``, its z-axis is the viewing axis.
        """
        p_cam, w_R_cam, _, _ = self._run(q, False)
        return p_cam, w_R_cam

    def target_point(self, q):
        """Visual target point ct, ``Lc + Le`` along z_2e from the end of segment 2: (..., 3) in m (eq 8)."""
        return self._run(q, False)[2]

    def target_pose(self, q):
        """``(w_p_ct (..., 3) in m, w_R_ct (..., 3, 3))`` (eqs 7 and 8 with paper-notes §2.2 / §2.3 item 2)."""
        _, w_R_ct, p_ct, _ = self._run(q, False)
        return p_ct, w_R_ct

    def jacobian(self, q):
        """Twist Jacobian of the target point ct in {w}: (..., 6, 6).

        Eq (9) corrected per paper-notes §2.2 and §2.3 item 3.

        Rows ``[v (m/s); w (rad/s)]``; columns per rate of L0 (m/s), phi, theta1, delta1, theta2,
        delta2 (rad/s). J0v = [e3, 0], J0w = [0, e3]; T_t = J_tv - (lever from segment t's end to ct)^ J_tw,
        with J_tv, J_tw of eqs (5), (6) (series of paper-notes §2.2 near straight).
        """
        return self._run(q, True)[3]

    def fk_jacobian(self, q):
        """Everything in one kernel call: ``(p_cam (m), R, p_ct (m), J)`` as in the methods above.

        Equals ``forward_kinematics``, ``target_point`` and ``jacobian`` exactly; the fast path for
        controllers.
        """
        return self._run(q, True)

    def backbone(self, q, n_per_segment=20):
        """Sampled centre line for drawing: (..., 2 * n_per_segment + 4, 3) in m.

        Points: base origin (0, 0, 0); {1b} at [0, 0, L0]; ``n_per_segment`` points along segment 1
        (ending at {1e}); {2b} after the rigid Lm cylinder; ``n_per_segment`` points along segment 2
        (ending at {2e}); the camera, Lc further along z_2e. Arcs follow eq (3) at fractions of the segment.
        """
        m = int(n_per_segment)
        if m != n_per_segment or m < 1:
            raise ValueError(f"n_per_segment must be an integer >= 1; got {n_per_segment!r}")
        array = self._array(q)
        try:
            pts = _backbone_batch(array.reshape(-1, _DOF), self._geom, m)
        except ValueError:
            as_configuration(array, _DOF)  # raises "q must be finite ..."
            raise
        return pts.reshape(array.shape[:-1] + (2 * m + 4, 3))

    def __repr__(self):
        L1, Lm, L2, Lc, Le = self._geom
        return f"ContinuumEndoscope(L1={L1}, Lm={Lm}, L2={L2}, Lc={Lc}, Le={Le})"
