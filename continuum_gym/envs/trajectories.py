"""Tasks built from recorded data: time series of desired tip poses or of da Vinci configurations.

``TipTrajectory`` (OcclusionAvoidance) and ``DaVinciTrajectory`` (ViewTracking) take samples at
strictly increasing times and interpolate them with cubic splines (scipy ``CubicSpline``: C², so the
desired velocity, the feed-forward of the occlusion baseline, is continuous). Orientations are
interpolated as rotation vectors relative to the first sample, R(t) = R_0 exp([r(t)]).

The compiled kernels evaluate the spline in cubic-Hermite form (knot times, values and slopes),
which reproduces scipy's spline exactly; before the first and after the last sample the trajectory
holds its end value at zero velocity.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np

from continuum_gym.robots.compiled import kernel
from continuum_gym.validation import as_finite, describe

_T = TypeVar("_T")

#: A recording may last at most this long (s) and have at most this many samples.
MAX_DURATION = 3600.0
MAX_SAMPLES = 100_000
#: Consecutive orientation samples may differ by at most this angle (rad): finer sampling is needed beyond.
MAX_ROTATION_STEP = math.pi / 2
#: The interpolated orientation stays this far below pi from the first sample (rotation vectors wrap at pi).
MAX_ROTATION_FROM_START = math.pi - 0.2


def _times(times) -> np.ndarray:
    t = as_finite(times, (), "times")
    if t.ndim != 1 or t.size < 2:
        raise ValueError(f"times must be a 1-D array of at least 2 sample times (s); got shape {t.shape}")
    if t.size > MAX_SAMPLES:
        raise ValueError(f"times may hold at most {MAX_SAMPLES} samples; got {t.size}")
    steps = np.diff(t)
    if np.any(steps <= 0):
        k = int(np.flatnonzero(steps <= 0)[0])
        raise ValueError(f"times must be strictly increasing (s); times[{k + 1}] = {t[k + 1]!r} <= times[{k}] = "
                         f"{t[k]!r}")
    if t[-1] - t[0] > MAX_DURATION:
        raise ValueError(f"a trajectory may last at most {MAX_DURATION:g} s; got {t[-1] - t[0]:g} s")
    return t - t[0]


def _spline(times: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(values, slopes) at the knots of the C² cubic spline through the samples."""
    from scipy.interpolate import CubicSpline

    spline = CubicSpline(times, values, axis=0)
    return np.ascontiguousarray(values, dtype=float), np.ascontiguousarray(spline(times, 1), dtype=float)


@dataclass(frozen=True)
class TipTrajectory:
    """Desired tip poses of the MBCR over time (OcclusionAvoidance), from recorded samples.

    Args:
        times: sample times (s), strictly increasing (shifted to start at 0).
        positions: desired tip positions (K, 3) in m, in {w}.
        rotations: desired tip orientations (K, 3, 3) (None: hold the start orientation of the robot's
            start configuration, which then must be given).
        start_q: start configuration (dof,) (rad, m for q_ins); None: solved by bounded least squares from
            the robot's home so that the tip is at the first pose (an error if it cannot get within 0.1 mm).
        start_gamma: start endoscope rotation (rad).
    """

    times: np.ndarray
    positions: np.ndarray
    rotations: np.ndarray | None = None
    start_q: np.ndarray | None = None
    start_gamma: float = 0.0
    knots: dict = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        t = _times(self.times)
        p = as_finite(self.positions, (3,), "positions")
        if p.shape != (t.size, 3):
            raise ValueError(f"positions must have shape ({t.size}, 3) (one per time, m); got {p.shape}")
        if np.max(np.abs(p)) > 1.0:
            raise ValueError(f"positions must be within 1 m of the channel exit (m); got max |p| = {np.max(np.abs(p)):g}")
        knots: dict[str, np.ndarray | None] = {"t": t}
        knots["x"], knots["m"] = _spline(t, p)
        if self.rotations is not None:
            from scipy.spatial.transform import Rotation

            R = as_finite(self.rotations, (3, 3), "rotations")
            if R.shape != (t.size, 3, 3):
                raise ValueError(f"rotations must have shape ({t.size}, 3, 3); got {R.shape}")
            error = np.max(np.abs(np.einsum("kji,kjl->kil", R, R) - np.eye(3)))
            if error > 1e-6 or np.min(np.linalg.det(R)) <= 0:
                raise ValueError("rotations must be rotation matrices (R^T R = I to 1e-6, det R > 0)")
            steps = Rotation.from_matrix(np.einsum("kji,kjl->kil", R[:-1], R[1:])).magnitude()
            if np.max(steps) > MAX_ROTATION_STEP:
                k = int(np.argmax(steps))
                raise ValueError(f"rotations change by {steps[k]:.3g} rad between samples {k} and {k + 1}; at most "
                                 f"{MAX_ROTATION_STEP:.3g} rad: sample the recording more finely")
            relative = Rotation.from_matrix(np.einsum("ji,kjl->kil", R[0], R)).as_rotvec()
            if np.max(np.linalg.norm(relative, axis=1)) > MAX_ROTATION_FROM_START:
                raise ValueError(f"rotations may turn at most {MAX_ROTATION_FROM_START:.3g} rad away from the first "
                                 "sample (split the recording into several tasks)")
            knots["R0"] = np.ascontiguousarray(R[0])
            knots["r"], knots["rm"] = _spline(t, relative)
        else:
            knots["R0"] = None
            knots["r"] = knots["rm"] = np.zeros((t.size, 3))
        if self.rotations is None and self.start_q is None:
            raise ValueError("give rotations (K, 3, 3) or start_q: without either the desired orientation is unknown")
        if self.start_q is not None:
            object.__setattr__(self, "start_q", as_finite(self.start_q, (), "start_q").reshape(-1))
        if not math.isfinite(float(self.start_gamma)):
            raise ValueError(f"start_gamma must be a finite angle (rad); got {self.start_gamma!r}")
        object.__setattr__(self, "knots", knots)

    @property
    def duration(self) -> float:
        """Length of the recording (s)."""
        return float(self.knots["t"][-1])


@dataclass(frozen=True)
class DaVinciTrajectory:
    """Da Vinci configurations [L_dV (m), yaw, pitch, roll (rad)] over time (ViewTracking), from samples.

    Args:
        times: sample times (s), strictly increasing (shifted to start at 0).
        configurations: (K, 4) within the da Vinci's ranges (Table II): L_dV in [0, 0.1] m, yaw and pitch in
            [-pi/3, pi/3], roll in [-pi, pi] (unwrapped: consecutive rolls differ by less than pi).
    """

    times: np.ndarray
    configurations: np.ndarray
    knots: dict = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        from continuum_gym.robots.davinci import DaVinciEndoscope

        t = _times(self.times)
        x = as_finite(self.configurations, (4,), "configurations")
        if x.shape != (t.size, 4):
            raise ValueError(f"configurations must have shape ({t.size}, 4) [L_dV, yaw, pitch, roll]; got {x.shape}")
        lower, upper = DaVinciEndoscope().joint_limits
        names = DaVinciEndoscope.joint_names
        for k in range(3):
            bad = (x[:, k] < lower[k] - 1e-12) | (x[:, k] > upper[k] + 1e-12)
            if np.any(bad):
                j = int(np.flatnonzero(bad)[0])
                raise ValueError(f"configurations[:, {k}] ({names[k]}) must be in [{lower[k]:.6g}, {upper[k]:.6g}]; "
                                 f"got {x[j, k]!r} at sample {j}")
        if np.max(np.abs(np.diff(x[:, 3]))) >= math.pi:
            raise ValueError("configurations[:, 3] (roll) must be unwrapped: consecutive samples differ by < pi")
        knots = {"t": t, "R0": None, "r": np.zeros((t.size, 3)), "rm": np.zeros((t.size, 3))}
        knots["x"], knots["m"] = _spline(t, x)
        object.__setattr__(self, "knots", knots)

    @property
    def duration(self) -> float:
        return float(self.knots["t"][-1])


# ---------------------------------------------------------------------- kernels
@kernel(inline="always")
def hermite_point(t_knots, x_knots, m_knots, n, t, p, v):
    """Cubic-Hermite value and derivative at time t (s) of the first ``n`` knots into p and v."""
    dim = p.shape[0]
    if t < t_knots[0] or t > t_knots[n - 1]:  # outside the recording: hold its end at rest
        k = 0 if t < t_knots[0] else n - 1
        for a in range(dim):
            p[a] = x_knots[k, a]
            v[a] = 0.0
        return
    lo, hi = 0, n - 1
    while hi - lo > 1:  # t_knots[lo] <= t <= t_knots[hi]
        mid = (lo + hi) // 2
        if t_knots[mid] <= t:
            lo = mid
        else:
            hi = mid
    h = t_knots[hi] - t_knots[lo]
    s = (t - t_knots[lo]) / h
    s2 = s * s
    s3 = s2 * s
    h00 = 2.0 * s3 - 3.0 * s2 + 1.0
    h10 = s3 - 2.0 * s2 + s
    h01 = -2.0 * s3 + 3.0 * s2
    h11 = s3 - s2
    d00 = (6.0 * s2 - 6.0 * s) / h
    d10 = 3.0 * s2 - 4.0 * s + 1.0
    d01 = (-6.0 * s2 + 6.0 * s) / h
    d11 = 3.0 * s2 - 2.0 * s
    for a in range(dim):
        p[a] = h00 * x_knots[lo, a] + h10 * h * m_knots[lo, a] + h01 * x_knots[hi, a] + h11 * h * m_knots[hi, a]
        v[a] = d00 * x_knots[lo, a] + d10 * m_knots[lo, a] + d01 * x_knots[hi, a] + d11 * m_knots[hi, a]


def as_trajectory(task: Any, kind: type[_T]) -> _T:
    """``task`` if it is a ``kind``, else ``ValueError`` naming what was given."""
    if not isinstance(task, kind):
        raise ValueError(f"task must be a {kind.__name__} here; got {describe(task)}")
    return task


#: The sample fields of each kind of recording: what a trajectory is rebuilt from, bit for bit (its splines are
#: computed from them again). ``save_config`` stores them in a ``.tasks.npz`` file, datasets inline in JSON.
SAMPLE_FIELDS = {"TipTrajectory": ("times", "positions", "rotations", "start_q", "start_gamma"),
                 "DaVinciTrajectory": ("times", "configurations")}


def samples_of(trajectory: TipTrajectory | DaVinciTrajectory) -> dict[str, Any]:
    """``{"type": class name, field: float64 array}`` of a recording's samples (fields that are None left out)."""
    kind = type(trajectory).__name__
    out: dict[str, Any] = {"type": kind}
    for name in SAMPLE_FIELDS[kind]:
        value = getattr(trajectory, name)
        if value is not None:
            out[name] = np.asarray(value, dtype=np.float64)
    return out


def from_samples(data: Any) -> TipTrajectory | DaVinciTrajectory:
    """The recording ``samples_of`` (or its JSON form, nested lists) describes, validated as when it was made."""
    if not isinstance(data, dict) or data.get("type") not in SAMPLE_FIELDS:
        raise ValueError(f"a recorded trajectory must be a mapping with type {sorted(SAMPLE_FIELDS)} and its samples; "
                         f"got {describe(data)}")
    kind = TipTrajectory if data["type"] == "TipTrajectory" else DaVinciTrajectory
    kwargs: dict[str, Any] = {name: np.asarray(data[name], dtype=np.float64)
                              for name in SAMPLE_FIELDS[data["type"]] if data.get(name) is not None}
    if "start_gamma" in kwargs:
        kwargs["start_gamma"] = float(kwargs["start_gamma"])
    return kind(**kwargs)


__all__ = ["TipTrajectory", "DaVinciTrajectory", "hermite_point", "MAX_DURATION", "MAX_SAMPLES", "SAMPLE_FIELDS",
           "samples_of", "from_samples"]
