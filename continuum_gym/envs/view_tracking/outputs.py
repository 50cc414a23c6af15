"""What a ViewTracking step writes, declared once: the observation's layout and the columns of
``metrics`` and ``flags`` (see ``continuum_gym.envs.columns``).

The step kernels index these arrays only through these declarations, the env docstring's observation
table is made from ``OBSERVATION``, and the extension tutorial's column table is checked against
``Metric`` and ``Flag``.
"""

from __future__ import annotations

from continuum_gym.envs.columns import NON_FINITE, Block, Columns, Episode, Layout, Value, mean

POSITION_ERROR_SCALE = 0.05  # m, of the target point's offset from the tip

#: An observation row: 22 entries, 27 with ``observe_target`` (the blocks from ``target_insertion`` on).
OBSERVATION = Layout(
    "ViewObservation",
    Block("l0", "L0", "mapped to [-1, 1] over [0, 0.1] m"),
    Block("phi", "phi", "/ pi"),
    Block("theta1", "theta1", "mapped to [-1, 1] over [0, pi/4]"),
    Block("delta1", "sin delta1, cos delta1", "-", size=2),
    Block("theta2", "theta2", "mapped to [-1, 1] over [0, pi/2]"),
    Block("delta2", "sin delta2, cos delta2", "-", size=2),
    Block("target_error", "target point error p_dVt - p_ct (world)", f"/ {POSITION_ERROR_SCALE} m", size=3),
    Block("orientation_error", "orientation error log(R_dVt R_ct^T)", "rad", size=3),
    Block("overlap", "overlap ratio", "-"),
    Block("base_command", "baseline command at this state", "/ action scale", size=6),
    Block("time", "elapsed time", "/ task duration"),
    Block("target_insertion", "da Vinci insertion L_dV (only with ``observe_target``)", "(L_dV - 0.05 m) / 0.05 m"),
    Block("target_yaw_pitch", "da Vinci yaw, pitch (only with ``observe_target``)", "/ (pi/3)", size=2),
    Block("target_roll", "sin, cos of the da Vinci roll (only with ``observe_target``)", "-", size=2),
)
#: Each block's first entry (the layout does not depend on the robot): ``OBS.overlap`` in a kernel.
OBS = OBSERVATION.starts()
#: Entries without ``observe_target``, and the ones it adds (the da Vinci configuration).
OBS_DIM = OBSERVATION.width(upto="target_insertion")
TARGET_OBS_DIM = OBSERVATION.width() - OBS_DIM


#: The coverage map's success criterion (paper-notes §2.6): OR above it counts as reproducing the view.
OVERLAP_THRESHOLD = 0.8


class Metric(Columns):
    """Columns of ``metrics`` (float64), at the state after the step."""

    OR = Value("exact overlap ratio of the two view frustums at the new state", info="overlap_ratio", episode=(
        mean("mean_or", "mean overlap ratio (OR)", higher_is_better=True),
        Episode("final_or", "final"),
        Episode("coverage_percent", "final", "coverage (final OR > 0.8 on the grid)", True, "%",
                grid_threshold=OVERLAP_THRESHOLD)))
    POSITION_ERROR = Value("distance of the target point from the da Vinci's (m)", info="position_error_m", unit="m",
                           episode=(mean("mean_position_error_m", "mean target-point error", unit="m",
                                         display_unit="mm", display_scale=1e3),))
    ORIENTATION_ERROR = Value("orientation error of the camera frame (rad)", info="orientation_error_rad", unit="rad")
    OR_ABOVE = Value("the overlap ratio is above 0.8 (1 or 0)", info="overlap_above_0.8", kind="bool",
                     episode=(mean("or_above_0.8_fraction", "steps with OR > 0.8", higher_is_better=True),))


class Flag(Columns):
    """Columns of ``flags`` (int64; ``CLAMPED`` is a bit mask, bit k for joint k)."""

    CLAMPED = Value("joints clamped at a limit (6,)", info="clamped_joints", kind="bits")
    RATE_SATURATED = Value("joint rates scaled down to ``rate_limits``", info="rate_saturated", kind="bool")
    TERMINATED = "the pose error is not finite (always with NON_FINITE: the env raises, or ends it as truncated)"
    TRUNCATED = "the task's duration is over"
    NON_FINITE = NON_FINITE


__all__ = ["OBSERVATION", "OBS", "OBS_DIM", "TARGET_OBS_DIM", "Metric", "Flag", "POSITION_ERROR_SCALE", "OVERLAP_THRESHOLD"]
