"""Occlusion-avoidance baselines of Sarli & Simaan (paper 000): minimum-norm and projected gradient.

Both track a desired tip pose with the saturated proportional law of paper-notes §1.3 item 11 and
rotate the endoscope with eq (24) (gamma_dot = -eta2 dd_c/dgamma, paper-notes §1.3 item 10).

- ``MinimumNorm``: q_dot = J^+ xi_dot with the damped inverse of eq (23) (first term of eq 22).
- ``ProjectedGradient``: eq (22), q_dot = J^+ xi_dot - eta1 (I - J^+ J) grad Pi, with grad Pi of eq (12).

The damped projector leaks into the task (paper-notes §1.3 item 12); that is the paper's epsilon
trade-off and is kept.

Limits (the paper has none; ``OcclusionLimits``): a two-sided bend limit |pi/2 - theta_j| <= max_bend,
an insertion range, joint-rate limits and a gamma-rate limit. They are respected by
1. a quadratic barrier added to grad Pi inside a margin of each position limit (projected gradient),
2. rate saturation: the whole q_dot is scaled down uniformly, which keeps its direction and so the
   tracking direction,
3. saturation handling: a joint whose next step would cross its position limit is frozen (its column
   removed from J, its entry from the null-space step) and the step recomputed, as the
   dimension-reduced IK of paper 001 does.
``info`` of ``step`` reports frozen joints, the rate scale and any clamping.
"""

from __future__ import annotations

import math
from collections import namedtuple
from dataclasses import dataclass

import numpy as np
from numba import njit

from continuum_gym.baselines.base import Controller, as_finite, as_rotation_field, broadcast_rows
from continuum_gym.geometry.force_field import PAPER_PSPS, potential_gradient_kernel, resolve_field
from continuum_gym.geometry.lens_cone import centre_distance_kernel, resolve_cone
from continuum_gym.robots.mbcr import DOF, MultiBackboneRobot, make_workspace, tip_kernel
from continuum_gym.robots.rotations import cholesky_solve_inplace, orientation_error
from continuum_gym.robots.validation import non_negative, positive

HALF_PI = 0.5 * math.pi
MAX_FREEZE_PASSES = DOF + 1

# Numba-friendly parameter bundle: one argument instead of thirty.
OcclusionParams = namedtuple("OcclusionParams", [
    "eta1", "eta2", "epsilon", "k_track", "v_max", "w_max", "use_gradient", "rotate",
    "d_o", "alpha", "beta", "model", "d0", "r_star", "f_star", "p_exp", "q_exp",
    "lower", "upper", "rate_limit", "gamma_rate_limit", "barrier_gain", "barrier_margin",
])


@dataclass(frozen=True)
class OcclusionLimits:
    """Joint limits the paper lacks (issue: environments), SI.

    Args:
        max_bend: per-segment bend limit |pi/2 - theta_j| <= max_bend (rad), two-sided; default 90 degrees.
        insertion: (min, max) of q_ins (m); default (0, 0.04).
        bend_rate: |theta_dot| limit (rad/s).
        plane_rate: |delta_dot| limit (rad/s).
        insertion_rate: |q_ins_dot| limit (m/s).
        gamma_rate: |gamma_dot| limit (rad/s).
        barrier_margin: width (rad, and the same fraction of the insertion range) inside each position
            limit where the projected gradient's barrier acts.
        barrier_gain: stiffness of that barrier (N·m/rad²; per m² for insertion, scaled by range).
    """

    max_bend: float = math.pi / 2
    insertion: tuple = (0.0, 0.04)
    bend_rate: float = 3.0
    plane_rate: float = 6.0
    insertion_rate: float = 0.02
    gamma_rate: float = 3.0
    barrier_margin: float = 0.1
    barrier_gain: float = 10.0

    def __post_init__(self):
        positive(self.max_bend, "max_bend", "rad")
        lo, hi = (float(x) for x in self.insertion)
        if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
            raise ValueError(f"insertion must be (min, max) in m with min < max; got {self.insertion!r}")
        object.__setattr__(self, "insertion", (lo, hi))
        for name in ("bend_rate", "plane_rate", "insertion_rate", "gamma_rate"):
            positive(getattr(self, name), name, "rad/s or m/s")
        non_negative(self.barrier_margin, "barrier_margin", "rad")
        non_negative(self.barrier_gain, "barrier_gain", "N·m/rad²")

    @property
    def lower(self) -> np.ndarray:
        """Lower position limits of q (7,): theta_j >= pi/2 - max_bend, delta unlimited, q_ins >= min."""
        b = self.max_bend
        return np.array([HALF_PI - b, -np.inf, HALF_PI - b, -np.inf, HALF_PI - b, -np.inf, self.insertion[0]])

    @property
    def upper(self) -> np.ndarray:
        b = self.max_bend
        return np.array([HALF_PI + b, np.inf, HALF_PI + b, np.inf, HALF_PI + b, np.inf, self.insertion[1]])

    @property
    def rate_limit(self) -> np.ndarray:
        """|q_dot| limits (7,): rad/s for angles, m/s for insertion."""
        r = (self.bend_rate, self.plane_rate)
        return np.array([*r, *r, *r, self.insertion_rate])


UNLIMITED = None


# ---------------------------------------------------------------------- compiled kernels
@njit(cache=True)
def tracking_twist(p, R, p_des, R_des, v_ff, k_track, v_max, w_max, work33, e_w, xi):
    """Desired twist xi (6,) of paper-notes §1.3 item 11: saturated proportional + linear feed-forward."""
    e0 = p_des[0] - p[0]
    e1 = p_des[1] - p[1]
    e2 = p_des[2] - p[2]
    n = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    gain = min(k_track * n, v_max) / n if n > 0.0 else 0.0
    xi[0] = gain * e0 + v_ff[0]
    xi[1] = gain * e1 + v_ff[1]
    xi[2] = gain * e2 + v_ff[2]
    orientation_error(R_des, R, work33, e_w)
    n = math.sqrt(e_w[0] ** 2 + e_w[1] ** 2 + e_w[2] ** 2)
    gain = min(k_track * n, w_max) / n if n > 0.0 else 0.0
    for a in range(3):
        xi[3 + a] = gain * e_w[a]


@njit(cache=True)
def add_limit_barrier(q, lower, upper, gain, margin, grad):
    """Quadratic barrier inside ``margin`` of each finite position limit, added to grad Pi.

    U = gain/2 * (depth)^2 with depth the penetration into the margin; for the insertion the margin
    and gain scale with the range so that the barrier is comparable in joint space.
    """
    if gain <= 0.0 or margin <= 0.0:
        return
    for i in range(q.shape[0]):
        lo = lower[i]
        hi = upper[i]
        if not (math.isfinite(lo) and math.isfinite(hi)):
            continue
        width = min(margin, 0.25 * (hi - lo))
        scale = margin / width
        depth_hi = q[i] - (hi - width)
        if depth_hi > 0.0:
            grad[i] += gain * depth_hi * scale * scale
        depth_lo = (lo + width) - q[i]
        if depth_lo > 0.0:
            grad[i] -= gain * depth_lo * scale * scale


@njit(cache=True)
def occlusion_rates_kernel(q, gamma, p_des, R_des, v_ff, dt, lengths, stiffness, segments, fractions,
                           prm, ws, scratch, qdot):
    """One control evaluation: q_dot (7,) into ``qdot``; returns (gamma_dot, frozen_mask_bits, rate_scale).

    ``scratch`` holds work arrays (see ``make_scratch``). The tip law of paper-notes §1.3 item 11, then
    ``resolve_rates``.
    """
    p, R, J, work33, e_w, xi = scratch[0], scratch[1], scratch[2], scratch[3], scratch[4], scratch[5]
    tip_kernel(q, lengths, ws, p, R, J)
    tracking_twist(p, R, p_des, R_des, v_ff, prm.k_track, prm.v_max, prm.w_max, work33, e_w, xi)
    return resolve_rates(q, gamma, xi, dt, lengths, stiffness, segments, fractions, prm, ws, scratch, qdot)


@njit(cache=True)
def resolve_rates(q, gamma, xi, dt, lengths, stiffness, segments, fractions, prm, ws, scratch, qdot):
    """Eqs (22)-(24) for a desired twist ``xi`` (6,), with J and the tip in ``scratch`` already.

    Returns (gamma_dot, frozen_mask_bits, rate_scale); limit handling as the module docstring says.
    """
    p, J, grad, P, JV, A, B, mask = (scratch[0], scratch[2], scratch[6], scratch[7], scratch[8], scratch[9],
                                     scratch[10], scratch[11])
    if prm.use_gradient:
        potential_gradient_kernel(q, lengths, stiffness, ws, segments, fractions, P, JV, gamma,
                                  prm.d_o, prm.alpha, prm.beta, prm.model,
                                  prm.d0, prm.r_star, prm.f_star, prm.p_exp, prm.q_exp, grad)
        add_limit_barrier(q, prm.lower, prm.upper, prm.barrier_gain, prm.barrier_margin, grad)
    else:
        for k in range(DOF):
            grad[k] = 0.0
    for k in range(DOF):
        mask[k] = 1.0
    rate_scale = 1.0
    frozen_bits = 0
    for _ in range(MAX_FREEZE_PASSES):
        # A = Jm Jm^T + eps I ; B = [xi, Jm g]
        for a in range(6):
            for b in range(a + 1):
                acc = 0.0
                for k in range(DOF):
                    acc += J[a, k] * J[b, k] * mask[k]
                A[a, b] = acc
                A[b, a] = acc
            A[a, a] += prm.epsilon
            B[a, 0] = xi[a]
            acc = 0.0
            for k in range(DOF):
                acc += J[a, k] * mask[k] * grad[k]
            B[a, 1] = acc
        cholesky_solve_inplace(A, B)
        for k in range(DOF):
            if mask[k] == 0.0:
                qdot[k] = 0.0
                continue
            task = 0.0
            back = 0.0
            for a in range(6):
                task += J[a, k] * B[a, 0]
                back += J[a, k] * B[a, 1]
            qdot[k] = task - prm.eta1 * (grad[k] - back)
        rate_scale = 1.0
        for k in range(DOF):
            limit = prm.rate_limit[k]
            if abs(qdot[k]) * rate_scale > limit:
                rate_scale = limit / abs(qdot[k])
        newly_frozen = False
        for k in range(DOF):
            if mask[k] == 0.0:
                continue
            nxt = q[k] + rate_scale * qdot[k] * dt
            if nxt > prm.upper[k] or nxt < prm.lower[k]:
                mask[k] = 0.0
                frozen_bits |= 1 << k
                newly_frozen = True
        if not newly_frozen:
            break
    for k in range(DOF):
        qdot[k] *= rate_scale
    gamma_dot = 0.0
    if prm.rotate:
        _, dd_c = centre_distance_kernel(p, gamma, prm.d_o, prm.alpha, prm.model)
        gamma_dot = -prm.eta2 * dd_c
        if gamma_dot > prm.gamma_rate_limit:
            gamma_dot = prm.gamma_rate_limit
        elif gamma_dot < -prm.gamma_rate_limit:
            gamma_dot = -prm.gamma_rate_limit
    return gamma_dot, frozen_bits, rate_scale


@njit(cache=True)
def _twist_rates_batch(Q, G, XI, dt, lengths, stiffness, segments, fractions, prm, qdot, gamma_dot):
    ws = make_workspace()
    scratch = make_scratch(segments.shape[0])
    for i in range(Q.shape[0]):
        tip_kernel(Q[i], lengths, ws, scratch[0], scratch[1], scratch[2])
        gamma_dot[i], _, _ = resolve_rates(Q[i], G[i], XI[i], dt, lengths, stiffness, segments, fractions,
                                           prm, ws, scratch, qdot[i])


@njit(cache=True)
def make_scratch(n_points):
    """Work arrays of ``occlusion_rates_kernel``: (p, R, J, work33, e_w, xi, grad, P, JV, A, B, mask)."""
    return (np.empty(3), np.empty((3, 3)), np.empty((6, 7)), np.empty((3, 3)), np.empty(3), np.empty(6),
            np.empty(7), np.empty((n_points, 3)), np.empty((n_points, 3, 7)), np.empty((6, 6)),
            np.empty((6, 2)), np.empty(7))


@njit(cache=True)
def wrap_angle(x):
    """Wrap an angle (rad) to (-pi, pi]."""
    return math.pi - (math.pi - x) % (2.0 * math.pi)


@njit(cache=True)
def _rates_batch(Q, G, P_des, R_des, V_ff, dt, lengths, stiffness, segments, fractions, prm,
                 qdot, gamma_dot, frozen, scale):
    ws = make_workspace()
    scratch = make_scratch(segments.shape[0])
    for i in range(Q.shape[0]):
        gamma_dot[i], frozen[i], scale[i] = occlusion_rates_kernel(
            Q[i], G[i], P_des[i], R_des[i], V_ff[i], dt, lengths, stiffness, segments, fractions,
            prm, ws, scratch, qdot[i])


@njit(cache=True)
def _rollout_batch(Q0, G0, P_des, R_des, V_ff, dt, lengths, stiffness, segments, fractions, prm,
                   q_traj, gamma_traj):
    """Explicit Euler (paper-notes §1.3 item 6) over T steps with per-step targets (N, T, ...)."""
    ws = make_workspace()
    scratch = make_scratch(segments.shape[0])
    qdot = np.empty(DOF)
    n_steps = P_des.shape[1]
    for i in range(Q0.shape[0]):
        q = Q0[i].copy()
        gamma = G0[i]
        q_traj[i, 0] = q
        gamma_traj[i, 0] = gamma
        for t in range(n_steps):
            gd, _, _ = occlusion_rates_kernel(q, gamma, P_des[i, t], R_des[i, t], V_ff[i, t], dt, lengths,
                                              stiffness, segments, fractions, prm, ws, scratch, qdot)
            for k in range(DOF):
                q[k] = min(max(q[k] + qdot[k] * dt, prm.lower[k]), prm.upper[k])
            gamma = wrap_angle(gamma + gd * dt)
            q_traj[i, t + 1] = q
            gamma_traj[i, t + 1] = gamma


# ---------------------------------------------------------------------- public controllers
class OcclusionController(Controller):
    """Common part of the two paper-000 controllers (use ``MinimumNorm`` or ``ProjectedGradient``).

    Args:
        robot: ``MultiBackboneRobot`` (default geometry of Table I).
        cone: ``LensCone`` (None: Table I, literal lens).
        field: ``ForceField`` (None: Table I with p = 1, q = 2).
        psps: points subject to potential, (segment, arc fraction) pairs (paper-notes §1.5).
        eta1: null-space gradient gain (Table I: 30).
        eta2: endoscope rotation gain (Table I: 30).
        epsilon: damping of eq (23) (Table I: 1e-6, SI).
        k_track: proportional gain of the tip law (1/s), paper-notes §1.3 item 11: 100.
        v_max: tip speed cap (m/s): 0.05.
        w_max: tip angular-speed cap (rad/s): 1.
        rotate_endoscope: apply eq (24) to gamma (task (a) of the paper holds gamma fixed).
        limits: ``OcclusionLimits`` or None (the paper: unlimited).
    """

    name = "occlusion"
    use_gradient = False
    action_dim = DOF + 1

    def __init__(self, robot=None, cone=None, field=None, psps=PAPER_PSPS, eta1=30.0, eta2=30.0,
                 epsilon=1e-6, k_track=100.0, v_max=0.05, w_max=1.0, rotate_endoscope=True, limits=UNLIMITED):
        self.robot = robot if robot is not None else MultiBackboneRobot()
        if not isinstance(self.robot, MultiBackboneRobot):
            raise ValueError(f"robot must be a MultiBackboneRobot; got {type(self.robot).__name__}")
        self.cone = resolve_cone(cone)
        self.field = resolve_field(field)
        self.psps = tuple(psps)
        self._segments, self._fractions = self.robot._point_spec(self.psps)
        if limits is not None and not isinstance(limits, OcclusionLimits):
            raise ValueError(f"limits must be an OcclusionLimits or None; got {type(limits).__name__}")
        self.limits = limits
        self.eta1 = non_negative(eta1, "eta1", "1/s")
        self.eta2 = non_negative(eta2, "eta2", "1/s")
        self.epsilon = positive(epsilon, "epsilon", "m²")
        self.k_track = positive(k_track, "k_track", "1/s")
        self.v_max = positive(v_max, "v_max", "m/s")
        self.w_max = positive(w_max, "w_max", "rad/s")
        self.rotate_endoscope = bool(rotate_endoscope)
        inf7 = np.full(DOF, np.inf)
        self.params = OcclusionParams(
            eta1=self.eta1, eta2=self.eta2, epsilon=self.epsilon, k_track=self.k_track, v_max=self.v_max,
            w_max=self.w_max, use_gradient=self.use_gradient, rotate=self.rotate_endoscope,
            d_o=self.cone.d_o, alpha=self.cone.alpha, beta=self.cone.beta, model=self.cone.model_code,
            d0=self.field.d0, r_star=self.field.r_star, f_star=self.field.f_star,
            p_exp=float(self.field.p), q_exp=float(self.field.q),
            lower=limits.lower if limits else -inf7, upper=limits.upper if limits else inf7,
            rate_limit=limits.rate_limit if limits else inf7,
            gamma_rate_limit=limits.gamma_rate if limits else np.inf,
            barrier_gain=limits.barrier_gain if limits else 0.0,
            barrier_margin=limits.barrier_margin if limits else 0.0,
        )

    # -------------------------------------------------------------- input handling
    def _inputs(self, q, gamma, target):
        q = as_finite(q, (DOF,), "q")
        if isinstance(target, dict):
            target = (target["p_des"], target["R_des"], target.get("v_des"))
        if not isinstance(target, (tuple, list)) or len(target) not in (2, 3):
            raise ValueError("target must be (p_des (...,3) m, R_des (...,3,3)[, v_des (...,3) m/s])")
        p_des = as_finite(target[0], (3,), "target position p_des")
        R_des = as_finite(target[1], (3, 3), "target rotation R_des")
        v_des = np.zeros(3) if len(target) < 3 or target[2] is None else as_finite(target[2], (3,), "v_des")
        gamma = as_finite(gamma, (), "gamma")
        try:
            shape = np.broadcast_shapes(q.shape[:-1], gamma.shape, p_des.shape[:-1], R_des.shape[:-2],
                                        v_des.shape[:-1])
        except ValueError as error:
            raise ValueError(f"q, gamma and target batch shapes do not broadcast: {error}") from error
        return (*broadcast_rows(shape, (q, (DOF,)), (gamma, ()), (p_des, (3,)), (R_des, (3, 3)), (v_des, (3,))),
                shape)

    def joint_rates(self, q, target, gamma=0.0, dt=1e-3):
        """Commanded rates [q_dot (7), gamma_dot] of shape (..., 8) (rad/s; m/s for q_ins).

        Args:
            q: configuration(s) (..., 7).
            target: (p_des (..., 3) m, R_des (..., 3, 3)[, v_des (..., 3) m/s feed-forward]) or a dict
                with those keys.
            gamma: endoscope rotation (rad).
            dt: step (s) used to predict position-limit crossings (saturation handling).
        """
        rates, _ = self.joint_rates_with_info(q, target, gamma, dt)
        return rates

    def joint_rates_with_info(self, q, target, gamma=0.0, dt=1e-3):
        """As ``joint_rates``, plus info: ``frozen`` (..., 7) bool, ``rate_scale`` (...)."""
        Q, G, P, R, V, shape = self._inputs(q, gamma, target)
        positive(dt, "dt", "s")
        n = Q.shape[0]
        qdot = np.empty((n, DOF))
        gamma_dot = np.empty(n)
        frozen = np.empty(n, dtype=np.int64)
        scale = np.empty(n)
        _rates_batch(Q, G, P, R, V, float(dt), self.robot._lengths_array, self.robot.stiffness,
                     self._segments, self._fractions, self.params, qdot, gamma_dot, frozen, scale)
        rates = np.concatenate([qdot, gamma_dot[:, None]], axis=1).reshape(shape + (DOF + 1,))
        frozen_mask = ((frozen[:, None] >> np.arange(DOF)) & 1).astype(bool).reshape(shape + (DOF,))
        return rates, {"frozen": frozen_mask, "rate_scale": scale.reshape(shape)}

    def rates_for_twist(self, q, xi_dot, gamma=0.0, dt=1e-3):
        """Rates [q_dot (7), gamma_dot] (..., 8) for a given desired tip twist xi_dot = [v; w] (..., 6), eq (22)."""
        q = as_finite(q, (DOF,), "q")
        gamma = as_finite(gamma, (), "gamma")
        xi_dot = as_finite(xi_dot, (6,), "xi_dot")
        shape = np.broadcast_shapes(q.shape[:-1], gamma.shape, xi_dot.shape[:-1])
        Q = np.ascontiguousarray(np.broadcast_to(q, shape + (DOF,)).reshape(-1, DOF))
        G = np.ascontiguousarray(np.broadcast_to(gamma, shape).reshape(-1))
        XI = np.ascontiguousarray(np.broadcast_to(xi_dot, shape + (6,)).reshape(-1, 6))
        qdot = np.empty((Q.shape[0], DOF))
        gamma_dot = np.empty(Q.shape[0])
        _twist_rates_batch(Q, G, XI, positive(dt, "dt", "s"), self.robot._lengths_array, self.robot.stiffness,
                           self._segments, self._fractions, self.params, qdot, gamma_dot)
        return np.concatenate([qdot, gamma_dot[:, None]], axis=1).reshape(shape + (DOF + 1,))

    def rollout(self, q0, gamma0, p_des, R_des, v_des=None, dt=1e-3):
        """Closed-loop explicit-Euler run (paper-notes §1.3 item 6) from q0 over per-step targets.

        Args:
            q0: (N, 7) or (7,) start configurations.
            gamma0: (N,) or scalar start rotation (rad).
            p_des: (T, 3) or (N, T, 3) desired tip positions (m), one per step.
            R_des: (T, 3, 3) or (N, T, 3, 3).
            v_des: feed-forward velocities like p_des (m/s), default 0.
            dt: step (s), the paper's 1 ms.

        Returns:
            (q, gamma): (N, T+1, 7) and (N, T+1), iteration 0 first (squeezed to T+1 for a single q0).
        """
        single = np.ndim(q0) == 1
        q0 = np.atleast_2d(as_finite(q0, (DOF,), "q0"))
        n = q0.shape[0]
        p_des = as_finite(p_des, (3,), "p_des")
        R_des = as_finite(R_des, (3, 3), "R_des")
        steps = p_des.shape[-2]
        v_des = np.zeros_like(p_des) if v_des is None else as_finite(v_des, (3,), "v_des")
        P = np.ascontiguousarray(np.broadcast_to(p_des, (n, steps, 3)))
        R = np.ascontiguousarray(np.broadcast_to(R_des, (n, steps, 3, 3)))
        V = np.ascontiguousarray(np.broadcast_to(v_des, (n, steps, 3)))
        G = np.ascontiguousarray(np.broadcast_to(as_finite(gamma0, (), "gamma0"), (n,)))
        q_traj = np.empty((n, steps + 1, DOF))
        gamma_traj = np.empty((n, steps + 1))
        _rollout_batch(np.ascontiguousarray(q0), G, P, R, V, positive(dt, "dt", "s"), self.robot._lengths_array,
                       self.robot.stiffness, self._segments, self._fractions, self.params, q_traj, gamma_traj)
        if single:
            return q_traj[0], gamma_traj[0]
        return q_traj, gamma_traj

    def predict(self, observation, state=None, episode_start=None, deterministic=False):
        """SB3 ``predict``: observation dict with ``q``, ``gamma``, ``p_des``, ``R_des`` (and ``v_des``).

        Returns (rates (..., 8), None): the same command as ``joint_rates``.
        """
        obs = self._observation_dict(observation, ("q", "gamma", "p_des", "R_des"))
        target = (obs["p_des"], as_rotation_field(obs["R_des"]), obs.get("v_des"))
        gamma = np.asarray(obs["gamma"], dtype=float)
        if gamma.ndim and gamma.shape[-1] == 1:
            gamma = gamma[..., 0]
        return self.joint_rates(obs["q"], target, gamma, dt=float(obs.get("dt", 1e-3))), state


class MinimumNorm(OcclusionController):
    """Minimum-norm rates J^+ xi_dot with the damped inverse of eq (23) (first term of eq 22), paper 000."""

    name = "minimum_norm"
    use_gradient = False


class ProjectedGradient(OcclusionController):
    """Projected gradient of eqs (21)-(23) on grad Pi of eq (12), with gamma by eq (24), paper 000."""

    name = "projected_gradient"
    use_gradient = True
