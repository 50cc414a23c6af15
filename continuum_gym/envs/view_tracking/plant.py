"""ViewTracking's model-error plant (issue 37): what differs when the true endoscope is not the nominal one.

The row functions of ``view_tracking.kernel`` run the same control step and the same observation and metric
code under a model error (``plant`` not None); these are the pieces only the plant has:

- ``true_model``: the row's true endoscope (segment lengths scaled);
- ``true_camera``: the camera on its true mounting at the tip (turned by the mounting error) and the target
  point riding on it;
- ``plant_step``: the command waits ``delay_steps``, the actuators follow it with ``actuator_lag_s`` within the
  joint limits, and the bending angles theta1, theta2 follow their actuators through the ``backlash_rad``
  deadband;
- per-thread scratch (``ViewMismatchWork``).

The IK (and the target-space residual) computes with the **nominal** endoscope at the **measured** joints. The
observation holds what the real system of paper 001 has: the measured joints, the tip pose from a tip-mounted
electromagnetic tracker (the true tip body, ``tip_noise_m`` on its position; the tracker cannot see the camera's
mounting rotation) and the overlap ratio computed from that tracked pose, and the baseline's command. With a zero
error every value equals the nominal step's bit for bit (tests/envs/test_model_error.py).
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from continuum_gym.baselines.view_tracking import integrate_view_step
from continuum_gym.envs.mismatch_kernels import delay_command, lag_rates, play
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.endoscope_kernels import EndoscopeKernelArgs
from continuum_gym.robots.rotations import rotation_exp

#: Per-thread scratch: the true camera position, body rotation, target point and Jacobian; the mounting
#: rotation, the true camera rotation and target point; the true orientation error; the applied command.
ViewMismatchWork = namedtuple("ViewMismatchWork", ["p_cam", "R_body", "p_ct", "J", "mount", "R_cam", "p_tgt",
                                                   "e_true", "u", "w", "p_seen"])


@kernel
def make_view_mismatch_work():
    return ViewMismatchWork(np.empty(3), np.empty((3, 3)), np.empty(3), np.empty((6, 6)), np.empty((3, 3)),
                            np.empty((3, 3)), np.empty(3), np.empty(3), np.empty(7), np.empty(3), np.empty(3))


@kernel(inline="always")
def true_model(i, robot, me):
    """Row i's true endoscope: the nominal one with its bending segments' lengths scaled."""
    return EndoscopeKernelArgs(robot.L1 * me.scale[i, 0], robot.Lm, robot.L2 * me.scale[i, 1], robot.Lc, robot.Le)


@kernel(inline="always")
def true_camera(i, me, mw, exact_mount):
    """The camera on its true mounting (``mw.R_cam``) and its target point (``mw.p_tgt``) from the tracked body
    (``mw.p_cam``, ``mw.R_body``, ``mw.p_ct``)."""
    p_cam, R_body, p_ct = mw.p_cam, mw.R_body, mw.p_ct
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


@kernel(inline="always")
def plant_step(i, q, cmd, control_dt, lower, upper, me, mw, q_new):
    """The true endoscope's control step under the command ``cmd``: delay, actuator lag, the joint limits,
    backlash of theta1 and theta2. Returns the clamped joint bits."""
    u = mw.u
    for k in range(6):
        u[k] = cmd[k]
    u[6] = 0.0
    delay_command(me, i, u, 1)
    lag_rates(me, i, u, control_dt)
    qa = me.q_act[i]
    clamped = integrate_view_step(qa, me.rate[i], control_dt, lower, upper, q_new)
    backlash = me.backlash[i]
    for k in range(6):
        qa[k] = q_new[k]
        q[k] = play(q[k], qa[k], backlash) if (k == 2 or k == 4) else qa[k]
    return clamped


__all__ = ["ViewMismatchWork", "make_view_mismatch_work", "true_model", "true_camera", "plant_step"]
