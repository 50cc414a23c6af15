"""The compiled step of ``MyLab/EndoscopeReach-v0``: every row of the batch in one call.

A step kernel takes the core's bundles (``core.kernel_args``) and the rows ``[start, stop)``; the
threads of a large batch claim rows through ``claims`` (``first_rows`` / ``next_rows``). A row whose
``active`` is ``OBSERVE_ONLY`` is observed (after a reset), not stepped.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from continuum_gym.envs.columns import Block, Columns, Layout
from continuum_gym.envs.common_kernels import (
    OBSERVE_ONLY,
    clip_observation,
    desired_point,
    mark_non_finite,
    mark_non_finite_reward,
)
from continuum_gym.envs.row_claims import first_rows, next_rows
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.endoscope_kernels import endoscope_kinematics, make_endoscope_workspace


class Metric(Columns):
    """Columns of ``metrics``: the kernel writes ``metrics[i, Metric.DISTANCE]``, ``info`` reads it."""

    DISTANCE = "distance of the view's target point from the goal (m)"


class Flag(Columns):
    """Columns of ``flags``."""

    CLAMPED = "joint bits clamped at a limit"
    TERMINATED = "the distance is not finite"
    TRUNCATED = "the task's duration is over"
    NON_FINITE = "a value of the row is not finite (the library raises, or ends the episode as truncated)"


#: The observation, declared once: the kernel indexes it by block (``OBS.goal_error``), the docs table it.
OBSERVATION = Layout(
    "ReachObservation",
    Block("l0", "L0", "/ 0.05 m, minus 1"),
    Block("phi", "phi", "/ pi"),
    Block("theta1", "theta1", "rad"),
    Block("delta1", "sin delta1, cos delta1", "-", size=2),
    Block("theta2", "theta2", "rad"),
    Block("delta2", "sin delta2, cos delta2", "-", size=2),
    Block("goal_error", "goal - target point (world)", "/ 0.05 m", size=3),
    Block("base_command", "Jacobian-transpose command", "/ action scale", size=6),
)
OBS = OBSERVATION.starts()
OBS_DIM = OBSERVATION.width()
REWARD_TERMS = ("distance", "action")
OBS_LIMIT = 10.0
GAIN = 20.0  #: Jacobian-transpose gain (1/s per m of error, per m of Jacobian)

ReachState = namedtuple("ReachState", ["q", "steps"])
ReachParams = namedtuple("ReachParams", ["control_dt", "substeps", "has_base", "residual_scale", "action_scale",
                                         "lower", "upper", "weights"])
ReachOutputs = namedtuple("ReachOutputs", ["base_cmd", "obs", "metrics", "terms", "rewards", "flags", "faults"])


@kernel(nogil=True)  # the threads of a large batch step rows in parallel
def reach_step_batch(state, actions, active, tasks, robot, env, custom, out, claims, start, stop):
    """Step (or observe) every row in [start, stop) whose ``active`` is nonzero."""
    ws = make_endoscope_workspace()
    p_cam, R, p_ct, J = np.empty(3), np.empty((3, 3)), np.empty(3), np.empty((6, 6))
    goal, goal_rate, cmd = np.empty(3), np.empty(3), np.empty(6)
    first, last = first_rows(claims, start, stop)
    while first < last:
        for i in range(first, last):
            mode = active[i]
            if mode == 0:
                continue
            q = state.q[i]
            action_sq, clamped = 0.0, 0
            if mode != OBSERVE_ONLY:
                h = env.control_dt / env.substeps
                for _ in range(env.substeps):
                    base_rates(q, state.steps[i] * env.control_dt, i, tasks, robot, ws, p_cam, R, p_ct, J, goal,
                               goal_rate, env, cmd)
                    clamped = 0
                    for k in range(6):
                        a = actions[i, k]
                        rate = cmd[k] + (a * env.residual_scale if env.has_base else a) * env.action_scale[k]
                        q[k] += h * rate
                        if q[k] < env.lower[k] or q[k] > env.upper[k]:
                            q[k] = min(max(q[k], env.lower[k]), env.upper[k])
                            clamped |= 1 << k
                for k in range(6):
                    action_sq += actions[i, k] * actions[i, k]
                state.steps[i] += 1
            distance = base_rates(q, state.steps[i] * env.control_dt, i, tasks, robot, ws, p_cam, R, p_ct, J, goal,
                                  goal_rate, env, cmd)
            observe(i, q, p_ct, goal, cmd, env, out)
            out.metrics[i, Metric.DISTANCE] = distance
            mark_non_finite(i, q, out, Flag.NON_FINITE)  # the library raises or truncates such a row
            if mode != OBSERVE_ONLY:
                out.terms[i, 0] = -env.weights[0] * distance / 0.01
                out.terms[i, 1] = -env.weights[1] * action_sq / 6.0
                out.rewards[i] = out.terms[i, 0] + out.terms[i, 1]
                out.flags[i, Flag.CLAMPED] = clamped
                out.flags[i, Flag.TERMINATED] = 0 if math.isfinite(distance) else 1
                out.flags[i, Flag.TRUNCATED] = 1 if state.steps[i] >= tasks.limit[i] else 0
                mark_non_finite_reward(i, out, Flag.NON_FINITE)
        first, last = next_rows(claims, start, stop, first, last)


@kernel
def base_rates(q, t, i, tasks, robot, ws, p_cam, R, p_ct, J, goal, goal_rate, env, cmd):
    """The Jacobian-transpose command GAIN J_v^T (goal - p_ct) into cmd (zero without a base); the distance (m)."""
    endoscope_kinematics(q, robot, ws, p_cam, R, p_ct, J, True)
    desired_point(tasks, i, t, goal, goal_rate)
    distance = 0.0
    for a in range(3):
        distance += (goal[a] - p_ct[a]) ** 2
    for k in range(6):
        rate = 0.0
        for a in range(3):
            rate += J[a, k] * (goal[a] - p_ct[a])
        cmd[k] = GAIN * rate if env.has_base else 0.0
    return math.sqrt(distance)


@kernel
def observe(i, q, p_ct, goal, cmd, env, out):
    """Row i's observation: joint features, goal error / 5 cm, base command / action scale (clipped to +-10)."""
    o = out.obs[i]
    o[OBS.l0] = q[0] / 0.05 - 1.0
    o[OBS.phi] = q[1] / math.pi
    o[OBS.theta1] = q[2]
    o[OBS.delta1] = math.sin(q[3])
    o[OBS.delta1 + 1] = math.cos(q[3])
    o[OBS.theta2] = q[4]
    o[OBS.delta2] = math.sin(q[5])
    o[OBS.delta2 + 1] = math.cos(q[5])
    for a in range(3):
        o[OBS.goal_error + a] = (goal[a] - p_ct[a]) / 0.05
    for k in range(6):
        o[OBS.base_command + k] = cmd[k] / env.action_scale[k]
        out.base_cmd[i, k] = cmd[k]
    clip_observation(o, OBS_LIMIT)
