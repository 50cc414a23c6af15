"""What a ViewTracking step writes, declared once: the observation's layout and the columns of
``metrics`` and ``flags`` (see ``continuum_gym.envs.columns``).

The step kernels index these arrays only through these declarations, the env docstring's observation
table is made from ``OBSERVATION``, and the extension tutorial's column table is checked against
``Metric`` and ``Flag``.
"""

from __future__ import annotations

from continuum_gym.envs.columns import Block, Columns, Layout

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


class Metric(Columns):
    """Columns of ``metrics`` (float64), at the state after the step."""

    OR = "overlap ratio of the two views"
    POSITION_ERROR = "target-point error eps_p (m)"
    ORIENTATION_ERROR = "orientation error eps_R (rad)"


class Flag(Columns):
    """Columns of ``flags`` (int64; ``CLAMPED`` is a bit mask, bit k for joint k)."""

    CLAMPED = "joint bits clamped at a limit"
    RATE_SATURATED = "rates scaled down to the rate limits"
    TERMINATED = "the pose error is not finite (always with NON_FINITE: the env raises, or ends it as truncated)"
    TRUNCATED = "the task's duration is over"
    NON_FINITE = "a value of the row is not finite (NaN or inf): the episode cannot be scored"


__all__ = ["OBSERVATION", "OBS", "OBS_DIM", "TARGET_OBS_DIM", "Metric", "Flag", "POSITION_ERROR_SCALE"]
