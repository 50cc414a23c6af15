"""ViewTracking's step under a model error (issue 37): nominal IK, true endoscope.

The same control step as ``view_kernel`` (baseline IK rates + residual, rate limits, Euler step with
the joint limits), with the plant of ``envs/model_error.py``: the IK (and the target-space residual)
computes with the **nominal** endoscope at the **measured** joints; the command waits ``delay_steps``,
the actuators follow it with ``actuator_lag_s``, and the bending angles theta1, theta2 follow their
actuators through the ``backlash_rad`` deadband. Overlap ratio, pose errors and reward are those of
the **true** endoscope (segment lengths scaled, the camera turned by its mounting error at the tip).

Observation (what the real system of paper 001 has): the measured joints; the tip pose from a
tip-mounted electromagnetic tracker (the true tip body, ``tip_noise_m`` on its position; the tracker
cannot see the camera's mounting rotation) for the target-point and orientation errors, and the
overlap ratio the system computes from that tracked pose; the baseline's command. With a zero error
every value equals ``view_kernel``'s bit for bit (tests/envs/test_model_error.py).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from continuum_gym.baselines.view_tracking import integrate_view_step, view_rates_kernel
from continuum_gym.envs.common_kernels import OBSERVE_ONLY, clip_observation, desired_point
from continuum_gym.envs.mismatch_kernels import delay_command, lag_rates, measure, play, tip_noise
from continuum_gym.envs.model_error import MISMATCH_CALIB_EXACT, MISMATCH_TIP_EXACT
from continuum_gym.envs.row_claims import first_rows, next_rows
from continuum_gym.envs.view_tracking.controller import view_slot_rates
from continuum_gym.envs.view_tracking.kernel import (
    METRIC_OR,
    METRIC_ORIENTATION_ERROR,
    METRIC_POSITION_ERROR,
    OBS_DIM,
    OBS_LIMIT,
    POSITION_ERROR_SCALE,
    finish_view_row,
    make_view_step_work,
    target_residual_rates,
)
from continuum_gym.geometry.overlap_clipping import overlap_ratio_inline
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.davinci import davinci_pose
from continuum_gym.robots.endoscope_kernels import EndoscopeKernelArgs, endoscope_kinematics
from continuum_gym.robots.rotations import orientation_error, rotation_exp

#: Per-thread scratch: the true camera position, body rotation, target point and Jacobian; the mounting
#: rotation, the true camera rotation and target point; the true orientation error; the applied command.
ViewMismatchWork = namedtuple("ViewMismatchWork", ["p_cam", "R_body", "p_ct", "J", "mount", "R_cam", "p_tgt",
                                                   "e_true", "u", "w", "p_seen"])


@kernel
def make_view_mismatch_work():
    return ViewMismatchWork(np.empty(3), np.empty((3, 3)), np.empty(3), np.empty((6, 6)), np.empty((3, 3)),
                            np.empty((3, 3)), np.empty(3), np.empty(3), np.empty(7), np.empty(3), np.empty(3))


@kernel(borrows=True, no_cpython_wrapper=True)
def view_mismatch_observe(i, state, tasks, robot, true_robot, prm, dv, frustum, env, custom, work, mw, me, out):
    """``view_observe`` under the model error: IK at the measured joints, metrics on the true endoscope."""
    q = state.q[i]
    qm = me.q_meas[i]
    control_dt = env.control_dt
    counter = state.steps[i]
    measure(me, i, counter, 0)
    t = state.steps[i] * control_dt
    scratch, q_dv, p_dv, R_dv, p_tgt, qdot = work.scratch, work.q_dv, work.p_dv, work.R_dv, work.p_tgt, \
        work.base_rates
    desired_point(tasks, i, t, q_dv, work.dv_rate)
    davinci_pose(q_dv, dv, True, p_dv, R_dv, p_tgt)
    base_cmd = out.base_cmd
    if env.has_base and custom is not None:
        view_slot_rates(custom, qm, p_tgt, R_dv, control_dt, robot, qdot)
        for k in range(6):
            base_cmd[i, k] = qdot[k]
    elif env.has_base:
        view_rates_kernel(qm, p_tgt, R_dv, control_dt, robot, prm, scratch, qdot)
        for k in range(6):
            base_cmd[i, k] = qdot[k]
    else:
        for k in range(6):
            base_cmd[i, k] = 0.0
    # the truth: the tracked body (true kinematics), then the camera on its true mounting
    p_cam, R_body, p_ct = mw.p_cam, mw.R_body, mw.p_ct
    endoscope_kinematics(q, true_robot, scratch.ws, p_cam, R_body, p_ct, mw.J, False)
    exact_mount = me.flags[i, MISMATCH_CALIB_EXACT] != 0
    R_cam, p_true = mw.R_cam, mw.p_tgt
    if exact_mount:
        for a in range(3):
            p_true[a] = p_ct[a]
            for b in range(3):
                R_cam[a, b] = R_body[a, b]
    else:
        for a in range(3):
            mw.w[a] = me.calib[i, a]
        rotation_exp(mw.w, mw.mount)
        for a in range(3):
            for b in range(3):
                R_cam[a, b] = R_body[a, 0] * mw.mount[0, b] + R_body[a, 1] * mw.mount[1, b] + \
                    R_body[a, 2] * mw.mount[2, b]
        for a in range(3):  # the target point rides on the camera: offset body-frame, turned by the mounting
            acc = 0.0
            for b in range(3):
                local = 0.0
                for c in range(3):
                    local += R_body[c, b] * (p_ct[c] - p_cam[c])
                acc += R_cam[a, b] * local
            p_true[a] = p_cam[a] + acc
    ratio = overlap_ratio_inline(p_dv, R_dv, p_cam, R_cam, frustum.tan_half, frustum.near, frustum.far, work.overlap)
    d0 = p_tgt[0] - p_true[0]
    d1 = p_tgt[1] - p_true[1]
    d2 = p_tgt[2] - p_true[2]
    e_true = mw.e_true
    orientation_error(R_dv, R_cam, scratch.work33, e_true)
    metrics = out.metrics
    metrics[i, METRIC_OR] = ratio
    metrics[i, METRIC_POSITION_ERROR] = math.sqrt(d0 ** 2 + d1 ** 2 + d2 ** 2)
    metrics[i, METRIC_ORIENTATION_ERROR] = math.sqrt(e_true[0] ** 2 + e_true[1] ** 2 + e_true[2] ** 2)
    # what the system measures: the tracked tip (body pose, nominal mounting) and its overlap ratio
    p_seen = mw.p_seen
    for a in range(3):
        p_seen[a] = p_ct[a]
    if me.flags[i, MISMATCH_TIP_EXACT] == 0:
        for a in range(3):
            p_seen[a] += tip_noise(me, i, counter, a)
    e_w = scratch.e_w
    orientation_error(R_dv, R_body, scratch.work33, e_w)
    ratio_seen = ratio if exact_mount else overlap_ratio_inline(p_dv, R_dv, p_cam, R_body, frustum.tan_half,
                                                                frustum.near, frustum.far, work.overlap)
    o = out.obs[i]
    lower, upper, action_scale = prm.lower, prm.upper, env.action_scale
    o[0] = 2.0 * (qm[0] - lower[0]) / (upper[0] - lower[0]) - 1.0
    o[1] = qm[1] / math.pi
    o[2] = 2.0 * (qm[2] - lower[2]) / (upper[2] - lower[2]) - 1.0
    o[3] = math.sin(qm[3])
    o[4] = math.cos(qm[3])
    o[5] = 2.0 * (qm[4] - lower[4]) / (upper[4] - lower[4]) - 1.0
    o[6] = math.sin(qm[5])
    o[7] = math.cos(qm[5])
    for a in range(3):
        o[8 + a] = (p_tgt[a] - p_seen[a]) / POSITION_ERROR_SCALE
        o[11 + a] = e_w[a]
    o[14] = ratio_seen
    for k in range(6):
        o[15 + k] = base_cmd[i, k] / action_scale[k]
    o[21] = t / (tasks.duration[i] * control_dt)
    if o.shape[0] > OBS_DIM:  # observe_target
        o[22] = (min(max(q_dv[0], dv.lower[0]), dv.upper[0]) - 0.05) / 0.05
        o[23] = min(max(q_dv[1], dv.lower[1]), dv.upper[1]) / (math.pi / 3)
        o[24] = min(max(q_dv[2], dv.lower[2]), dv.upper[2]) / (math.pi / 3)
        o[25] = math.sin(q_dv[3])
        o[26] = math.cos(q_dv[3])
    clip_observation(o, OBS_LIMIT)


@kernel(borrows=True, no_cpython_wrapper=True)
def advance_view_mismatch(i, state, actions, tasks, robot, prm, dv, env, custom, out, work, mw, me):
    """``advance_view_row`` with the nominal IK at the measured joints driving the true plant."""
    cmd, q_new = work.cmd, work.q_new
    q = state.q[i]
    qa = me.q_act[i]
    qm = me.q_meas[i]
    base_cmd = out.base_cmd
    control_dt = env.control_dt
    action_sq = 0.0
    for k in range(6):
        action_sq += actions[i, k] * actions[i, k]
    if env.target_space and action_sq > 0.0:
        target_residual_rates(i, qm, state.steps[i] * control_dt, actions, tasks, robot, prm, dv, env, custom, work,
                              cmd)
    elif env.target_space:
        for k in range(6):
            cmd[k] = base_cmd[i, k]
    else:
        action_scale = env.action_scale
        for k in range(6):
            cmd[k] = base_cmd[i, k] + actions[i, k] * env.residual_scale * action_scale[k]
    scale = 1.0
    rate_limit = env.rate_limit
    for k in range(6):
        if abs(cmd[k]) > rate_limit[k] * (1.0 + 1e-12) and abs(cmd[k]) * scale > rate_limit[k]:
            scale = rate_limit[k] / abs(cmd[k])
    if scale < 1.0:
        for k in range(6):
            cmd[k] *= scale
    u = mw.u
    for k in range(6):
        u[k] = cmd[k]
    u[6] = 0.0
    delay_command(me, i, u, 1)
    lag_rates(me, i, u, control_dt)
    clamped = integrate_view_step(qa, me.rate[i], control_dt, prm.lower, prm.upper, q_new)
    backlash = me.backlash[i]
    for k in range(6):
        qa[k] = q_new[k]
        q[k] = play(q[k], qa[k], backlash) if (k == 2 or k == 4) else qa[k]
    state.steps[i] += 1
    return action_sq, clamped, scale


@kernel(nogil=True)
def view_mismatch_batch(state, actions, active, tasks, robot, prm, dv, frustum, env, custom, out, me, claims, start,
                        stop):
    """``view_step_batch`` under a model error: ``me`` is the rows' ``MismatchArrays``."""
    work = make_view_step_work()
    mw = make_view_mismatch_work()
    first, last = first_rows(claims, start, stop)
    while first < last:
        for i in range(first, last):
            mode = active[i]
            if mode == 0:
                continue
            true_robot = EndoscopeKernelArgs(robot.L1 * me.scale[i, 0], robot.Lm, robot.L2 * me.scale[i, 1],
                                             robot.Lc, robot.Le)
            step = mode != OBSERVE_ONLY
            action_sq, clamped, scale = 0.0, 0, 1.0
            if step:
                action_sq, clamped, scale = advance_view_mismatch(i, state, actions, tasks, robot, prm, dv, env,
                                                                  custom, out, work, mw, me)
            view_mismatch_observe(i, state, tasks, robot, true_robot, prm, dv, frustum, env, custom, work, mw, me,
                                  out)
            if step:
                finish_view_row(i, state, actions, tasks, env, out, action_sq, clamped, scale)
        first, last = next_rows(claims, start, stop, first, last)


__all__ = ["view_mismatch_batch"]
