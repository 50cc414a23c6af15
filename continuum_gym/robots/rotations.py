"""Rotations as compiled kernels: the log map (rotation vectors), the exponential map and orientation errors."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.robots.compiled import kernel
from continuum_gym.validation import as_rotations, describe

#: Tolerance of the orthogonality check of ``rotation_vector``'s input.
ROTATION_TOL = 1e-6


@kernel(inline="always")
def rotation_log(R, out):
    """Rotation vector (axis * angle, rad) of a 3x3 rotation R into ``out``; robust at 0 and pi.

    Goes through the unit quaternion (Shepperd's method), so no branch loses precision.
    """
    trace = R[0, 0] + R[1, 1] + R[2, 2]
    if trace > R[0, 0] and trace > R[1, 1] and trace > R[2, 2]:
        s = math.sqrt(max(trace + 1.0, 0.0)) * 2.0
        w = 0.25 * s
        x = (R[2, 1] - R[1, 2]) / s
        y = (R[0, 2] - R[2, 0]) / s
        z = (R[1, 0] - R[0, 1]) / s
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = math.sqrt(max(1.0 + R[0, 0] - R[1, 1] - R[2, 2], 0.0)) * 2.0
        w = (R[2, 1] - R[1, 2]) / s
        x = 0.25 * s
        y = (R[0, 1] + R[1, 0]) / s
        z = (R[0, 2] + R[2, 0]) / s
    elif R[1, 1] > R[2, 2]:
        s = math.sqrt(max(1.0 + R[1, 1] - R[0, 0] - R[2, 2], 0.0)) * 2.0
        w = (R[0, 2] - R[2, 0]) / s
        x = (R[0, 1] + R[1, 0]) / s
        y = 0.25 * s
        z = (R[1, 2] + R[2, 1]) / s
    else:
        s = math.sqrt(max(1.0 + R[2, 2] - R[0, 0] - R[1, 1], 0.0)) * 2.0
        w = (R[1, 0] - R[0, 1]) / s
        x = (R[0, 2] + R[2, 0]) / s
        y = (R[1, 2] + R[2, 1]) / s
        z = 0.25 * s
    if w < 0.0:
        w = -w
        x = -x
        y = -y
        z = -z
    norm_v = math.sqrt(x * x + y * y + z * z)
    if norm_v < 1e-300:
        out[0] = 0.0
        out[1] = 0.0
        out[2] = 0.0
        return
    angle = 2.0 * math.atan2(norm_v, w)
    scale = angle / norm_v
    out[0] = x * scale
    out[1] = y * scale
    out[2] = z * scale


@kernel(inline="always")
def rotation_exp(w, out):
    """Rotation matrix of the rotation vector w (axis * angle, rad) into ``out`` (Rodrigues)."""
    angle = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    if angle < 1e-8:  # second-order series: exact to rounding below this angle
        a, b = 1.0 - angle * angle / 6.0, 0.5 - angle * angle / 24.0
    else:
        a, b = math.sin(angle) / angle, (1.0 - math.cos(angle)) / (angle * angle)
    x, y, z = w[0], w[1], w[2]
    out[0, 0] = 1.0 - b * (y * y + z * z)
    out[1, 1] = 1.0 - b * (x * x + z * z)
    out[2, 2] = 1.0 - b * (x * x + y * y)
    out[0, 1] = b * x * y - a * z
    out[1, 0] = b * x * y + a * z
    out[0, 2] = b * x * z + a * y
    out[2, 0] = b * x * z - a * y
    out[1, 2] = b * y * z - a * x
    out[2, 1] = b * y * z + a * x


@kernel(inline="always")
def orientation_error(R_des, R, work, out):
    """log(R_des R^T) (rad), the world-frame rotation that takes R to R_des (paper-notes §1.3 item 11)."""
    for a in range(3):
        for b in range(3):
            acc = 0.0
            for c in range(3):
                acc += R_des[a, c] * R[b, c]
            work[a, b] = acc
    rotation_log(work, out)


@kernel
def _log_batch(flat, out):
    for i in range(flat.shape[0]):
        rotation_log(flat[i], out[i])


def rotation_vector(R: ArrayLike) -> np.ndarray:
    """Batched log map: rotation vectors (..., 3) in rad of rotations (..., 3, 3).

    ``R`` must be finite; each matrix is read as a rotation (its nearest quaternion), so pass proper
    rotations: the result of a non-orthogonal matrix is not meaningful.
    """
    R = as_rotations(R, "R")
    flat = np.ascontiguousarray(R.reshape(-1, 3, 3))
    gram = np.einsum("nji,njk->nik", flat, flat) - np.eye(3)
    if flat.size and (np.max(np.abs(gram)) > ROTATION_TOL or np.min(np.linalg.det(flat)) <= 0.0):
        raise ValueError(f"R must hold rotation matrices (max |R^T R - I| <= {ROTATION_TOL:g}, det R > 0); "
                         f"got {describe(R)}")
    out = np.empty((flat.shape[0], 3))
    _log_batch(flat, out)
    return out.reshape(R.shape[:-2] + (3,))
