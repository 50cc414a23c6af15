"""One constant-curvature continuum segment, as compiled scalar kernels: the one segment model of both robots.

Both papers use the same segment model (paper-notes §2.1: theta_001 = pi/2 - theta_000). The kernels take
the *bend* angle, bend = theta_001 = pi/2 - theta_000 (0 straight, > 0 leaning toward (cos delta, -sin delta, 0)
of the base frame), and compute 1 - cos through the half angle, so no digit is lost to cancellation
near straight. The MBCR (``mbcr.py``) and the continuum endoscope (``endoscope.py``) both build on them.

Each kernel works on one segment and writes into caller-provided arrays, so the robot kernels can
call them inside their own compiled loops without allocating.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.robots.compiled import kernel
from continuum_gym.validation import as_finite, positive

# Below this |bend| the closed forms lose digits to cancellation; the series error at the switch is < 1e-11.
SERIES_SWITCH = 2e-3


@kernel(inline="always")
def bend_terms(bend):
    """Return ``s, omc, a, b, da, db`` of a bend angle (rad; 0 is straight).

    ``s = sin(bend)``, ``omc = 1 - cos(bend)`` (through the half angle: no cancellation near 0),
    ``a = (1 - cos)/bend`` (the lateral shape factor), ``b = sin/bend`` (the axial one) and their
    derivatives ``da``, ``db`` in the bend. Below ``SERIES_SWITCH`` the series of paper-notes §1.4 /
    §2.2 are used, so all are exact and finite at a straight segment.
    """
    sh = math.sin(0.5 * bend)
    ch = math.cos(0.5 * bend)
    s = 2.0 * sh * ch
    omc = 2.0 * sh * sh
    if abs(bend) < SERIES_SWITCH:
        t2 = bend * bend
        a = bend * (0.5 - t2 * (1.0 / 24.0 - t2 / 720.0))
        b = 1.0 - t2 * (1.0 / 6.0 - t2 / 120.0)
        da = 0.5 - t2 * (1.0 / 8.0 - t2 / 144.0)
        db = -bend * (1.0 / 3.0 - t2 * (1.0 / 30.0 - t2 / 840.0))
    else:
        a = omc / bend
        b = s / bend
        da = (s - a) / bend  # sin/bend - (1 - cos)/bend^2
        db = (1.0 - omc - b) / bend  # cos/bend - sin/bend^2
    return s, omc, a, b, da, db


@kernel(inline="always")
def bend_rotation(s, omc, cd, sd, R):
    """Write ``Rz(-delta) Ry(bend) Rz(delta)`` (eq 6 of paper 000, eq 4 corrected of paper 001) into R."""
    R[0, 0] = 1.0 - omc * cd * cd
    R[0, 1] = omc * cd * sd
    R[0, 2] = s * cd
    R[1, 0] = omc * cd * sd
    R[1, 1] = 1.0 - omc * sd * sd
    R[1, 2] = -s * sd
    R[2, 0] = -s * cd
    R[2, 1] = s * sd
    R[2, 2] = 1.0 - omc


@kernel(inline="always")
def segment_position(bend, delta, length, out):
    """End-disk position in the segment base frame (m): eq (8) of paper 000 / eq (3) of paper 001."""
    segment_position_cs(bend, math.cos(delta), math.sin(delta), length, out)


@kernel(inline="always")
def segment_position_cs(bend, cd, sd, length, out):
    """``segment_position`` given cos and sin of delta: the backbone samples of one segment share them."""
    _, _, a, b, _, _ = bend_terms(bend)
    out[0] = length * cd * a
    out[1] = -length * sd * a
    out[2] = length * b


@kernel(inline="always")
def segment_rotation(bend, delta, out):
    """End-disk rotation ``Rz(-delta) Ry(bend) Rz(delta)`` in the segment base frame."""
    s, omc, _, _, _, _ = bend_terms(bend)
    bend_rotation(s, omc, math.cos(delta), math.sin(delta), out)


@kernel(inline="always")
def segment_jacobian(bend, delta, length, sigma, jv, jw):
    """Twist of the point at arc fraction ``sigma`` per (d bend_end, d delta), in the segment base frame.

    With sigma = 1 this is eqs (5)-(6) of paper 001 (and eq (3) of paper 000 up to the sign of the
    bend column, since theta_000 = pi/2 - bend). For sigma < 1 it is paper-notes §1.2 "points on the
    body": the terms at sigma * bend, and the bend column carries the extra factor sigma
    (d bend_sigma / d bend = sigma). ``jv`` and ``jw`` are (3, 2).
    """
    s, omc, a, _, da, db = bend_terms(sigma * bend)
    segment_jacobian_terms(s, omc, a, da, db, math.cos(delta), math.sin(delta), length, sigma, jv, jw)


@kernel(inline="always")
def segment_jacobian_terms(s, omc, a, da, db, cd, sd, length, sigma, jv, jw):
    """``segment_jacobian`` from the bend terms at sigma * bend and cos / sin of delta (computed once by
    a caller that also needs them for the pose)."""
    ls = sigma * length
    ls2 = sigma * ls
    jv[0, 0] = ls2 * cd * da
    jv[1, 0] = -ls2 * sd * da
    jv[2, 0] = ls2 * db
    jv[0, 1] = -ls * sd * a
    jv[1, 1] = -ls * cd * a
    jv[2, 1] = 0.0
    jw[0, 0] = sd * sigma
    jw[1, 0] = cd * sigma
    jw[2, 0] = 0.0
    jw[0, 1] = cd * s
    jw[1, 1] = -sd * s
    jw[2, 1] = -omc


@kernel
def _pose_batch(bend, delta, length, p, R):
    for i in range(bend.shape[0]):
        segment_position(bend[i], delta[i], length, p[i])
        segment_rotation(bend[i], delta[i], R[i])


def segment_tip_pose(phi: ArrayLike, delta: ArrayLike, length: float) -> tuple[np.ndarray, np.ndarray]:
    """Batched end-disk pose of one segment in its base frame.

    Args:
        phi: bend variable (rad), any shape; 0 is straight.
        delta: bending-plane angle (rad), broadcasts with ``phi``.
        length: arc length (m), > 0.

    Returns:
        (p, R) with shapes (..., 3) in m and (..., 3, 3).
    """
    length = positive(length, "length", "m")
    phi = as_finite(phi, (), "phi")
    delta = as_finite(delta, (), "delta")
    try:
        phi, delta = np.broadcast_arrays(phi, delta)
    except ValueError:
        raise ValueError(f"phi of shape {phi.shape} and delta of shape {delta.shape} do not broadcast") from None
    flat_phi = phi.reshape(-1)
    flat_delta = delta.reshape(-1)
    p = np.empty((flat_phi.size, 3))
    R = np.empty((flat_phi.size, 3, 3))
    _pose_batch(np.ascontiguousarray(-flat_phi), np.ascontiguousarray(flat_delta), length, p, R)
    return p.reshape(phi.shape + (3,)), R.reshape(phi.shape + (3, 3))


@kernel
def _segment_batch(theta, delta, length, with_jacobian, out):
    """Pose (n, 12: p then R row-major) or Jacobian (n, 12: rows [J_tv; J_tw], columns theta, delta)."""
    R = np.empty((3, 3))
    for i in range(theta.shape[0]):
        s, omc, a, b, da, db = bend_terms(theta[i])
        cd = math.cos(delta[i])
        sd = math.sin(delta[i])
        o = out[i]
        if with_jacobian:
            o[0] = length * cd * da
            o[1] = -length * sd * a
            o[2] = -length * sd * da
            o[3] = -length * cd * a
            o[4] = length * db
            o[5] = 0.0
            o[6] = sd
            o[7] = cd * s
            o[8] = cd
            o[9] = -sd * s
            o[10] = 0.0
            o[11] = -omc
        else:
            o[0] = length * cd * a
            o[1] = -length * sd * a
            o[2] = length * b
            bend_rotation(s, omc, cd, sd, R)
            for a_ in range(3):
                for b_ in range(3):
                    o[3 + 3 * a_ + b_] = R[a_, b_]


def _segment_inputs(theta: ArrayLike, delta: ArrayLike, length: float
                    ) -> tuple[np.ndarray, np.ndarray, float, tuple[int, ...]]:
    length = positive(length, "length", "m")
    theta = as_finite(theta, (), "theta")
    delta = as_finite(delta, (), "delta")
    try:
        theta, delta = np.broadcast_arrays(theta, delta)
    except ValueError:
        raise ValueError(f"theta of shape {theta.shape} and delta of shape {delta.shape} do not broadcast") from None
    return (np.ascontiguousarray(theta.reshape(-1)), np.ascontiguousarray(delta.reshape(-1)), length,
            theta.shape)


def endoscope_segment_pose(theta: ArrayLike, delta: ArrayLike, length: float) -> tuple[np.ndarray, np.ndarray]:
    """Pose of {te} in {tb} of one constant-curvature segment (eqs 3 and 4, paper-notes §2.3 item 2).

    ``theta`` (rad, 0 = straight), ``delta`` (rad) broadcast together; ``length`` in m.
    Returns ``tb_p_te`` (..., 3) in m and ``tb_R_te = Rz(-delta) Ry(theta) Rz(delta)`` (..., 3, 3).
    Exact and finite at theta = 0 (series of paper-notes §2.2 below ``SERIES_THRESHOLD``).
    """
    theta, delta, length, shape = _segment_inputs(theta, delta, length)
    out = np.empty((theta.shape[0], 12))
    _segment_batch(theta, delta, length, False, out)
    return out[:, :3].reshape(shape + (3,)), out[:, 3:].reshape(shape + (3, 3))


def endoscope_segment_jacobian(theta: ArrayLike, delta: ArrayLike, length: float) -> np.ndarray:
    """Twist Jacobian of {te}'s origin in {tb} per [theta, delta] rate (eqs 5 and 6, as printed).

    Returns (..., 6, 2): rows [J_tv (m/rad); J_tw (rad/rad)], columns theta, delta. ``length`` in m.
    Below ``SERIES_THRESHOLD`` uses the series of paper-notes §2.2 (exact and finite at theta = 0).
    """
    theta, delta, length, shape = _segment_inputs(theta, delta, length)
    out = np.empty((theta.shape[0], 12))
    _segment_batch(theta, delta, length, True, out)
    return out.reshape(shape + (6, 2))
