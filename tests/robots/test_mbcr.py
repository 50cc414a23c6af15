"""MultiBackboneRobot against the independent reference, finite differences and closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from continuum_gym.robots.mbcr import PAPER_PSPS, MultiBackboneRobot
from tests.conftest import fd_gradient, fd_twist_jacobian

ROBOT = MultiBackboneRobot()
HALF_PI = math.pi / 2


def random_configurations(rng, n, max_bend=1.4):
    q = np.empty((n, 7))
    q[:, 0:6:2] = HALF_PI - rng.uniform(-max_bend, max_bend, (n, 3))
    q[:, 1:6:2] = rng.uniform(-math.pi, math.pi, (n, 3))
    q[:, 6] = rng.uniform(0.0, 0.04, n)
    return q


def near_straight_configurations():
    configs = []
    for offset in (0.0, 1e-8, 1e-4, 1.999e-3, 2.001e-3, 5e-3):
        for delta in (0.0, 0.7, -2.5):
            configs.append([HALF_PI - offset, delta, HALF_PI + offset, -delta, HALF_PI - offset, delta, 0.01])
    configs.append([HALF_PI, 0.3, 1.0, 0.2, HALF_PI, -1.0, 0.0])  # mixed straight and bent
    return np.array(configs)


# ---------------------------------------------------------------- reference implementation
@pytest.mark.parametrize("index", range(8))
def test_reference_values(reference, index):
    entry = reference["mbcr"][index]
    p, R, J = ROBOT.forward_kinematics_and_jacobian(entry["q"])
    np.testing.assert_allclose(p, entry["tip_p"], atol=1e-12)
    np.testing.assert_allclose(R, entry["tip_R"], atol=1e-12)
    np.testing.assert_allclose(J, entry["J"], atol=1e-12)
    for point in entry["points"]:
        p_point, Jv = ROBOT.point_jacobian(entry["q"], point["segment"], point["fraction"])
        np.testing.assert_allclose(p_point, point["p"], atol=1e-12)
        np.testing.assert_allclose(Jv, point["Jv"], atol=1e-12)
    assert ROBOT.elastic_energy(entry["q"]) == pytest.approx(entry["elastic_energy"], rel=1e-9, abs=1e-15)
    np.testing.assert_allclose(ROBOT.elastic_energy_gradient(entry["q"]), entry["grad_elastic"], atol=1e-12)


# ---------------------------------------------------------------- finite differences
def _relative_error(J, J_fd):
    return np.abs(J - J_fd).max() / max(np.abs(J_fd).max(), 1e-12)


def test_tip_jacobian_matches_finite_differences_random():
    rng = np.random.default_rng(0)
    worst = 0.0
    for q in random_configurations(rng, 200):
        J = ROBOT.jacobian(q)
        J_fd = fd_twist_jacobian(ROBOT.forward_kinematics, q)
        worst = max(worst, _relative_error(J, J_fd))
    assert worst <= 1e-6


def test_tip_jacobian_matches_finite_differences_near_straight():
    for q in near_straight_configurations():
        J = ROBOT.jacobian(q)
        J_fd = fd_twist_jacobian(ROBOT.forward_kinematics, q)
        assert _relative_error(J, J_fd) <= 1e-6, q


def test_printed_eq4_would_fail_the_finite_difference_check():
    """The check separates the corrected S_j from the printed one (paper-notes §1.3 item 1)."""
    q = ROBOT.psi_a
    J = ROBOT.jacobian(q)
    J_fd = fd_twist_jacobian(ROBOT.forward_kinematics, q)
    # Rebuild segment 2's linear columns with the printed (g_2 - g_3)^ (no R_1): must differ by >> 1e-6.
    p_tip, _ = ROBOT.forward_kinematics(q)
    p_g2, _ = ROBOT.point_jacobian(q, 1, 1.0)
    w = J[3:, 2:4]
    R1_T_w = segment1_rotation(q).T @ w
    printed = J[:3, 2:4] - np.cross(p_g2 - p_tip, w, axis=0) + np.cross(p_g2 - p_tip, R1_T_w, axis=0)
    assert np.abs(printed - J_fd[:3, 2:4]).max() / np.abs(J_fd).max() > 1e-4


def segment1_rotation(q):
    """^wR_1, the end-disk rotation of segment 1, from a 1-segment robot with the same first segment."""
    one = q.copy()
    one[2:6] = [HALF_PI, 0.0, HALF_PI, 0.0]
    return ROBOT.forward_kinematics(one)[1]


@pytest.mark.parametrize("segment, fraction", [(0, 0.0), (0, 0.3), (1, 0.5), (2, 0.25), (2, 1.0)] + list(PAPER_PSPS))
def test_point_jacobian_matches_finite_differences(segment, fraction):
    rng = np.random.default_rng(1)
    configs = np.concatenate([random_configurations(rng, 30), near_straight_configurations()])
    for q in configs:
        _, Jv = ROBOT.point_jacobian(q, segment, fraction)
        Jv_fd = fd_gradient(lambda x: ROBOT.point_jacobian(x, segment, fraction)[0], q)
        assert np.abs(Jv - Jv_fd).max() <= 1e-6 * max(np.abs(Jv_fd).max(), 1e-3), (q, segment, fraction)


def test_elastic_gradient_matches_finite_differences():
    rng = np.random.default_rng(2)
    for q in random_configurations(rng, 20):
        np.testing.assert_allclose(ROBOT.elastic_energy_gradient(q), fd_gradient(ROBOT.elastic_energy, q),
                                   rtol=1e-7, atol=1e-12)


# ---------------------------------------------------------------- closed forms and the paper's geometry
def test_straight_robot_closed_form():
    for q_ins in (0.0, 0.013):
        q = ROBOT.straight.copy()
        q[6] = q_ins
        p, R = ROBOT.forward_kinematics(q)
        np.testing.assert_allclose(p, [0, 0, 0.065 + q_ins], atol=1e-15)
        np.testing.assert_allclose(R, np.eye(3), atol=1e-15)
    # paper-notes §1.4: rank 4 when straight (bending planes distinct; with equal deltas the bends are coplanar).
    straight = np.array([HALF_PI, 0.0, HALF_PI, 0.7, HALF_PI, -2.5, 0.0])
    assert np.linalg.matrix_rank(ROBOT.jacobian(straight), tol=1e-9) == 4
    assert np.linalg.matrix_rank(ROBOT.jacobian(ROBOT.straight), tol=1e-9) == 3


@pytest.mark.parametrize("delta", [0.0, 0.5, -2.0])
def test_single_segment_planar_bend(delta):
    """Segment 1 bent by b toward (cos d, -sin d, 0): arc of radius l/b, the others straight."""
    bend = 0.8
    l1, l2, l3 = ROBOT.lengths
    q = np.array([HALF_PI - bend, delta, HALF_PI, 0.0, HALF_PI, 0.0, 0.0])
    p, R = ROBOT.forward_kinematics(q)
    radius = l1 / bend
    u = np.array([math.cos(delta), -math.sin(delta), 0.0])
    end1 = radius * (1 - math.cos(bend)) * u + np.array([0, 0, radius * math.sin(bend)])
    axis = math.sin(bend) * u + np.array([0, 0, math.cos(bend)])
    np.testing.assert_allclose(p, end1 + (l2 + l3) * axis, atol=1e-14)
    np.testing.assert_allclose(R[:, 2], axis, atol=1e-14)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-14)


def test_quarter_circle_bend():
    """A 90-degree bend of segment 3 alone puts its tip l3 * 2/pi sideways and l3 * 2/pi up."""
    l1, l2, l3 = ROBOT.lengths
    q = np.array([HALF_PI, 0.0, HALF_PI, 0.0, 0.0, 0.0, 0.0])
    p, R = ROBOT.forward_kinematics(q)
    np.testing.assert_allclose(p, [l3 * 2 / math.pi, 0, l1 + l2 + l3 * 2 / math.pi], atol=1e-15)
    np.testing.assert_allclose(R, [[0, 0, 1], [0, 1, 0], [-1, 0, 0]], atol=1e-15)


def test_psi_a_matches_errata_description():
    """paper-notes §1.5: psi_a bends 0.589, 0.136, 0.469 rad; tip at (-14.5, 28.7, 63.3) mm."""
    np.testing.assert_allclose(ROBOT.bend_angles(ROBOT.psi_a), [0.589, 0.136, 0.469], atol=1e-3)
    p, _ = ROBOT.forward_kinematics(ROBOT.psi_a)
    np.testing.assert_allclose(p * 1e3, [-14.5, 28.7, 63.3], atol=0.05)


def test_stiffness_matches_errata():
    np.testing.assert_allclose(ROBOT.stiffness, [0.0234, 0.0304, 0.0320], atol=1e-4)


def test_backbone_samples_the_paper_way():
    q = ROBOT.psi_a
    pts = ROBOT.backbone(q)
    assert pts.shape == (5 + 3 * 40 + 1, 3)
    np.testing.assert_allclose(pts[0], 0.0)
    np.testing.assert_allclose(pts[5], [0, 0, q[6]], atol=1e-15)  # base of segment 1
    np.testing.assert_allclose(pts[-1], ROBOT.forward_kinematics(q)[0], atol=1e-15)
    np.testing.assert_allclose(pts[45], ROBOT.point_jacobian(q, 0, 1.0)[0], atol=1e-15)
    # Consecutive samples on a segment are l/40 apart along the arc, so chords are slightly shorter.
    chords = np.linalg.norm(np.diff(pts[5:46], axis=0), axis=1)
    assert np.all(chords <= ROBOT.lengths[0] / 40 + 1e-15) and np.all(chords > 0.99 * ROBOT.lengths[0] / 40)


# ---------------------------------------------------------------- batching and input checks
def test_batched_equals_looped_exactly():
    rng = np.random.default_rng(3)
    q = random_configurations(rng, 24).reshape(4, 6, 7)
    p, R, J = ROBOT.forward_kinematics_and_jacobian(q)
    P, JV = ROBOT.points_jacobians(q)
    B = ROBOT.backbone(q, n_per_segment=10)
    assert p.shape == (4, 6, 3) and R.shape == (4, 6, 3, 3) and J.shape == (4, 6, 6, 7)
    assert P.shape == (4, 6, 10, 3) and JV.shape == (4, 6, 10, 3, 7) and B.shape == (4, 6, 36, 3)
    for idx in np.ndindex(4, 6):
        p1, R1, J1 = ROBOT.forward_kinematics_and_jacobian(q[idx])
        assert np.array_equal(p1, p[idx]) and np.array_equal(R1, R[idx]) and np.array_equal(J1, J[idx])
        P1, JV1 = ROBOT.points_jacobians(q[idx])
        assert np.array_equal(P1, P[idx]) and np.array_equal(JV1, JV[idx])
        assert np.array_equal(ROBOT.backbone(q[idx], n_per_segment=10), B[idx])


def test_single_configuration_gives_unbatched_shapes():
    p, R = ROBOT.forward_kinematics(ROBOT.psi_a)
    assert p.shape == (3,) and R.shape == (3, 3)
    assert ROBOT.elastic_energy(ROBOT.psi_a).shape == ()


@pytest.mark.parametrize("bad", [np.zeros(6), np.zeros((2, 8)), 1.0, [1, 2, "x", 4, 5, 6, 7]])
def test_wrong_shapes_raise(bad):
    with pytest.raises(ValueError, match="q"):
        ROBOT.forward_kinematics(bad)


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_non_finite_raises(value):
    q = ROBOT.psi_a.copy()
    q[3] = value
    for call in (ROBOT.forward_kinematics, ROBOT.jacobian, ROBOT.backbone, ROBOT.elastic_energy):
        with pytest.raises(ValueError, match="finite"):
            call(q)
    with pytest.raises(ValueError, match="finite"):
        ROBOT.forward_kinematics(np.stack([ROBOT.psi_a, q]))


@pytest.mark.parametrize("kwargs, name", [
    ({"lengths": (0.026, 0.0, 0.019)}, "lengths"),
    ({"lengths": (0.026, -0.01, 0.019)}, "lengths"),
    ({"lengths": ()}, "lengths"),
    ({"lengths": (0.02,) * 5}, "lengths"),
    ({"youngs_modulus": 0.0}, "youngs_modulus"),
    ({"primary_diameter": -1e-3}, "primary_diameter"),
])
def test_bad_geometry_raises(kwargs, name):
    with pytest.raises(ValueError, match=name):
        MultiBackboneRobot(**kwargs)


@pytest.mark.parametrize("segment, fraction", [(3, 0.5), (-1, 0.5), (0, 1.5), (1, -0.1)])
def test_bad_point_spec_raises(segment, fraction):
    with pytest.raises(ValueError, match="segment|fraction"):
        ROBOT.point_jacobian(ROBOT.psi_a, segment, fraction)


def test_kinematics_accepts_configurations_beyond_any_limit():
    q = np.array([HALF_PI - 3.0, 10.0, HALF_PI + 2.5, -7.0, -1.0, 0.0, -0.5])
    J = ROBOT.jacobian(q)
    assert np.all(np.isfinite(J))
    assert _relative_error(J, fd_twist_jacobian(ROBOT.forward_kinematics, q)) <= 1e-6


def test_the_single_configuration_path_equals_the_batch_path():
    """One C-contiguous float64 q takes a kernel of its own (no bundle unboxing); same bits as a batch."""
    from continuum_gym.robots import MultiBackboneRobot

    robot = MultiBackboneRobot()
    qs = np.random.default_rng(3).uniform(-1, 1, (5, 7)) * [1.5, 3, 1.5, 3, 1.5, 3, 0.02]
    p_batch, R_batch, J_batch = robot.forward_kinematics_and_jacobian(qs)
    for k, q in enumerate(qs):
        p, R, J = robot.forward_kinematics_and_jacobian(np.ascontiguousarray(q))
        assert np.array_equal(p, p_batch[k]) and np.array_equal(R, R_batch[k]) and np.array_equal(J, J_batch[k])
        p_list, _, _ = robot.forward_kinematics_and_jacobian(list(q))  # not an array: the general path
        assert np.array_equal(p_list, p)
    bad = qs[0].copy()
    bad[3] = np.nan
    with pytest.raises(ValueError, match="finite"):
        robot.forward_kinematics_and_jacobian(bad)


@pytest.mark.parametrize("lengths", [(0.03,), (0.02, 0.02, 0.02), (0.02, 0.018, 0.016, 0.014)])
def test_positions_only_equal_the_jacobian_kernels_positions_bit_for_bit(lengths):
    """``points`` (no Jacobians) is the hold-start search's path; it must give exactly the positions of
    ``points_jacobians``, for robots of 1-4 segments, any batch shape, and refuse NaN naming q."""
    robot = MultiBackboneRobot(lengths=lengths)
    n_segments = robot.n_segments
    rng = np.random.default_rng(n_segments)
    q = np.empty((2, 5, robot.dof))
    q[..., 0:2 * n_segments:2] = math.pi / 2 - rng.uniform(0.05, 1.2, (2, 5, n_segments))
    q[..., 1:2 * n_segments:2] = rng.uniform(-math.pi, math.pi, (2, 5, n_segments))
    q[..., 2 * n_segments] = rng.uniform(0.0, 0.02, (2, 5))
    points = [(k, f) for k in range(n_segments) for f in (0.0, 0.35, 1.0)]
    P, _ = robot.points_jacobians(q, points)
    np.testing.assert_array_equal(robot.points(q, points), P)
    assert robot.points(q[0, 0], points).shape == (len(points), 3)
    q[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match="q"):
        robot.points(q, points)
