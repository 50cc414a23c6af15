"""What an OcclusionAvoidance step writes, declared once: the observation's layout and the columns of
``metrics``, ``flags`` and ``base_info`` (see ``continuum_gym.envs.columns``).

The step kernels index these arrays only through these declarations, the env docstring's observation
table is made from ``OBSERVATION``, and the extension tutorial's column table is checked against
``Metric`` and ``Flag``.
"""

from __future__ import annotations

from continuum_gym.envs.columns import Block, Columns, Layout

# Observation scales.
POSITION_ERROR_SCALE = 0.01  # m
ORIENTATION_ERROR_SCALE = 0.1  # rad
VELOCITY_SCALE = 0.05  # m/s

#: An observation row for a robot of n segments (5 n + 17 entries; 32 for the paper's three).
OBSERVATION = Layout(
    "OcclusionObservation",
    Block("bend", "bend pi/2 - theta_j", "/ max_bend", size=0, per_segment=1),
    Block("delta", "sin delta_j, cos delta_j (j = 1..n, interleaved)", "-", size=0, per_segment=2),
    Block("insertion", "insertion", "mapped to [-1, 1] over the insertion range"),
    Block("gamma", "sin gamma, cos gamma", "-", size=2),
    Block("tip_position_error", "tip position error p_des - p (world)", f"/ {POSITION_ERROR_SCALE} m", size=3),
    Block("tip_orientation_error", "tip orientation error log(R_des R^T)", f"/ {ORIENTATION_ERROR_SCALE} rad",
          size=3),
    Block("desired_velocity", "desired tip velocity (feed-forward)", f"/ {VELOCITY_SCALE} m/s", size=3),
    Block("view_fraction", "tip angle from the view axis", "/ cone half-angle"),
    Block("voi", "VOI (eq 27, paper-notes §1.3 item 13)", "-"),
    Block("base_command", "baseline command at this state (the next substep's; dof + 1 = 2 n + 2)", "/ rate limits",
          size=2, per_segment=2),
    Block("time", "elapsed time", "/ task duration"),
)
#: Each block's first entry as (per segment, constant): ``at(OBS.voi, n)`` in a kernel.
OBS = OBSERVATION.offsets()


class Metric(Columns):
    """Columns of ``metrics`` (float64), at the state after the step."""

    VOI = "Visual Occlusion Index (eq 27)"
    TIP_ERROR = "tip position error (m)"
    ORIENTATION_ERROR = "tip orientation error (rad)"
    VIEW_FRACTION = "tip angle from the view axis / cone half-angle"


class Flag(Columns):
    """Columns of ``flags`` (int64; joint flags are bit masks, bit k for joint k)."""

    CLAMPED = "joint bits clamped at a position limit"
    RATE_SATURATED = "joint rates scaled down to the rate limits"
    GAMMA_SATURATED = "endoscope rate clipped to its limit"
    TERMINATED = "the tip is lost (more than 10 mm from its desired position)"
    TRUNCATED = "the task's duration is over"
    BASE_FROZEN = "joint bits the baseline froze at a limit (OR over the substeps)"
    BASE_SATURATED = "the baseline's rates were scaled down"
    GUARDED = "the visibility guard cut the residual's endoscope rotation"
    NON_FINITE = "a value of the row is not finite (NaN or inf): the episode cannot be scored"


class BaseInfo(Columns):
    """Columns of ``base_info``: what the cached baseline command (``base_cmd``) reported."""

    FROZEN = "joint bits the cached baseline command froze"
    SATURATED = "its rates were scaled down"


__all__ = ["OBSERVATION", "OBS", "Metric", "Flag", "BaseInfo", "POSITION_ERROR_SCALE", "ORIENTATION_ERROR_SCALE",
           "VELOCITY_SCALE"]
