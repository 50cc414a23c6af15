"""View-tracking baselines of Deng, Xu et al. (paper 001): resolved-rate and dimension-reduced IK.

The continuum endoscope's visual target point ct must reach the da Vinci target frame (p_dVt, R_dVt).
Each step computes the errors of eq (10) and the capped twist of paper-notes §2.3 item 5
(v = e_p_hat min(v_lim, eps_p/dt), w = r_hat min(w_lim, eps_R/dt)), then

- ``ResolvedRate`` (eqs 10-13): q_dot = pinv(J) [v; w] with the undamped Moore-Penrose inverse
  (paper-notes §2.3 item 6); the step is clamped to the joint limits.
- ``DimensionReduced`` (eqs 14-19, paper-notes §2.5): prioritised position-then-orientation solution with
  damped inverses (lambda = 0.01 for every inverse); any active variable whose update would leave its
  range is frozen at its last value, its column removed, and the step recomputed.

Units (paper-notes §2.7): the paper's inverses are minimum-norm in its own units, mm and rad, and
lambda = 0.01 is a mm value. The arithmetic here runs in mm and rad (rows of v and the L0 column
scaled), which is exactly the SI formulation with lambda_v = 1e-8 m² and lambda_w = 0.01; the public
interface is SI. delta is wrapped to [-pi, pi); phi is a hard limit.
"""

from __future__ import annotations

import math
from collections import namedtuple
from collections.abc import Mapping, Sequence
from typing import TypeAlias

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.baselines.base import Controller, as_rotation_field, broadcast_rows
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.endoscope import (
    ContinuumEndoscope,
    endoscope_kinematics,
    make_endoscope_workspace,
)
from continuum_gym.robots.linalg import gram_solve_3x6
from continuum_gym.robots.rotations import orientation_error
from continuum_gym.validation import as_finite, positive

DOF = ContinuumEndoscope.dof
RMRC = 0
DR = 1
# Internal length unit of the paper-001 IK: mm (paper-notes §2.7).
MM_PER_M = 1000.0
# paper-notes §2.6 stopping rules, in the paper's units (mm, rad).
CONVERGED_POSITION_MM = 1e-3
CONVERGED_ORIENTATION = 1e-5
STALL_MOTION = 1e-9
STALL_STEPS = 50

#: What the controllers track: the da Vinci target frame ``(p_target (..., 3) m, R_target (..., 3, 3))`` or a
#: dict with those keys.
ViewTarget: TypeAlias = Sequence[ArrayLike] | Mapping[str, ArrayLike]

#: What the IK kernels read besides the robot: RMRC or DR, the twist caps (m/s, rad/s), the damping of
#: eq (19) in mm units and the joint limits (6,).
ViewParams = namedtuple("ViewParams", ["method", "v_lim", "w_lim", "damping", "lower", "upper"])
#: Work arrays of one IK step: camera pose, target point, Jacobian, kinematics scratch, orientation-error
#: scratch, capped twist, the Jacobian in mm, the active-column mask, solver scratch, the next configuration,
#: a column of ones, and the dimension-reduced solution's masked Jacobians, damped inverses and partial results.
ViewScratch = namedtuple("ViewScratch", ["p_cam", "R_ct", "p_ct", "J", "ws", "work33", "e_w", "twist", "Jmm", "mask",
                                         "A3", "X3", "M6", "C", "q_new", "ones", "Jv", "Jw", "pv", "pc", "first",
                                         "r"])


@kernel
def wrap_half_open(x):
    """Wrap an angle (rad) to [-pi, pi) (paper-notes §2.1: deltas are wrapped, not limited)."""
    return x - 2.0 * math.pi * math.floor((x + math.pi) / (2.0 * math.pi))


@kernel
def make_view_scratch():
    """Work arrays of ``view_rates_kernel`` (``ViewScratch``)."""
    return ViewScratch(np.empty(3), np.empty((3, 3)), np.empty(3), np.empty((6, 6)), make_endoscope_workspace(),
                       np.empty((3, 3)), np.empty(3), np.empty(6), np.empty((6, 6)), np.empty(6), np.empty((3, 3)),
                       np.empty((3, 6)), np.empty((6, 6)), np.empty((3, 6)), np.empty(6), np.ones(6),
                       np.empty((3, 6)), np.empty((3, 6)), np.empty((6, 3)), np.empty((6, 3)), np.empty(6),
                       np.empty(3))


@kernel(borrows=True)
def view_errors(q, p_tgt, R_tgt, robot, scratch):
    """FK + Jacobian into scratch; returns (eps_p (m), eps_R (rad)); e_p in twist[:3], e_w in e_w."""
    p_ct, e_w, twist = scratch.p_ct, scratch.e_w, scratch.twist
    endoscope_kinematics(q, robot, scratch.ws, scratch.p_cam, scratch.R_ct, p_ct, scratch.J, True)
    for a in range(3):
        twist[a] = p_tgt[a] - p_ct[a]
    eps_p = math.sqrt(twist[0] ** 2 + twist[1] ** 2 + twist[2] ** 2)
    orientation_error(R_tgt, scratch.R_ct, scratch.work33, e_w)
    eps_r = math.sqrt(e_w[0] ** 2 + e_w[1] ** 2 + e_w[2] ** 2)
    return eps_p, eps_r


# Inlined, with their work arrays in ``ViewScratch``: the DR loop runs these up to 7 times per step, and a
# call or an allocation there costs more than its 3 x 6 arithmetic (see the reference-count note in
# robots/mbcr_kernels.py).
@kernel(inline="always")
def damped_pinv_rows(A, damping, out, work3, ones, X):
    """out (6 x 3) = A^T (A A^T + damping I)^-1 for A (3 x 6); undamped if damping == 0 and A A^T invertible.

    X (3 x 6) is scratch."""
    # Solve (A A^T + damping I) X = A for X (3 x 6); then out = X^T.
    for a in range(3):
        for k in range(6):
            X[a, k] = A[a, k]
    ok = gram_solve_3x6(A, ones, damping, work3, X)
    for k in range(6):
        for a in range(3):
            out[k, a] = X[a, k] if ok else 0.0
    return ok


@kernel(borrows=True)
def view_rates_kernel(q, p_tgt, R_tgt, dt, robot, prm, scratch, qdot):
    """Joint rates (SI) for one step into ``qdot``; returns (eps_p, eps_R, frozen_bits).

    RMRC: undamped pinv of the full 6x6 J. DR: paper-notes §2.5 loop with freezing. Both in mm/rad.
    """
    J, e_w, twist, Jmm, mask = scratch.J, scratch.e_w, scratch.twist, scratch.Jmm, scratch.mask
    eps_p, eps_r = view_errors(q, p_tgt, R_tgt, robot, scratch)
    # Capped twist (paper-notes §2.3 item 5) from SI errors and limits, then expressed in mm/s and rad/s.
    v_gain = min(prm.v_lim, eps_p / dt) / eps_p if eps_p > 0.0 else 0.0
    w_gain = min(prm.w_lim, eps_r / dt) / eps_r if eps_r > 0.0 else 0.0
    for a in range(3):
        twist[a] = twist[a] * v_gain * MM_PER_M
        twist[3 + a] = e_w[a] * w_gain
    # J in mm: linear rows x1000; L0 column per mm of L0.
    for a in range(6):
        for k in range(6):
            value = J[a, k]
            if a < 3:
                value *= MM_PER_M
            if k == 0:
                value /= MM_PER_M
            Jmm[a, k] = value
    frozen_bits = 0
    # The limits are read into locals once: reading a bundle's array costs a reference count each time.
    lower, upper = prm.lower, prm.upper
    if prm.method == RMRC:
        rmrc_rates(Jmm, twist, qdot)
    else:
        for k in range(6):
            mask[k] = 1.0
        for _ in range(DOF + 1):
            dr_solution(Jmm, twist, mask, prm.damping, scratch, qdot)
            newly = False
            for k in range(6):
                if mask[k] == 0.0:
                    continue
                step = qdot[k] / MM_PER_M if k == 0 else qdot[k]
                nxt = q[k] + step * dt
                if nxt > upper[k] or nxt < lower[k]:
                    mask[k] = 0.0
                    frozen_bits |= 1 << k
                    newly = True
            if not newly:
                break
    qdot[0] /= MM_PER_M
    return eps_p, eps_r, frozen_bits


# A kernel of its own, with reference counting: LAPACK's pseudo-inverse allocates, which a borrowing
# kernel (view_rates_kernel) cannot.
@kernel
def rmrc_rates(Jmm, twist, qdot):
    """qdot (6,) = pinv(Jmm) twist with the undamped pseudo-inverse of the full 6 x 6 J (mm, rad)."""
    pinv = np.linalg.pinv(Jmm, rcond=1e-15)
    for k in range(6):
        acc = 0.0
        for a in range(6):
            acc += pinv[k, a] * twist[a]
        qdot[k] = acc


@kernel(inline="always")
def dr_solution(Jmm, twist, mask, damping, scratch, qdot):
    """Eq (17) with the damped inverse of eq (19) on the active columns (mask); frozen rates are 0.

    scratch.M6 holds N = I - J~v^+ J~v and scratch.C holds J~w N.
    """
    A3, X3, M6, C, ones = scratch.A3, scratch.X3, scratch.M6, scratch.C, scratch.ones
    Jv, Jw, pv, pc, first, r = scratch.Jv, scratch.Jw, scratch.pv, scratch.pc, scratch.first, scratch.r
    for a in range(3):
        for k in range(6):
            Jv[a, k] = Jmm[a, k] * mask[k]
            Jw[a, k] = Jmm[3 + a, k] * mask[k]
    damped_pinv_rows(Jv, damping, pv, A3, ones, X3)
    # first = J~v^+ v
    for k in range(6):
        first[k] = pv[k, 0] * twist[0] + pv[k, 1] * twist[1] + pv[k, 2] * twist[2]
    # N = I - J~v^+ J~v ; C = J~w N
    for k in range(6):
        for m in range(6):
            acc = 0.0
            for a in range(3):
                acc += pv[k, a] * Jv[a, m]
            M6[k, m] = (1.0 if k == m else 0.0) - acc
    for a in range(3):
        for m in range(6):
            acc = 0.0
            for k in range(6):
                acc += Jw[a, k] * M6[k, m]
            C[a, m] = acc
    # residual orientation task: w - J~w J~v^+ v
    for a in range(3):
        acc = 0.0
        for k in range(6):
            acc += Jw[a, k] * first[k]
        r[a] = twist[3 + a] - acc
    damped_pinv_rows(C, damping, pc, A3, ones, X3)
    for k in range(6):
        if mask[k] == 0.0:
            qdot[k] = 0.0
        else:
            qdot[k] = first[k] + pc[k, 0] * r[0] + pc[k, 1] * r[1] + pc[k, 2] * r[2]


@kernel(borrows=True)
def integrate_view_step(q, qdot, dt, lower, upper, out):
    """Euler step, clamped to the position limits (eq 13), deltas wrapped; returns clamped-joint bits."""
    clamped = 0
    for k in range(6):
        value = q[k] + qdot[k] * dt
        out[k] = min(max(value, lower[k]), upper[k])
        if out[k] != value:
            clamped |= 1 << k
    out[3] = wrap_half_open(out[3])
    out[5] = wrap_half_open(out[5])
    return clamped


@kernel
def _solve_batch(Q0, P_tgt, R_tgt, dt, max_steps, robot, prm, record, q_final, steps, status, q_hist):
    """Run each row to convergence, stall or max_steps (paper-notes §2.6).

    status: 0 max steps, 1 converged, 2 stalled."""
    scratch = make_view_scratch()
    q_new = scratch.q_new
    qdot = np.empty(6)
    q = np.empty(6)
    for i in range(Q0.shape[0]):
        for k in range(6):
            q[k] = Q0[i, k]
        if record:
            q_hist[i, 0] = q
        still = 0
        status[i] = 0
        n = 0
        while n < max_steps:
            eps_p, eps_r, _ = view_rates_kernel(q, P_tgt[i], R_tgt[i], dt, robot, prm, scratch, qdot)
            if eps_p * MM_PER_M < CONVERGED_POSITION_MM and eps_r < CONVERGED_ORIENTATION:
                status[i] = 1
                break
            integrate_view_step(q, qdot, dt, prm.lower, prm.upper, q_new)
            moved = 0.0
            for k in range(6):
                moved = max(moved, abs(q_new[k] - q[k]))
                q[k] = q_new[k]
            n += 1
            if record:
                q_hist[i, n] = q
            still = still + 1 if moved <= STALL_MOTION else 0
            if still >= STALL_STEPS:
                status[i] = 2
                break
        if record:
            for m in range(n + 1, q_hist.shape[1]):
                q_hist[i, m] = q
        q_final[i] = q
        steps[i] = n


class ViewTrackingController(Controller):
    """Common part of the paper-001 controllers (use ``ResolvedRate`` or ``DimensionReduced``).

    Args:
        robot: ``ContinuumEndoscope`` (default: Table II).
        v_lim: linear speed cap of the target point (m/s), 100 mm/s (paper).
        w_lim: angular speed cap (rad/s), pi/2 (paper).
        damping: lambda of eq (19) in the paper's mm units (0.01; = 1e-8 m² on the position block).
        lower, upper: joint limits (6,) (default the robot's, Table II).
    """

    method = DR
    action_dim = DOF

    def __init__(self, robot: ContinuumEndoscope | None = None, v_lim: float = 0.1, w_lim: float = math.pi / 2,
                 damping: float = 0.01, lower: ArrayLike | None = None, upper: ArrayLike | None = None) -> None:
        self.robot = robot if robot is not None else ContinuumEndoscope()
        if not isinstance(self.robot, ContinuumEndoscope):
            raise ValueError(f"robot must be a ContinuumEndoscope; got {type(self.robot).__name__}")
        robot_lower, robot_upper = self.robot.joint_limits
        self.lower = robot_lower if lower is None else np.asarray(lower, dtype=float).copy()
        self.upper = robot_upper if upper is None else np.asarray(upper, dtype=float).copy()
        if self.lower.shape != (DOF,) or self.upper.shape != (DOF,) or np.any(self.lower > self.upper):
            raise ValueError("lower and upper must be shape (6,) joint limits with lower <= upper")
        self.v_lim = positive(v_lim, "v_lim", "m/s")
        self.w_lim = positive(w_lim, "w_lim", "rad/s")
        if not (np.isfinite(damping) and damping >= 0):
            raise ValueError(f"damping must be finite and >= 0 (mm² in the paper's units); got {damping!r}")
        self.damping = float(damping)
        self.params = ViewParams(method=self.method, v_lim=self.v_lim, w_lim=self.w_lim,
                                 damping=self.damping, lower=self.lower, upper=self.upper)

    def _inputs(self, q, target):
        q = as_finite(q, (DOF,), "q")
        if isinstance(target, dict):
            target = (target["p_target"], target["R_target"])
        if not isinstance(target, (tuple, list)) or len(target) != 2:
            raise ValueError("target must be (p_target (..., 3) m, R_target (..., 3, 3)): the da Vinci target frame")
        p = as_finite(target[0], (3,), "target position p_target")
        R = as_finite(target[1], (3, 3), "target rotation R_target")
        try:
            shape = np.broadcast_shapes(q.shape[:-1], p.shape[:-1], R.shape[:-2])
        except ValueError as error:
            raise ValueError(f"q and target batch shapes do not broadcast: {error}") from error
        return (*broadcast_rows(shape, (q, (DOF,)), (p, (3,)), (R, (3, 3))), shape)

    def joint_rates(self, q: ArrayLike, target: ViewTarget, dt: float = 0.01) -> np.ndarray:
        """Rates (..., 6) in SI (m/s for L0, rad/s) toward the target frame; dt (s) sets the capped twist."""
        return self.joint_rates_with_info(q, target, dt)[0]

    def joint_rates_with_info(self, q: ArrayLike, target: ViewTarget, dt: float = 0.01
                              ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """As ``joint_rates`` plus info: ``position_error_m``, ``orientation_error_rad``, ``frozen`` (..., 6)."""
        Q, P, R, shape = self._inputs(q, target)
        dt = positive(dt, "dt", "s")
        n = Q.shape[0]
        rates = np.empty((n, DOF))
        errors = np.empty((n, 2))
        frozen = np.empty(n, dtype=np.int64)
        _rates_batch(Q, P, R, dt, self.robot.kernel_args(), self.params, rates, errors, frozen)
        info = {
            "position_error_m": errors[:, 0].reshape(shape),
            "orientation_error_rad": errors[:, 1].reshape(shape),
            "frozen": ((frozen[:, None] >> np.arange(DOF)) & 1).astype(bool).reshape(shape + (DOF,)),
        }
        return rates.reshape(shape + (DOF,)), info

    def solve(self, q0: ArrayLike, target: ViewTarget, dt: float = 0.01, max_steps: int = 1000, record: bool = False
              ) -> dict[str, np.ndarray]:
        """Iterate to convergence, stall or ``max_steps`` (paper-notes §2.6), each row independently.

        Returns a dict: ``q`` (..., 6) final configurations, ``steps`` (...), ``status`` (...: 0 ran out
        of steps, 1 converged, 2 stalled) and, with ``record``, ``history`` (..., max_steps + 1, 6)
        (held at the final value after the stop).
        """
        Q, P, R, shape = self._inputs(q0, target)
        dt = positive(dt, "dt", "s")
        if int(max_steps) != max_steps or max_steps < 1:
            raise ValueError(f"max_steps must be an integer >= 1; got {max_steps!r}")
        n = Q.shape[0]
        q_final = np.empty((n, DOF))
        steps = np.empty(n, dtype=np.int64)
        status = np.empty(n, dtype=np.int64)
        history = np.empty((n, int(max_steps) + 1, DOF) if record else (1, 1, DOF))
        _solve_batch(Q, P, R, dt, int(max_steps), self.robot.kernel_args(), self.params, bool(record),
                     q_final, steps, status, history)
        result = {"q": q_final.reshape(shape + (DOF,)), "steps": steps.reshape(shape),
                  "status": status.reshape(shape)}
        if record:
            result["history"] = history.reshape(shape + (int(max_steps) + 1, DOF))
        return result

    def predict(self, observation: np.ndarray | dict[str, np.ndarray], state: tuple[np.ndarray, ...] | None = None,
                episode_start: np.ndarray | None = None, deterministic: bool = False
                ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """SB3 ``predict``: observation dict with ``q``, ``p_target``, ``R_target`` (and optional ``dt``)."""
        obs = self._observation_dict(observation, ("q", "p_target", "R_target"))
        target = (obs["p_target"], as_rotation_field(obs["R_target"]))
        return self.joint_rates(obs["q"], target, dt=float(obs.get("dt", 0.01))), state


@kernel
def _rates_batch(Q, P, R, dt, robot, prm, rates, errors, frozen):
    scratch = make_view_scratch()
    for i in range(Q.shape[0]):
        errors[i, 0], errors[i, 1], frozen[i] = view_rates_kernel(Q[i], P[i], R[i], dt, robot, prm, scratch, rates[i])


class ResolvedRate(ViewTrackingController):
    """Resolved-motion-rate control with clamping (eqs 10-13; undamped pseudo-inverse), paper 001."""

    name = "resolved_rate"
    method = RMRC


class DimensionReduced(ViewTrackingController):
    """Dimension-reduced IK with a prioritised, damped Jacobian and frozen saturated joints (eqs 14-19)."""

    name = "dimension_reduced"
    method = DR
