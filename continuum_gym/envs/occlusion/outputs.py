"""What an OcclusionAvoidance step writes, declared once: the observation's layout and the columns of
``metrics``, ``flags`` and ``base_info`` (see ``continuum_gym.envs.columns``).

The row functions index these arrays only through these declarations; a column declared as a ``Value``
reaches ``info``, the env docstring and the evaluation's tables from here (the library reads it), the
observation's table is made from ``OBSERVATION``, and the extension tutorial's column table is checked
against ``Metric`` and ``Flag``.
"""

from __future__ import annotations

from continuum_gym.envs.columns import NON_FINITE, Block, Columns, Layout, Value, mean

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

    VOI = Value("Visual Occlusion Index (eq 27) at the new state", info="voi",
                episode=(mean("mean_voi", "mean visual occlusion index (VOI)"),))
    TIP_ERROR = Value("tip position error (m)", info="tip_error_m", unit="m",
                      episode=(mean("mean_tip_error_m", "mean tip position error", unit="m", display_unit="mm",
                                    display_scale=1e3),))
    ORIENTATION_ERROR = Value("tip orientation error (rad)", info="orientation_error_rad", unit="rad",
                              episode=(mean("mean_orientation_error_rad", "mean tip orientation error", unit="rad"),))
    VIEW_FRACTION = Value("tip angle from the view axis / cone half-angle", info="tip_view_fraction")
    TIP_IN_VIEW = Value("tip within 0.7 of the half-angle (1 or 0)", info="tip_in_view", kind="bool",
                        episode=(mean("tip_in_view_fraction", "tip in view (within 0.7 of the half-angle)",
                                      higher_is_better=True),))


class Flag(Columns):
    """Columns of ``flags`` (int64; joint flags are bit masks, bit k for joint k)."""

    CLAMPED = Value("joints clamped at a position limit (dof,)", info="clamped_joints", kind="bits")
    RATE_SATURATED = Value("joint rates scaled down to the rate limits", info="rate_saturated", kind="bool")
    GAMMA_SATURATED = Value("endoscope rate clipped to its limit", info="gamma_rate_saturated", kind="bool")
    TERMINATED = "the tip is lost (more than 10 mm from its desired position)"
    TRUNCATED = "the task's duration is over"
    BASE_FROZEN = Value("joints the baseline froze at a limit during the step (dof,)", info="base_frozen_joints",
                        kind="bits")
    BASE_SATURATED = Value("the baseline's rates were scaled down", info="base_rate_saturated", kind="bool")
    GUARDED = Value("the visibility guard cut the residual's endoscope rotation", info="visibility_guarded",
                    kind="bool", episode=(mean("visibility_guarded_fraction"),))
    NON_FINITE = NON_FINITE


class BaseInfo(Columns):
    """Columns of ``base_info``: what the cached baseline command (``base_cmd``) reported."""

    FROZEN = "joint bits the cached baseline command froze"
    SATURATED = "its rates were scaled down"


__all__ = ["OBSERVATION", "OBS", "Metric", "Flag", "BaseInfo", "POSITION_ERROR_SCALE", "ORIENTATION_ERROR_SCALE",
           "VELOCITY_SCALE"]
