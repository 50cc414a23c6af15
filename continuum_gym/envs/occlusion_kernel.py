"""One compiled call per environment step of OcclusionAvoidance, for the whole batch.

Per control step and robot: for each kinematic substep, the baseline command at the current state
(its cached value for the first substep), plus the residual (projected into the tip Jacobian's null
space unless ``residual_space="joint"``), saturated by the rate limits (uniform scaling of the joint
rates; gamma rate clipped), integrated by explicit Euler and clamped to the position limits. Then
the geometry once at the new state: tip errors, VOI, tip visibility, the next baseline command, the
observation and the reward terms.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from continuum_gym.baselines.occlusion import make_scratch, occlusion_rates_kernel, wrap_angle
from continuum_gym.geometry.lens_cone import to_lens
from continuum_gym.geometry.occlusion import voi_of_configuration
from continuum_gym.robots.mbcr import DOF, make_workspace, tip_kernel
from continuum_gym.envs.common_kernels import clamp, clip_observation, trajectory_point
from continuum_gym.robots.rotations import cholesky_solve_inplace, orientation_error

ACTION_DIM = DOF + 1
OBS_DIM = 32
OBS_LIMIT = 10.0
# Observation scales (documented in the env docstring).
POSITION_ERROR_SCALE = 0.01  # m
ORIENTATION_ERROR_SCALE = 0.1  # rad
VELOCITY_SCALE = 0.05  # m/s
NULLSPACE_DAMPING = 1e-12  # m², numerically exact projector away from singularities
# Reward terms, in this order everywhere.
REWARD_TERMS = ("voi", "tip_position", "tip_orientation", "visibility", "action")
N_TERMS_REWARD = len(REWARD_TERMS)
# Failure: the tip is lost.
MAX_TIP_ERROR = 0.01  # m
# Share of the residual kept by the visibility guard, resolved to 2^-20.
GUARD_BISECTIONS = 20


@njit(cache=True)
def _project_nullspace(J, r, A, B, out):
    """out = (I - J^T (J J^T + eps I)^-1 J) r for the 6x7 tip Jacobian J."""
    for a in range(6):
        for b in range(a + 1):
            acc = 0.0
            for k in range(DOF):
                acc += J[a, k] * J[b, k]
            A[a, b] = acc
            A[b, a] = acc
        A[a, a] += NULLSPACE_DAMPING
        acc = 0.0
        for k in range(DOF):
            acc += J[a, k] * r[k]
        B[a, 0] = acc
        B[a, 1] = 0.0
    cholesky_solve_inplace(A, B)
    for k in range(DOF):
        acc = 0.0
        for a in range(6):
            acc += J[a, k] * B[a, 0]
        out[k] = r[k] - acc


@njit(cache=True)
def view_fraction_at(p, gamma, prm):
    """Angle of point p (m, {w}) from the lens axis at endoscope rotation gamma, in half-angles."""
    xl, yl, zl = to_lens(p[0], p[1], p[2], gamma, prm.d_o, prm.alpha, prm.model)
    return math.atan2(math.sqrt(xl * xl + yl * yl), zl) / prm.beta


@njit(cache=True)
def guard_gamma_rate(p, gamma, base_rate, residual_rate, dt, bound, prm):
    """Endoscope rate with the residual's share scaled back so the tip p stays within ``bound`` half-angles.

    The baseline's own rate is never changed: the residual is cut only where it would carry the tip
    beyond max(bound, where the baseline alone leaves it). Returns (rate, guarded).
    """
    limit = max(bound, view_fraction_at(p, gamma + base_rate * dt, prm))
    if view_fraction_at(p, gamma + (base_rate + residual_rate) * dt, prm) <= limit:
        return base_rate + residual_rate, False
    low, high = 0.0, 1.0  # share of the residual: low is feasible, high is not
    for _ in range(GUARD_BISECTIONS):
        mid = 0.5 * (low + high)
        if view_fraction_at(p, gamma + (base_rate + mid * residual_rate) * dt, prm) <= limit:
            low = mid
        else:
            high = mid
    return base_rate + low * residual_rate, True


@njit(cache=True)
def occlusion_observe(i, Q, G, step, centre, amp, omega, phase, R_des, duration, control_dt, sub_dt, lengths,
                      stiffness, segments, fractions, prm, has_base, limits_lower, limits_upper, max_bend,
                      rate_scale_vec, ws, scratch, base_cmd, base_info, obs, metrics):
    """Geometry at the state of row i: next baseline command (cached), observation and metrics.

    metrics[i] = [voi, tip_error_m, orientation_error_rad, tip_view_fraction];
    base_info[i] = [frozen_bits, rate_saturated] of the cached baseline command.
    """
    q = Q[i]
    gamma = G[i]
    t = step[i] * control_dt
    p_des = np.empty(3)
    v_des = np.empty(3)
    trajectory_point(centre[i], amp[i], omega[i], phase[i], t, p_des, v_des)
    qdot = np.empty(DOF)
    if has_base:
        gd, frozen, scale = occlusion_rates_kernel(q, gamma, p_des, R_des[i], v_des, sub_dt, lengths, stiffness,
                                                   segments, fractions, prm, ws, scratch, qdot)
        for k in range(DOF):
            base_cmd[i, k] = qdot[k]
        base_cmd[i, DOF] = gd
        base_info[i, 0] = frozen
        base_info[i, 1] = 1 if scale < 1.0 else 0
    else:
        tip_kernel(q, lengths, ws, scratch[0], scratch[1], scratch[2])
        for k in range(DOF + 1):
            base_cmd[i, k] = 0.0
        base_info[i, 0] = 0
        base_info[i, 1] = 0
    p = scratch[0]
    R = scratch[1]
    e_w = np.empty(3)
    orientation_error(R_des[i], R, np.empty((3, 3)), e_w)
    e_p0 = p_des[0] - p[0]
    e_p1 = p_des[1] - p[1]
    e_p2 = p_des[2] - p[2]
    tip_error = math.sqrt(e_p0 * e_p0 + e_p1 * e_p1 + e_p2 * e_p2)
    ori_error = math.sqrt(e_w[0] ** 2 + e_w[1] ** 2 + e_w[2] ** 2)
    m = 5 + 3 * 40 + 1
    voi, _, _, _ = voi_of_configuration(q, lengths, ws, gamma, prm.d_o, prm.alpha, prm.beta, prm.model, 5, 40,
                                        np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 2)))
    view_fraction = view_fraction_at(p, gamma, prm)
    metrics[i, 0] = voi
    metrics[i, 1] = tip_error
    metrics[i, 2] = ori_error
    metrics[i, 3] = view_fraction
    o = obs[i]
    for j in range(3):
        o[j] = (0.5 * math.pi - q[2 * j]) / max_bend
        o[3 + 2 * j] = math.sin(q[2 * j + 1])
        o[4 + 2 * j] = math.cos(q[2 * j + 1])
    span = limits_upper[6] - limits_lower[6]
    o[9] = 2.0 * (q[6] - limits_lower[6]) / span - 1.0 if math.isfinite(span) else q[6] / 0.02
    o[10] = math.sin(gamma)
    o[11] = math.cos(gamma)
    o[12] = e_p0 / POSITION_ERROR_SCALE
    o[13] = e_p1 / POSITION_ERROR_SCALE
    o[14] = e_p2 / POSITION_ERROR_SCALE
    for a in range(3):
        o[15 + a] = e_w[a] / ORIENTATION_ERROR_SCALE
        o[18 + a] = v_des[a] / VELOCITY_SCALE
    o[21] = view_fraction
    o[22] = voi
    for k in range(DOF + 1):
        o[23 + k] = base_cmd[i, k] / rate_scale_vec[k]
    o[31] = t / (duration[i] * control_dt)
    clip_observation(o, OBS_LIMIT)


@njit(cache=True)
def make_step_work(n_points):
    """Per-thread scratch of ``occlusion_step_row``."""
    return (make_workspace(), make_scratch(n_points), np.empty(DOF), np.empty(DOF), np.empty(DOF), np.empty(DOF),
            np.empty(3), np.empty(3), np.empty((6, 6)), np.empty((6, 2)))


@njit(cache=True)
def occlusion_step_row(i, Q, G, step, actions, centre, amp, omega, phase, R_des, duration, limit, control_dt,
                       substeps, lengths, stiffness, segments, fractions, prm, has_base, nullspace, residual_scale,
                       rate_scale_vec, rate_limit, gamma_rate_limit, lower, upper, max_bend, weights,
                       visibility_fraction, visibility_guard, base_cmd, base_info, obs, metrics, terms, rewards, flags,
                       work):
    """Advance row i by one control step; fills its obs, metrics, reward terms, reward and flags.

    flags[i] = [clamped_bits, rate_saturated, gamma_saturated, terminated, truncated, base_frozen_bits,
    base_rate_saturated, visibility_guarded] (the base bits OR-ed over the substeps). ``visibility_guard``
    <= 0 turns the guard off. base_cmd holds the baseline command
    at the current state on entry (cached from the last observe) and at the new state on exit.
    """
    ws, scratch, qdot, residual, projected, cmd, p_des, v_des, A, B = work
    dt = control_dt / substeps
    q = Q[i]
    clamped = 0
    rate_saturated = 0
    gamma_saturated = 0
    guarded = 0
    base_frozen = base_info[i, 0]
    base_saturated = base_info[i, 1]
    action_sq = 0.0
    for k in range(DOF + 1):
        action_sq += actions[i, k] * actions[i, k]
    for k in range(DOF):
        residual[k] = actions[i, k] * residual_scale * rate_scale_vec[k]
    gamma_residual = actions[i, DOF] * residual_scale * rate_scale_vec[DOF]
    for s in range(substeps):
        t = step[i] * control_dt + s * dt
        if s == 0:
            for k in range(DOF):
                qdot[k] = base_cmd[i, k]
            gd = base_cmd[i, DOF]
            if has_base and nullspace:
                tip_kernel(q, lengths, ws, scratch[0], scratch[1], scratch[2])
        elif has_base:
            trajectory_point(centre[i], amp[i], omega[i], phase[i], t, p_des, v_des)
            gd, frozen, base_scale = occlusion_rates_kernel(q, G[i], p_des, R_des[i], v_des, dt, lengths,
                                                            stiffness, segments, fractions, prm, ws, scratch, qdot)
            base_frozen |= frozen
            if base_scale < 1.0:
                base_saturated = 1
        else:
            for k in range(DOF):
                qdot[k] = 0.0
            gd = 0.0
        if has_base and nullspace:
            _project_nullspace(scratch[2], residual, A, B, projected)
        else:
            for k in range(DOF):
                projected[k] = residual[k]
        # Uniform scaling keeps the command's direction; a baseline command already at its limit
        # (within rounding) is left exactly as it is, so a zero residual reproduces the baseline.
        scale = 1.0
        for k in range(DOF):
            cmd[k] = qdot[k] + projected[k]
            if abs(cmd[k]) > rate_limit[k] * (1.0 + 1e-12) and abs(cmd[k]) * scale > rate_limit[k]:
                scale = rate_limit[k] / abs(cmd[k])
        if scale < 1.0:
            rate_saturated = 1
        for k in range(DOF):
            q[k], hit = clamp(q[k] + scale * cmd[k] * dt, lower[k], upper[k])
            if hit:
                clamped |= 1 << k
        if visibility_guard > 0.0 and gamma_residual != 0.0:
            tip_kernel(q, lengths, ws, scratch[0], scratch[1], scratch[2])
            g_rate, hit = guard_gamma_rate(scratch[0], G[i], gd, gamma_residual, dt, visibility_guard, prm)
            if hit:
                guarded = 1
        else:
            g_rate = gd + gamma_residual
        if g_rate > gamma_rate_limit:
            g_rate = gamma_rate_limit
            gamma_saturated = 1
        elif g_rate < -gamma_rate_limit:
            g_rate = -gamma_rate_limit
            gamma_saturated = 1
        G[i] = wrap_angle(G[i] + g_rate * dt)
    step[i] += 1
    occlusion_observe(i, Q, G, step, centre, amp, omega, phase, R_des, duration, control_dt, dt, lengths,
                      stiffness, segments, fractions, prm, has_base, lower, upper, max_bend, rate_scale_vec,
                      ws, scratch, base_cmd, base_info, obs, metrics)
    voi = metrics[i, 0]
    over = metrics[i, 3] - visibility_fraction
    terms[i, 0] = -weights[0] * voi
    terms[i, 1] = -weights[1] * metrics[i, 1] / 0.001
    terms[i, 2] = -weights[2] * metrics[i, 2] / 0.01
    terms[i, 3] = -weights[3] * (over / (1.0 - visibility_fraction) if over > 0.0 else 0.0)
    terms[i, 4] = -weights[4] * action_sq / (DOF + 1)
    total = 0.0
    for k in range(N_TERMS_REWARD):
        total += terms[i, k]
    rewards[i] = total
    flags[i, 0] = clamped
    flags[i, 1] = rate_saturated
    flags[i, 2] = gamma_saturated
    flags[i, 3] = 1 if (metrics[i, 1] > MAX_TIP_ERROR or not math.isfinite(metrics[i, 1])) else 0
    flags[i, 4] = 1 if step[i] >= limit[i] else 0
    flags[i, 5] = base_frozen
    flags[i, 6] = base_saturated
    flags[i, 7] = guarded


@njit(cache=True)
def occlusion_step_batch(Q, G, step, actions, active, centre, amp, omega, phase, R_des, duration, limit, control_dt,
                         substeps, lengths, stiffness, segments, fractions, prm, has_base, nullspace, residual_scale,
                         rate_scale_vec, rate_limit, gamma_rate_limit, lower, upper, max_bend, weights,
                         visibility_fraction, visibility_guard, base_cmd, base_info, obs, metrics, terms, rewards,
                         flags):
    """Advance every active row by one control step (serial)."""
    work = make_step_work(segments.shape[0])
    for i in range(Q.shape[0]):
        if active[i] != 0:
            occlusion_step_row(i, Q, G, step, actions, centre, amp, omega, phase, R_des, duration, limit, control_dt,
                               substeps, lengths, stiffness, segments, fractions, prm, has_base, nullspace,
                               residual_scale, rate_scale_vec, rate_limit, gamma_rate_limit, lower, upper, max_bend,
                               weights, visibility_fraction, visibility_guard, base_cmd, base_info, obs, metrics,
                               terms, rewards, flags, work)


@njit(cache=True, parallel=True)
def occlusion_step_batch_parallel(Q, G, step, actions, active, centre, amp, omega, phase, R_des, duration, limit,
                                  control_dt, substeps, lengths, stiffness, segments, fractions, prm, has_base,
                                  nullspace, residual_scale, rate_scale_vec, rate_limit, gamma_rate_limit, lower, upper,
                                  max_bend, weights, visibility_fraction, visibility_guard, base_cmd, base_info, obs,
                                  metrics, terms, rewards, flags, n_chunks):
    """As ``occlusion_step_batch``, rows split into ``n_chunks`` contiguous chunks over threads.

    Rows are independent and each is computed by the same row function, so results equal the serial ones.
    """
    n = Q.shape[0]
    for chunk in prange(n_chunks):
        work = make_step_work(segments.shape[0])
        for i in range(chunk * n // n_chunks, (chunk + 1) * n // n_chunks):
            if active[i] != 0:
                occlusion_step_row(i, Q, G, step, actions, centre, amp, omega, phase, R_des, duration, limit,
                                   control_dt, substeps, lengths, stiffness, segments, fractions, prm, has_base,
                                   nullspace, residual_scale, rate_scale_vec, rate_limit, gamma_rate_limit, lower,
                                   upper, max_bend, weights, visibility_fraction, visibility_guard, base_cmd,
                                   base_info, obs, metrics, terms, rewards, flags, work)


@njit(cache=True)
def occlusion_observe_batch(rows, Q, G, step, centre, amp, omega, phase, R_des, duration, control_dt, substeps,
                            lengths, stiffness, segments, fractions, prm, has_base, lower, upper, max_bend,
                            rate_scale_vec, base_cmd, base_info, obs, metrics):
    ws = make_workspace()
    scratch = make_scratch(segments.shape[0])
    for i in rows:
        occlusion_observe(i, Q, G, step, centre, amp, omega, phase, R_des, duration, control_dt,
                          control_dt / substeps, lengths, stiffness, segments, fractions, prm, has_base, lower, upper,
                          max_bend, rate_scale_vec, ws, scratch, base_cmd, base_info, obs, metrics)


__all__ = ["occlusion_step_batch", "occlusion_step_batch_parallel", "occlusion_observe_batch", "REWARD_TERMS",
           "OBS_DIM", "ACTION_DIM"]
