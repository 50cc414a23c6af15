"""Input checks shared by every public kinematic and geometric function.

Errors name the parameter and its valid shape or range; nothing is clamped silently.
"""

from __future__ import annotations

import numpy as np


def as_configuration(q, dof: int, name: str = "q") -> np.ndarray:
    """Return ``q`` as a float64 array of shape (..., dof), finite, or raise ``ValueError``."""
    try:
        array = np.asarray(q, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name} must be a numeric array of shape (..., {dof}); got {q!r}") from error
    if array.ndim == 0 or array.shape[-1] != dof:
        raise ValueError(f"{name} must have shape (..., {dof}); got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite (no NaN or inf); got {array}")
    return array


def as_vectors(x, size: int, name: str) -> np.ndarray:
    """Return ``x`` as a finite float64 array of shape (..., size), or raise ``ValueError``."""
    return as_configuration(x, size, name)


def as_rotations(R, name: str) -> np.ndarray:
    """Return ``R`` as a finite float64 array of shape (..., 3, 3), or raise ``ValueError``."""
    try:
        array = np.asarray(R, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name} must be a numeric array of shape (..., 3, 3)") from error
    if array.ndim < 2 or array.shape[-2:] != (3, 3):
        raise ValueError(f"{name} must have shape (..., 3, 3); got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite (no NaN or inf)")
    return array


def positive(value, name: str, unit: str = "m") -> float:
    """Return ``value`` as a float if it is finite and > 0, else raise ``ValueError``."""
    try:
        number = float(value)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name} must be a positive number ({unit}); got {value!r}") from error
    if not np.isfinite(number) or number <= 0.0:
        raise ValueError(f"{name} must be finite and > 0 ({unit}); got {value!r}")
    return number


def non_negative(value, name: str, unit: str = "m") -> float:
    """Return ``value`` as a float if it is finite and >= 0, else raise ``ValueError``."""
    try:
        number = float(value)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name} must be a number >= 0 ({unit}); got {value!r}") from error
    if not np.isfinite(number) or number < 0.0:
        raise ValueError(f"{name} must be finite and >= 0 ({unit}); got {value!r}")
    return number


def angle_in_open_interval(value, name: str, low: float, high: float, label: str) -> float:
    """Return ``value`` (rad) if low < value < high, else raise ``ValueError`` naming ``label``."""
    try:
        number = float(value)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name} must be an angle in {label} (rad); got {value!r}") from error
    if not np.isfinite(number) or not (low < number < high):
        raise ValueError(f"{name} must be an angle in {label} (rad); got {value!r}")
    return number
