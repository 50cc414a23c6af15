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
batch, so a batched result equals the looped single results bit for bit. Both segments use the
segment terms of ``continuum_gym.robots.segment``.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit
from numpy.typing import ArrayLike

from continuum_gym.robots.segment import (  # noqa: F401  (the segment functions are public here too)
    SERIES_SWITCH,
    bend_rotation,
    bend_terms,
    endoscope_segment_jacobian,
    endoscope_segment_pose,
)
from continuum_gym.validation import (
    as_array,
    as_configuration,
    integer,
    number,
    positive,
)

__all__ = [
    "ContinuumEndoscope",
    "EndoscopeKernelArgs",
    "EndoscopeWorkspace",
    "SERIES_THRESHOLD",
    "endoscope_kinematics",
    "endoscope_segment_pose",
    "endoscope_segment_jacobian",
    "make_endoscope_workspace",
]

#: |theta| below which the series of paper-notes §2.2 replace the closed forms of eqs (3), (5).
SERIES_THRESHOLD = SERIES_SWITCH

DOF = 6
#: What the compiled kernels read of the endoscope: its lengths (m).
EndoscopeKernelArgs = namedtuple("EndoscopeKernelArgs", ["L1", "Lm", "L2", "Lc", "Le"])
#: Scratch of one evaluation: the two segment rotations and w_R_1e (3 x 3 each).
EndoscopeWorkspace = namedtuple("EndoscopeWorkspace", ["R1", "W1", "R2"])


@njit(cache=True)
def make_endoscope_workspace():
    """Scratch arrays of ``endoscope_kinematics``."""
    return EndoscopeWorkspace(np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)))


@njit(cache=True, inline="always")
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


@njit(cache=True, inline="always")
def _require_finite(q):
    for j in range(q.shape[0]):
        if not math.isfinite(q[j]):
            raise ValueError("q must be finite (no NaN or inf)")


@njit(cache=True)
def _kinematics_batch(Q, robot, p_cam, w_R_cam, p_ct, J, with_jacobian):
    """Rows of Q (n, 6) into p_cam (n, 3), w_R_cam (n, 3, 3), p_ct (n, 3) and, if ``with_jacobian``,
    J (n, 6, 6) (else J is (1, 6, 6) and unused)."""
    for k in range(Q.shape[0]):
        _require_finite(Q[k])
    ws = make_endoscope_workspace()
    for k in range(Q.shape[0]):
        endoscope_kinematics(Q[k], robot, ws, p_cam[k], w_R_cam[k], p_ct[k], J[k if with_jacobian else 0],
                             with_jacobian)


@njit(cache=True)
def _kinematics_single(q, L1, Lm, L2, Lc, Le, p_cam, w_R_cam, p_ct, J, with_jacobian):
    # Plain floats, not the bundle: unboxing a namedtuple argument costs ~0.7 us per call.
    _require_finite(q)
    endoscope_kinematics(q, EndoscopeKernelArgs(L1, Lm, L2, Lc, Le), make_endoscope_workspace(), p_cam, w_R_cam,
                         p_ct, J, with_jacobian)


# placeholder for J when only forward kinematics are asked for (never written)
_UNUSED_J = np.empty((1, 6, 6))


@njit(cache=True)
def _backbone_batch(Q, robot, m):
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



# ----------------------------------------------------------------------------------------------
# Robot class
# ----------------------------------------------------------------------------------------------
#: Table II / paper-notes §2.1 joint limits: L0 in [0, 0.1] m, phi in [-pi, pi] (hard), theta1 in
#: [0, pi/4], theta2 in [0, pi/2]; the deltas are unlimited (wrapped by the controllers).
PAPER_LOWER = (0.0, -math.pi, 0.0, -math.inf, 0.0, -math.inf)
PAPER_UPPER = (0.100, math.pi, math.pi / 4, math.inf, math.pi / 2, math.inf)
#: Physical ranges a user's limits must stay in: insertion 0-0.5 m, |phi| <= pi, bends 0-pi.
_LIMIT_RANGES = ((0.0, 0.5, "m"), (-math.pi, math.pi, "rad"), (0.0, math.pi, "rad"), (-math.inf, math.inf, "rad"),
                 (0.0, math.pi, "rad"), (-math.inf, math.inf, "rad"))


def _read_only(values) -> np.ndarray:
    array = np.array(values, dtype=float)
    array.flags.writeable = False
    return array


class ContinuumEndoscope:
    """6-DoF two-segment continuum endoscope (paper 001, Fig. 2c, Table II; paper-notes §2).

    Parameters (all lengths in m, each must be finite and > 0):
        L1: length of segment 1 (default 0.020).
        Lm: length of the rigid multi-lumen cylinder between the segments (default 0.006).
        L2: length of segment 2 (default 0.030).
        Lc: camera offset along z_2e from the end of segment 2 (default 0.020).
        Le: effective view distance, camera to target point ct (default 0.120).
        joint_limits: ``(lower, upper)``, each 6 values [L0 (m), phi, theta1, delta1, theta2, delta2 (rad)];
            ``None`` is Table II's. L0 within [0, 0.5] m, phi within [-pi, pi], bends within [0, pi];
            the deltas may be +-inf (unlimited, wrapped).

    ``q = [L0 (m), phi, theta1, delta1, theta2, delta2 (rad)]``; every method accepts shape (6,)
    or (..., 6) and returns matching leading dimensions.
    """

    dof = DOF
    joint_names = ("L0", "phi", "theta1", "delta1", "theta2", "delta2")

    def __init__(self, L1: float = 0.020, Lm: float = 0.006, L2: float = 0.030, Lc: float = 0.020,
                 Le: float = 0.120, joint_limits=None) -> None:
        self._args = EndoscopeKernelArgs(positive(L1, "L1", "m"), positive(Lm, "Lm", "m"), positive(L2, "L2", "m"),
                                         positive(Lc, "Lc", "m"), positive(Le, "Le", "m"))
        self._geom = _read_only(self._args)
        if joint_limits is None:
            lower, upper = PAPER_LOWER, PAPER_UPPER
        else:
            try:
                lower, upper = joint_limits
            except (TypeError, ValueError):
                raise ValueError("joint_limits must be (lower, upper), each 6 values [L0 (m), phi, theta1, delta1, "
                                 f"theta2, delta2 (rad)]; got {joint_limits!r}") from None
            lower = as_array(lower, "joint_limits lower", (6,)).reshape(6)
            upper = as_array(upper, "joint_limits upper", (6,)).reshape(6)
            for k, (lo, hi, unit) in enumerate(_LIMIT_RANGES):
                name = self.joint_names[k]
                for side, value in (("lower", lower[k]), ("upper", upper[k])):
                    if math.isfinite(lo) or math.isfinite(value):  # only the deltas may be unlimited (+-inf)
                        number(value, f"joint_limits {side} {name}", low=lo, high=hi, unit=unit)
                if math.isnan(lower[k]) or math.isnan(upper[k]) or not lower[k] < upper[k]:
                    raise ValueError(f"joint_limits: lower {name} must be < upper {name}; got {lower[k]} and "
                                     f"{upper[k]}")
        self._lower = _read_only(lower)
        self._upper = _read_only(upper)

    # -- parameters ---------------------------------------------------------------------------
    L1 = property(lambda self: self._args.L1, doc="Segment 1 length (m).")
    Lm = property(lambda self: self._args.Lm, doc="Rigid cylinder length (m).")
    L2 = property(lambda self: self._args.L2, doc="Segment 2 length (m).")
    Lc = property(lambda self: self._args.Lc, doc="Camera offset from the end of segment 2 (m).")
    Le = property(lambda self: self._args.Le, doc="View distance camera -> target point (m).")

    def kernel_args(self) -> EndoscopeKernelArgs:
        """(L1, Lm, L2, Lc, Le) in m: the bundle ``endoscope_kinematics`` and the controllers' kernels read."""
        return self._args

    @property
    def geometry(self) -> np.ndarray:
        """Read-only float64 array ``[L1, Lm, L2, Lc, Le]`` (m)."""
        return self._geom

    @property
    def joint_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)``, each shape (6,): L0 in m, angles in rad; deltas may be +-inf. Fresh copies."""
        return self._lower.copy(), self._upper.copy()

    # -- named configurations -----------------------------------------------------------------
    @property
    def straight(self) -> np.ndarray:
        """All zeros: stem not inserted (L0 = 0 m), both segments straight."""
        return np.zeros(DOF)

    @property
    def case_study_start(self) -> np.ndarray:
        """Psi0 of the case studies (paper-notes §2.1): [0.008 m, 0, 0.3857, -1.57, 0.7828, 1.57]."""
        return np.array([0.008, 0.0, 0.3857, -1.57, 0.7828, 1.57])

    home = case_study_start

    @property
    def named_configurations(self) -> dict:
        """``{"straight": ..., "home": ..., "case_study_start": ...}`` (fresh arrays)."""
        return {"straight": self.straight, "home": self.home, "case_study_start": self.case_study_start}

    # -- kinematics ----------------------------------------------------------------------------
    def _run(self, q: ArrayLike, with_jacobian):
        """reshape -> kernel -> reshape: ``(p_cam, w_R_cam, p_ct, J or None)`` with q's leading shape."""
        if type(q) is np.ndarray and q.shape == (DOF,) and q.dtype == np.float64 and q.flags.c_contiguous:
            # one configuration, already in the kernel's layout: the controllers' per-step call
            p_cam, w_R_cam, p_ct = np.empty(3), np.empty((3, 3)), np.empty(3)
            J = np.empty((6, 6)) if with_jacobian else _UNUSED_J[0]
            try:
                _kinematics_single(q, *self._args, p_cam, w_R_cam, p_ct, J, with_jacobian)
            except ValueError:
                as_configuration(q, DOF)  # raises "q must be finite ..."
                raise
            return p_cam, w_R_cam, p_ct, (J if with_jacobian else None)
        array = np.ascontiguousarray(as_array(q, "q", (DOF,)))
        if array.ndim == 0:
            raise ValueError(f"q must have shape (..., {DOF}); got a scalar")
        lead = array.shape[:-1]
        n = math.prod(lead)  # np.prod of an empty shape costs 4 us
        p_cam = np.empty((n, 3))
        w_R_cam = np.empty((n, 3, 3))
        p_ct = np.empty((n, 3))
        J = np.empty((n, 6, 6)) if with_jacobian else _UNUSED_J
        try:
            _kinematics_batch(array.reshape(-1, DOF), self._args, p_cam, w_R_cam, p_ct, J, with_jacobian)
        except ValueError:
            as_configuration(array, DOF)  # raises "q must be finite ..."
            raise
        return (p_cam.reshape(lead + (3,)), w_R_cam.reshape(lead + (3, 3)), p_ct.reshape(lead + (3,)),
                J.reshape(lead + (6, 6)) if with_jacobian else None)

    def forward_kinematics(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Camera frame in {w}: ``(p (..., 3) in m, R (..., 3, 3))``.

        Eqs (3), (4), (7), (8) with paper-notes §2.2 and §2.3 item 2. The camera sits ``Lc`` along z_2e
        from the end of segment 2; ``R = w_R_ct = w_R_2e``, its z-axis is the viewing axis.
        """
        p_cam, w_R_cam, _, _ = self._run(q, False)
        return p_cam, w_R_cam

    def target_point(self, q: ArrayLike) -> np.ndarray:
        """Visual target point ct, ``Lc + Le`` along z_2e from the end of segment 2: (..., 3) in m (eq 8)."""
        return self._run(q, False)[2]

    def target_pose(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """``(w_p_ct (..., 3) in m, w_R_ct (..., 3, 3))`` (eqs 7 and 8 with paper-notes §2.2 / §2.3 item 2)."""
        _, w_R_ct, p_ct, _ = self._run(q, False)
        return p_ct, w_R_ct

    def jacobian(self, q: ArrayLike) -> np.ndarray:
        """Twist Jacobian of the target point ct in {w}: (..., 6, 6).

        Eq (9) corrected per paper-notes §2.2 and §2.3 item 3.

        Rows ``[v (m/s); w (rad/s)]``; columns per rate of L0 (m/s), phi, theta1, delta1, theta2,
        delta2 (rad/s). J0v = [e3, 0], J0w = [0, e3]; T_t = J_tv - (lever from segment t's end to ct)^ J_tw,
        with J_tv, J_tw of eqs (5), (6) (series of paper-notes §2.2 near straight).
        """
        return self._run(q, True)[3]

    def fk_jacobian(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Everything in one kernel call: ``(p_cam (m), R, p_ct (m), J)`` as in the methods above."""
        return self._run(q, True)

    def backbone(self, q: ArrayLike, n_per_segment: int = 20) -> np.ndarray:
        """Sampled centre line for drawing: (..., 2 * n_per_segment + 4, 3) in m.

        Points: base origin (0, 0, 0); {1b} at [0, 0, L0]; ``n_per_segment`` points along segment 1
        (ending at {1e}); {2b} after the rigid Lm cylinder; ``n_per_segment`` points along segment 2
        (ending at {2e}); the camera, Lc further along z_2e. Arcs follow eq (3) at fractions of the segment.
        """
        m = integer(n_per_segment, "n_per_segment", low=1)
        array = np.ascontiguousarray(as_array(q, "q", (DOF,)))
        try:
            pts = _backbone_batch(array.reshape(-1, DOF), self._args, m)
        except ValueError:
            as_configuration(array, DOF)  # raises "q must be finite ..."
            raise
        return pts.reshape(array.shape[:-1] + (2 * m + 4, 3))

    def to_dict(self) -> dict:
        """The constructor arguments as plain YAML/JSON values (m, rad; unlimited as None)."""
        def plain(values):
            return [None if not math.isfinite(v) else float(v) for v in values]

        return {"L1": self.L1, "Lm": self.Lm, "L2": self.L2, "Lc": self.Lc, "Le": self.Le,
                "joint_limits": [plain(self._lower), plain(self._upper)]}

    def __repr__(self) -> str:
        L1, Lm, L2, Lc, Le = self._args
        return f"ContinuumEndoscope(L1={L1}, Lm={Lm}, L2={L2}, Lc={Lc}, Le={Le})"
