"""Multi-backbone robots with 1, 2 and 4 segments, verified the way the paper's 3-segment robot is."""

from __future__ import annotations

import math

import numpy as np
import pytest

from continuum_gym.geometry import (
    ForceField,
    LensCone,
    occlusion_details,
    potential_gradient,
    repulsive_force,
)
from continuum_gym.robots import MultiBackboneRobot
from continuum_gym.robots.mbcr import default_psps
from tests.conftest import fd_twist_jacobian

ROBOTS = {1: MultiBackboneRobot(lengths=(0.03,)),
          2: MultiBackboneRobot(lengths=(0.028, 0.022), backbone_stiffness=(0.02, 0.03)),
          4: MultiBackboneRobot(lengths=(0.02, 0.018, 0.016, 0.014))}


def _configurations(robot, rng, count=6):
    n = robot.n_segments
    random = np.empty((count, robot.dof))
    random[:, 0:2 * n:2] = math.pi / 2 - rng.uniform(-1.2, 1.2, (count, n))
    random[:, 1:2 * n:2] = rng.uniform(-math.pi, math.pi, (count, n))
    random[:, -1] = rng.uniform(0.0, 0.02, count)
    straight = robot.straight + np.r_[np.tile([0.0, 0.4], n), 0.005]  # exactly straight, planes set
    return np.vstack([random, straight])


@pytest.mark.parametrize("n", sorted(ROBOTS))
def test_dof_joint_names_and_straight_pose(n):
    robot = ROBOTS[n]
    assert robot.dof == 2 * n + 1 and len(robot.joint_names) == robot.dof
    p, R = robot.forward_kinematics(robot.straight)
    np.testing.assert_allclose(p, [0.0, 0.0, sum(robot.lengths)], atol=1e-15)
    np.testing.assert_allclose(R, np.eye(3), atol=1e-15)


@pytest.mark.parametrize("n", sorted(ROBOTS))
def test_tip_jacobian_matches_finite_differences_random_and_straight(n):
    robot = ROBOTS[n]
    for q in _configurations(robot, np.random.default_rng(n)):
        J = robot.jacobian(q)
        J_fd = fd_twist_jacobian(robot.forward_kinematics, q)
        assert np.max(np.abs(J - J_fd)) <= 2e-9 * max(1.0, np.max(np.abs(J)))


@pytest.mark.parametrize("n", sorted(ROBOTS))
def test_body_point_jacobians_match_finite_differences(n):
    robot = ROBOTS[n]
    points = [(s, f) for s in range(n) for f in (0.0, 0.3, 0.75, 1.0)]
    for q in _configurations(robot, np.random.default_rng(10 + n), 3):
        _, JV = robot.points_jacobians(q, points)
        h = 1e-6
        for k in range(robot.dof):
            dq = np.zeros(robot.dof)
            dq[k] = h
            plus, _ = robot.points_jacobians(q + dq, points)
            minus, _ = robot.points_jacobians(q - dq, points)
            np.testing.assert_allclose(JV[:, :, k], (plus - minus) / (2 * h), atol=2e-8)


@pytest.mark.parametrize("n", sorted(ROBOTS))
def test_last_body_point_is_the_tip_and_batched_equals_looped(n):
    robot = ROBOTS[n]
    Q = _configurations(robot, np.random.default_rng(20 + n))
    tip, _ = robot.forward_kinematics(Q)
    backbone = robot.backbone(Q, 12)
    np.testing.assert_allclose(backbone[:, -1], tip, atol=1e-15)
    assert backbone.shape[1] == robot.n_insert_samples + n * 12 + 1
    looped = np.array([robot.jacobian(q) for q in Q])
    np.testing.assert_array_equal(robot.jacobian(Q), looped)


def test_a_vanishing_fourth_segment_changes_nothing():
    """4 segments, the last 1 um long and straight, is the 3-segment robot (kinematics, VOI)."""
    three = MultiBackboneRobot()
    four = MultiBackboneRobot(lengths=(*three.lengths, 1e-6))
    rng = np.random.default_rng(3)
    for q3 in _configurations(three, rng):
        q4 = np.r_[q3[:6], math.pi / 2, 0.0, q3[6]]
        p3, R3 = three.forward_kinematics(q3)
        p4, R4 = four.forward_kinematics(q4)
        np.testing.assert_allclose(p4, p3 + R3[:, 2] * 1e-6, atol=1e-15)
        np.testing.assert_allclose(R4, R3, atol=1e-15)
    q = three.psi_a
    voi3 = float(occlusion_details(three, q, 0.0)["voi"])
    voi4 = float(occlusion_details(four, np.r_[q[:6], math.pi / 2, 0.0, q[6]], 0.0)["voi"])
    assert voi3 == pytest.approx(0.2502, abs=1e-3) and voi4 == pytest.approx(voi3, abs=2e-4)


@pytest.mark.parametrize("n", sorted(ROBOTS))
def test_force_field_gradient_on_the_new_backbone(n):
    """grad Pi = grad E - sum Jv^T f over the robot's default psps, assembled from the public pieces."""
    robot = ROBOTS[n]
    psps = default_psps(n)
    assert {s for s, _ in psps} == set(range(n)) and (n - 1, 1.0) not in psps  # every segment, not the tip
    cone, field = LensCone(), ForceField()
    for q in _configurations(robot, np.random.default_rng(30 + n)):
        for gamma in (0.0, 0.4):
            P, JV = robot.points_jacobians(q, psps)
            forces = repulsive_force(P, gamma, cone, field)
            expected = robot.elastic_energy_gradient(q) - np.einsum("mik,mi->k", JV, forces)
            scale = np.abs(robot.elastic_energy_gradient(q)) + np.einsum("mik,mi->k", np.abs(JV), np.abs(forces))
            got = potential_gradient(robot, q, gamma, cone, field, psps)
            assert np.all(np.abs(got - expected) <= 1e-13 * scale + 1e-15)


@pytest.mark.parametrize("n", sorted(ROBOTS))
def test_elastic_energy_gradient_matches_finite_differences(n):
    robot = ROBOTS[n]
    q = _configurations(robot, np.random.default_rng(40 + n))[0]
    h = 1e-6
    grad = np.array([(robot.elastic_energy(q + h * e) - robot.elastic_energy(q - h * e)) / (2 * h)
                     for e in np.eye(robot.dof)])
    np.testing.assert_allclose(robot.elastic_energy_gradient(q), grad, atol=1e-9)
    if n == 2:
        np.testing.assert_allclose(robot.stiffness, (0.02, 0.03))


@pytest.mark.parametrize("kwargs, name", [
    ({"lengths": ()}, "lengths"), ({"lengths": (0.01,) * 5}, "lengths"), ({"lengths": (0.02, -0.01)}, "lengths"),
    ({"lengths": (0.02, 0.02), "backbone_stiffness": (0.1,)}, "backbone_stiffness"),
    ({"lengths": (0.02,), "backbone_stiffness": (-1.0,)}, "backbone_stiffness"),
])
def test_bad_robots_name_the_parameter(kwargs, name):
    with pytest.raises(ValueError, match=name):
        MultiBackboneRobot(**kwargs)


def test_wrong_configuration_size_names_q():
    with pytest.raises(ValueError, match=r"q must have shape \(\.\.\., 5\)"):
        ROBOTS[2].forward_kinematics(np.zeros(7))
    with pytest.raises(ValueError, match="segment"):
        ROBOTS[2].points_jacobians(ROBOTS[2].straight, [(2, 0.5)])
