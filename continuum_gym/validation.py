"""Input checks for every public entry point, in one form.

Each check returns the value converted to its canonical type or raises ``ValueError`` whose message
names the parameter, states the valid type or range, and shows what was given:
``max_bend must be in (0, 3.14159] (rad); got 100``. Nothing here clamps silently.

This module imports only numpy, so every layer (robots upwards) can use it.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

__all__ = [
    "as_array", "as_configuration", "as_vectors", "as_rotations", "as_finite", "number", "positive",
    "non_negative", "fraction", "integer", "choice", "angle_in_open_interval", "boolean", "weights",
    "interval", "closest", "describe",
]


def describe(value: Any) -> str:
    """A short ``repr`` for error messages (arrays summarised by shape)."""
    if isinstance(value, np.ndarray) and value.size > 8:
        return f"array of shape {value.shape}"
    text = repr(value)
    return text if len(text) <= 120 else text[:117] + "..."


def closest(name: str, valid: Iterable[str]) -> str:
    """'; did you mean 'x'?' for a misspelt name, or ''."""
    match = difflib.get_close_matches(str(name), [str(v) for v in valid], n=1)
    return f"; did you mean {match[0]!r}?" if match else ""


def _unit(unit: str) -> str:
    return f" ({unit})" if unit else ""


def number(value: Any, name: str, *, low: float = -math.inf, high: float = math.inf, low_open: bool = False,
           high_open: bool = False, unit: str = "") -> float:
    """``value`` as a finite float within [low, high] (open ends as asked), else ``ValueError``."""
    left = "(" if low_open or low == -math.inf else "["
    right = ")" if high_open or high == math.inf else "]"
    span = f"in {left}{low:g}, {high:g}{right}"
    if isinstance(value, (bool, np.bool_)) or isinstance(value, str):
        raise ValueError(f"{name} must be a number {span}{_unit(unit)}; got {describe(value)}")
    try:
        result = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number {span}{_unit(unit)}; got {describe(value)}") from None
    if not math.isfinite(result):
        raise ValueError(f"{name} must be a finite number {span}{_unit(unit)}; got {describe(value)}")
    if result < low or result > high or (low_open and result == low) or (high_open and result == high):
        raise ValueError(f"{name} must be {span}{_unit(unit)}; got {describe(value)}")
    return result


def positive(value: Any, name: str, unit: str = "m") -> float:
    """``value`` as a finite float > 0 (``unit`` named in the message)."""
    return number(value, name, low=0.0, low_open=True, unit=unit)


def non_negative(value: Any, name: str, unit: str = "m") -> float:
    """``value`` as a finite float >= 0."""
    return number(value, name, low=0.0, unit=unit)


def fraction(value: Any, name: str, *, allow_zero: bool = False, allow_one: bool = True) -> float:
    """A number in (0, 1] (or [0, 1] / (0, 1) as asked)."""
    return number(value, name, low=0.0, high=1.0, low_open=not allow_zero, high_open=not allow_one)


def angle_in_open_interval(value: Any, name: str, low: float, high: float, label: str) -> float:
    """An angle (rad) with low < value < high; ``label`` spells the interval, e.g. ``"(0, pi/2)"``."""
    try:
        return number(value, name, low=low, high=high, low_open=True, high_open=True, unit="rad")
    except ValueError:
        raise ValueError(f"{name} must be an angle in {label} (rad); got {describe(value)}") from None


def integer(value: Any, name: str, *, low: int | None = None, high: int | None = None) -> int:
    """``value`` as an int (an integral float is accepted) within [low, high]."""
    span = ""
    if low is not None and high is not None:
        span = f" in [{low}, {high}]"
    elif low is not None:
        span = f" >= {low}"
    elif high is not None:
        span = f" <= {high}"
    if isinstance(value, (bool, np.bool_)) or isinstance(value, str):
        raise ValueError(f"{name} must be an integer{span}; got {describe(value)}")
    try:
        as_float = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be an integer{span}; got {describe(value)}") from None
    if not math.isfinite(as_float) or as_float != int(as_float):
        raise ValueError(f"{name} must be an integer{span}; got {describe(value)}")
    result = int(as_float)
    if (low is not None and result < low) or (high is not None and result > high):
        raise ValueError(f"{name} must be an integer{span}; got {describe(value)}")
    return result


def boolean(value: Any, name: str) -> bool:
    """``True`` or ``False`` (numpy bools too); strings and numbers are refused."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    raise ValueError(f"{name} must be True or False; got {describe(value)}")


def choice(value: Any, valid: Sequence, name: str) -> Any:
    """``value`` if it is one of ``valid``, else ``ValueError`` listing them (and the closest match)."""
    try:
        ok = value in valid
    except TypeError:
        ok = False
    if not ok:
        hint = closest(value, [v for v in valid if isinstance(v, str)]) if isinstance(value, str) else ""
        raise ValueError(f"{name} must be one of {list(valid)}; got {describe(value)}{hint}")
    return value


def interval(value: Any, name: str, *, low: float = -math.inf, high: float = math.inf, unit: str = "") -> tuple:
    """A (min, max) pair of finite numbers with low <= min < max <= high."""
    try:
        lo, hi = value
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a (min, max) pair in [{low:g}, {high:g}]{_unit(unit)} with min < max; "
                         f"got {describe(value)}") from None
    lo = number(lo, f"{name}[0]", low=low, high=high, unit=unit)
    hi = number(hi, f"{name}[1]", low=low, high=high, unit=unit)
    if not lo < hi:
        raise ValueError(f"{name} must be (min, max) with min < max{_unit(unit)}; got {describe(value)}")
    return lo, hi


def weights(value: Any, defaults: Mapping[str, float], name: str = "reward_weights", *,
            high: float = 1e6) -> dict:
    """User weights merged into ``defaults``; each a finite number in [0, high]; unknown names raise."""
    merged = dict(defaults)
    if value is None:
        return merged
    if not isinstance(value, Mapping):
        raise ValueError(f"{name} must be a dict of term name -> weight; got {type(value).__name__}")
    for key, weight in value.items():
        if key not in defaults:
            raise ValueError(f"{name} has unknown term {key!r}; valid terms: {sorted(defaults)}"
                             f"{closest(key, defaults)}")
        merged[key] = number(weight, f"{name}[{key!r}]", low=0.0, high=high)
    return merged


# ---------------------------------------------------------------------- arrays
def _shape_text(tail: tuple) -> str:
    return "(..., " + ", ".join(map(str, tail)) + ")" if tail else "(...)"


def _all_finite(array: np.ndarray) -> bool:
    # math.isfinite on a 0-d array is ~10x faster than np.isfinite(...).all(), and gamma is often a scalar
    return math.isfinite(array) if array.ndim == 0 else bool(np.isfinite(array).all())


def as_array(x: Any, name: str, tail: tuple = ()) -> np.ndarray:
    """``x`` as float64 with trailing shape ``tail`` (no finiteness check: the kernels check it)."""
    try:
        array = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a numeric array of shape {_shape_text(tail)}; got {describe(x)}") from None
    if tail and (array.ndim < len(tail) or array.shape[array.ndim - len(tail):] != tuple(tail)):
        raise ValueError(f"{name} must have shape {_shape_text(tail)}; got shape {array.shape}")
    return array


def as_finite(x: Any, tail: tuple, name: str) -> np.ndarray:
    """``x`` as float64 with trailing shape ``tail`` and only finite entries."""
    array = as_array(x, name, tail)
    if not _all_finite(array):
        raise ValueError(f"{name} must be finite (no NaN or inf); got {describe(x)}")
    return array


def as_configuration(q: Any, dof: int, name: str = "q") -> np.ndarray:
    """A finite float64 configuration array of shape (..., dof); at least one dimension."""
    array = as_array(q, name, (dof,))
    if array.ndim == 0:
        raise ValueError(f"{name} must have shape (..., {dof}); got a scalar")
    if not _all_finite(array):
        raise ValueError(f"{name} must be finite (no NaN or inf); got {describe(q)}")
    return array


def as_vectors(x: Any, size: int, name: str) -> np.ndarray:
    """Finite float64 vectors of shape (..., size)."""
    return as_configuration(x, size, name)


def as_rotations(R: Any, name: str) -> np.ndarray:
    """Finite float64 matrices of shape (..., 3, 3)."""
    return as_finite(R, (3, 3), name)
