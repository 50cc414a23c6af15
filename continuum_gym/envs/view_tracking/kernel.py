"""ViewTracking's rows: what one endoscope does in a control step, and what is observed of it.

The library runs these row functions for the whole batch in one compiled call (``envs/rows.py``). Per
control step and robot: the da Vinci target at the current time, the baseline's joint rates
(cached from the previous observation), plus the residual, optional rate limits, explicit Euler
clamped to the paper's joint limits (deltas wrapped), then the overlap ratio, pose errors, the next
baseline command, the observation and the reward terms at the new state.

The row functions take the library's bundles (``envs/core.py``): ``ViewState`` (q, step counters),
``TaskArrays`` (the da Vinci trajectory of each row), ``model`` = (the robot's, the controller's, the da Vinci's
and the frustum's ``kernel_args``), the env's ``ViewStepParams``, the registered controller's slot (or None),
the thread's work, the ``ViewOutputs`` they fill and ``plant``: the model-error arrays, or None. Under a model
error the same step, observation and metric code runs with the plant's pieces (``view_tracking.plant``). The
observation's layout and the columns of ``metrics`` and ``flags`` are declared once, in ``outputs`` (``OBS``,
``Metric``, ``Flag``).
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
from continuum_gym.envs.common_kernels import clip_observation, desired_point
from continuum_gym.envs.mismatch_kernels import measure, tip_noise
from continuum_gym.envs.model_error import MISMATCH_CALIB_EXACT, MISMATCH_TIP_EXACT
from continuum_gym.envs.rows import by_plant
from continuum_gym.envs.view_tracking.controller import view_slot_rates
from continuum_gym.envs.view_tracking.outputs import OBS, OBS_DIM, OVERLAP_THRESHOLD, POSITION_ERROR_SCALE, Flag, Metric
from continuum_gym.envs.view_tracking.plant import (
    make_view_mismatch_work,
    plant_step,
    true_camera,
    true_model,
)
from continuum_gym.geometry.overlap import make_overlap_work
from continuum_gym.geometry.overlap_clipping import overlap_ratio_inline
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.davinci import davinci_pose
from continuum_gym.robots.endoscope_kernels import endoscope_kinematics
from continuum_gym.robots.rotations import orientation_error, rotation_exp

ACTION_DIM = 6
OBS_LIMIT = 10.0
#: Target-space residual at action 1.0 (times residual_scale): shift of the target point (m) and rotation of
#: the target frame (rad), both in {w}.
TARGET_SHIFT_SCALE = np.array([0.02, 0.5])
REWARD_TERMS = ("overlap", "position", "orientation", "action", "overlap_bonus")
#: The coverage map's success criterion (paper-notes §2.6): OR above it counts as reproducing the view.
OVERLAP_BONUS_THRESHOLD = OVERLAP_THRESHOLD
N_REWARD_TERMS = len(REWARD_TERMS)


#: Per-row state: configurations (N, 6) and control steps (N,).
ViewState = namedtuple("ViewState", ["q", "steps"])
#: What the env adds to the robot and the controller: timing, the residual (scale, target space and its
#: scales, the action scale), optional rate limits and the reward weights.
ViewStepParams = namedtuple("ViewStepParams", ["control_dt", "has_base", "residual_scale", "target_space",
                                               "target_scale", "action_scale", "rate_limit", "weights"])
#: What a step writes: the cached baseline command, observations, metrics, reward terms, rewards, flags.
ViewOutputs = namedtuple("ViewOutputs", ["base_cmd", "obs", "metrics", "terms", "rewards", "flags", "faults"])
#: A thread's work: the step's scratch and the model-error plant's (None without a model error).
ViewWork = namedtuple("ViewWork", ["step", "plant"])
#: Per-thread scratch of a ViewTracking row's step (``step_row``).
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
def observe(i, state, tasks, robot, prm, dv, frustum, env, custom, work, out, plant, mw, true_robot):
    """State of row i -> next baseline command (cached), metrics [OR, eps_p (m), eps_R (rad), OR > 0.8] and
    observation.

    The IK reads the joints the sensors measure (the true ones without a model error); the metrics are those of
    the true endoscope (its camera on its true mounting); the observation holds what the system measures. Without
    a model error (``plant`` None) the three coincide and the plant's lines are compiled out. ``work`` is the
    step's ``ViewStepWork``: the step that calls this is done with its arrays (no allocation per row).
    """
    q = state.q[i]
    control_dt = env.control_dt
    t = state.steps[i] * control_dt
    scratch, q_dv, p_dv, R_dv, p_tgt = work.scratch, work.q_dv, work.p_dv, work.R_dv, work.p_tgt
    base_cmd = out.base_cmd
    exact_mount = True
    if plant is None:
        qc = q
    else:
        measure(plant, i, state.steps[i], 0)
        qc = plant.q_meas[i]
    eps_p, eps_r = target_and_base_command(i, qc, t, tasks, robot, prm, dv, env, custom, work, plant is None,
                                           base_cmd)
    # the truth: the camera of the true endoscope (computed with the base command above when the IK reads it)
    if plant is None:
        p_cam, R_cam = scratch.p_cam, scratch.R_ct
    else:
        endoscope_kinematics(q, true_robot, scratch.ws, mw.p_cam, mw.R_body, mw.p_ct, mw.J, False)
        exact_mount = plant.flags[i, MISMATCH_CALIB_EXACT] != 0
        true_camera(i, plant, mw, exact_mount)
        p_cam, R_cam = mw.p_cam, mw.R_cam
    ratio = overlap_ratio_inline(p_dv, R_dv, p_cam, R_cam, frustum.tan_half, frustum.near, frustum.far, work.overlap)
    if plant is not None:
        d0 = p_tgt[0] - mw.p_tgt[0]
        d1 = p_tgt[1] - mw.p_tgt[1]
        d2 = p_tgt[2] - mw.p_tgt[2]
        e_true = mw.e_true
        orientation_error(R_dv, R_cam, scratch.work33, e_true)
        eps_p = math.sqrt(d0 ** 2 + d1 ** 2 + d2 ** 2)
        eps_r = math.sqrt(e_true[0] ** 2 + e_true[1] ** 2 + e_true[2] ** 2)
    metrics = out.metrics
    metrics[i, Metric.OR] = ratio
    metrics[i, Metric.POSITION_ERROR] = eps_p
    metrics[i, Metric.ORIENTATION_ERROR] = eps_r
    metrics[i, Metric.OR_ABOVE] = 1.0 if ratio > OVERLAP_BONUS_THRESHOLD else 0.0
    # what the system measures: the observation
    if plant is None:
        view_observation(out.obs[i], i, t, q, p_tgt, scratch.p_ct, scratch.e_w, ratio, q_dv, tasks, prm, dv, env,
                         base_cmd)
    else:  # the tracked tip (body pose, nominal mounting) and its overlap ratio
        p_seen = mw.p_seen
        for a in range(3):
            p_seen[a] = mw.p_ct[a]
        if plant.flags[i, MISMATCH_TIP_EXACT] == 0:
            for a in range(3):
                p_seen[a] += tip_noise(plant, i, state.steps[i], a)
        e_w = scratch.e_w
        orientation_error(R_dv, mw.R_body, scratch.work33, e_w)
        ratio_seen = ratio if exact_mount else overlap_ratio_inline(p_dv, R_dv, mw.p_cam, mw.R_body,
                                                                    frustum.tan_half, frustum.near, frustum.far,
                                                                    work.overlap)
        view_observation(out.obs[i], i, t, qc, p_tgt, p_seen, e_w, ratio_seen, q_dv, tasks, prm, dv, env, base_cmd)


@kernel(inline="always")
def row_truth(i, robot, plant):
    """The endoscope that moves and is scored in row i: the nominal one, or the plant's true one."""
    if plant is None:
        return robot
    return true_model(i, robot, plant)


@kernel(borrows=True, no_cpython_wrapper=True, inline="always")
def observe_row(i, state, tasks, model, params, custom, work, out, plant):
    """Row i observed at its state (a reset): ``observe`` with its true endoscope."""
    robot, prm, dv, frustum = model
    observe(i, state, tasks, robot, prm, dv, frustum, params, custom, work.step, out, plant, work.plant,
            row_truth(i, robot, plant))


@kernel
def make_view_step_work():
    return ViewStepWork(make_view_scratch(), np.empty(6), np.empty(6), np.empty(4), np.empty(4), np.empty(3),
                        np.empty((3, 3)), np.empty(3), np.empty(3), np.empty((3, 3)), np.empty((3, 3)), np.empty(6),
                        make_overlap_work())


@kernel
def _nominal_work(model, params, plant):
    return ViewWork(make_view_step_work(), None)


@kernel
def _plant_work(model, params, plant):
    return ViewWork(make_view_step_work(), make_view_mismatch_work())


#: A thread's ``ViewWork`` (the plant's scratch only under a model error).
make_work = by_plant(_nominal_work, _plant_work)


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


# The row's parts and its observation are inlined into the library's loop over rows (``envs/rows.py``): a call
# passes every array of the bundles as flattened arguments, a sizeable cost against a row of ~3 us. The
# observation is inlined at one place, for resets and steps alike, and DR IK stays a call: inlined as well it
# makes the step no faster and the first compile much longer.
@kernel(borrows=True, no_cpython_wrapper=True, inline="always")
def step_row(i, state, actions, tasks, model, params, custom, work, out, plant):
    """Row i's control step: one IK step of dt = control_dt (the paper's 0.01 s), then its observation, reward
    terms and flags. Under a model error (``plant``) the IK reads the measured joints and the plant moves the true
    endoscope (``view_tracking.plant.plant_step``)."""
    robot, prm, dv, frustum = model
    env = params
    sw = work.step
    cmd, q_new = sw.cmd, sw.q_new
    q = state.q[i]
    if plant is None:
        qc = q
    else:
        qc = plant.q_meas[i]
    base_cmd = out.base_cmd
    control_dt = env.control_dt
    action_sq, scale = view_command(i, qc, state, actions, tasks, robot, prm, dv, env, custom, base_cmd, sw, cmd)
    if plant is None:
        clamped = integrate_view_step(q, cmd, control_dt, prm.lower, prm.upper, q_new)
        for k in range(6):
            q[k] = q_new[k]
    else:
        clamped = plant_step(i, q, cmd, control_dt, prm.lower, prm.upper, plant, work.plant, q_new)
    state.steps[i] += 1
    observe(i, state, tasks, robot, prm, dv, frustum, env, custom, sw, out, plant, work.plant,
            row_truth(i, robot, plant))
    finish_view_row(i, state, actions, tasks, env, out, action_sq, clamped, scale)


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


__all__ = ["make_work", "observe_row", "step_row", "REWARD_TERMS", "ViewState", "ViewStepParams", "ViewOutputs",
           "ViewWork", "ACTION_DIM", "OBS_LIMIT", "TARGET_SHIFT_SCALE"]
