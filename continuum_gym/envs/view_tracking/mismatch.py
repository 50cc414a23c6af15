"""ViewTracking's step under a model error (issue 37): nominal IK, true endoscope.

The same control step as ``view_tracking.kernel`` (baseline IK rates + residual, rate limits, Euler step with
the joint limits), with the plant of ``envs/model_error.py``: the IK (and the target-space residual)
computes with the **nominal** endoscope at the **measured** joints; the command waits ``delay_steps``,
the actuators follow it with ``actuator_lag_s``, and the bending angles theta1, theta2 follow their
actuators through the ``backlash_rad`` deadband. Overlap ratio, pose errors and reward are those of
the **true** endoscope (segment lengths scaled, the camera turned by its mounting error at the tip).

Observation (what the real system of paper 001 has): the measured joints; the tip pose from a
tip-mounted electromagnetic tracker (the true tip body, ``tip_noise_m`` on its position; the tracker
cannot see the camera's mounting rotation) for the target-point and orientation errors, and the
overlap ratio the system computes from that tracked pose; the baseline's command. With a zero error
every value equals ``view_tracking.kernel``'s bit for bit (tests/envs/test_model_error.py).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from continuum_gym.baselines.view_tracking import integrate_view_step
from continuum_gym.envs.common_kernels import OBSERVE_ONLY, mark_non_finite
from continuum_gym.envs.mismatch_kernels import delay_command, lag_rates, measure, play, tip_noise
from continuum_gym.envs.model_error import MISMATCH_CALIB_EXACT, MISMATCH_TIP_EXACT
from continuum_gym.envs.row_claims import first_rows, next_rows
from continuum_gym.envs.view_tracking.kernel import (
    finish_view_row,
    make_view_step_work,
    target_and_base_command,
    view_command,
    view_observation,
)
from continuum_gym.envs.view_tracking.outputs import Flag, Metric
from continuum_gym.geometry.overlap_clipping import overlap_ratio_inline
from continuum_gym.robots.compiled import kernel
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
    scratch, q_dv, p_dv, R_dv, p_tgt = work.scratch, work.q_dv, work.p_dv, work.R_dv, work.p_tgt
    base_cmd = out.base_cmd
    target_and_base_command(i, qm, t, tasks, robot, prm, dv, env, custom, work, False, base_cmd)
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
    metrics[i, Metric.OR] = ratio
    metrics[i, Metric.POSITION_ERROR] = math.sqrt(d0 ** 2 + d1 ** 2 + d2 ** 2)
    metrics[i, Metric.ORIENTATION_ERROR] = math.sqrt(e_true[0] ** 2 + e_true[1] ** 2 + e_true[2] ** 2)
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
    view_observation(out.obs[i], i, t, qm, p_tgt, p_seen, e_w, ratio_seen, q_dv, tasks, prm, dv, env, base_cmd)
    mark_non_finite(i, q, out, Flag.NON_FINITE)


@kernel(borrows=True, no_cpython_wrapper=True)
def advance_view_mismatch(i, state, actions, tasks, robot, prm, dv, env, custom, out, work, mw, me):
    """``advance_view_row`` with the nominal IK at the measured joints driving the true plant."""
    cmd, q_new = work.cmd, work.q_new
    q = state.q[i]
    qa = me.q_act[i]
    qm = me.q_meas[i]
    base_cmd = out.base_cmd
    control_dt = env.control_dt
    action_sq, scale = view_command(i, qm, state, actions, tasks, robot, prm, dv, env, custom, base_cmd, work, cmd)
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
        view_mismatch_rows(state, actions, active, tasks, robot, prm, dv, frustum, env, custom, out, me, work, mw,
                           first, last)
        first, last = next_rows(claims, start, stop, first, last)


@kernel(borrows=True, no_cpython_wrapper=True)
def view_mismatch_rows(state, actions, active, tasks, robot, prm, dv, frustum, env, custom, out, me, work, mw, start,
                       stop):
    """``view_mismatch_batch``'s loop on a given work, as ``view_step_rows``: rows [start, stop) of the true
    endoscopes (segment lengths scaled)."""
    for i in range(start, stop):
        mode = active[i]
        if mode == 0:
            continue
        true_robot = EndoscopeKernelArgs(robot.L1 * me.scale[i, 0], robot.Lm, robot.L2 * me.scale[i, 1], robot.Lc,
                                         robot.Le)
        step = mode != OBSERVE_ONLY
        action_sq, clamped, scale = 0.0, 0, 1.0
        if step:
            action_sq, clamped, scale = advance_view_mismatch(i, state, actions, tasks, robot, prm, dv, env, custom,
                                                              out, work, mw, me)
        view_mismatch_observe(i, state, tasks, robot, true_robot, prm, dv, frustum, env, custom, work, mw, me, out)
        if step:
            finish_view_row(i, state, actions, tasks, env, out, action_sq, clamped, scale)


__all__ = ["view_mismatch_batch"]
