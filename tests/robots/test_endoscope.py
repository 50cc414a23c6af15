"""Continuum endoscope of paper 001 (paper-notes §2): reference values, finite differences, closed forms."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from continuum_gym.robots.endoscope import (
    SERIES_THRESHOLD,
    ContinuumEndoscope,
    endoscope_segment_jacobian,
    endoscope_segment_pose,
)
from tests.conftest import load_reference

ROOT = Path(__file__).resolve().parents[2]
ENDOSCOPE_REF = load_reference()["endoscope"]


@pytest.fixture(scope="module")
def robot():
    return ContinuumEndoscope()


def _random_configurations(rng, n, wide=False):
    """Within the joint limits (deltas over a full turn) or, if ``wide``, far outside them."""
    if wide:
        low = [-0.05, -2 * np.pi, -3.0, -2 * np.pi, -3.0, -2 * np.pi]
        high = [0.15, 2 * np.pi, 3.0, 2 * np.pi, 3.0, 2 * np.pi]
    else:
        low = [0.0, -np.pi, 0.0, -np.pi, 0.0, -np.pi]
        high = [0.1, np.pi, np.pi / 4, np.pi, np.pi / 2, np.pi]
    return rng.uniform(low, high, size=(n, 6))


def _fd_jacobian(robot, Q, h=1e-6):
    """Central differences of the target pose: v = dp_ct/dq, w = log(R(q+h) R(q-h)^T) / 2h."""
    n = Q.shape[0]
    step = h * np.eye(6)
    p_plus, R_plus = robot.target_pose(Q[:, None, :] + step)
    p_minus, R_minus = robot.target_pose(Q[:, None, :] - step)
    v = (p_plus - p_minus) / (2 * h)  # (n, joint, 3)
    dR = R_plus @ np.swapaxes(R_minus, -1, -2)
    w = Rotation.from_matrix(dR.reshape(-1, 3, 3)).as_rotvec().reshape(n, 6, 3) / (2 * h)
    return np.swapaxes(np.concatenate([v, w], axis=-1), -1, -2)


def _relative_errors(J, J_fd):
    return np.linalg.norm(J - J_fd, axis=(-2, -1)) / np.linalg.norm(J, axis=(-2, -1))


def _column_errors(J, J_fd):
    """Per column: |error| / (|column| + 1e-3); the floor covers columns that vanish (e.g. at straight)."""
    return np.linalg.norm(J - J_fd, axis=-2) / (np.linalg.norm(J, axis=-2) + 1e-3)


# ---------------------------------------------------------------------------------------------
# reference values of the independent implementation
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("index", range(len(ENDOSCOPE_REF)))
def test_reference_values(robot, index):
    entry = ENDOSCOPE_REF[index]
    q = np.array(entry["q"])
    p, R = robot.forward_kinematics(q)
    np.testing.assert_allclose(p, entry["camera_p"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(R, entry["camera_R"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(robot.target_point(q), entry["target_point"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(robot.jacobian(q), entry["J_target_point"], rtol=1e-9, atol=1e-12)


# ---------------------------------------------------------------------------------------------
# Jacobian (eq 9 corrected) against finite differences of the forward kinematics
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("wide", [False, True], ids=["within-limits", "any-finite-q"])
def test_jacobian_matches_finite_differences(robot, wide):
    Q = _random_configurations(np.random.default_rng(20240601 + wide), 300, wide=wide)
    J = robot.jacobian(Q)
    J_fd = _fd_jacobian(robot, Q)
    assert _relative_errors(J, J_fd).max() <= 1e-6
    assert _column_errors(J, J_fd).max() <= 1e-6


@pytest.mark.parametrize("theta", [0.0, 1e-4, 1e-3, SERIES_THRESHOLD, 2.5e-3, -1e-3])
def test_jacobian_near_straight(robot, theta):
    rng = np.random.default_rng(7)
    Q = _random_configurations(rng, 40)
    Q[:20, 2] = theta  # segment 1 (nearly) straight
    Q[10:30, 4] = theta  # segment 2 (nearly) straight; rows 10-19 both
    J = robot.jacobian(Q)
    assert np.all(np.isfinite(J))
    J_fd = _fd_jacobian(robot, Q)
    assert _relative_errors(J, J_fd).max() <= 1e-6
    assert _column_errors(J, J_fd).max() <= 1e-6


def test_jacobian_at_joint_limits(robot):
    lower, upper = robot.joint_limits
    q_low = np.where(np.isfinite(lower), lower, 0.3)
    q_high = np.where(np.isfinite(upper), upper, -2.0)
    Q = np.stack([q_low, q_high, robot.straight, robot.home])
    J_fd = _fd_jacobian(robot, Q)
    assert _relative_errors(robot.jacobian(Q), J_fd).max() <= 1e-6


def test_series_branch_is_continuous(robot):
    """Closed form and series of paper-notes §2.2 meet at the threshold."""
    eps = 1e-12
    q = robot.home
    below, above = q.copy(), q.copy()
    below[[2, 4]] = SERIES_THRESHOLD * (1 - eps)
    above[[2, 4]] = SERIES_THRESHOLD * (1 + eps)
    for f in (robot.target_point, robot.jacobian):
        np.testing.assert_allclose(f(below), f(above), rtol=0, atol=1e-13)


def test_matches_plain_numpy_reference(robot):
    spec = importlib.util.spec_from_file_location(
        "numpy_reference_endoscope", ROOT / "benchmarks" / "numpy_reference_endoscope.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    Q = np.concatenate(
        [_random_configurations(np.random.default_rng(3), 25, wide=True), [robot.straight, robot.home]]
    )
    for q in Q:
        expected = module.endoscope_fk_jacobian_numpy(q, robot)
        for got, want in zip(robot.fk_jacobian(q), expected):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-14)


def test_segment_jacobian_matches_finite_differences():
    """Eqs (5), (6) as printed against central differences of eqs (3), (4) (paper-notes §2.8)."""
    rng = np.random.default_rng(11)
    theta = np.concatenate([rng.uniform(-2.5, 2.5, 50), [0.0, 1e-4, 1e-3, 2.5e-3]])
    delta = rng.uniform(-np.pi, np.pi, theta.shape)
    length = 0.03
    h = 1e-6
    J = endoscope_segment_jacobian(theta, delta, length)
    columns = []
    for dt, dd in ((h, 0.0), (0.0, h)):
        p_plus, R_plus = endoscope_segment_pose(theta + dt, delta + dd, length)
        p_minus, R_minus = endoscope_segment_pose(theta - dt, delta - dd, length)
        w = Rotation.from_matrix(R_plus @ np.swapaxes(R_minus, -1, -2)).as_rotvec()
        columns.append(np.concatenate([p_plus - p_minus, w], axis=-1) / (2 * h))
    J_fd = np.stack(columns, axis=-1)
    np.testing.assert_allclose(J, J_fd, rtol=0, atol=1e-8)


# ---------------------------------------------------------------------------------------------
# closed forms
# ---------------------------------------------------------------------------------------------
def test_straight_closed_form(robot):
    L0 = 0.037
    q = np.array([L0, 0.0, 0.0, 0.4, 0.0, -1.1])  # deltas do not matter when straight
    p, R = robot.forward_kinematics(q)
    total = L0 + robot.L1 + robot.Lm + robot.L2 + robot.Lc
    np.testing.assert_allclose(p, [0.0, 0.0, total], rtol=0, atol=1e-16)
    np.testing.assert_allclose(R, np.eye(3), rtol=0, atol=1e-16)
    np.testing.assert_allclose(robot.target_point(q), [0.0, 0.0, total + robot.Le], atol=1e-16)
    p0, R0 = robot.forward_kinematics(robot.straight)
    np.testing.assert_allclose(p0, [0.0, 0.0, total - L0], atol=1e-16)
    np.testing.assert_array_equal(R0, np.eye(3))
    # phi only rolls the camera about z_w
    phi = 0.7
    _, R_phi = robot.forward_kinematics([L0, phi, 0.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(R_phi, Rotation.from_rotvec([0, 0, phi]).as_matrix(), atol=1e-15)


def test_segment_one_quarter_bend_closed_form(robot):
    """theta1 = pi/2 toward +x (delta1 = 0): a quarter circle of radius r = 2 L1 / pi."""
    L0 = 0.01
    r = robot.L1 / (np.pi / 2)
    p, R = robot.forward_kinematics([L0, 0.0, np.pi / 2, 0.0, 0.0, 0.0])
    reach = robot.Lm + robot.L2 + robot.Lc
    np.testing.assert_allclose(p, [r + reach, 0.0, L0 + r], rtol=0, atol=1e-15)
    Ry90 = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    np.testing.assert_allclose(R, Ry90, rtol=0, atol=1e-15)
    np.testing.assert_allclose(
        robot.target_point([L0, 0.0, np.pi / 2, 0.0, 0.0, 0.0]),
        [r + reach + robot.Le, 0.0, L0 + r],
        atol=1e-15,
    )
    # delta1 = pi/2: the bending direction (cos d, -sin d, 0) is -y
    p, R = robot.forward_kinematics([L0, 0.0, np.pi / 2, np.pi / 2, 0.0, 0.0])
    np.testing.assert_allclose(p, [0.0, -(r + reach), L0 + r], rtol=0, atol=1e-15)
    np.testing.assert_allclose(R[:, 2], [0.0, -1.0, 0.0], atol=1e-15)


def test_segment_two_half_bend_closed_form(robot):
    """theta2 = pi, delta2 = 0: segment 2 is a half circle of radius L2 / pi; the camera looks back down."""
    r = robot.L2 / np.pi
    base = robot.L1 + robot.Lm
    p, R = robot.forward_kinematics([0.0, 0.0, 0.0, 0.0, np.pi, 0.0])
    np.testing.assert_allclose(p, [2 * r, 0.0, base - robot.Lc], rtol=0, atol=1e-15)
    np.testing.assert_allclose(R, np.diag([-1.0, 1.0, -1.0]), atol=1e-15)


def test_s_shape_restores_orientation(robot):
    """Equal and opposite bends (delta2 = delta1 + pi) leave the camera parallel to the stem."""
    q = np.array([0.02, 0.3, 0.6, -0.4, 0.6, -0.4 + np.pi])
    _, R = robot.forward_kinematics(q)
    np.testing.assert_allclose(R, Rotation.from_rotvec([0, 0, 0.3]).as_matrix(), atol=1e-15)


def test_rotations_are_orthonormal(robot):
    Q = _random_configurations(np.random.default_rng(5), 200, wide=True)
    _, R = robot.forward_kinematics(Q)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-14)


def test_camera_and_target_on_viewing_axis(robot):
    Q = _random_configurations(np.random.default_rng(6), 50, wide=True)
    p, R = robot.forward_kinematics(Q)
    p_ct, R_ct = robot.target_pose(Q)
    np.testing.assert_array_equal(R, R_ct)
    np.testing.assert_allclose(p_ct, p + robot.Le * R[..., :, 2], rtol=0, atol=1e-15)


def test_backbone(robot):
    m = 7
    Q = _random_configurations(np.random.default_rng(8), 10, wide=True)
    pts = robot.backbone(Q, n_per_segment=m)
    assert pts.shape == (10, 2 * m + 4, 3)
    np.testing.assert_array_equal(pts[:, 0], 0.0)
    np.testing.assert_array_equal(pts[:, 1], np.stack([0 * Q[:, 0], 0 * Q[:, 0], Q[:, 0]], axis=-1))
    p_cam, _ = robot.forward_kinematics(Q)
    np.testing.assert_allclose(pts[:, -1], p_cam, rtol=0, atol=1e-15)
    # constant curvature: equal chords along each segment, Lm between {1e} and {2b}
    chords = np.linalg.norm(np.diff(pts, axis=1), axis=-1)
    seg1 = chords[:, 1 : m + 1]  # {1b} -> first sample ... -> {1e}
    seg2 = chords[:, m + 2 : 2 * m + 2]
    np.testing.assert_allclose(seg1, seg1[:, :1] * np.ones(m), rtol=1e-12)
    np.testing.assert_allclose(seg2, seg2[:, :1] * np.ones(m), rtol=1e-12)
    np.testing.assert_allclose(chords[:, m + 1], robot.Lm, rtol=1e-12)
    np.testing.assert_allclose(chords[:, -1], robot.Lc, rtol=1e-12)
    straight = robot.backbone(robot.straight, n_per_segment=4)
    assert straight.shape == (12, 3)
    np.testing.assert_allclose(straight[:, :2], 0.0, atol=0)
    assert np.all(np.diff(straight[:, 2]) >= 0)
    with pytest.raises(ValueError, match="n_per_segment"):
        robot.backbone(robot.home, n_per_segment=0)


# ---------------------------------------------------------------------------------------------
# batching, parameters, limits, input checks
# ---------------------------------------------------------------------------------------------
def test_batch_equals_looped_single_calls(robot):
    Q = _random_configurations(np.random.default_rng(9), 20, wide=True).reshape(4, 5, 6)
    Q[0, 0, [2, 4]] = 0.0
    Q[0, 1, [2, 4]] = 1e-3
    batched = {
        "forward_kinematics": robot.forward_kinematics(Q),
        "target_pose": robot.target_pose(Q),
        "target_point": (robot.target_point(Q),),
        "jacobian": (robot.jacobian(Q),),
        "fk_jacobian": robot.fk_jacobian(Q),
        "backbone": (robot.backbone(Q, n_per_segment=5),),
    }
    expected_shapes = {"forward_kinematics": [(3,), (3, 3)], "target_pose": [(3,), (3, 3)],
                       "target_point": [(3,)], "jacobian": [(6, 6)],
                       "fk_jacobian": [(3,), (3, 3), (3,), (6, 6)], "backbone": [(14, 3)]}
    for name, outputs in batched.items():
        for out, tail in zip(outputs, expected_shapes[name]):
            assert out.shape == (4, 5) + tail, name
    for i in range(4):
        for j in range(5):
            single = {
                "forward_kinematics": robot.forward_kinematics(Q[i, j]),
                "target_pose": robot.target_pose(Q[i, j]),
                "target_point": (robot.target_point(Q[i, j]),),
                "jacobian": (robot.jacobian(Q[i, j]),),
                "fk_jacobian": robot.fk_jacobian(Q[i, j]),
                "backbone": (robot.backbone(Q[i, j], n_per_segment=5),),
            }
            for name, outputs in single.items():
                for a, b in zip(batched[name], outputs):
                    assert np.array_equal(a[i, j], b), name
    # the combined call equals the individual ones
    p, R, p_ct, J = batched["fk_jacobian"]
    assert np.array_equal(p, batched["forward_kinematics"][0])
    assert np.array_equal(R, batched["forward_kinematics"][1])
    assert np.array_equal(p_ct, batched["target_point"][0])
    assert np.array_equal(J, batched["jacobian"][0])


def test_large_batch_equals_single_calls(robot):
    Q = _random_configurations(np.random.default_rng(10), 4096, wide=True)
    p, R, p_ct, J = robot.fk_jacobian(Q)
    for k in [0, 1, 2, 3, 7, 100, 2047, 4093, 4094, 4095]:
        for a, b in zip((p, R, p_ct, J), robot.fk_jacobian(Q[k])):
            assert np.array_equal(a[k], b)


def test_input_layouts(robot):
    """Lists, non-contiguous and read-only arrays, and empty batches are accepted."""
    Q = _random_configurations(np.random.default_rng(12), 6)
    expected = robot.jacobian(Q)
    np.testing.assert_array_equal(robot.jacobian(Q.tolist()), expected)
    wide = np.zeros((6, 12))
    wide[:, ::2] = Q
    np.testing.assert_array_equal(robot.jacobian(wide[:, ::2]), expected)
    frozen = Q.copy()
    frozen.flags.writeable = False
    np.testing.assert_array_equal(robot.jacobian(frozen), expected)
    np.testing.assert_array_equal(robot.jacobian(Q.T.copy().T), expected)
    assert robot.jacobian(np.zeros((0, 6))).shape == (0, 6, 6)
    assert robot.forward_kinematics(np.zeros((2, 0, 6)))[1].shape == (2, 0, 3, 3)


def test_parameters_limits_and_named_configurations():
    robot = ContinuumEndoscope(L1=0.025, Lm=0.005, L2=0.035, Lc=0.01, Le=0.1)
    assert (robot.L1, robot.Lm, robot.L2, robot.Lc, robot.Le) == (0.025, 0.005, 0.035, 0.01, 0.1)
    p, _ = robot.forward_kinematics([0.01, 0, 0, 0, 0, 0])
    np.testing.assert_allclose(p, [0, 0, 0.01 + 0.025 + 0.005 + 0.035 + 0.01], atol=1e-16)
    lower, upper = robot.joint_limits
    assert lower.shape == upper.shape == (6,)
    np.testing.assert_array_equal(lower, [0.0, -np.pi, 0.0, -np.inf, 0.0, -np.inf])
    np.testing.assert_array_equal(upper, [0.1, np.pi, np.pi / 4, np.inf, np.pi / 2, np.inf])
    lower[0] = 5.0  # a copy: the robot is not changed
    assert robot.joint_limits[0][0] == 0.0
    np.testing.assert_array_equal(robot.straight, np.zeros(6))
    psi0 = [0.008, 0.0, 0.3857, -1.57, 0.7828, 1.57]
    np.testing.assert_array_equal(robot.home, psi0)
    np.testing.assert_array_equal(robot.case_study_start, psi0)
    assert set(robot.named_configurations) == {"straight", "home", "case_study_start"}
    assert np.all((robot.home >= robot.joint_limits[0]) & (robot.home <= robot.joint_limits[1]))
    default = ContinuumEndoscope()
    assert (default.L1, default.Lm, default.L2, default.Lc, default.Le) == (0.020, 0.006, 0.030, 0.020, 0.120)


@pytest.mark.parametrize("name", ["L1", "Lm", "L2", "Lc", "Le"])
@pytest.mark.parametrize("value", [0.0, -0.01, np.nan, np.inf, "long"])
def test_bad_lengths_raise(name, value):
    with pytest.raises(ValueError, match=name):
        ContinuumEndoscope(**{name: value})


@pytest.mark.parametrize(
    "q",
    [
        np.zeros(5),
        np.zeros((3, 7)),
        np.float64(0.1),
        [0.0, 0.0, np.nan, 0.0, 0.0, 0.0],
        [[0.0] * 6, [0.0, np.inf, 0.0, 0.0, 0.0, 0.0]],
        [0.0, 0.0, 0.0, 0.0, 0.0, -np.inf],
        "not a configuration",
    ],
)
@pytest.mark.parametrize(
    "method", ["forward_kinematics", "target_point", "target_pose", "jacobian", "fk_jacobian", "backbone"]
)
def test_bad_configurations_raise(robot, q, method):
    with pytest.raises(ValueError, match=r"\bq\b"):
        getattr(robot, method)(q)


def test_segment_functions_reject_bad_input():
    with pytest.raises(ValueError, match="length"):
        endoscope_segment_pose(0.1, 0.0, 0.0)
    with pytest.raises(ValueError, match="theta"):
        endoscope_segment_jacobian(np.nan, 0.0, 0.02)


def test_the_single_configuration_path_equals_the_batch_path():
    """One C-contiguous float64 q takes a kernel of its own (no bundle unboxing); same bits as a batch."""
    from continuum_gym.robots import ContinuumEndoscope

    endo = ContinuumEndoscope()
    qs = np.random.default_rng(4).uniform(0.1, 1.0, (4, 6))
    batch = endo.fk_jacobian(qs)
    for k, q in enumerate(qs):
        single = endo.fk_jacobian(np.ascontiguousarray(q))
        for a, b in zip(single, batch):
            assert np.array_equal(a, b[k])
        p, R = endo.forward_kinematics(np.ascontiguousarray(q))
        assert np.array_equal(p, batch[0][k]) and np.array_equal(R, batch[1][k])
    bad = qs[0].copy()
    bad[0] = np.inf
    with pytest.raises(ValueError, match="finite"):
        endo.fk_jacobian(bad)
