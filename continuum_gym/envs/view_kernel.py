"""One compiled call per environment step of ViewTracking, for the whole batch.

Per control step and robot: the da Vinci target at the current time, the baseline's joint rates
(cached from the previous observation for the first substep), plus the residual, optional rate
limits, explicit Euler clamped to the paper's joint limits (deltas wrapped), then the overlap ratio,
pose errors, the next baseline command, the observation and the reward terms at the new state.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from continuum_gym.baselines.view_tracking import integrate_view_step, make_view_scratch, view_errors, view_rates_kernel
from continuum_gym.envs.common_kernels import clip_observation, trajectory_point
from continuum_gym.geometry.overlap import overlap_ratio_nb
from continuum_gym.robots.rotations import rotation_exp

ACTION_DIM = 6
OBS_DIM = 22
#: Extra entries with ``observe_target``: the da Vinci configuration [L_dV, yaw, pitch, sin roll, cos roll].
TARGET_OBS_DIM = 5
OBS_LIMIT = 10.0
POSITION_ERROR_SCALE = 0.05  # m
#: Target-space residual at action 1.0 (times residual_scale): shift of the target point (m) and rotation of
#: the target frame (rad), both in {w}.
TARGET_SHIFT_SCALE = np.array([0.02, 0.5])
REWARD_TERMS = ("overlap", "position", "orientation", "action", "overlap_bonus")
#: The coverage map's success criterion (paper-notes §2): OR above it counts as reproducing the view.
OVERLAP_BONUS_THRESHOLD = 0.8
N_REWARD_TERMS = len(REWARD_TERMS)


@njit(cache=True)
def davinci_pose(q_dv, alpha, Le, lower, upper, p_cam, R_cam, p_tgt):
    """da Vinci camera (= target) frame and target point for q_dv clipped to its ranges (paper-notes §2.2)."""
    L = min(max(q_dv[0], lower[0]), upper[0])
    yaw = min(max(q_dv[1], lower[1]), upper[1])
    pitch = min(max(q_dv[2], lower[2]), upper[2])
    roll = min(max(q_dv[3], lower[3]), upper[3])
    cy, sy = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    # R3 = Ry(yaw) Rx(pitch) Rz(roll), column by column.
    c1x = sy * sp
    c1z = cy * sp
    r0 = (cr * cy + sr * c1x, sr * cp, sr * c1z - cr * sy)
    r1 = (cr * c1x - sr * cy, cr * cp, sr * sy + cr * c1z)
    r2 = (sy * cp, -sp, cy * cp)
    ca, sa = math.cos(alpha), math.sin(alpha)
    for a in range(3):
        p_cam[a] = L * r2[a]
        R_cam[a, 0] = r0[a]
        R_cam[a, 1] = ca * r1[a] - sa * r2[a]
        R_cam[a, 2] = sa * r1[a] + ca * r2[a]
        p_tgt[a] = p_cam[a] + Le * R_cam[a, 2]


@njit(cache=True)
def view_observe(i, Q, step, centre, amp, omega, phase, duration, control_dt, geom, prm, has_base, dv_alpha, dv_Le,
                 dv_lower, dv_upper, action_scale, tan_half, near, far, scratch, base_cmd, obs, metrics):
    """State of row i -> next baseline command (cached), observation, metrics [OR, eps_p (m), eps_R (rad)]."""
    q = Q[i]
    t = step[i] * control_dt
    q_dv = np.empty(4)
    dv_rate = np.empty(4)
    trajectory_point(centre[i], amp[i], omega[i], phase[i], t, q_dv, dv_rate)
    p_dv = np.empty(3)
    R_dv = np.empty((3, 3))
    p_tgt = np.empty(3)
    davinci_pose(q_dv, dv_alpha, dv_Le, dv_lower, dv_upper, p_dv, R_dv, p_tgt)
    qdot = np.empty(6)
    if has_base:
        eps_p, eps_r, _ = view_rates_kernel(q, p_tgt, R_dv, control_dt, geom, prm, scratch, qdot)
        for k in range(6):
            base_cmd[i, k] = qdot[k]
    else:
        eps_p, eps_r = view_errors(q, p_tgt, R_dv, geom, scratch)
        for k in range(6):
            base_cmd[i, k] = 0.0
    p_cam = scratch[0]
    R_ct = scratch[1]
    p_ct = scratch[2]
    e_w = scratch[8]
    ratio = overlap_ratio_nb(p_dv, R_dv, p_cam, R_ct, tan_half, near, far)
    metrics[i, 0] = ratio
    metrics[i, 1] = eps_p
    metrics[i, 2] = eps_r
    o = obs[i]
    o[0] = 2.0 * (q[0] - prm.lower[0]) / (prm.upper[0] - prm.lower[0]) - 1.0
    o[1] = q[1] / math.pi
    o[2] = 2.0 * (q[2] - prm.lower[2]) / (prm.upper[2] - prm.lower[2]) - 1.0
    o[3] = math.sin(q[3])
    o[4] = math.cos(q[3])
    o[5] = 2.0 * (q[4] - prm.lower[4]) / (prm.upper[4] - prm.lower[4]) - 1.0
    o[6] = math.sin(q[5])
    o[7] = math.cos(q[5])
    for a in range(3):
        o[8 + a] = (p_tgt[a] - p_ct[a]) / POSITION_ERROR_SCALE
        o[11 + a] = e_w[a]
    o[14] = ratio
    for k in range(6):
        o[15 + k] = base_cmd[i, k] / action_scale[k]
    o[21] = t / (duration[i] * control_dt)
    if o.shape[0] > OBS_DIM:  # observe_target
        o[22] = (min(max(q_dv[0], dv_lower[0]), dv_upper[0]) - 0.05) / 0.05
        o[23] = min(max(q_dv[1], dv_lower[1]), dv_upper[1]) / (math.pi / 3)
        o[24] = min(max(q_dv[2], dv_lower[2]), dv_upper[2]) / (math.pi / 3)
        o[25] = math.sin(q_dv[3])
        o[26] = math.cos(q_dv[3])
    clip_observation(o, OBS_LIMIT)


@njit(cache=True)
def make_view_step_work():
    return (make_view_scratch(), np.empty(6), np.empty(6), np.empty(4), np.empty(4), np.empty(3), np.empty((3, 3)),
            np.empty(3), np.empty(3), np.empty((3, 3)), np.empty((3, 3)))


@njit(cache=True)
def target_residual_rates(i, q, t, actions, centre, amp, omega, phase, control_dt, geom, prm, residual_scale,
                          target_scale, dv_alpha, dv_Le, dv_lower, dv_upper, work, cmd):
    """The baseline's joint rates towards the da Vinci target moved by the action (target-space residual).

    The target point moves by a[0:3] * residual_scale * target_scale[0] (m) and the target frame turns by
    exp([a[3:6] * residual_scale * target_scale[1]]) (rad), both in {w}.
    """
    scratch, _, _, q_dv, dv_rate, p_dv, R_dv, p_tgt, w, turn, R_goal = work
    trajectory_point(centre[i], amp[i], omega[i], phase[i], t, q_dv, dv_rate)
    davinci_pose(q_dv, dv_alpha, dv_Le, dv_lower, dv_upper, p_dv, R_dv, p_tgt)
    for a in range(3):
        p_tgt[a] += actions[i, a] * residual_scale * target_scale[0]
        w[a] = actions[i, 3 + a] * residual_scale * target_scale[1]
    rotation_exp(w, turn)
    for a in range(3):
        for b in range(3):
            R_goal[a, b] = turn[a, 0] * R_dv[0, b] + turn[a, 1] * R_dv[1, b] + turn[a, 2] * R_dv[2, b]
    view_rates_kernel(q, p_tgt, R_goal, control_dt, geom, prm, scratch, cmd)


@njit(cache=True)
def view_step_row(i, Q, step, actions, centre, amp, omega, phase, duration, limit, control_dt, geom, prm, has_base,
                  residual_scale, target_space, target_scale, action_scale, rate_limit, dv_alpha, dv_Le, dv_lower,
                  dv_upper, tan_half, near, far, weights, base_cmd, obs, metrics, terms, rewards, flags, work):
    """One control step (one IK step of dt = control_dt, the paper's 0.01 s) for row i.

    flags[i] = [clamped_bits, rate_saturated, terminated, truncated].
    """
    scratch, cmd, q_new = work[0], work[1], work[2]
    q = Q[i]
    action_sq = 0.0
    for k in range(6):
        action_sq += actions[i, k] * actions[i, k]
    if target_space and action_sq > 0.0:
        target_residual_rates(i, q, step[i] * control_dt, actions, centre, amp, omega, phase, control_dt, geom, prm,
                              residual_scale, target_scale, dv_alpha, dv_Le, dv_lower, dv_upper, work, cmd)
    elif target_space:  # a zero target residual is the baseline's cached command, bit for bit
        for k in range(6):
            cmd[k] = base_cmd[i, k]
    else:
        for k in range(6):
            cmd[k] = base_cmd[i, k] + actions[i, k] * residual_scale * action_scale[k]
    scale = 1.0
    for k in range(6):
        if abs(cmd[k]) > rate_limit[k] * (1.0 + 1e-12) and abs(cmd[k]) * scale > rate_limit[k]:
            scale = rate_limit[k] / abs(cmd[k])
    if scale < 1.0:
        for k in range(6):
            cmd[k] *= scale
    clamped = integrate_view_step(q, cmd, control_dt, prm.lower, prm.upper, q_new)
    for k in range(6):
        q[k] = q_new[k]
    step[i] += 1
    view_observe(i, Q, step, centre, amp, omega, phase, duration, control_dt, geom, prm, has_base, dv_alpha,
                 dv_Le, dv_lower, dv_upper, action_scale, tan_half, near, far, scratch, base_cmd, obs, metrics)
    terms[i, 0] = weights[0] * metrics[i, 0]
    terms[i, 1] = -weights[1] * metrics[i, 1] / 0.01
    terms[i, 2] = -weights[2] * metrics[i, 2]
    terms[i, 3] = -weights[3] * action_sq / 6.0
    terms[i, 4] = weights[4] if metrics[i, 0] > OVERLAP_BONUS_THRESHOLD else 0.0
    total = 0.0
    for k in range(N_REWARD_TERMS):
        total += terms[i, k]
    rewards[i] = total
    flags[i, 0] = clamped
    flags[i, 1] = 1 if scale < 1.0 else 0
    flags[i, 2] = 0 if math.isfinite(metrics[i, 1]) else 1
    flags[i, 3] = 1 if step[i] >= limit[i] else 0


@njit(cache=True)
def view_step_batch(Q, step, actions, active, centre, amp, omega, phase, duration, limit, control_dt, geom, prm,
                    has_base, residual_scale, target_space, target_scale, action_scale, rate_limit, dv_alpha, dv_Le,
                    dv_lower, dv_upper, tan_half, near, far, weights, base_cmd, obs, metrics, terms, rewards, flags):
    work = make_view_step_work()
    for i in range(Q.shape[0]):
        if active[i] != 0:
            view_step_row(i, Q, step, actions, centre, amp, omega, phase, duration, limit, control_dt, geom, prm,
                          has_base, residual_scale, target_space, target_scale, action_scale, rate_limit, dv_alpha,
                          dv_Le, dv_lower, dv_upper, tan_half, near, far, weights, base_cmd, obs, metrics, terms,
                          rewards, flags, work)


@njit(cache=True, parallel=True)
def view_step_batch_parallel(Q, step, actions, active, centre, amp, omega, phase, duration, limit, control_dt, geom,
                             prm, has_base, residual_scale, target_space, target_scale, action_scale, rate_limit,
                             dv_alpha, dv_Le, dv_lower, dv_upper, tan_half, near, far, weights, base_cmd, obs, metrics,
                             terms, rewards, flags, n_chunks):
    n = Q.shape[0]
    for chunk in prange(n_chunks):
        work = make_view_step_work()
        for i in range(chunk * n // n_chunks, (chunk + 1) * n // n_chunks):
            if active[i] != 0:
                view_step_row(i, Q, step, actions, centre, amp, omega, phase, duration, limit, control_dt, geom, prm,
                              has_base, residual_scale, target_space, target_scale, action_scale, rate_limit,
                              dv_alpha, dv_Le, dv_lower, dv_upper, tan_half, near, far, weights, base_cmd, obs,
                              metrics, terms, rewards, flags, work)


@njit(cache=True)
def view_observe_batch(rows, Q, step, centre, amp, omega, phase, duration, control_dt, geom, prm, has_base, dv_alpha,
                       dv_Le, dv_lower, dv_upper, action_scale, tan_half, near, far, base_cmd, obs, metrics):
    scratch = make_view_scratch()
    for i in rows:
        view_observe(i, Q, step, centre, amp, omega, phase, duration, control_dt, geom, prm, has_base, dv_alpha,
                     dv_Le, dv_lower, dv_upper, action_scale, tan_half, near, far, scratch, base_cmd, obs, metrics)
