"""One constant-curvature continuum segment, as compiled scalar kernels.

Both papers use the same segment model (paper-notes §2.1: theta_001 = pi/2 - theta_000). The kernels here
use the bend variable ``phi`` of paper-notes §1.2, phi = theta_000 - pi/2 = -theta_001, so that phi = 0 is
straight in both conventions and a bend phi < 0 leans toward (cos delta, -sin delta, 0) of the base frame.

Each kernel works on one segment and writes into caller-provided arrays, so the robot kernels can
call them inside their own compiled loops without allocating.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from continuum_gym.validation import as_finite, positive

# Below this |phi| the closed forms lose digits to cancellation; the series error at the switch is < 1e-11.
SERIES_SWITCH = 2e-3


@njit(cache=True, inline="always")
def chi_functions(phi):
    """Return (chi1, chi2, chi3, sinc) of paper-notes §1.2 at bend variable ``phi`` (rad).

    chi3 = (cos phi - 1)/phi is the lateral shape factor, sinc = sin(phi)/phi the axial one,
    chi1 = d chi3/d phi and chi2 = d sinc/d phi. Series of paper-notes §1.4 near phi = 0.
    """
    if abs(phi) < SERIES_SWITCH:
        p2 = phi * phi
        p4 = p2 * p2
        chi1 = -0.5 + p2 / 8.0 - p4 / 144.0
        chi2 = phi * (-1.0 / 3.0 + p2 / 30.0 - p4 / 840.0)
        chi3 = phi * (-0.5 + p2 / 24.0 - p4 / 720.0)
        sinc = 1.0 - p2 / 6.0 + p4 / 120.0
    else:
        c = math.cos(phi)
        s = math.sin(phi)
        p2 = phi * phi
        chi1 = (1.0 - c - phi * s) / p2
        chi2 = (phi * c - s) / p2
        chi3 = (c - 1.0) / phi
        sinc = s / phi
    return chi1, chi2, chi3, sinc


@njit(cache=True, inline="always")
def segment_position(phi, delta, length, out):
    """End-disk position in the segment base frame (m): eq (8) of paper 000 / eq (3) of paper 001."""
    _, _, chi3, sinc = chi_functions(phi)
    cd = math.cos(delta)
    sd = math.sin(delta)
    out[0] = length * cd * chi3
    out[1] = -length * sd * chi3
    out[2] = length * sinc


@njit(cache=True, inline="always")
def segment_rotation(phi, delta, out):
    """End-disk rotation Rz(-delta) Ry(-phi) Rz(delta) (eq 6 of paper 000, eq 4 corrected of paper 001)."""
    cd = math.cos(delta)
    sd = math.sin(delta)
    cp = math.cos(phi)
    sp = math.sin(phi)
    one_minus = 1.0 - cp
    out[0, 0] = cd * cd * cp + sd * sd
    out[0, 1] = cd * sd * one_minus
    out[0, 2] = -sp * cd
    out[1, 0] = cd * sd * one_minus
    out[1, 1] = sd * sd * cp + cd * cd
    out[1, 2] = sp * sd
    out[2, 0] = sp * cd
    out[2, 1] = -sp * sd
    out[2, 2] = cp


@njit(cache=True, inline="always")
def segment_jacobian(phi, delta, length, sigma, jv, jw):
    """Twist of the point at arc fraction ``sigma`` per (d phi_end, d delta), in the segment base frame.

    With sigma = 1 this is eq (3) of paper 000 with the phi-derivative sign (d/d theta_000 = d/d phi).
    For sigma < 1 it is paper-notes §1.2 "points on the body": chi functions at sigma*phi, and the phi
    column carries the extra factor sigma (d phi_sigma / d phi = sigma). ``jv`` and ``jw`` are (3, 2).
    """
    chi1, chi2, chi3, _ = chi_functions(sigma * phi)
    cd = math.cos(delta)
    sd = math.sin(delta)
    ls = sigma * length
    ls2 = sigma * ls
    jv[0, 0] = ls2 * cd * chi1
    jv[1, 0] = -ls2 * sd * chi1
    jv[2, 0] = ls2 * chi2
    jv[0, 1] = -ls * sd * chi3
    jv[1, 1] = -ls * cd * chi3
    jv[2, 1] = 0.0
    sp = math.sin(sigma * phi)
    cp = math.cos(sigma * phi)
    jw[0, 0] = -sd * sigma
    jw[1, 0] = -cd * sigma
    jw[2, 0] = 0.0
    jw[0, 1] = -cd * sp
    jw[1, 1] = sd * sp
    jw[2, 1] = cp - 1.0


# Xu's convention (theta = -phi, 0 straight): the terms of eqs (3)-(6) of paper 001.
@njit(cache=True, inline="always")
def bend_terms(theta):
    """Return ``s, omc, a, b, da, db`` of a bending angle ``theta`` (rad).

    ``s = sin(theta)``, ``omc = 1 - cos(theta)`` (via the half angle, no cancellation),
    ``a = (1 - cos)/theta``, ``b = sin/theta`` and their derivatives ``da``, ``db`` in theta.
    Below ``SERIES_SWITCH`` the series of paper-notes §2.2 are used, so all are exact and finite
    at theta = 0.
    """
    sh = math.sin(0.5 * theta)
    ch = math.cos(0.5 * theta)
    s = 2.0 * sh * ch
    omc = 2.0 * sh * sh
    if abs(theta) < SERIES_SWITCH:
        t2 = theta * theta
        a = theta * (0.5 - t2 * (1.0 / 24.0 - t2 / 720.0))
        b = 1.0 - t2 * (1.0 / 6.0 - t2 / 120.0)
        da = 0.5 - t2 * (1.0 / 8.0 - t2 / 144.0)
        db = -theta * (1.0 / 3.0 - t2 * (1.0 / 30.0 - t2 / 840.0))
    else:
        a = omc / theta
        b = s / theta
        da = (s - a) / theta  # sin/theta - (1 - cos)/theta^2
        db = (1.0 - omc - b) / theta  # cos/theta - sin/theta^2
    return s, omc, a, b, da, db


@njit(cache=True, inline="always")
def bend_rotation(s, omc, cd, sd, R):
    """Write ``tb_R_te = Rz(-delta) Ry(theta) Rz(delta)`` (eq 4 corrected, paper-notes §2.3 item 2) into R."""
    R[0, 0] = 1.0 - omc * cd * cd
    R[0, 1] = omc * cd * sd
    R[0, 2] = s * cd
    R[1, 0] = omc * cd * sd
    R[1, 1] = 1.0 - omc * sd * sd
    R[1, 2] = -s * sd
    R[2, 0] = -s * cd
    R[2, 1] = s * sd
    R[2, 2] = 1.0 - omc


def segment_tip_pose(phi, delta, length: float) -> tuple[np.ndarray, np.ndarray]:
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
    for i in range(flat_phi.size):
        segment_position(flat_phi[i], flat_delta[i], length, p[i])
        segment_rotation(flat_phi[i], flat_delta[i], R[i])
    return p.reshape(phi.shape + (3,)), R.reshape(phi.shape + (3, 3))


@njit(cache=True)
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


def _segment_inputs(theta, delta, length):
    length = positive(length, "length", "m")
    theta = as_finite(theta, (), "theta")
    delta = as_finite(delta, (), "delta")
    try:
        theta, delta = np.broadcast_arrays(theta, delta)
    except ValueError:
        raise ValueError(f"theta of shape {theta.shape} and delta of shape {delta.shape} do not broadcast") from None
    return (np.ascontiguousarray(theta.reshape(-1)), np.ascontiguousarray(delta.reshape(-1)), length,
            theta.shape)


def endoscope_segment_pose(theta, delta, length: float) -> tuple[np.ndarray, np.ndarray]:
    """Pose of {te} in {tb} of one constant-curvature segment (eqs 3 and 4, paper-notes §2.3 item 2).

    ``theta`` (rad, 0 = straight), ``delta`` (rad) broadcast together; ``length`` in m.
    Returns ``tb_p_te`` (..., 3) in m and ``tb_R_te = Rz(-delta) Ry(theta) Rz(delta)`` (..., 3, 3).
    Exact and finite at theta = 0 (series of paper-notes §2.2 below ``SERIES_THRESHOLD``).
    """
    theta, delta, length, shape = _segment_inputs(theta, delta, length)
    out = np.empty((theta.shape[0], 12))
    _segment_batch(theta, delta, length, False, out)
    return out[:, :3].reshape(shape + (3,)), out[:, 3:].reshape(shape + (3, 3))


def endoscope_segment_jacobian(theta, delta, length: float) -> np.ndarray:
    """Twist Jacobian of {te}'s origin in {tb} per [theta, delta] rate (eqs 5 and 6, as printed).

    Returns (..., 6, 2): rows [J_tv (m/rad); J_tw (rad/rad)], columns theta, delta. ``length`` in m.
    Below ``SERIES_THRESHOLD`` uses the series of paper-notes §2.2 (exact and finite at theta = 0).
    """
    theta, delta, length, shape = _segment_inputs(theta, delta, length)
    out = np.empty((theta.shape[0], 12))
    _segment_batch(theta, delta, length, True, out)
    return out.reshape(shape + (6, 2))
