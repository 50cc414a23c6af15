"""OcclusionAvoidance's rows: what one robot does in a control step, and what is observed of it.

The library runs these row functions for the whole batch in one compiled call (``envs/rows.py``). Per
control step and robot: for each kinematic substep, the baseline command at the current state
(its cached value for the first substep), plus the residual (projected into the tip Jacobian's null
space unless ``residual_space="joint"``), saturated by the rate limits (uniform scaling of the joint
rates; gamma rate clipped), integrated by explicit Euler and clamped to the position limits. Then
the geometry once at the new state: tip errors, VOI, tip visibility, the next baseline command, the
observation and the reward terms.

The row functions take the library's bundles (``envs/core.py``): the batch ``OcclusionState`` (q, gamma,
step counters), the ``TaskArrays``, ``model`` = (the robot's, the controller's ``kernel_args``), the env's
``OcclusionStepParams``, the registered controller's slot (or None), the thread's work, the
``OcclusionOutputs`` they fill and ``plant``: the model-error arrays, or None. Under a model error the same
step, observation and metric code runs with the plant's pieces (``occlusion.plant``): the controller at the
measured joints, the true robot moving and scored. The observation's layout and the columns of
``metrics``, ``flags`` and ``base_info`` are declared once, in ``outputs`` (``OBS``, ``Metric``, ``Flag``,
``BaseInfo``).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from continuum_gym.baselines.occlusion_kernels import (
    make_scratch,
    occlusion_rates_kernel,
    wrap_angle,
)
from continuum_gym.envs.common_kernels import (
    at,
    clamp,
    clip_observation,
    desired_point,
    desired_rotation,
)
from continuum_gym.envs.mismatch_kernels import measure, tip_noise
from continuum_gym.envs.model_error import MISMATCH_TIP_EXACT
from continuum_gym.envs.occlusion.controller import occlusion_slot_rates
from continuum_gym.envs.occlusion.guard import endoscope_rate, guard_on, view_fraction_at
from continuum_gym.envs.occlusion.outputs import (
    OBS,
    OBSERVATION,
    ORIENTATION_ERROR_SCALE,
    POSITION_ERROR_SCALE,
    VELOCITY_SCALE,
    BaseInfo,
    Flag,
    Metric,
)
from continuum_gym.envs.occlusion.plant import make_mismatch_work, plant_substep, seen_tip, true_model
from continuum_gym.envs.rows import by_plant
from continuum_gym.geometry.occlusion import voi_of_configuration
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.linalg import twist_gram_solve
from continuum_gym.robots.mbcr_kernels import make_workspace, tip_kernel
from continuum_gym.robots.rotations import orientation_error

OBS_LIMIT = 10.0
NULLSPACE_DAMPING = 1e-12  # m², numerically exact projector away from singularities
VOI_SAMPLES_PER_SEGMENT = 40
# Reward terms, in this order everywhere.
REWARD_TERMS = ("voi", "tip_position", "tip_orientation", "visibility", "action")
N_TERMS_REWARD = len(REWARD_TERMS)
# Failure: the tip is lost.
MAX_TIP_ERROR = 0.01  # m

#: Per-row state of the batch: configurations (N, dof), endoscope rotations (N,) in rad, control steps (N,).
OcclusionState = namedtuple("OcclusionState", ["q", "gamma", "steps"])
#: What the env adds to the robot and the controller: timing, the residual's scale and space, the limits
#: (rate scales of the action, rate and position limits, max bend), reward weights, visibility criterion
#: and the visibility guard (<= 0: off).
OcclusionStepParams = namedtuple("OcclusionStepParams", [
    "control_dt", "substeps", "has_base", "nullspace", "residual_scale", "rate_scale_vec", "rate_limit",
    "gamma_rate_limit", "lower", "upper", "max_bend", "weights", "visibility_fraction", "visibility_guard",
])
#: What a step writes: the cached baseline command (N, dof + 1) and its base_info (N, 2), observations,
#: metrics, reward terms, rewards and flags, and ``faults`` (1,): the count of rows flagged ``NON_FINITE``.
OcclusionOutputs = namedtuple("OcclusionOutputs", ["base_cmd", "base_info", "obs", "metrics", "terms", "rewards",
                                                   "flags", "faults"])
#: A thread's work: the step's scratch and the model-error plant's (None without a model error).
OcclusionWork = namedtuple("OcclusionWork", ["step", "plant"])
#: Per-thread scratch of ``occlusion_step_row``.
OcclusionStepWork = namedtuple("OcclusionStepWork", ["ws", "scratch", "qdot", "residual", "projected", "cmd", "p_des",
                                                     "v_des", "A", "B", "ones", "points", "lens", "dr", "w", "w_rate",
                                                     "turn", "R_goal", "full_cmd"])


def observation_dim(n_segments: int) -> int:
    """Length of an observation row for a robot of ``n_segments`` (32 for the paper's three)."""
    return OBSERVATION.width(n_segments)


@kernel
def make_step_work(n_segments, n_points, n_insert):
    """Per-thread scratch of ``step_row`` and ``observe``."""
    dof = 2 * n_segments + 1
    m = n_insert + n_segments * VOI_SAMPLES_PER_SEGMENT + 1
    return OcclusionStepWork(make_workspace(n_segments), make_scratch(n_points, dof), np.empty(dof), np.empty(dof),
                             np.empty(dof), np.empty(dof), np.empty(3), np.empty(3), np.empty((6, 6)),
                             np.empty((6, 2)), np.ones(dof), np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 2)),
                             np.empty(3), np.empty(3), np.empty((3, 3)), np.empty((3, 3)), np.empty(dof + 1))


@kernel
def _nominal_work(model, params, plant):
    robot, prm = model
    return OcclusionWork(make_step_work(robot.lengths.shape[0], prm.segments.shape[0], robot.n_insert), None)


@kernel
def _plant_work(model, params, plant):
    robot, prm = model
    return OcclusionWork(make_step_work(robot.lengths.shape[0], prm.segments.shape[0], robot.n_insert),
                         make_mismatch_work(robot, robot.lengths.shape[0] * 2 + 1))


#: A thread's ``OcclusionWork`` (the plant's scratch only under a model error).
make_work = by_plant(_nominal_work, _plant_work)


@kernel(inline="always")
def project_nullspace(J, r, work, out):
    """out = (I - J^T (J J^T + eps I)^-1 J) r for the 6 x dof tip Jacobian J."""
    A, B = work.A, work.B
    dof = J.shape[1]
    for a in range(6):
        acc = 0.0
        for k in range(dof):
            acc += J[a, k] * r[k]
        B[a, 0] = acc
        B[a, 1] = 0.0
    twist_gram_solve(J, work.ones, NULLSPACE_DAMPING, A, B)
    for k in range(dof):
        acc = 0.0
        for a in range(6):
            acc += J[a, k] * B[a, 0]
        out[k] = r[k] - acc


@kernel(inline="always")
def cache_base_command(i, qc, gamma, p_des, R_des, v_des, sub_dt, robot, prm, env, custom, work, tip_at_qc, out):
    """The baseline's command at the controller's joints qc into ``out.base_cmd[i]`` (and ``out.base_info[i]``),
    cached for the next step's first substep; with ``tip_at_qc`` the tip at qc is in work.scratch (p, R, J) after."""
    scratch = work.scratch
    qdot = work.qdot
    dof = qc.shape[0]
    base_cmd = out.base_cmd
    if env.has_base and custom is not None:
        occlusion_slot_rates(custom, qc, gamma, p_des, R_des, v_des, sub_dt, robot, prm.cone, work.full_cmd)
        if tip_at_qc:
            tip_kernel(qc, robot, work.ws, scratch.p, scratch.R, scratch.J)
        for k in range(dof + 1):
            base_cmd[i, k] = work.full_cmd[k]
        out.base_info[i, BaseInfo.FROZEN] = 0
        out.base_info[i, BaseInfo.SATURATED] = 0
    elif env.has_base:
        gd, frozen, scale = occlusion_rates_kernel(qc, gamma, p_des, R_des, v_des, sub_dt, robot, prm,
                                                   work.ws, scratch, qdot)
        for k in range(dof):
            base_cmd[i, k] = qdot[k]
        base_cmd[i, dof] = gd
        out.base_info[i, BaseInfo.FROZEN] = frozen
        out.base_info[i, BaseInfo.SATURATED] = 1 if scale < 1.0 else 0
    else:
        if tip_at_qc:
            tip_kernel(qc, robot, work.ws, scratch.p, scratch.R, scratch.J)
        for k in range(dof + 1):
            base_cmd[i, k] = 0.0
        out.base_info[i, BaseInfo.FROZEN] = 0
        out.base_info[i, BaseInfo.SATURATED] = 0


@kernel(inline="always")
def occlusion_observation(o, i, n, q, gamma, e_p0, e_p1, e_p2, e_w, v_des, view_fraction, voi, t, tasks, env,
                          base_cmd):
    """Row i's observation into o (layout: ``outputs.OBSERVATION``) from the joints q, gamma, the tip
    position error (e_p0, e_p1, e_p2) and orientation error e_w, the view fraction, the VOI and the cached
    baseline command."""
    dof = q.shape[0]
    control_dt = env.control_dt
    bend, delta = at(OBS.bend, n), at(OBS.delta, n)
    for j in range(n):
        o[bend + j] = (0.5 * math.pi - q[2 * j]) / env.max_bend
        o[delta + 2 * j] = math.sin(q[2 * j + 1])
        o[delta + 1 + 2 * j] = math.cos(q[2 * j + 1])
    ins = 2 * n  # the insertion joint
    span = env.upper[ins] - env.lower[ins]
    o[at(OBS.insertion, n)] = 2.0 * (q[ins] - env.lower[ins]) / span - 1.0 if math.isfinite(span) else q[ins] / 0.02
    o[at(OBS.gamma, n)] = math.sin(gamma)
    o[at(OBS.gamma, n) + 1] = math.cos(gamma)
    e_p = at(OBS.tip_position_error, n)
    o[e_p] = e_p0 / POSITION_ERROR_SCALE
    o[e_p + 1] = e_p1 / POSITION_ERROR_SCALE
    o[e_p + 2] = e_p2 / POSITION_ERROR_SCALE
    e_r, v = at(OBS.tip_orientation_error, n), at(OBS.desired_velocity, n)
    for a in range(3):
        o[e_r + a] = e_w[a] / ORIENTATION_ERROR_SCALE
        o[v + a] = v_des[a] / VELOCITY_SCALE
    o[at(OBS.view_fraction, n)] = view_fraction
    o[at(OBS.voi, n)] = voi
    rate_scale_vec = env.rate_scale_vec
    base = at(OBS.base_command, n)
    for k in range(dof + 1):
        o[base + k] = base_cmd[i, k] / rate_scale_vec[k]
    o[at(OBS.time, n)] = t / (tasks.duration[i] * control_dt)
    clip_observation(o, OBS_LIMIT)


# Borrowing: they hand back arrays of the bundles, which a caller that borrows (the rows) never releases.
@kernel(borrows=True)
def _nominal_truth(i, robot, prm, plant, mw):
    return robot, prm.cone


@kernel(borrows=True)
def _plant_truth(i, robot, prm, plant, mw):
    return true_model(i, robot, prm.cone, plant, mw)


#: The robot and cone that move and are scored in row i: the nominal ones, or the plant's true ones.
row_truth = by_plant(_nominal_truth, _plant_truth)


@kernel(borrows=True, no_cpython_wrapper=True)
def observe(i, state, tasks, robot, prm, env, custom, work, out, plant, mw, true_robot, true_cone):
    """Geometry at the state of row i: next baseline command (cached), metrics and observation.

    The baseline reads the joints the sensors measure (the true ones without a model error); the metrics are
    those of the true robot in the true cone; the observation holds what the system measures. Without a
    model error (``plant`` None) the three coincide and the plant's lines are compiled out.
    The observation's layout is declared once, in ``outputs.OBSERVATION`` (and tabled in the env docstring).
    """
    q = state.q[i]
    gamma = state.gamma[i]
    n = robot.lengths.shape[0]
    control_dt = env.control_dt
    sub_dt = control_dt / env.substeps
    t = state.steps[i] * control_dt
    scratch = work.scratch
    # The step's scratch: the substeps that used it are done (no allocation per observation)
    p_des = work.p_des
    v_des = work.v_des
    if plant is None:
        qc = q
    else:
        measure(plant, i, state.steps[i] * env.substeps, q.shape[0] - 1)
        qc = plant.q_meas[i]
    desired_point(tasks, i, t, p_des, v_des)
    R_des = desired_rotation(tasks, i, t, work.w, work.w_rate, work.turn, work.R_goal)
    cache_base_command(i, qc, gamma, p_des, R_des, v_des, sub_dt, robot, prm, env, custom, work, plant is None, out)
    base_cmd = out.base_cmd
    # the truth: the tip (computed with the base command above when the controller reads the true joints)
    if plant is None:
        p, R, e_w = scratch.p, scratch.R, scratch.e_w
    else:
        p, R, e_w = mw.p, mw.R, mw.e_true
        tip_kernel(q, true_robot, work.ws, p, R, mw.J)
    orientation_error(R_des, R, scratch.work33, e_w)
    e_p0 = p_des[0] - p[0]
    e_p1 = p_des[1] - p[1]
    e_p2 = p_des[2] - p[2]
    voi, _, _, _ = voi_of_configuration(q, true_robot, work.ws, gamma, true_cone, VOI_SAMPLES_PER_SEGMENT,
                                        work.points, work.lens, work.dr)
    view_fraction = view_fraction_at(p, gamma, true_cone)
    metrics = out.metrics
    metrics[i, Metric.VOI] = voi
    metrics[i, Metric.TIP_ERROR] = math.sqrt(e_p0 * e_p0 + e_p1 * e_p1 + e_p2 * e_p2)
    metrics[i, Metric.ORIENTATION_ERROR] = math.sqrt(e_w[0] ** 2 + e_w[1] ** 2 + e_w[2] ** 2)
    metrics[i, Metric.VIEW_FRACTION] = view_fraction
    metrics[i, Metric.TIP_IN_VIEW] = 1.0 if view_fraction <= env.visibility_fraction else 0.0
    # what the system measures: the observation
    if plant is None:
        occlusion_observation(out.obs[i], i, n, q, gamma, e_p0, e_p1, e_p2, e_w, v_des, view_fraction, voi, t,
                              tasks, env, base_cmd)
    else:
        seen_tip(i, gamma, prm.cone, true_cone, plant, mw)
        ps = mw.p_seen
        if plant.flags[i, MISMATCH_TIP_EXACT] == 0:
            for a in range(3):
                ps[a] += tip_noise(plant, i, state.steps[i] * env.substeps, a)
        e_seen = scratch.e_w
        orientation_error(R_des, mw.R_seen, scratch.work33, e_seen)
        voi_estimate, _, _, _ = voi_of_configuration(qc, robot, work.ws, gamma, prm.cone, VOI_SAMPLES_PER_SEGMENT,
                                                     work.points, work.lens, work.dr)
        occlusion_observation(out.obs[i], i, n, qc, gamma, p_des[0] - ps[0], p_des[1] - ps[1], p_des[2] - ps[2],
                              e_seen, v_des, view_fraction, voi_estimate, t, tasks, env, base_cmd)


@kernel(borrows=True, no_cpython_wrapper=True)
def observe_row(i, state, tasks, model, params, custom, work, out, plant):
    """Row i observed at its state (a reset): ``observe`` with its true robot and cone."""
    robot, prm = model
    true_robot, true_cone = row_truth(i, robot, prm, plant, work.plant)
    observe(i, state, tasks, robot, prm, params, custom, work.step, out, plant, work.plant, true_robot, true_cone)


@kernel(inline="always")
def residual_rates(i, actions, env, rate_scale_vec, dof, residual):
    """Row i's residual: its joint rates into ``residual``; returns (|a|^2, the endoscope's residual rate,
    whether the joint residual is projected into the tip Jacobian's null space)."""
    action_sq = 0.0
    for k in range(dof + 1):
        action_sq += actions[i, k] * actions[i, k]
    joint_residual = False
    for k in range(dof):
        residual[k] = actions[i, k] * env.residual_scale * rate_scale_vec[k]
        if residual[k] != 0.0:
            joint_residual = True
    gamma_residual = actions[i, dof] * env.residual_scale * rate_scale_vec[dof]
    # The null-space projection of a zero residual is that residual, to the bit (its right-hand side and
    # solution are +0.0, and r - (+0.0) is r, signed zeros included), so a zero residual skips it and the
    # tip Jacobian it would need: ~10 % of a step of the baseline alone (zero actions, evaluations).
    project = env.has_base and env.nullspace and joint_residual
    return action_sq, gamma_residual, project


@kernel(inline="always")
def substep_base_rates(i, s, t, dt, qc, gamma, tasks, robot, prm, env, custom, work, base_cmd, project, base_frozen,
                       base_saturated):
    """The baseline's joint rates of substep s at the controller's joints qc into qdot (the cached command
    for s == 0), and the tip Jacobian at qc where the residual is projected.

    Returns (the baseline's endoscope rate, base_frozen, base_saturated), the two ORed with this substep's.
    Its callers borrow (no reference counts), so reading the scratch arrays from ``work`` costs nothing.
    """
    ws, scratch, qdot, p_des, v_des = work.ws, work.scratch, work.qdot, work.p_des, work.v_des
    tip_p, tip_R, tip_J = scratch.p, scratch.R, scratch.J
    w, w_rate, turn, R_goal = work.w, work.w_rate, work.turn, work.R_goal
    dof = qdot.shape[0]
    if s == 0:
        for k in range(dof):
            qdot[k] = base_cmd[i, k]
        gd = base_cmd[i, dof]
        if project:
            tip_kernel(qc, robot, ws, tip_p, tip_R, tip_J)
    elif env.has_base and custom is not None:
        desired_point(tasks, i, t, p_des, v_des)
        R_des = desired_rotation(tasks, i, t, w, w_rate, turn, R_goal)
        occlusion_slot_rates(custom, qc, gamma, p_des, R_des, v_des, dt, robot, prm.cone, work.full_cmd)
        for k in range(dof):
            qdot[k] = work.full_cmd[k]
        gd = work.full_cmd[dof]
        if project:
            tip_kernel(qc, robot, ws, tip_p, tip_R, tip_J)
    elif env.has_base:
        desired_point(tasks, i, t, p_des, v_des)
        R_des = desired_rotation(tasks, i, t, w, w_rate, turn, R_goal)
        gd, frozen, base_scale = occlusion_rates_kernel(qc, gamma, p_des, R_des, v_des, dt, robot, prm, ws,
                                                        scratch, qdot)
        base_frozen |= frozen
        if base_scale < 1.0:
            base_saturated = 1
    else:
        for k in range(dof):
            qdot[k] = 0.0
        gd = 0.0
    return gd, base_frozen, base_saturated


@kernel(inline="always")
def joint_command(project, tip_J, residual, work, qdot, projected, rate_limit, cmd):
    """cmd = the baseline's joint rates qdot + the residual (projected where ``project``); returns the
    uniform scale (<= 1) that brings cmd within the rate limits."""
    dof = qdot.shape[0]
    if project:
        project_nullspace(tip_J, residual, work, projected)
    else:
        for k in range(dof):
            projected[k] = residual[k]
    # Uniform scaling keeps the command's direction; a baseline command already at its limit
    # (within rounding) is left exactly as it is, so a zero residual reproduces the baseline.
    scale = 1.0
    for k in range(dof):
        cmd[k] = qdot[k] + projected[k]
        if abs(cmd[k]) > rate_limit[k] * (1.0 + 1e-12) and abs(cmd[k]) * scale > rate_limit[k]:
            scale = rate_limit[k] / abs(cmd[k])
    return scale


@kernel(inline="always")
def finish_occlusion_row(i, state, tasks, env, out, action_sq, dof, clamped, rate_saturated, gamma_saturated,
                         base_frozen, base_saturated, guarded):
    """Row i's reward terms, reward and flags after its observation."""
    metrics = out.metrics
    terms = out.terms
    weights = env.weights
    voi = metrics[i, Metric.VOI]
    over = metrics[i, Metric.VIEW_FRACTION] - env.visibility_fraction
    terms[i, 0] = -weights[0] * voi
    terms[i, 1] = -weights[1] * metrics[i, Metric.TIP_ERROR] / 0.001
    terms[i, 2] = -weights[2] * metrics[i, Metric.ORIENTATION_ERROR] / 0.01
    terms[i, 3] = -weights[3] * (over / (1.0 - env.visibility_fraction) if over > 0.0 else 0.0)
    terms[i, 4] = -weights[4] * action_sq / (dof + 1)
    flags = out.flags
    tip_error = metrics[i, Metric.TIP_ERROR]
    flags[i, Flag.CLAMPED] = clamped
    flags[i, Flag.RATE_SATURATED] = rate_saturated
    flags[i, Flag.GAMMA_SATURATED] = gamma_saturated
    flags[i, Flag.TERMINATED] = 1 if (tip_error > MAX_TIP_ERROR or not math.isfinite(tip_error)) else 0
    flags[i, Flag.TRUNCATED] = 1 if state.steps[i] >= tasks.limit[i] else 0
    flags[i, Flag.BASE_FROZEN] = base_frozen
    flags[i, Flag.BASE_SATURATED] = base_saturated
    flags[i, Flag.GUARDED] = guarded
    total = 0.0
    for k in range(N_TERMS_REWARD):
        total += terms[i, k]
    out.rewards[i] = total


@kernel(borrows=True, no_cpython_wrapper=True)
def step_row(i, state, actions, tasks, model, params, custom, work, out, plant):
    """Advance row i by one control step; fills its obs, metrics, reward terms, reward and flags.

    ``out.base_cmd`` holds the baseline command at the current state on entry (cached from the last
    observe) and at the new state on exit. Under a model error (``plant``) the controller, the null-space
    projection and the guard compute with the nominal model at the measured joints, and the plant moves the
    true robot: the command is delayed, the actuators lag, the bending angles follow through the backlash.
    """
    robot, prm = model
    env = params
    sw, mw = work.step, work.plant
    true_robot, true_cone = row_truth(i, robot, prm, plant, mw)
    ws, scratch, qdot, residual, projected, cmd = sw.ws, sw.scratch, sw.qdot, sw.residual, sw.projected, sw.cmd
    tip_p, tip_R, tip_J = scratch.p, scratch.R, scratch.J
    rate_limit, lower, upper, rate_scale_vec = env.rate_limit, env.lower, env.upper, env.rate_scale_vec
    G = state.gamma
    dof = state.q.shape[1]
    substeps = env.substeps
    dt = env.control_dt / substeps
    q = state.q[i]
    if plant is None:
        qc = q
    else:
        qc = plant.q_meas[i]
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
        if plant is not None:
            if s > 0:  # the first substep's measurement is the observation's
                measure(plant, i, state.steps[i] * substeps + s, dof - 1)
        gd, base_frozen, base_saturated = substep_base_rates(
            i, s, t, dt, qc, G[i], tasks, robot, prm, env, custom, sw, base_cmd, project, base_frozen, base_saturated)
        scale = joint_command(project, tip_J, residual, sw, qdot, projected, rate_limit, cmd)
        if scale < 1.0:
            rate_saturated = 1
        if plant is None:  # the joints move by the command; the guard checks the tip at them
            for k in range(dof):
                q[k], hit = clamp(q[k] + scale * cmd[k] * dt, lower[k], upper[k])
                if hit:
                    clamped |= 1 << k
            qg = q
        else:  # the guard predicts with the nominal model where the command takes the measured joints
            u = mw.u
            for k in range(dof):
                u[k] = scale * cmd[k]
            if guard_on(env, gamma_residual):
                for k in range(dof):
                    mw.q_pred[k], _ = clamp(qc[k] + u[k] * dt, lower[k], upper[k])
            qg = mw.q_pred
        g_rate, hit, clipped = endoscope_rate(qg, G[i], gd, gamma_residual, dt, robot, prm, env, ws, tip_p, tip_R,
                                              tip_J)
        if hit:
            guarded = 1
        if clipped:
            gamma_saturated = 1
        if plant is None:
            G[i] = wrap_angle(G[i] + g_rate * dt)
        else:  # the plant: delay, actuator lag, position limits, backlash of the bending angles
            clamped = plant_substep(i, q, G, g_rate, substeps, dt, lower, upper, plant, mw, clamped)
    state.steps[i] += 1
    observe(i, state, tasks, robot, prm, env, custom, sw, out, plant, mw, true_robot, true_cone)
    finish_occlusion_row(i, state, tasks, env, out, action_sq, dof, clamped, rate_saturated, gamma_saturated,
                         base_frozen, base_saturated, guarded)


__all__ = ["make_work", "observe_row", "step_row", "REWARD_TERMS", "Metric", "Flag", "BaseInfo", "OBSERVATION",
           "observation_dim", "OcclusionState", "OcclusionStepParams", "OcclusionOutputs", "OcclusionWork"]
