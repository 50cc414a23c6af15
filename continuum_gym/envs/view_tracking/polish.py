"""ViewTracking's helper ``overlap_polish`` (``envs/helpers.py``): a one-step lookahead on the overlap ratio.

The learned residuals settle 0.01-0.02 below an OR they could hold on many targets (experiments/notebook.md,
Campaigns 6-7). The polish moves each row's action along the gradient of the OR predicted for the next
configuration, by the step (of ``POLISH_FRACTIONS`` times ``POLISH_STEP``, in action units) that maximises that
predicted OR, where it beats the action as given, and only while the observed OR is at least ``POLISH_MIN_OR``
(far from the target a greedy climb settles in the wrong local maximum). It reads the observation and the
controller's nominal model only, as the base controller does: the configuration (normalised joints), the target
point and orientation errors (hence the da Vinci camera) and the cached base command. The prediction is
q + control_dt (base command + action x residual_scale x action scale), clipped to the joint limits: exact for
a static target without rate limits or model error, an estimate otherwise.
"""

from __future__ import annotations

import math

import numpy as np

from continuum_gym.envs.view_tracking.outputs import OBS, POSITION_ERROR_SCALE
from continuum_gym.geometry.overlap_clipping import make_overlap_work, overlap_ratio_in
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.endoscope import endoscope_kinematics, make_endoscope_workspace
from continuum_gym.robots.rotations import rotation_exp

#: The largest step (action units): 0.05, the value the shipped residuals were measured with (experiments/README.md).
POLISH_STEP = 0.05
#: Candidate steps, as fractions of ``POLISH_STEP``.
POLISH_FRACTIONS = np.array([0.2, 0.4, 1.0])
#: The polish acts only while the observed OR is at least this.
POLISH_MIN_OR = 0.75
#: Central-difference step of the OR's gradient (m for L0, rad).
POLISH_H = 1e-4


@kernel(inline="always")
def observed_camera(o, lower, upper, robot, le_dv, ws, q, p_cam, R, p_ct, J, w, turn, R_dv, p_dv):
    """From one observation row o: its configuration q and the da Vinci camera (p_dv, R_dv) it observes."""
    q[0] = lower[0] + (o[OBS.l0] + 1.0) * 0.5 * (upper[0] - lower[0])
    q[1] = o[OBS.phi] * math.pi
    q[2] = lower[2] + (o[OBS.theta1] + 1.0) * 0.5 * (upper[2] - lower[2])
    q[3] = math.atan2(o[OBS.delta1], o[OBS.delta1 + 1])
    q[4] = lower[4] + (o[OBS.theta2] + 1.0) * 0.5 * (upper[4] - lower[4])
    q[5] = math.atan2(o[OBS.delta2], o[OBS.delta2 + 1])
    endoscope_kinematics(q, robot, ws, p_cam, R, p_ct, J, False)
    for a in range(3):
        w[a] = o[OBS.orientation_error + a]
    rotation_exp(w, turn)
    for a in range(3):
        for b in range(3):
            R_dv[a, b] = turn[a, 0] * R[0, b] + turn[a, 1] * R[1, b] + turn[a, 2] * R[2, b]
    for a in range(3):
        p_dv[a] = p_ct[a] + o[OBS.target_error + a] * POSITION_ERROR_SCALE - le_dv * R_dv[a, 2]


@kernel
def predicted_overlap(o, q, action, step, direction, dt, rate, action_scale, lower, upper, robot, p_dv, R_dv,
                      frustum, ws, work, q_next, p_cam, R, p_ct, J, joint, nudge):
    """OR against (p_dv, R_dv) after one step from q with the action clip(action + step direction, -1, 1),
    the next configuration's joint ``joint`` (if >= 0) moved by ``nudge`` after the step."""
    for k in range(6):
        a = min(max(action[k] + step * direction[k], -1.0), 1.0)
        q_next[k] = min(max(q[k] + dt * (o[OBS.base_command + k] * action_scale[k] + a * rate[k]), lower[k]),
                        upper[k])
    if joint >= 0:
        q_next[joint] += nudge
    endoscope_kinematics(q_next, robot, ws, p_cam, R, p_ct, J, False)
    return overlap_ratio_in(p_dv, R_dv, p_cam, R, frustum[0], frustum[1], frustum[2], work)


@kernel
def polish_actions(obs, actions, active, largest, dt, rate, action_scale, lower, upper, robot, le_dv, frustum, out):
    """``out`` (N, 6): the active rows' actions polished (see the module doc); other rows copied."""
    ws = make_endoscope_workspace()
    work = make_overlap_work()
    q, q_next, w, p_dv, p_cam, p_ct = np.empty(6), np.empty(6), np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    turn, R_dv, R, J = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((6, 6))
    action, grad, zero = np.empty(6), np.empty(6), np.zeros(6)
    for i in range(obs.shape[0]):
        for k in range(6):
            out[i, k] = actions[i, k]
        o = obs[i]
        if active[i] != 1 or o[OBS.overlap] < POLISH_MIN_OR:
            continue
        observed_camera(o, lower, upper, robot, le_dv, ws, q, p_cam, R, p_ct, J, w, turn, R_dv, p_dv)
        for k in range(6):
            action[k] = min(max(actions[i, k], -1.0), 1.0)
        best = predicted_overlap(o, q, action, 0.0, zero, dt, rate, action_scale, lower, upper, robot, p_dv, R_dv,
                                 frustum, ws, work, q_next, p_cam, R, p_ct, J, -1, 0.0)
        # the gradient at the action's next configuration (central differences), in action units
        norm = 0.0
        for k in range(6):
            up = predicted_overlap(o, q, action, 0.0, zero, dt, rate, action_scale, lower, upper, robot, p_dv, R_dv,
                                   frustum, ws, work, q_next, p_cam, R, p_ct, J, k, POLISH_H)
            down = predicted_overlap(o, q, action, 0.0, zero, dt, rate, action_scale, lower, upper, robot, p_dv,
                                     R_dv, frustum, ws, work, q_next, p_cam, R, p_ct, J, k, -POLISH_H)
            grad[k] = (up - down) / (2.0 * POLISH_H) * dt * rate[k]
            norm += grad[k] * grad[k]
        if norm <= 0.0:
            continue
        norm = math.sqrt(norm)
        for k in range(6):
            grad[k] /= norm
        for f in range(POLISH_FRACTIONS.shape[0]):
            step = largest * POLISH_FRACTIONS[f]
            value = predicted_overlap(o, q, action, step, grad, dt, rate, action_scale, lower, upper, robot, p_dv,
                                      R_dv, frustum, ws, work, q_next, p_cam, R, p_ct, J, -1, 0.0)
            if value > best:
                best = value
                for k in range(6):
                    out[i, k] = min(max(action[k] + step * grad[k], -1.0), 1.0)


__all__ = ["POLISH_STEP", "POLISH_FRACTIONS", "POLISH_MIN_OR", "POLISH_H", "polish_actions", "observed_camera"]
