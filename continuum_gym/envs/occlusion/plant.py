"""OcclusionAvoidance's model-error plant (issue 37): what differs when the true robot is not the nominal one.

The row functions of ``occlusion.kernel`` run the same control step and the same observation and metric code
under a model error (``plant`` not None); these are the pieces only the plant has:

- ``true_model``: the row's true robot (segment lengths scaled) and true cone (channel offset and lens tilt off
  by the calibration error); metrics, reward and termination are computed on them;
- ``seen_tip``: the true tip as the endoscope sees it, turned into {w} by the nominal calibration (the tip
  errors of the observation), plus ``tip_noise_m``;
- per-thread scratch (``MismatchWork``).

The baseline, the null-space projection and the guard compute with the **nominal** robot and cone at the
**measured** joints; the command waits ``delay_steps``, the actuators follow it with ``actuator_lag_s``, and
each segment's true bending angle follows its actuator through ``backlash_rad`` (``envs/mismatch_kernels.py``).
The observation holds what the real system of paper 000 has: the measured joints, gamma, the seen tip, the
tip's angle from the view axis as seen in the image (true), the VOI *estimated* from the nominal model at the
measured joints, and the baseline's command. With a zero error every value equals the nominal step's bit for
bit (tests/envs/test_model_error.py).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from continuum_gym.baselines.occlusion_kernels import wrap_angle
from continuum_gym.envs.common_kernels import clamp
from continuum_gym.envs.mismatch_kernels import delay_command, lag_rates, play
from continuum_gym.envs.model_error import MISMATCH_CALIB_EXACT
from continuum_gym.geometry.lens_cone import ConeKernelArgs, lens_to_world_direction, to_lens
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.mbcr_kernels import MBCRKernelArgs

#: Per-thread scratch of the mismatch step: the true tip (p, R, J), the seen tip (p, R), the tip error
#: and orientation error seen, the applied command (dof + 1) and the joints the guard predicts.
#: ``true_robot``: the row's true robot, its ``lengths`` rewritten per row (``true_model``).
MismatchWork = namedtuple("MismatchWork", ["p", "R", "J", "p_seen", "R_seen", "e_true", "u", "q_pred", "true_robot"])


@kernel
def make_mismatch_work(robot, dof):
    return MismatchWork(np.empty(3), np.empty((3, 3)), np.empty((6, dof)), np.empty(3), np.empty((3, 3)),
                        np.empty(3), np.empty(dof + 1), np.empty(dof),
                        MBCRKernelArgs(np.empty(robot.lengths.shape[0]), robot.stiffness, robot.n_insert))


@kernel(inline="always")
def true_model(i, robot, cone, me, mw):
    """Row i's true robot (segment lengths scaled, in ``mw.true_robot``) and true cone (channel offset and lens
    tilt off by the calibration error)."""
    lengths = mw.true_robot.lengths
    for j in range(lengths.shape[0]):
        lengths[j] = robot.lengths[j] * me.scale[i, j]
    return mw.true_robot, ConeKernelArgs(cone.d_o + me.calib[i, 0], cone.alpha + me.calib[i, 1], cone.beta, cone.model)


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


@kernel(inline="always")
def plant_substep(i, q, G, g_rate, substeps, dt, lower, upper, me, mw, clamped):
    """The true robot's substep under the command ``mw.u`` (joints) and ``g_rate`` (endoscope): the command waits
    ``delay_steps``, the actuators follow it with their lag within the position limits, each bending angle
    follows its actuator through the backlash. Returns the clamped joint bits."""
    u = mw.u
    dof = q.shape[0]
    u[dof] = g_rate
    delay_command(me, i, u, substeps)
    lag_rates(me, i, u, dt)
    qa = me.q_act[i]
    rate = me.rate[i]
    backlash = me.backlash[i]
    for k in range(dof):
        qa[k], hit = clamp(qa[k] + rate[k] * dt, lower[k], upper[k])
        if hit:
            clamped |= 1 << k
    for k in range(dof):
        q[k] = play(q[k], qa[k], backlash) if (k % 2 == 0 and k < dof - 1) else qa[k]
    G[i] = wrap_angle(G[i] + rate[dof] * dt)
    return clamped


__all__ = ["MismatchWork", "make_mismatch_work", "true_model", "seen_tip", "plant_substep"]
