"""The one constant-curvature segment model of both robots: exact to rounding at every bend, straight included."""

from __future__ import annotations

import numpy as np
import pytest

from continuum_gym.robots.segment import (
    SERIES_SWITCH,
    endoscope_segment_jacobian,
    endoscope_segment_pose,
    segment_tip_pose,
)

BENDS = np.concatenate([-np.logspace(-9, 0.4, 60), [0.0], np.logspace(-9, 0.4, 60),
                        SERIES_SWITCH * np.array([0.999, 1.0, 1.001, 1.5, 3.0])])


def _reference_pose(bend, delta, length):
    """The segment pose in 80-bit long double, 1 - cos through the half angle (no cancellation)."""
    b = np.asarray(bend, dtype=np.longdouble)
    d = np.asarray(delta, dtype=np.longdouble)
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.where(b == 0, 0, 2 * np.sin(b / 2) ** 2 / np.where(b == 0, 1, b))
        s = np.where(b == 0, 1, np.sin(b) / np.where(b == 0, 1, b))
    p = length * np.stack([np.cos(d) * a, -np.sin(d) * a, s], axis=-1)
    return p


def test_pose_is_exact_to_rounding_at_every_bend_including_the_series_switch():
    """Relative error < 1e-15 of the lateral and axial shape factors from 1e-9 rad to 2.5 rad.

    A direct (cos - 1)/bend loses up to 5e-11 of relative accuracy just above the series switch.
    """
    delta = 0.7
    p, _ = segment_tip_pose(-BENDS, np.full_like(BENDS, delta), 0.02)
    reference = _reference_pose(BENDS, delta, 0.02)
    lateral = np.hypot(p[:, 0], p[:, 1])
    lateral_ref = np.hypot(reference[:, 0], reference[:, 1]).astype(float)
    scale = np.maximum(lateral_ref, 1e-300)
    assert np.max(np.abs(lateral - lateral_ref) / scale * (lateral_ref > 0)) < 1e-15
    assert np.max(np.abs(p[:, 2] - reference[:, 2].astype(float)) / 0.02) < 1e-15


def test_both_conventions_are_the_same_segment():
    """paper-notes §2.1: theta_001 = pi/2 - theta_000; the MBCR's phi is -theta_001: identical poses."""
    rng = np.random.default_rng(0)
    theta = rng.uniform(-2.0, 2.0, 200)
    delta = rng.uniform(-np.pi, np.pi, 200)
    p_mbcr, R_mbcr = segment_tip_pose(-theta, delta, 0.03)
    p_endo, R_endo = endoscope_segment_pose(theta, delta, 0.03)
    np.testing.assert_array_equal(p_mbcr, p_endo)
    np.testing.assert_array_equal(R_mbcr, R_endo)


@pytest.mark.parametrize("bend", [0.0, 1e-7, SERIES_SWITCH, 0.3, -1.2])
def test_segment_jacobian_matches_finite_differences_of_the_pose(bend):
    delta, length, h = 0.4, 0.025, 1e-6
    J = endoscope_segment_jacobian(bend, delta, length)
    for column, (db, dd) in enumerate(((h, 0.0), (0.0, h))):
        plus_p, plus_R = endoscope_segment_pose(bend + db, delta + dd, length)
        minus_p, minus_R = endoscope_segment_pose(bend - db, delta - dd, length)
        np.testing.assert_allclose(J[:3, column], (plus_p - minus_p) / (2 * h), atol=1e-10)
        W = (plus_R - minus_R) / (2 * h) @ endoscope_segment_pose(bend, delta, length)[1].T
        omega = np.array([W[2, 1], W[0, 2], W[1, 0]])
        np.testing.assert_allclose(J[3:, column], omega, atol=1e-8)


@pytest.mark.parametrize("bad, name", [({"length": 0.0}, "length"), ({"length": -1.0}, "length"),
                                       ({"phi": np.nan}, "phi"), ({"delta": np.inf}, "delta")])
def test_bad_input_names_the_argument(bad, name):
    kwargs = {"phi": 0.1, "delta": 0.2, "length": 0.02, **bad}
    with pytest.raises(ValueError, match=name):
        segment_tip_pose(**kwargs)
