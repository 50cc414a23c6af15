"""One compiled call per environment step of ViewTracking, for the whole batch.

Per control step and robot: the da Vinci target at the current time, the baseline's joint rates
(cached from the previous observation), plus the residual, optional rate limits, explicit Euler
clamped to the paper's joint limits (deltas wrapped), then the overlap ratio, pose errors, the next
baseline command, the observation and the reward terms at the new state.

Kernels take named bundles: ``ViewState`` (q, step counters), ``TaskArrays`` (the da Vinci trajectory
of each row), the robot's, the controller's, the da Vinci's and the frustum's ``kernel_args``, the
env's ``ViewStepParams`` and the ``ViewOutputs`` they fill. The observation's layout and the columns of
``metrics`` and ``flags`` are declared once, in ``outputs`` (``OBS``, ``Metric``, ``Flag``).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from continuum_gym.baselines.view_tracking import (
    integrate_view_step,
    make_view_scratch,
    view_errors,
    view_rates_kernel,
)
from continuum_gym.envs.common_kernels import (
    OBSERVE_ONLY,
    clip_observation,
    desired_point,
    mark_non_finite,
    mark_non_finite_reward,
)
from continuum_gym.envs.row_claims import first_rows, next_rows
from continuum_gym.envs.view_tracking.controller import view_slot_rates
from continuum_gym.envs.view_tracking.outputs import OBS, OBS_DIM, POSITION_ERROR_SCALE, Flag, Metric
from continuum_gym.geometry.overlap import make_overlap_work
from continuum_gym.geometry.overlap_clipping import overlap_ratio_inline
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.davinci import davinci_pose
from continuum_gym.robots.rotations import rotation_exp

ACTION_DIM = 6
OBS_LIMIT = 10.0
#: Target-space residual at action 1.0 (times residual_scale): shift of the target point (m) and rotation of
#: the target frame (rad), both in {w}.
TARGET_SHIFT_SCALE = np.array([0.02, 0.5])
REWARD_TERMS = ("overlap", "position", "orientation", "action", "overlap_bonus")
#: The coverage map's success criterion (paper-notes §2.6): OR above it counts as reproducing the view.
OVERLAP_BONUS_THRESHOLD = 0.8
N_REWARD_TERMS = len(REWARD_TERMS)


#: Per-row state: configurations (N, 6) and control steps (N,).
ViewState = namedtuple("ViewState", ["q", "steps"])
#: What the env adds to the robot and the controller: timing, the residual (scale, target space and its
#: scales, the action scale), optional rate limits and the reward weights.
ViewStepParams = namedtuple("ViewStepParams", ["control_dt", "has_base", "residual_scale", "target_space",
                                               "target_scale", "action_scale", "rate_limit", "weights"])
#: What a step writes: the cached baseline command, observations, metrics, reward terms, rewards, flags.
ViewOutputs = namedtuple("ViewOutputs", ["base_cmd", "obs", "metrics", "terms", "rewards", "flags", "faults"])
#: Per-thread scratch of a ViewTracking row's step (``view_step_rows``).
ViewStepWork = namedtuple("ViewStepWork", ["scratch", "cmd", "q_new", "q_dv", "dv_rate", "p_dv", "R_dv", "p_tgt",
                                           "w", "turn", "R_goal", "base_rates", "overlap"])


@kernel(inline="always")
def view_observation(o, i, t, q, p_tgt, p_tip, e_w, ratio, q_dv, tasks, prm, dv, env, base_cmd):
    """Row i's observation into o: joints q, target point p_tgt's offset from the tip's p_tip, orientation
    error e_w, overlap ratio, the cached baseline command, time (and the da Vinci's q_dv with observe_target)."""
    control_dt = env.control_dt
    lower, upper, action_scale = prm.lower, prm.upper, env.action_scale
    o[OBS.l0] = 2.0 * (q[0] - lower[0]) / (upper[0] - lower[0]) - 1.0
    o[OBS.phi] = q[1] / math.pi
    o[OBS.theta1] = 2.0 * (q[2] - lower[2]) / (upper[2] - lower[2]) - 1.0
    o[OBS.delta1] = math.sin(q[3])
    o[OBS.delta1 + 1] = math.cos(q[3])
    o[OBS.theta2] = 2.0 * (q[4] - lower[4]) / (upper[4] - lower[4]) - 1.0
    o[OBS.delta2] = math.sin(q[5])
    o[OBS.delta2 + 1] = math.cos(q[5])
    for a in range(3):
        o[OBS.target_error + a] = (p_tgt[a] - p_tip[a]) / POSITION_ERROR_SCALE
        o[OBS.orientation_error + a] = e_w[a]
    o[OBS.overlap] = ratio
    for k in range(6):
        o[OBS.base_command + k] = base_cmd[i, k] / action_scale[k]
    o[OBS.time] = t / (tasks.duration[i] * control_dt)
    if o.shape[0] > OBS_DIM:  # observe_target
        o[OBS.target_insertion] = (min(max(q_dv[0], dv.lower[0]), dv.upper[0]) - 0.05) / 0.05
        o[OBS.target_yaw_pitch] = min(max(q_dv[1], dv.lower[1]), dv.upper[1]) / (math.pi / 3)
        o[OBS.target_yaw_pitch + 1] = min(max(q_dv[2], dv.lower[2]), dv.upper[2]) / (math.pi / 3)
        o[OBS.target_roll] = math.sin(q_dv[3])
        o[OBS.target_roll + 1] = math.cos(q_dv[3])
    clip_observation(o, OBS_LIMIT)


@kernel(inline="always")
def target_and_base_command(i, qc, t, tasks, robot, prm, dv, env, custom, work, errors, base_cmd):
    """Row i's da Vinci target at time t (work.q_dv, p_dv, R_dv, p_tgt) and the baseline's joint rates at the
    controller's joints qc, cached into base_cmd[i]. With ``errors``: returns the pose errors (eps_p, eps_r)
    at qc, its camera pose left in work.scratch; else (0, 0)."""
    control_dt = env.control_dt
    scratch, q_dv, p_dv, R_dv, p_tgt, qdot = work.scratch, work.q_dv, work.p_dv, work.R_dv, work.p_tgt, \
        work.base_rates
    desired_point(tasks, i, t, q_dv, work.dv_rate)
    davinci_pose(q_dv, dv, True, p_dv, R_dv, p_tgt)
    eps_p, eps_r = 0.0, 0.0
    if env.has_base and custom is not None:
        view_slot_rates(custom, qc, p_tgt, R_dv, control_dt, robot, qdot)
        if errors:
            eps_p, eps_r = view_errors(qc, p_tgt, R_dv, robot, scratch)
        for k in range(6):
            base_cmd[i, k] = qdot[k]
    elif env.has_base:
        eps_p, eps_r, _ = view_rates_kernel(qc, p_tgt, R_dv, control_dt, robot, prm, scratch, qdot)
        for k in range(6):
            base_cmd[i, k] = qdot[k]
    else:
        if errors:
            eps_p, eps_r = view_errors(qc, p_tgt, R_dv, robot, scratch)
        for k in range(6):
            base_cmd[i, k] = 0.0
    return eps_p, eps_r


@kernel(borrows=True, no_cpython_wrapper=True, inline="always")
def view_observe(i, state, tasks, robot, prm, dv, frustum, env, custom, work, out):
    """State of row i -> next baseline command (cached), observation, metrics [OR, eps_p (m), eps_R (rad)].

    ``work`` is a ``ViewStepWork``: the step that calls this is done with its arrays (no allocation per row).
    """
    q = state.q[i]
    control_dt = env.control_dt
    t = state.steps[i] * control_dt
    scratch, q_dv, p_dv, R_dv, p_tgt = work.scratch, work.q_dv, work.p_dv, work.R_dv, work.p_tgt
    base_cmd = out.base_cmd
    eps_p, eps_r = target_and_base_command(i, q, t, tasks, robot, prm, dv, env, custom, work, True, base_cmd)
    p_ct = scratch.p_ct
    e_w = scratch.e_w
    ratio = overlap_ratio_inline(p_dv, R_dv, scratch.p_cam, scratch.R_ct, frustum.tan_half, frustum.near,
                                 frustum.far, work.overlap)
    metrics = out.metrics
    metrics[i, Metric.OR] = ratio
    metrics[i, Metric.POSITION_ERROR] = eps_p
    metrics[i, Metric.ORIENTATION_ERROR] = eps_r
    view_observation(out.obs[i], i, t, q, p_tgt, p_ct, e_w, ratio, q_dv, tasks, prm, dv, env, base_cmd)
    mark_non_finite(i, q, out, Flag.NON_FINITE)


@kernel
def make_view_step_work():
    return ViewStepWork(make_view_scratch(), np.empty(6), np.empty(6), np.empty(4), np.empty(4), np.empty(3),
                        np.empty((3, 3)), np.empty(3), np.empty(3), np.empty((3, 3)), np.empty((3, 3)), np.empty(6),
                        make_overlap_work())


@kernel(borrows=True, no_cpython_wrapper=True)
def target_residual_rates(i, q, t, actions, tasks, robot, prm, dv, env, custom, work, cmd):
    """The baseline's joint rates towards the da Vinci target moved by the action (target-space residual).

    The target point moves by a[0:3] * residual_scale * target_scale[0] (m) and the target frame turns by
    exp([a[3:6] * residual_scale * target_scale[1]]) (rad), both in {w}.
    """
    q_dv, p_dv, R_dv, p_tgt, w, turn, R_goal = work.q_dv, work.p_dv, work.R_dv, work.p_tgt, work.w, work.turn, \
        work.R_goal
    desired_point(tasks, i, t, q_dv, work.dv_rate)
    davinci_pose(q_dv, dv, True, p_dv, R_dv, p_tgt)
    for a in range(3):
        p_tgt[a] += actions[i, a] * env.residual_scale * env.target_scale[0]
        w[a] = actions[i, 3 + a] * env.residual_scale * env.target_scale[1]
    rotation_exp(w, turn)
    for a in range(3):
        for b in range(3):
            R_goal[a, b] = turn[a, 0] * R_dv[0, b] + turn[a, 1] * R_dv[1, b] + turn[a, 2] * R_dv[2, b]
    if custom is not None:
        view_slot_rates(custom, q, p_tgt, R_goal, env.control_dt, robot, cmd)
    else:
        view_rates_kernel(q, p_tgt, R_goal, env.control_dt, robot, prm, work.scratch, cmd)


@kernel(inline="always")
def view_command(i, qc, state, actions, tasks, robot, prm, dv, env, custom, base_cmd, work, cmd):
    """Row i's joint rates into cmd: the baseline's (cached, or at the controller's joints qc for a target
    residual) with the residual, scaled uniformly within the rate limits. Returns (|a|^2, rate scale)."""
    control_dt = env.control_dt
    action_sq = 0.0
    for k in range(6):
        action_sq += actions[i, k] * actions[i, k]
    if env.target_space and action_sq > 0.0:
        target_residual_rates(i, qc, state.steps[i] * control_dt, actions, tasks, robot, prm, dv, env, custom, work,
                              cmd)
    elif env.target_space:  # a zero target residual is the baseline's cached command, bit for bit
        for k in range(6):
            cmd[k] = base_cmd[i, k]
    else:
        action_scale = env.action_scale
        for k in range(6):
            cmd[k] = base_cmd[i, k] + actions[i, k] * env.residual_scale * action_scale[k]
    scale = 1.0
    rate_limit = env.rate_limit  # a local: reading a bundle's array costs a reference count each time
    for k in range(6):
        if abs(cmd[k]) > rate_limit[k] * (1.0 + 1e-12) and abs(cmd[k]) * scale > rate_limit[k]:
            scale = rate_limit[k] / abs(cmd[k])
    if scale < 1.0:
        for k in range(6):
            cmd[k] *= scale
    return action_sq, scale


# The row's parts and its observation are inlined into view_step_rows, their only caller (the command and
# the observation's layout into the model-mismatch rows too): a call passes every array of the bundles as
# flattened arguments, a sizeable cost against a row of ~3 us. The observation is inlined at one place, for
# resets and steps alike, and DR IK stays a call: inlined as well it makes the step no faster and the first
# compile much longer.
@kernel(inline="always")
def advance_view_row(i, state, actions, tasks, robot, prm, dv, env, custom, out, work):
    """Row i's control step up to its observation: one IK step of dt = control_dt (the paper's 0.01 s).

    Returns (|a|^2, clamped joint bits, rate scale) for ``finish_view_row``.
    """
    cmd, q_new = work.cmd, work.q_new
    q = state.q[i]
    base_cmd = out.base_cmd
    control_dt = env.control_dt
    action_sq, scale = view_command(i, q, state, actions, tasks, robot, prm, dv, env, custom, base_cmd, work, cmd)
    clamped = integrate_view_step(q, cmd, control_dt, prm.lower, prm.upper, q_new)
    for k in range(6):
        q[k] = q_new[k]
    state.steps[i] += 1
    return action_sq, clamped, scale


@kernel(inline="always")
def finish_view_row(i, state, actions, tasks, env, out, action_sq, clamped, scale):
    """Row i's reward terms, reward and flags after its observation."""
    metrics = out.metrics
    terms = out.terms
    weights = env.weights
    terms[i, 0] = weights[0] * metrics[i, Metric.OR]
    terms[i, 1] = -weights[1] * metrics[i, Metric.POSITION_ERROR] / 0.01
    terms[i, 2] = -weights[2] * metrics[i, Metric.ORIENTATION_ERROR]
    terms[i, 3] = -weights[3] * action_sq / 6.0
    terms[i, 4] = weights[4] if metrics[i, Metric.OR] > OVERLAP_BONUS_THRESHOLD else 0.0
    flags = out.flags
    flags[i, Flag.CLAMPED] = clamped
    flags[i, Flag.RATE_SATURATED] = 1 if scale < 1.0 else 0
    flags[i, Flag.TERMINATED] = 0 if math.isfinite(metrics[i, Metric.POSITION_ERROR]) else 1
    flags[i, Flag.TRUNCATED] = 1 if state.steps[i] >= tasks.limit[i] else 0
    total = 0.0
    for k in range(N_REWARD_TERMS):
        total += terms[i, k]
    out.rewards[i] = total
    mark_non_finite_reward(i, out, Flag.NON_FINITE)


@kernel(nogil=True)
def view_step_batch(state, actions, active, tasks, robot, prm, dv, frustum, env, custom, out, claims,
                    start, stop):
    """Advance every row in [start, stop) whose ``active`` is nonzero by one control step, or observe a row
    marked ``OBSERVE_ONLY`` (releases the GIL; rows claimed from ``claims``: see occlusion.kernel)."""
    work = make_view_step_work()
    first, last = first_rows(claims, start, stop)
    while first < last:
        view_step_rows(state, actions, active, tasks, robot, prm, dv, frustum, env, custom, out, work,
                       first, last)
        first, last = next_rows(claims, start, stop, first, last)


@kernel(borrows=True, no_cpython_wrapper=True)
def view_step_rows(state, actions, active, tasks, robot, prm, dv, frustum, env, custom, out, work, start,
                   stop):
    """``view_step_batch``'s loop on a given work: apart from its allocation, so that the rows run without
    reference counts (``kernel(borrows=True)``)."""
    for i in range(start, stop):
        mode = active[i]
        if mode == 0:
            continue
        step = mode != OBSERVE_ONLY
        action_sq, clamped, scale = 0.0, 0, 1.0
        if step:
            action_sq, clamped, scale = advance_view_row(i, state, actions, tasks, robot, prm, dv, env, custom, out,
                                                         work)
        view_observe(i, state, tasks, robot, prm, dv, frustum, env, custom, work, out)
        if step:
            finish_view_row(i, state, actions, tasks, env, out, action_sq, clamped, scale)

