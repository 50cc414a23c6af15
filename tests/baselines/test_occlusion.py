"""Paper-000 controllers: reference step, closed-form leak, limits, batching, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from continuum_gym.baselines.occlusion import (
    MinimumNorm,
    OcclusionLimits,
    ProjectedGradient,
    wrap_angle,
)
from continuum_gym.baselines.scenarios import CircleTask, sample_hold_starts
from continuum_gym.geometry.force_field import potential_gradient
from continuum_gym.geometry.occlusion import visual_occlusion_index
from continuum_gym.robots.mbcr import MultiBackboneRobot

ROBOT = MultiBackboneRobot()


def hold_targets(q, steps):
    p, R = ROBOT.forward_kinematics(q)
    return np.broadcast_to(p, (steps, 3)), np.broadcast_to(R, (steps, 3, 3))


@pytest.mark.parametrize("index", range(8))
def test_projected_gradient_step_matches_reference(reference, index):
    entry = reference["mbcr"][index]
    step = entry["projected_gradient_step"]
    rates = ProjectedGradient().rates_for_twist(entry["q"], step["xi_dot"], step["gamma"])
    np.testing.assert_allclose(rates[:7], step["psi_dot"], rtol=1e-9, atol=1e-9 * np.abs(step["psi_dot"]).max())
    assert step["gamma"] + rates[7] * 1e-3 == pytest.approx(step["gamma_after_1ms"], abs=1e-15)


def test_null_space_term_leaks_exactly_the_damping_term():
    """With xi = 0, J q_dot = -eta1 eps (J J^T + eps I)^-1 J grad Pi (paper-notes §1.3 item 12)."""
    rng = np.random.default_rng(0)
    controller = ProjectedGradient()
    for _ in range(10):
        q = ROBOT.psi_a + rng.normal(0, 0.2, 7) * [1, 1, 1, 1, 1, 1, 0.01]
        rates = controller.rates_for_twist(q, np.zeros(6), 0.0)
        J = ROBOT.jacobian(q)
        grad = potential_gradient(ROBOT, q, 0.0)
        eps = controller.epsilon
        leak = -controller.eta1 * eps * np.linalg.solve(J @ J.T + eps * np.eye(6), J @ grad)
        np.testing.assert_allclose(J @ rates[:7], leak, atol=1e-9 * max(1.0, np.abs(leak).max()))
        # The null-space motion itself is large compared with its leak into the task.
        assert np.linalg.norm(rates[:7]) > 10 * np.linalg.norm(J @ rates[:7])


def test_hold_task_reproduces_the_paper():
    """Task (a): VOI 0.25 -> 0.16 (paper-notes §3 band 0.14-0.18 at 800 and 1500 it), drift <= 0.3 mm."""
    p, R = hold_targets(ROBOT.psi_a, 1500)
    q, gamma = ProjectedGradient(rotate_endoscope=False).rollout(ROBOT.psi_a, 0.0, p, R)
    voi = visual_occlusion_index(ROBOT, q, gamma)
    assert voi[0] == pytest.approx(0.2502, abs=1e-4)
    assert 0.14 <= voi[800] <= 0.18 and 0.14 <= voi[1500] <= 0.18
    assert voi[100] > voi[200] > voi[300]
    drift = np.linalg.norm(ROBOT.forward_kinematics(q)[0] - p[0], axis=-1).max()
    assert drift <= 0.3e-3
    assert np.all(gamma == 0.0)


def test_minimum_norm_holds_the_tip_within_a_tenth_of_a_millimetre():
    starts = np.concatenate([ROBOT.psi_a[None], sample_hold_starts(ROBOT, 5, np.random.default_rng(1))])
    for q0 in starts:
        p, R = hold_targets(q0, 1500)
        q, _ = MinimumNorm().rollout(q0, 0.0, p, R)
        tip, _ = ROBOT.forward_kinematics(q)
        assert np.linalg.norm(tip - p[0], axis=-1).max() <= 1e-4


def test_circle_matches_errata_bands():
    task = CircleTask()
    q0 = task.start_configuration()
    _, R0 = ROBOT.forward_kinematics(q0)
    t = np.arange(10000) * 1e-3
    P, V = task.trajectory(t)
    R = np.broadcast_to(R0, (t.size, 3, 3))
    means = {}
    for controller in (MinimumNorm(), ProjectedGradient()):
        q, gamma = controller.rollout(q0, 0.0, P, R, V)
        means[controller.name] = visual_occlusion_index(ROBOT, q[:-1], gamma[:-1]).mean()
        assert 16 <= -np.degrees(gamma.min()) <= 19 and 16 <= np.degrees(gamma.max()) <= 19
        assert np.degrees(gamma[:3000]).min() < -10 < np.degrees(gamma[:3000]).max() + 20  # negative first
        assert gamma[np.argmax(np.abs(gamma) > 0.1)] < 0
    assert 0.27 <= means["minimum_norm"] <= 0.33
    assert 0.14 <= means["projected_gradient"] <= 0.20
    assert means["projected_gradient"] <= 0.7 * means["minimum_norm"]


# ---------------------------------------------------------------- limits
LIMITS = OcclusionLimits()


def test_limits_are_never_left_and_rates_are_bounded():
    rng = np.random.default_rng(2)
    starts = sample_hold_starts(ROBOT, 6, rng)
    controller = ProjectedGradient(limits=LIMITS)
    lower, upper = LIMITS.lower, LIMITS.upper
    for q0 in starts:
        p, R = hold_targets(q0, 1500)
        q, gamma = controller.rollout(q0, 0.0, p, R)
        assert np.all(q >= lower - 1e-12) and np.all(q <= upper + 1e-12)
        rates = np.diff(q, axis=0) / 1e-3
        assert np.all(np.abs(rates) <= LIMITS.rate_limit * (1 + 1e-9))
        assert np.all(np.abs(np.diff(gamma)) <= LIMITS.gamma_rate * 1e-3 * (1 + 1e-9) + 1e-15)


def test_unlimited_projected_gradient_breaks_the_bend_limit_that_the_limited_one_keeps():
    task = CircleTask()
    q0 = task.start_configuration()
    _, R0 = ROBOT.forward_kinematics(q0)
    t = np.arange(4000) * 1e-3
    P, V = task.trajectory(t)
    R = np.broadcast_to(R0, (t.size, 3, 3))
    q_free, _ = ProjectedGradient().rollout(q0, 0.0, P, R, V)
    q_lim, _ = ProjectedGradient(limits=LIMITS).rollout(q0, 0.0, P, R, V)
    assert np.abs(ROBOT.bend_angles(q_free)).max() > LIMITS.max_bend
    assert np.abs(ROBOT.bend_angles(q_lim)).max() <= LIMITS.max_bend + 1e-12


def test_joint_at_its_limit_moving_outward_is_frozen():
    q = ROBOT.psi_a.copy()
    q[6] = LIMITS.insertion[0]  # at the lower insertion limit
    controller = MinimumNorm(limits=LIMITS)
    p, R = ROBOT.forward_kinematics(q)
    # Ask the tip to move straight down: insertion would go negative, so it freezes and others take over.
    rates, info = controller.joint_rates_with_info(q, (p - [0, 0, 0.002], R), 0.0)
    assert info["frozen"][6] and rates[6] == 0.0
    assert np.any(rates[:6] != 0.0)


def test_wrap_angle():
    for x, expected in [(0.0, 0.0), (math.pi, math.pi), (-math.pi, math.pi), (3 * math.pi / 2, -math.pi / 2),
                        (-7.0, -7.0 + 2 * math.pi), (10.0, 10.0 - 4 * math.pi)]:
        assert wrap_angle(x) == pytest.approx(expected)


# ---------------------------------------------------------------- batching, predict and bad input
def test_batched_rates_equal_looped_and_predict_matches():
    rng = np.random.default_rng(3)
    q = sample_hold_starts(ROBOT, 6, rng).reshape(2, 3, 7)
    p, R = ROBOT.forward_kinematics(q)
    p_des = p + rng.normal(0, 1e-3, p.shape)
    gammas = rng.uniform(-0.3, 0.3, (2, 3))
    for controller in (MinimumNorm(), ProjectedGradient(limits=LIMITS)):
        batch = controller.joint_rates(q, (p_des, R), gammas)
        assert batch.shape == (2, 3, 8)
        for idx in np.ndindex(2, 3):
            assert np.array_equal(batch[idx], controller.joint_rates(q[idx], (p_des[idx], R[idx]), gammas[idx]))
        action, state = controller.predict({"q": q, "gamma": gammas, "p_des": p_des, "R_des": R.reshape(2, 3, 9)})
        assert state is None and np.array_equal(action, batch)
    # Batched rollout rows equal single rollouts.
    P, RR = hold_targets(ROBOT.psi_a, 50)
    starts = q.reshape(-1, 7)[:3]
    q_batch, g_batch = ProjectedGradient().rollout(starts, np.zeros(3), P, RR)
    for i in range(3):
        q_one, g_one = ProjectedGradient().rollout(starts[i], 0.0, P, RR)
        assert np.array_equal(q_batch[i], q_one) and np.array_equal(g_batch[i], g_one)


def test_bad_inputs_raise_clear_errors():
    controller = ProjectedGradient()
    p, R = ROBOT.forward_kinematics(ROBOT.psi_a)
    with pytest.raises(ValueError, match="q"):
        controller.joint_rates(ROBOT.psi_a[:5], (p, R))
    with pytest.raises(ValueError, match="finite"):
        controller.joint_rates(np.full(7, np.nan), (p, R))
    with pytest.raises(ValueError, match="p_des"):
        controller.joint_rates(ROBOT.psi_a, (p[:2], R))
    with pytest.raises(ValueError, match="target"):
        controller.joint_rates(ROBOT.psi_a, p)
    with pytest.raises(ValueError, match="gamma"):
        controller.joint_rates(ROBOT.psi_a, (p, R), gamma=np.inf)
    with pytest.raises(ValueError, match="observation"):
        controller.predict(np.zeros(20))
    with pytest.raises(ValueError, match="epsilon"):
        ProjectedGradient(epsilon=0.0)
    with pytest.raises(ValueError, match="max_bend"):
        OcclusionLimits(max_bend=-1.0)
    with pytest.raises(ValueError, match="insertion"):
        OcclusionLimits(insertion=(0.04, 0.0))
    with pytest.raises(ValueError, match="limits"):
        ProjectedGradient(limits={"max_bend": 1.0})
