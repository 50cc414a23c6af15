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


def segment_tip_pose(phi, delta, length):
    """Batched end-disk pose of one segment in its base frame.

    Args:
        phi: bend variable (rad), any shape; 0 is straight.
        delta: bending-plane angle (rad), same shape.
        length: arc length (m).

    Returns:
        (p, R) with shapes (..., 3) and (..., 3, 3).
    """
    phi, delta = np.broadcast_arrays(np.asarray(phi, dtype=float), np.asarray(delta, dtype=float))
    flat_phi = phi.reshape(-1)
    flat_delta = delta.reshape(-1)
    p = np.empty((flat_phi.size, 3))
    R = np.empty((flat_phi.size, 3, 3))
    for i in range(flat_phi.size):
        segment_position(flat_phi[i], flat_delta[i], float(length), p[i])
        segment_rotation(flat_phi[i], flat_delta[i], R[i])
    return p.reshape(phi.shape + (3,)), R.reshape(phi.shape + (3, 3))
