"""Visual Occlusion Index (VOI) of paper 000, eq (27), exactly as paper-notes §1.3 item 13 reads it.

VOI = [sin nu / (2 sin beta cos(nu - beta))]^2 (1 - (r_e/r_max)^3): the squared fraction of the cone
diameter swept by the body, times the fraction of the cone volume between slant heights r_e and r_max.

- r_max: slant height of the tip; samples: ``MultiBackboneRobot.backbone`` (inserted part, then 40
  intervals per segment).
- entry: the first sample with d <= 0 and r > 0, linearly interpolated at d = 0 against its predecessor.
- nu: the largest angle seen from the cone vertex between the entry point and the samples from the
  entry onward that are inside (d <= 0, r > 0) with r <= r_max; nu := min(nu, 2 beta).
- VOI = 0 if no sample is inside, none qualifies for nu, or r_e >= r_max.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.geometry.lens_cone import (
    LensCone,
    cone_distance_slant_cs,
    resolve_cone,
    to_lens_cs,
)
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.mbcr import MultiBackboneRobot, backbone_sample_count
from continuum_gym.robots.mbcr_kernels import (
    all_finite,
    backbone_kernel,
    make_workspace,
)
from continuum_gym.validation import as_finite, integer

VOI_SAMPLES_PER_SEGMENT = 40
# Angles (rad) closer than this are compared by atan2 itself when VOI's nu is sought.
ANGLE_TIE = 1e-9


@kernel(borrows=True)
def voi_kernel(points, gamma, cone, lens, dr):
    """(voi, nu, r_e, r_max) of one sampled backbone ``points`` (m, 3); ``lens`` (m, 3), ``dr`` (m, 2) scratch.

    ``cone`` is a ``LensCone.kernel_args()`` bundle. r_e is NaN when there is no entry point.
    """
    d_o, alpha, beta, model = cone.d_o, cone.alpha, cone.beta, cone.model
    m = points.shape[0]
    cg = math.cos(gamma)
    sg = math.sin(gamma)
    ca = math.cos(alpha)
    sa = math.sin(alpha)
    cb = math.cos(beta)
    sb = math.sin(beta)
    for i in range(m):
        xl, yl, zl = to_lens_cs(points[i, 0], points[i, 1], points[i, 2], cg, sg, ca, sa, d_o, model)
        lens[i, 0] = xl
        lens[i, 1] = yl
        lens[i, 2] = zl
        d, r, _ = cone_distance_slant_cs(xl, yl, zl, cb, sb)
        dr[i, 0] = d
        dr[i, 1] = r
    r_max = dr[m - 1, 1]
    entry = -1
    for i in range(m):
        if dr[i, 0] <= 0.0 and dr[i, 1] > 0.0:
            entry = i
            break
    if entry < 0:
        return 0.0, 0.0, math.nan, r_max
    if entry > 0:
        d_prev = dr[entry - 1, 0]
        t = d_prev / (d_prev - dr[entry, 0])
        ex = lens[entry - 1, 0] + t * (lens[entry, 0] - lens[entry - 1, 0])
        ey = lens[entry - 1, 1] + t * (lens[entry, 1] - lens[entry - 1, 1])
        ez = lens[entry - 1, 2] + t * (lens[entry, 2] - lens[entry - 1, 2])
    else:
        ex = lens[0, 0]
        ey = lens[0, 1]
        ez = lens[0, 2]
    _, r_e, _ = cone_distance_slant_cs(ex, ey, ez, cb, sb)
    if r_e >= r_max:
        return 0.0, 0.0, r_e, r_max
    # nu is the largest atan2(|e x p|, e . p) over the qualifying samples. The angles are ordered without
    # atan2: for a, b in [0, pi], a > b exactly when sin(a - b) > 0, i.e. when n_a d_b - d_a n_b > 0. Only
    # a near tie (|a - b| below ~1e-9 rad, far above atan2's last-bit error) is settled by atan2 itself, so
    # nu is the same double as the maximum of every sample's atan2 (atan2 runs once, not per sample).
    found = False
    best_n = 0.0
    best_d = 0.0
    best_angle = math.nan  # atan2 of the best sample once a near tie has needed it
    for i in range(entry, m):
        if dr[i, 0] <= 0.0 and dr[i, 1] > 0.0 and dr[i, 1] <= r_max:
            px = lens[i, 0]
            py = lens[i, 1]
            pz = lens[i, 2]
            cx = ey * pz - ez * py
            cy = ez * px - ex * pz
            cz = ex * py - ey * px
            n_i = math.sqrt(cx * cx + cy * cy + cz * cz)
            d_i = ex * px + ey * py + ez * pz
            if not found:
                found, best_n, best_d = True, n_i, d_i
                continue
            sine = n_i * best_d - d_i * best_n  # |v_i| |v_best| sin(angle_i - angle_best)
            if sine * sine > ANGLE_TIE * ANGLE_TIE * (n_i * n_i + d_i * d_i) * (best_n * best_n + best_d * best_d):
                if sine > 0.0:
                    best_n, best_d, best_angle = n_i, d_i, math.nan
                continue
            if math.isnan(best_angle):
                best_angle = math.atan2(best_n, best_d)
            angle = math.atan2(n_i, d_i)
            if angle > best_angle:
                best_n, best_d, best_angle = n_i, d_i, angle
    if not found:
        return 0.0, 0.0, r_e, r_max
    # n >= 0, so atan2 is in [0, pi]: no sign to check
    nu = math.atan2(best_n, best_d) if math.isnan(best_angle) else best_angle
    nu = min(nu, 2.0 * beta)
    sweep = math.sin(nu) / (2.0 * math.sin(beta) * math.cos(nu - beta))
    voi = sweep * sweep * (1.0 - (r_e / r_max) ** 3)
    return voi, nu, r_e, r_max


@kernel(borrows=True)
def voi_of_configuration(q, robot, ws, gamma, cone, n_per_segment, points, lens, dr):
    """VOI tuple of one configuration; ``points``, ``lens`` (m, 3) and ``dr`` (m, 2) are scratch."""
    backbone_kernel(q, robot, ws, n_per_segment, points)
    return voi_kernel(points, gamma, cone, lens, dr)


@kernel
def _voi_batch(qs, G, robot, cone, n_per_segment, out):
    if not all_finite(qs):
        return False
    n = robot.lengths.shape[0]
    ws = make_workspace(n)
    m = robot.n_insert + n * n_per_segment + 1
    points = np.empty((m, 3))
    lens = np.empty((m, 3))
    dr = np.empty((m, 2))
    for i in range(qs.shape[0]):
        voi, nu, r_e, r_max = voi_of_configuration(qs[i], robot, ws, G[i], cone, n_per_segment, points, lens, dr)
        out[i, 0] = voi
        out[i, 1] = nu
        out[i, 2] = r_e
        out[i, 3] = r_max
    return True


@kernel
def _voi_single(q, gamma, robot, cone, n_per_segment):
    if not all_finite(q) or not math.isfinite(gamma):
        return False, 0.0, 0.0, 0.0, 0.0
    n = robot.lengths.shape[0]
    m = robot.n_insert + n * n_per_segment + 1
    voi, nu, r_e, r_max = voi_of_configuration(q, robot, make_workspace(n), gamma, cone, n_per_segment,
                                               np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 2)))
    return True, voi, nu, r_e, r_max


def occlusion_details(robot: MultiBackboneRobot, q: ArrayLike, gamma: ArrayLike, cone: LensCone | None = None,
                      n_per_segment: int = VOI_SAMPLES_PER_SEGMENT) -> dict:
    """VOI and its parts: dict of ``voi``, ``nu`` (rad), ``r_e`` (m, NaN without entry), ``r_max`` (m).

    Shapes: the broadcast of q.shape[:-1] and gamma.shape.
    """
    if not isinstance(robot, MultiBackboneRobot):
        raise ValueError(f"robot must be a MultiBackboneRobot; got {type(robot).__name__}")
    cone = resolve_cone(cone)
    q = robot.as_configuration(q)
    if q.ndim == 0:
        raise ValueError(f"q must have shape (..., {robot.dof}); got a scalar")
    n_per_segment = integer(n_per_segment, "n_per_segment", low=1)
    if q.ndim == 1 and isinstance(gamma, (float, int)) and not isinstance(gamma, bool):
        ok, *values = _voi_single(q, float(gamma), robot.kernel_args(), cone.kernel_args(), n_per_segment)
        if not ok:
            raise ValueError(f"q and gamma must be finite (no NaN or inf); got q={q}, gamma={gamma}")
        return {key: np.asarray(v) for key, v in zip(("voi", "nu", "r_e", "r_max"), values)}
    gamma = as_finite(gamma, (), "gamma")
    try:
        shape = np.broadcast_shapes(q.shape[:-1], gamma.shape)
    except ValueError as error:
        raise ValueError(f"gamma of shape {gamma.shape} does not broadcast with q of shape {q.shape}") from error
    dof = robot.dof
    Q = np.ascontiguousarray(np.broadcast_to(q, shape + (dof,)).reshape(-1, dof))
    G = np.ascontiguousarray(np.broadcast_to(gamma, shape).reshape(-1))
    out = np.empty((Q.shape[0], 4))
    if not _voi_batch(Q, G, robot.kernel_args(), cone.kernel_args(), n_per_segment, out):
        raise ValueError(f"q must be finite (no NaN or inf); got {q}")
    return {key: out[:, k].reshape(shape) for k, key in enumerate(("voi", "nu", "r_e", "r_max"))}


def visual_occlusion_index(robot: MultiBackboneRobot, q: ArrayLike, gamma: ArrayLike,
                           cone: LensCone | None = None) -> np.ndarray:
    """Visual Occlusion Index (eq 27, paper-notes §1.3 item 13) of shape q.shape[:-1] (0-d for one q).

    Args:
        robot: a ``MultiBackboneRobot``.
        q: configuration(s), (..., dof).
        gamma: endoscope rotation (rad); broadcasts with q.shape[:-1].
        cone: ``LensCone`` (d_o, alpha, beta, lens model); None means the paper's (literal lens).
    """
    return occlusion_details(robot, q, gamma, cone)["voi"]


__all__ = ["visual_occlusion_index", "occlusion_details", "backbone_sample_count", "VOI_SAMPLES_PER_SEGMENT"]
