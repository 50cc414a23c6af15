"""What one endoscope of ``MyLab/EndoscopeReach-v0`` does in a step, and what the library needs to run it."""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from continuum_gym.envs.common_kernels import clip_observation, desired_point
from continuum_gym.envs.core import Built, RowFunctions
from continuum_gym.envs.front_ends import front_ends
from continuum_gym.envs.tasks import TaskContext
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.endoscope_kernels import endoscope_kinematics, make_endoscope_workspace
from my_reach import SPEC
from my_reach.config import OBSERVATION, Flag, Metric

ACTION_SCALE = np.array([0.1, math.pi / 2, math.pi / 2, math.pi, math.pi / 2, math.pi])  # m/s, rad/s at action 1
GAIN = 20.0  #: Jacobian-transpose gain (1/s per m of error, per m of Jacobian)


OBS = OBSERVATION.starts()
State = namedtuple("ReachState", ["q", "steps"])
Params = namedtuple("ReachParams", ["control_dt", "substeps", "has_base", "residual_scale", "lower", "upper",
                                    "weights"])
Outputs = namedtuple("ReachOutputs", ["base_cmd", "obs", "metrics", "terms", "rewards", "flags", "faults"])
Work = namedtuple("ReachWork", ["ws", "p_cam", "R", "p_ct", "J", "goal", "goal_rate"])


@kernel
def make_work(model, params, plant):
    return Work(make_endoscope_workspace(), np.empty(3), np.empty((3, 3)), np.empty(3), np.empty((6, 6)),
                np.empty(3), np.empty(3))


@kernel(borrows=True, no_cpython_wrapper=True)
def observe_row(i, state, tasks, model, params, custom, work, out, plant):
    """The base command GAIN J_v^T (goal - p_ct) at the row's state, its observation and distance."""
    q = state.q[i]
    endoscope_kinematics(q, model[0], work.ws, work.p_cam, work.R, work.p_ct, work.J, True)
    desired_point(tasks, i, state.steps[i] * params.control_dt, work.goal, work.goal_rate)
    o = out.obs[i]
    for k in range(6):
        rate = 0.0
        for a in range(3):
            rate += work.J[a, k] * (work.goal[a] - work.p_ct[a])
        out.base_cmd[i, k] = GAIN * rate if params.has_base else 0.0
        o[OBS.joints + k] = q[k]
        o[OBS.base_command + k] = out.base_cmd[i, k] / ACTION_SCALE[k]
    squared = 0.0
    for a in range(3):
        o[OBS.goal_error + a] = (work.goal[a] - work.p_ct[a]) / 0.05
        squared += (work.goal[a] - work.p_ct[a]) ** 2
    clip_observation(o, 10.0)
    out.metrics[i, Metric.DISTANCE] = math.sqrt(squared)


@kernel(borrows=True, no_cpython_wrapper=True)
def step_row(i, state, actions, tasks, model, params, custom, work, out, plant):
    """Explicit Euler of base + residual within the joint limits, then the observation, reward and flags."""
    q, clamped, action_sq = state.q[i], 0, 0.0
    scale = params.residual_scale if params.has_base else 1.0
    for _ in range(params.substeps):
        observe_row(i, state, tasks, model, params, custom, work, out, plant)
        clamped = 0
        for k in range(6):
            q[k] += params.control_dt / params.substeps * (out.base_cmd[i, k] + actions[i, k] * scale * ACTION_SCALE[k])
            if q[k] < params.lower[k] or q[k] > params.upper[k]:
                q[k], clamped = min(max(q[k], params.lower[k]), params.upper[k]), clamped | 1 << k
    for k in range(6):
        action_sq += actions[i, k] ** 2
    state.steps[i] += 1
    observe_row(i, state, tasks, model, params, custom, work, out, plant)
    out.terms[i, 0] = -params.weights[0] * out.metrics[i, Metric.DISTANCE] / 0.01
    out.terms[i, 1] = -params.weights[1] * action_sq / 6.0
    out.rewards[i] = out.terms[i, 0] + out.terms[i, 1]
    out.flags[i, Flag.CLAMPED] = clamped
    out.flags[i, Flag.TRUNCATED] = 1 if state.steps[i] >= tasks.limit[i] else 0


def build(config) -> Built:
    lower, upper = config.robot.joint_limits
    params = Params(config.control_dt, config.substeps, config.base_controller is not None, config.residual_scale,
                    lower, upper, np.array([config.reward_weights["distance"], config.reward_weights["action"]]))
    return Built(model=(config.robot.kernel_args(),), params=params, action_dim=6, obs_dim=OBSERVATION.width(),
                 command=6, context=TaskContext(config.robot, config.control_dt))


def controller_observation(core, row: int) -> dict:
    goal, _ = core.desired(row, core.steps[row] * core.control_dt)
    return {"q": core.measured_joints(row), "goal": goal, "dt": core.control_dt, "robot": core.robot}


ROWS = RowFunctions(make_work=make_work, observe_row=observe_row, step_row=step_row, params=Params, state=State,
                    outputs=Outputs, metrics=Metric, flags=Flag, observation=OBSERVATION,
                    reward_terms=("distance", "action"), build=build, controller_observation=controller_observation,
                    controller="")
ReachCore, EndoscopeReachEnv, EndoscopeReachVectorEnv = front_ends(
    SPEC, ROWS, __name__, "The continuum endoscope points its view at a goal point (a toy third environment).",
    core_name="ReachCore")
