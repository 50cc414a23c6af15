"""Rigid 30° da Vinci endoscope of paper 001 (paper-notes §2.2, §2.3 item 1)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from continuum_gym.robots.davinci import ALPHA_CONVENTIONS, DaVinciEndoscope
from tests.conftest import load_reference

DAVINCI_REF = load_reference()["davinci"]


@pytest.fixture(scope="module")
def robot():
    return DaVinciEndoscope()


def _random_configurations(rng, n, wide=False):
    scale = 3.0 if wide else 1.0
    low = np.array([0.0, -np.pi / 3, -np.pi / 3, -np.pi]) * scale
    high = np.array([0.1, np.pi / 3, np.pi / 3, np.pi]) * scale
    return rng.uniform(low, high, size=(n, 4))


def _rx(a):
    return Rotation.from_rotvec([a, 0.0, 0.0]).as_matrix()


def _stem(q):
    """Ry(yaw) Rx(pitch) Rz(roll), intrinsic y-x-z."""
    q = np.asarray(q)
    return Rotation.from_euler("YXZ", q[..., 1:].reshape(-1, 3)).as_matrix().reshape(q.shape[:-1] + (3, 3))


@pytest.mark.parametrize("index", range(len(DAVINCI_REF)))
def test_reference_values(robot, index):
    entry = DAVINCI_REF[index]
    p, R = robot.forward_kinematics(entry["q"])
    np.testing.assert_allclose(p, entry["camera_p"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(R, entry["camera_R"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(robot.target_point(entry["q"]), entry["target_p"], rtol=1e-9, atol=1e-12)
    p_t, R_t = robot.target_pose(entry["q"])
    np.testing.assert_allclose(p_t, entry["target_p"], rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(R_t, R)


@pytest.mark.parametrize("convention", ALPHA_CONVENTIONS)
def test_optical_axis_points_at_target(convention):
    """paper-notes §2.3 item 1: R_dVt e3 == (p_dVt - cam) / Le (the printed eq 1 is off by ~1)."""
    robot = DaVinciEndoscope(alpha_convention=convention)
    Q = _random_configurations(np.random.default_rng(1), 500, wide=True)
    p, R = robot.forward_kinematics(Q)
    p_t, R_t = robot.target_pose(Q)
    np.testing.assert_array_equal(R, R_t)
    np.testing.assert_allclose(R[..., :, 2], (p_t - p) / robot.Le, rtol=0, atol=1e-15)


@pytest.mark.parametrize("convention", ALPHA_CONVENTIONS)
def test_against_rotation_composition(convention):
    """Camera = R3 [0, 0, L_dV]; R = R3 Rx(-alpha) ("eq2") or R3 Rx(+alpha) ("eq1"); target per eq (2)."""
    robot = DaVinciEndoscope(alpha_convention=convention)
    sign = 1.0 if convention == "eq2" else -1.0
    alpha = robot.alpha
    Q = _random_configurations(np.random.default_rng(2), 100, wide=True)
    R3 = _stem(Q)
    p, R = robot.forward_kinematics(Q)
    np.testing.assert_allclose(p, R3[..., :, 2] * Q[:, :1], atol=1e-15)
    np.testing.assert_allclose(R, R3 @ _rx(-sign * alpha), atol=1e-15)
    u = robot.Le * np.array([0.0, sign * np.sin(alpha), np.cos(alpha)])
    np.testing.assert_allclose(robot.target_point(Q), p + R3 @ u, atol=1e-15)
    np.testing.assert_allclose(robot.stem_rotation(Q), R3, atol=1e-15)


def test_closed_forms(robot):
    L, a, Le = 0.065, np.pi / 6, 0.12
    p, R = robot.forward_kinematics([L, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(p, [0.0, 0.0, L])
    np.testing.assert_allclose(R, _rx(-a), atol=1e-16)
    np.testing.assert_allclose(
        robot.target_point([L, 0.0, 0.0, 0.0]), [0.0, Le * np.sin(a), L + Le * np.cos(a)], atol=1e-16
    )
    # yaw swings the stem in the x-z plane; pitch (about x_dV1) tips it toward -y
    yaw = 0.4
    p, _ = robot.forward_kinematics([L, yaw, 0.0, 0.0])
    np.testing.assert_allclose(p, [L * np.sin(yaw), 0.0, L * np.cos(yaw)], atol=1e-16)
    pitch = 0.3
    p, _ = robot.forward_kinematics([L, 0.0, pitch, 0.0])
    np.testing.assert_allclose(p, [0.0, -L * np.sin(pitch), L * np.cos(pitch)], atol=1e-16)
    # roll spins the view about the stem: the camera stays put, the target circles the stem
    p0, _ = robot.forward_kinematics([L, 0.0, 0.0, 0.0])
    p1, _ = robot.forward_kinematics([L, 0.0, 0.0, np.pi])
    np.testing.assert_allclose(p1, p0, atol=1e-16)
    np.testing.assert_allclose(
        robot.target_point([L, 0.0, 0.0, np.pi]), [0.0, -Le * np.sin(a), L + Le * np.cos(a)], atol=1e-16
    )


def test_zero_degree_endoscope_looks_along_the_stem():
    robot = DaVinciEndoscope(alpha=0.0)
    Q = _random_configurations(np.random.default_rng(3), 20)
    p, R = robot.forward_kinematics(Q)
    np.testing.assert_allclose(R, _stem(Q), atol=1e-15)
    np.testing.assert_allclose(robot.target_point(Q), p * (1 + robot.Le / Q[:, :1]), rtol=1e-12)


def test_rotations_are_orthonormal(robot):
    Q = _random_configurations(np.random.default_rng(4), 200, wide=True)
    _, R = robot.forward_kinematics(Q)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-15)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-15)


def test_batch_equals_looped_single_calls(robot):
    Q = _random_configurations(np.random.default_rng(5), 20, wide=True).reshape(4, 5, 4)
    p, R = robot.forward_kinematics(Q)
    p_t, R_t = robot.target_pose(Q)
    p_point = robot.target_point(Q)
    R3 = robot.stem_rotation(Q)
    assert p.shape == p_t.shape == p_point.shape == (4, 5, 3)
    assert R.shape == R_t.shape == R3.shape == (4, 5, 3, 3)
    for i in range(4):
        for j in range(5):
            q = Q[i, j]
            assert all(np.array_equal(a[i, j], b) for a, b in zip((p, R), robot.forward_kinematics(q)))
            assert all(np.array_equal(a[i, j], b) for a, b in zip((p_t, R_t), robot.target_pose(q)))
            assert np.array_equal(p_point[i, j], robot.target_point(q))
            assert np.array_equal(R3[i, j], robot.stem_rotation(q))
    assert robot.forward_kinematics(np.zeros((0, 4)))[1].shape == (0, 3, 3)


def test_parameters_limits_and_named_configurations(robot):
    assert robot.alpha == np.pi / 6 and robot.Le == 0.120 and robot.alpha_convention == "eq2"
    lower, upper = robot.joint_limits
    np.testing.assert_array_equal(lower, [0.0, -np.pi / 3, -np.pi / 3, -np.pi])
    np.testing.assert_array_equal(upper, [0.1, np.pi / 3, np.pi / 3, np.pi])
    np.testing.assert_array_equal(robot.straight, np.zeros(4))
    np.testing.assert_array_equal(robot.home, [0.065, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(robot.case1, [0.06088, 0.5, -0.4, 0.0])
    np.testing.assert_array_equal(robot.case2, [0.0625, -0.9, 0.7, 0.0])
    assert set(robot.named_configurations) == {"straight", "home", "case1", "case2"}
    custom = DaVinciEndoscope(alpha=0.2, Le=0.1)
    p_t = custom.target_point([0.05, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(p_t, [0.0, 0.1 * np.sin(0.2), 0.05 + 0.1 * np.cos(0.2)], atol=1e-16)


@pytest.mark.parametrize("value", [0.0, -0.1, np.nan, np.inf, "far"])
def test_bad_view_distance_raises(value):
    with pytest.raises(ValueError, match="Le"):
        DaVinciEndoscope(Le=value)


@pytest.mark.parametrize("value", [np.pi / 2, -2.0, np.nan, np.inf, None])
def test_bad_alpha_raises(value):
    with pytest.raises(ValueError, match="alpha"):
        DaVinciEndoscope(alpha=value)


@pytest.mark.parametrize("value", ["eq3", "EQ2", "", None, 2])
def test_bad_alpha_convention_lists_valid_values(value):
    with pytest.raises(ValueError, match="alpha_convention") as info:
        DaVinciEndoscope(alpha_convention=value)
    assert "'eq1'" in str(info.value) and "'eq2'" in str(info.value)


@pytest.mark.parametrize(
    "q",
    [np.zeros(3), np.zeros((2, 6)), 0.1, [0.05, np.nan, 0.0, 0.0], [[0.05, 0.0, np.inf, 0.0]], "q"],
)
@pytest.mark.parametrize("method", ["forward_kinematics", "target_pose", "target_point", "stem_rotation"])
def test_bad_configurations_raise(robot, q, method):
    with pytest.raises(ValueError, match=r"\bq\b"):
        getattr(robot, method)(q)


@pytest.mark.parametrize("convention", ["eq2", "eq1"])
def test_configuration_of_inverts_target_pose(convention):
    """Round trip over the joint ranges (roll all the way round), for both conventions and another alpha."""
    rng = np.random.default_rng(7)
    q = np.stack([rng.uniform(0.0, 0.1, 500), rng.uniform(-np.pi / 3, np.pi / 3, 500),
                  rng.uniform(-np.pi / 3, np.pi / 3, 500), rng.uniform(-np.pi + 1e-9, np.pi, 500)], axis=1)
    for alpha in (np.pi / 6, -0.4):
        robot = DaVinciEndoscope(alpha=alpha, alpha_convention=convention)
        p, R = robot.target_pose(q)
        np.testing.assert_allclose(robot.configuration_of(p, R), q, atol=1e-12, rtol=0)
        np.testing.assert_allclose(robot.configuration_of(p[3], R[3]), q[3], atol=1e-12, rtol=0)


def test_configuration_of_rejects_bad_shapes():
    robot = DaVinciEndoscope()
    p, R = robot.target_pose(robot.home)
    with pytest.raises(ValueError, match="p_target must be"):
        robot.configuration_of(p[:2], R)
    with pytest.raises(ValueError, match="finite"):
        robot.configuration_of(p * np.nan, R)
