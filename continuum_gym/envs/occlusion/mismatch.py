"""OcclusionAvoidance's step under a model error (issue 37): nominal controller, true plant.

The same control step as ``occlusion.kernel.occlusion_step_row`` (baseline + residual per substep,
null-space projection, rate saturation, visibility guard), with the plant of ``envs/model_error.py``:

- the baseline, the null-space projection and the guard compute with the **nominal** robot and cone
  at the **measured** joints (actuator positions + encoder noise, one measurement per substep);
- the command then waits ``delay_steps`` control steps, the actuators follow it with the first-order
  ``actuator_lag_s``, and each segment's true bending angle follows its actuator through the
  ``backlash_rad`` deadband;
- metrics, reward and termination are those of the **true** robot (segment lengths scaled) in the
  **true** cone (channel offset and lens tilt off by the calibration error).

Observation (what the real system of paper 000 has): the measured joints; gamma (the endoscope's own
encoder); the tip as the endoscope sees it (the true tip in the true lens frame, turned into {w} by
the nominal calibration, plus ``tip_noise_m``) for the tip errors; the tip's angle from the view axis
as seen in the image (true); the VOI *estimated* from the nominal model at the measured joints (a real
system cannot measure eq 27); and the baseline's command. With a zero error every value equals
``occlusion.kernel``'s bit for bit (tests/envs/test_model_error.py).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from continuum_gym.baselines.occlusion_kernels import wrap_angle
from continuum_gym.envs.common_kernels import (
    OBSERVE_ONLY,
    clamp,
    desired_point,
    desired_rotation,
    mark_non_finite,
)
from continuum_gym.envs.mismatch_kernels import delay_command, lag_rates, measure, play, tip_noise
from continuum_gym.envs.model_error import MISMATCH_CALIB_EXACT, MISMATCH_TIP_EXACT
from continuum_gym.envs.occlusion.kernel import (
    VOI_SAMPLES_PER_SEGMENT,
    cache_base_command,
    endoscope_rate,
    finish_occlusion_row,
    guard_on,
    joint_command,
    make_step_work,
    occlusion_observation,
    residual_rates,
    substep_base_rates,
    view_fraction_at,
)
from continuum_gym.envs.occlusion.outputs import BaseInfo, Flag, Metric
from continuum_gym.envs.row_claims import first_rows, next_rows
from continuum_gym.geometry.lens_cone import ConeKernelArgs, lens_to_world_direction, to_lens
from continuum_gym.geometry.occlusion import voi_of_configuration
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.mbcr_kernels import MBCRKernelArgs, tip_kernel
from continuum_gym.robots.rotations import orientation_error

#: Per-thread scratch of the mismatch step: the true tip (p, R, J), the seen tip (p, R), the tip error
#: and orientation error seen, the applied command (dof + 1) and the joints the guard predicts.
MismatchWork = namedtuple("MismatchWork", ["p", "R", "J", "p_seen", "R_seen", "e_true", "u", "q_pred"])


@kernel
def make_mismatch_work(dof):
    return MismatchWork(np.empty(3), np.empty((3, 3)), np.empty((6, dof)), np.empty(3), np.empty((3, 3)),
                        np.empty(3), np.empty(dof + 1), np.empty(dof))


@kernel(inline="always")
def _turn_about_lens(x, y, z, cg, sg, ca, sa):
    """Rz(gamma) Ry(d_alpha) Rz(-gamma) (x, y, z): the nominal lens frame's error, seen in {w}."""
    ux = cg * x + sg * y
    uy = -sg * x + cg * y
    vx = ca * ux + sa * z
    vz = -sa * ux + ca * z
    return cg * vx - sg * uy, sg * vx + cg * uy, vz


@kernel(borrows=True, no_cpython_wrapper=True)
def seen_tip(i, gamma, cone, true_cone, me, mw):
    """The true tip (mw.p, mw.R) as the endoscope sees it, in {w} by the nominal calibration (+ noise)."""
    p, R, ps, Rs = mw.p, mw.R, mw.p_seen, mw.R_seen
    if me.flags[i, MISMATCH_CALIB_EXACT] != 0:
        for a in range(3):
            ps[a] = p[a]
            for b in range(3):
                Rs[a, b] = R[a, b]
    else:
        xl, yl, zl = to_lens(p[0], p[1], p[2], gamma, true_cone.d_o, true_cone.alpha, true_cone.model)
        if cone.model == 0:
            yl += cone.d_o
        ps[0], ps[1], ps[2] = lens_to_world_direction(xl, yl, zl, gamma, cone.alpha)
        if cone.model == 1:
            ps[1] += cone.d_o
        cg, sg = math.cos(gamma), math.sin(gamma)
        d_alpha = true_cone.alpha - cone.alpha
        ca, sa = math.cos(d_alpha), math.sin(d_alpha)
        for b in range(3):
            Rs[0, b], Rs[1, b], Rs[2, b] = _turn_about_lens(R[0, b], R[1, b], R[2, b], cg, sg, ca, sa)


@kernel(borrows=True, no_cpython_wrapper=True)
def mismatch_observe(i, state, tasks, robot, true_robot, prm, true_cone, env, custom, work, mw, me, out):
    """``occlusion_observe`` under the model error: controller at the measured joints, metrics on the truth."""
    q = state.q[i]
    qm = me.q_meas[i]
    gamma = state.gamma[i]
    n = robot.lengths.shape[0]
    dof = q.shape[0]
    control_dt = env.control_dt
    sub_dt = control_dt / env.substeps
    counter = state.steps[i] * env.substeps
    measure(me, i, counter, dof - 1)
    t = state.steps[i] * control_dt
    scratch = work.scratch
    p_des = work.p_des
    v_des = work.v_des
    desired_point(tasks, i, t, p_des, v_des)
    R_des = desired_rotation(tasks, i, t, work.w, work.w_rate, work.turn, work.R_goal)
    cache_base_command(i, qm, gamma, p_des, R_des, v_des, sub_dt, robot, prm, env, custom, work, False, out)
    base_cmd = out.base_cmd
    # the truth: metrics
    p, R = mw.p, mw.R
    tip_kernel(q, true_robot, work.ws, p, R, mw.J)
    e_w = mw.e_true
    orientation_error(R_des, R, scratch.work33, e_w)
    e_p0 = p_des[0] - p[0]
    e_p1 = p_des[1] - p[1]
    e_p2 = p_des[2] - p[2]
    metrics = out.metrics
    metrics[i, Metric.TIP_ERROR] = math.sqrt(e_p0 * e_p0 + e_p1 * e_p1 + e_p2 * e_p2)
    metrics[i, Metric.ORIENTATION_ERROR] = math.sqrt(e_w[0] ** 2 + e_w[1] ** 2 + e_w[2] ** 2)
    voi, _, _, _ = voi_of_configuration(q, true_robot, work.ws, gamma, true_cone, VOI_SAMPLES_PER_SEGMENT,
                                        work.points, work.lens, work.dr)
    view_fraction = view_fraction_at(p, gamma, true_cone)
    metrics[i, Metric.VOI] = voi
    metrics[i, Metric.VIEW_FRACTION] = view_fraction
    # what the system measures: the observation
    seen_tip(i, gamma, prm.cone, true_cone, me, mw)
    ps = mw.p_seen
    if me.flags[i, MISMATCH_TIP_EXACT] == 0:
        for a in range(3):
            ps[a] += tip_noise(me, i, counter, a)
    e_seen = scratch.e_w
    orientation_error(R_des, mw.R_seen, scratch.work33, e_seen)
    voi_estimate, _, _, _ = voi_of_configuration(qm, robot, work.ws, gamma, prm.cone, VOI_SAMPLES_PER_SEGMENT,
                                                 work.points, work.lens, work.dr)
    occlusion_observation(out.obs[i], i, n, qm, gamma, p_des[0] - ps[0], p_des[1] - ps[1], p_des[2] - ps[2], e_seen,
                          v_des, view_fraction, voi_estimate, t, tasks, env, base_cmd)
    mark_non_finite(i, q, out, Flag.NON_FINITE)


@kernel(borrows=True, no_cpython_wrapper=True)
def mismatch_step_row(i, state, actions, tasks, robot, true_robot, prm, true_cone, env, custom, out, work, mw, me):
    """``occlusion_step_row`` with the nominal controller at the measured joints driving the true plant."""
    ws, scratch, qdot, residual, projected, cmd = work.ws, work.scratch, work.qdot, work.residual, work.projected, \
        work.cmd
    tip_p, tip_R, tip_J = scratch.p, scratch.R, scratch.J
    rate_limit, lower, upper, rate_scale_vec = env.rate_limit, env.lower, env.upper, env.rate_scale_vec
    G = state.gamma
    dof = state.q.shape[1]
    substeps = env.substeps
    dt = env.control_dt / substeps
    q = state.q[i]
    qa = me.q_act[i]
    qm = me.q_meas[i]
    rate = me.rate[i]
    u, q_pred = mw.u, mw.q_pred
    backlash = me.backlash[i]
    clamped = 0
    rate_saturated = 0
    gamma_saturated = 0
    guarded = 0
    base_frozen = out.base_info[i, BaseInfo.FROZEN]
    base_saturated = out.base_info[i, BaseInfo.SATURATED]
    base_cmd = out.base_cmd
    action_sq, gamma_residual, project = residual_rates(i, actions, env, rate_scale_vec, dof, residual)
    for s in range(substeps):
        t = state.steps[i] * env.control_dt + s * dt
        if s > 0:  # the first substep's measurement is the observation's
            measure(me, i, state.steps[i] * substeps + s, dof - 1)
        gd, base_frozen, base_saturated = substep_base_rates(
            i, s, t, dt, qm, G[i], tasks, robot, prm, env, custom, work, base_cmd, project, base_frozen,
            base_saturated)
        scale = joint_command(project, tip_J, residual, work, qdot, projected, rate_limit, cmd)
        if scale < 1.0:
            rate_saturated = 1
        for k in range(dof):
            u[k] = scale * cmd[k]
        if guard_on(env, gamma_residual):  # the guard predicts with the nominal model
            for k in range(dof):
                q_pred[k], _ = clamp(qm[k] + u[k] * dt, lower[k], upper[k])
        g_rate, hit, clipped = endoscope_rate(q_pred, G[i], gd, gamma_residual, dt, robot, prm, env, ws, tip_p, tip_R,
                                              tip_J)
        if hit:
            guarded = 1
        if clipped:
            gamma_saturated = 1
        u[dof] = g_rate
        # the plant: delay, actuator lag, position limits, backlash of the bending angles
        delay_command(me, i, u, substeps)
        lag_rates(me, i, u, dt)
        for k in range(dof):
            qa[k], hit = clamp(qa[k] + rate[k] * dt, lower[k], upper[k])
            if hit:
                clamped |= 1 << k
        for k in range(dof):
            q[k] = play(q[k], qa[k], backlash) if (k % 2 == 0 and k < dof - 1) else qa[k]
        G[i] = wrap_angle(G[i] + rate[dof] * dt)
    state.steps[i] += 1
    mismatch_observe(i, state, tasks, robot, true_robot, prm, true_cone, env, custom, work, mw, me, out)
    finish_occlusion_row(i, state, tasks, env, out, action_sq, dof, clamped, rate_saturated, gamma_saturated,
                         base_frozen, base_saturated, guarded)


@kernel(nogil=True)
def occlusion_mismatch_batch(state, actions, active, tasks, robot, prm, env, custom, out, me, claims, start, stop):
    """``occlusion_step_batch`` under a model error: ``me`` is the rows' ``MismatchArrays``."""
    n = robot.lengths.shape[0]
    dof = state.q.shape[1]
    work = make_step_work(n, prm.segments.shape[0], robot.n_insert)
    mw = make_mismatch_work(dof)
    lengths = np.empty(n)
    true_robot = MBCRKernelArgs(lengths, robot.stiffness, robot.n_insert)
    cone = prm.cone
    first, last = first_rows(claims, start, stop)
    while first < last:
        for i in range(first, last):
            mode = active[i]
            if mode == 0:
                continue
            for j in range(n):
                lengths[j] = robot.lengths[j] * me.scale[i, j]
            true_cone = ConeKernelArgs(cone.d_o + me.calib[i, 0], cone.alpha + me.calib[i, 1], cone.beta, cone.model)
            if mode == OBSERVE_ONLY:
                mismatch_observe(i, state, tasks, robot, true_robot, prm, true_cone, env, custom, work, mw, me, out)
            else:
                mismatch_step_row(i, state, actions, tasks, robot, true_robot, prm, true_cone, env, custom, out, work,
                                  mw, me)
        first, last = next_rows(claims, start, stop, first, last)


__all__ = ["occlusion_mismatch_batch"]
