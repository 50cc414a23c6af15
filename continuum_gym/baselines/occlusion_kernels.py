"""Compiled kernels of the occlusion-avoidance baselines (paper 000): the tip law, eqs (22)-(24), limits.

Every kernel reads the robot's ``kernel_args()`` bundle, the controller's ``OcclusionParams`` bundle
and an ``OcclusionScratch`` of work arrays; see ``continuum_gym.baselines.occlusion`` for the
controllers built on them and the limit handling they implement.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from continuum_gym.geometry.force_field import potential_gradient_framed
from continuum_gym.geometry.lens_cone import centre_distance_kernel
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.linalg import twist_gram_solve
from continuum_gym.robots.mbcr_kernels import make_workspace, tip_kernel
from continuum_gym.robots.rotations import orientation_error

#: Everything a controller evaluation reads besides the robot: gains (eq 22-24 and the tip law of
#: paper-notes §1.3 item 11), whether the gradient / the endoscope rotation act, the cone and force-field
#: bundles, the points subject to potential (segments, arc fractions), and the limits (position, rate,
#: gamma rate, barrier).
OcclusionParams = namedtuple("OcclusionParams", [
    "eta1", "eta2", "epsilon", "k_track", "v_max", "w_max", "use_gradient", "rotate", "cone", "field",
    "segments", "fractions", "lower", "upper", "rate_limit", "gamma_rate_limit", "barrier_gain", "barrier_margin",
])
#: Work arrays of one evaluation: tip pose and Jacobian, orientation-error scratch, desired twist,
#: potential gradient, psp positions and Jacobians, the 6 x 6 Gram matrix and its two right-hand sides,
#: and the active-column mask.
OcclusionScratch = namedtuple("OcclusionScratch", ["p", "R", "J", "work33", "e_w", "xi", "grad", "P", "JV", "A", "B",
                                                   "mask"])


@kernel
def make_scratch(n_points, dof):
    """Work arrays of ``occlusion_rates_kernel`` for ``n_points`` psps and ``dof`` joints."""
    return OcclusionScratch(np.empty(3), np.empty((3, 3)), np.empty((6, dof)), np.empty((3, 3)), np.empty(3),
                            np.empty(6), np.empty(dof), np.empty((n_points, 3)), np.empty((n_points, 3, dof)),
                            np.empty((6, 6)), np.empty((6, 2)), np.empty(dof))


@kernel(inline="always")
def wrap_angle(x):
    """Wrap an angle (rad) to (-pi, pi]."""
    return math.pi - (math.pi - x) % (2.0 * math.pi)


@kernel(inline="always")
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


@kernel(inline="always")
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


@kernel(inline="always")
def occlusion_rates_kernel(q, gamma, p_des, R_des, v_ff, dt, robot, prm, ws, scratch, qdot):
    """One control evaluation: q_dot (dof,) into ``qdot``; returns (gamma_dot, frozen_mask_bits, rate_scale).

    The tip law of paper-notes §1.3 item 11, then ``resolve_rates``.
    """
    tip_kernel(q, robot, ws, scratch.p, scratch.R, scratch.J)
    tracking_twist(scratch.p, scratch.R, p_des, R_des, v_ff, prm.k_track, prm.v_max, prm.w_max, scratch.work33,
                   scratch.e_w, scratch.xi)
    return resolve_rates_inline(q, gamma, scratch.xi, dt, robot, prm, ws, scratch, qdot)


@kernel(borrows=True)
def occlusion_rates(q, gamma, p_des, R_des, v_ff, dt, robot, prm, ws, scratch, qdot):
    """``occlusion_rates_kernel`` as a call, for the batch entry points below (they allocate, so they count
    references, and the borrowing evaluation must not be inlined into them)."""
    return occlusion_rates_kernel(q, gamma, p_des, R_des, v_ff, dt, robot, prm, ws, scratch, qdot)


@kernel(borrows=True)
def resolve_rates(q, gamma, xi, dt, robot, prm, ws, scratch, qdot):
    """Eqs (22)-(24) for a desired twist ``xi`` (6,), with J and the tip in ``scratch`` and the frames in
    ``ws`` already (``tip_kernel`` at q leaves both).

    Returns (gamma_dot, frozen_mask_bits, rate_scale); limit handling as ``baselines.occlusion`` says.
    """
    return resolve_rates_inline(q, gamma, xi, dt, robot, prm, ws, scratch, qdot)


# Inlined where the step's rows evaluate the controller (``occlusion_rates_kernel``): a call passes every
# array of its bundles as flattened arguments (prm, robot, ws and scratch: ~30 arrays), which costs more than
# the solve's own arithmetic, and it would be paid at every substep of every row.
@kernel(inline="always")
def resolve_rates_inline(q, gamma, xi, dt, robot, prm, ws, scratch, qdot):
    """``resolve_rates`` inlined into the caller (a borrowing one: inlined into a kernel that counts
    references, its array reads would be counted too)."""
    p, J, grad, A, B, mask = scratch.p, scratch.J, scratch.grad, scratch.A, scratch.B, scratch.mask
    dof = q.shape[0]
    if prm.use_gradient:
        potential_gradient_framed(q, robot, ws, prm.segments, prm.fractions, scratch.P, scratch.JV, gamma,
                                  prm.cone, prm.field, grad)
        add_limit_barrier(q, prm.lower, prm.upper, prm.barrier_gain, prm.barrier_margin, grad)
    else:
        for k in range(dof):
            grad[k] = 0.0
    for k in range(dof):
        mask[k] = 1.0
    rate_scale = 1.0
    frozen_bits = 0
    for _ in range(dof + 1):
        # (J M J^T + eps I) [y_task, y_back] = [xi, J M grad]: the damped inverse of eq (23) on the active joints
        for a in range(6):
            B[a, 0] = xi[a]
            acc = 0.0
            for k in range(dof):
                acc += J[a, k] * mask[k] * grad[k]
            B[a, 1] = acc
        twist_gram_solve(J, mask, prm.epsilon, A, B)
        for k in range(dof):
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
        for k in range(dof):
            limit = prm.rate_limit[k]
            if abs(qdot[k]) * rate_scale > limit:
                rate_scale = limit / abs(qdot[k])
        newly_frozen = False
        for k in range(dof):
            if mask[k] == 0.0:
                continue
            nxt = q[k] + rate_scale * qdot[k] * dt
            if nxt > prm.upper[k] or nxt < prm.lower[k]:
                mask[k] = 0.0
                frozen_bits |= 1 << k
                newly_frozen = True
        if not newly_frozen:
            break
    for k in range(dof):
        qdot[k] *= rate_scale
    gamma_dot = 0.0
    if prm.rotate:
        _, dd_c = centre_distance_kernel(p, gamma, prm.cone.d_o, prm.cone.alpha, prm.cone.model)
        gamma_dot = -prm.eta2 * dd_c
        if gamma_dot > prm.gamma_rate_limit:
            gamma_dot = prm.gamma_rate_limit
        elif gamma_dot < -prm.gamma_rate_limit:
            gamma_dot = -prm.gamma_rate_limit
    return gamma_dot, frozen_bits, rate_scale


@kernel
def twist_rates_batch(Q, G, XI, dt, robot, prm, qdot, gamma_dot):
    """Rates for given desired twists XI (n, 6) (eq 22 without the tip law)."""
    ws = make_workspace(robot.lengths.shape[0])
    scratch = make_scratch(prm.segments.shape[0], Q.shape[1])
    for i in range(Q.shape[0]):
        tip_kernel(Q[i], robot, ws, scratch.p, scratch.R, scratch.J)
        gamma_dot[i], _, _ = resolve_rates(Q[i], G[i], XI[i], dt, robot, prm, ws, scratch, qdot[i])


@kernel
def rates_batch(Q, G, P_des, R_des, V_ff, dt, robot, prm, qdot, gamma_dot, frozen, scale):
    """One control evaluation per row (tip law + eqs 22-24)."""
    ws = make_workspace(robot.lengths.shape[0])
    scratch = make_scratch(prm.segments.shape[0], Q.shape[1])
    for i in range(Q.shape[0]):
        gamma_dot[i], frozen[i], scale[i] = occlusion_rates(
            Q[i], G[i], P_des[i], R_des[i], V_ff[i], dt, robot, prm, ws, scratch, qdot[i])


@kernel
def rollout_batch(Q0, G0, P_des, R_des, V_ff, dt, robot, prm, q_traj, gamma_traj):
    """Explicit Euler (paper-notes §1.3 item 6) over T steps with per-step targets (N, T, ...)."""
    dof = Q0.shape[1]
    ws = make_workspace(robot.lengths.shape[0])
    scratch = make_scratch(prm.segments.shape[0], dof)
    qdot = np.empty(dof)
    n_steps = P_des.shape[1]
    for i in range(Q0.shape[0]):
        q = Q0[i].copy()
        gamma = G0[i]
        q_traj[i, 0] = q
        gamma_traj[i, 0] = gamma
        for t in range(n_steps):
            gd, _, _ = occlusion_rates(q, gamma, P_des[i, t], R_des[i, t], V_ff[i, t], dt, robot, prm, ws,
                                       scratch, qdot)
            for k in range(dof):
                q[k] = min(max(q[k] + qdot[k] * dt, prm.lower[k]), prm.upper[k])
            gamma = wrap_angle(gamma + gd * dt)
            q_traj[i, t + 1] = q
            gamma_traj[i, t + 1] = gamma
