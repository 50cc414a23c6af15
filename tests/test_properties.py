"""Property-based tests (hypothesis) over the whole valid configuration and keyword space.

Kinematics: rotations orthonormal, Jacobians equal central finite differences, batched equals looped,
for robots of 1-4 segments with any lengths, at random, exactly straight and joint-limit
configurations. Environments: for random keyword arguments within their valid ranges (model errors
included), observations
stay in the observation space, rewards are finite and equal the sum of ``reward_terms``, and a zero
residual gives the same trajectory whatever the residual scale (it is exactly the baseline).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import continuum_gym  # noqa: F401  (registers the ids)
from continuum_gym.envs.model_error import ModelError
from continuum_gym.robots import ContinuumEndoscope, MultiBackboneRobot

SETTINGS = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
H = 1e-6


def vee(S: np.ndarray) -> np.ndarray:
    return np.array([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]]) / 2


def fd_twist(pose, q: np.ndarray) -> np.ndarray:
    """Central finite differences of a pose map: (6, dof) twist columns [v; w] in the world frame."""
    columns = []
    for k in range(q.size):
        dq = np.zeros_like(q)
        dq[k] = H
        (p1, R1), (p0, R0) = pose(q + dq), pose(q - dq)
        _, R = pose(q)
        columns.append(np.concatenate([(p1 - p0) / (2 * H), vee((R1 - R0) / (2 * H) @ R.T)]))
    return np.stack(columns, axis=1)


@st.composite
def mbcr_cases(draw):
    n = draw(st.integers(1, 4))
    lengths = tuple(draw(st.floats(0.005, 0.05)) for _ in range(n))
    robot = MultiBackboneRobot(lengths=lengths)
    max_bend = np.pi / 2
    q = []
    for _ in range(n):
        kind = draw(st.sampled_from(["random", "straight", "limit"]))
        theta = {"random": draw(st.floats(np.pi / 2 - max_bend, np.pi / 2)), "straight": np.pi / 2,
                 "limit": np.pi / 2 - max_bend}[kind]
        q += [theta, draw(st.floats(-np.pi, np.pi))]
    q.append(draw(st.floats(0.0, 0.04)))
    return robot, np.array(q)


@SETTINGS
@given(mbcr_cases())
def test_mbcr_kinematics_invariants(case):
    robot, q = case
    p, R, J = robot.forward_kinematics_and_jacobian(q)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) > 0
    np.testing.assert_allclose(J, fd_twist(robot.forward_kinematics, q), atol=2e-6)
    batch = np.stack([q, q[::-1] * 0 + q, np.where(np.arange(q.size) % 2 == 0, np.pi / 2, q)])
    pb, Rb, Jb = robot.forward_kinematics_and_jacobian(batch)
    for row in range(len(batch)):
        pl, Rl, Jl = robot.forward_kinematics_and_jacobian(batch[row])
        np.testing.assert_array_equal(pb[row], pl)
        np.testing.assert_array_equal(Rb[row], Rl)
        np.testing.assert_array_equal(Jb[row], Jl)


@st.composite
def endoscope_cases(draw):
    robot = ContinuumEndoscope(L1=draw(st.floats(0.02, 0.15)), L2=draw(st.floats(0.01, 0.08)))
    lower, upper = robot.joint_limits
    q = []
    for k in range(6):
        lo, hi = (lower[k], upper[k]) if np.isfinite(lower[k]) else (-np.pi, np.pi)
        q.append(draw(st.one_of(st.floats(lo, hi), st.sampled_from([lo, hi]))))
    q = np.array(q)
    if draw(st.booleans()):
        q[[2, 4]] = 0.0  # both segments exactly straight
    return robot, q


@SETTINGS
@given(endoscope_cases())
def test_endoscope_kinematics_invariants(case):
    robot, q = case
    p_ct, R = robot.target_pose(q)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(robot.jacobian(q), fd_twist(robot.target_pose, q), atol=2e-6)
    batch = np.stack([q, q * 0.5, q * 0.0])
    Jb = robot.jacobian(batch)
    for row in range(len(batch)):
        np.testing.assert_array_equal(Jb[row], robot.jacobian(batch[row]))


OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"


@st.composite
def env_kwargs(draw):
    env_id = draw(st.sampled_from([OCCLUSION, VIEW]))
    kwargs = {"task": "random", "task_split": draw(st.sampled_from(["train", "validation", "test"])),
              "control_dt": draw(st.sampled_from([0.005, 0.01, 0.02])),
              "residual_scale": draw(st.floats(0.01, 1.0))}
    if env_id == OCCLUSION:
        kwargs["base_controller"] = draw(st.sampled_from(["projected_gradient", "minimum_norm"]))
        kwargs["max_bend"] = draw(st.floats(0.6, np.pi / 2))
        kwargs["reward_weights"] = {"voi": draw(st.floats(0.0, 10.0)), "action": draw(st.floats(0.0, 1.0))}
    else:
        kwargs["base_controller"] = draw(st.sampled_from(["dimension_reduced", "resolved_rate"]))
        kwargs["reward_weights"] = {"overlap": draw(st.floats(0.0, 10.0)), "overlap_bonus": draw(st.floats(0, 1))}
    kwargs["model_error"] = draw(model_errors(env_id))
    kwargs["randomize_model_error"] = kwargs["model_error"] in ("mild", "severe") and draw(st.booleans())
    return env_id, kwargs, draw(st.integers(0, 2**16))


@st.composite
def model_errors(draw, env_id):
    """A preset or any ModelError within its fields' limits (issue 37)."""
    kind = draw(st.sampled_from(["none", "mild", "severe", "custom"]))
    if kind != "custom":
        return kind
    mounting = {"channel_offset_m": draw(st.floats(-2e-3, 2e-3)), "lens_angle_rad": draw(st.floats(-0.2, 0.2))} \
        if env_id == OCCLUSION else {"camera_rotation_rad": tuple(draw(st.floats(-0.2, 0.2)) for _ in range(3))}
    return ModelError(length_scale=draw(st.floats(0.5, 1.5)), backlash_rad=draw(st.floats(0.0, 0.5)),
                      actuator_lag_s=draw(st.floats(0.0, 1.0)), joint_noise_rad=draw(st.floats(0.0, 0.1)),
                      tip_noise_m=draw(st.floats(0.0, 0.01)), delay_steps=draw(st.integers(0, 20)), **mounting)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(env_kwargs())
def test_env_invariants_over_valid_keyword_arguments(case):
    env_id, kwargs, seed = case
    env = gym.make(env_id, **kwargs)
    rng = np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed)
    assert env.observation_space.contains(obs)
    for _ in range(25):
        obs, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
        assert env.observation_space.contains(obs) and np.isfinite(reward)
        assert reward == sum(info["reward_terms"].values()) or np.isclose(reward, sum(info["reward_terms"].values()),
                                                                           rtol=1e-12, atol=1e-12)
        if terminated or truncated:
            break
    # A zero residual does not depend on its scale: the trajectory is the baseline's, bit for bit.
    other = gym.make(env_id, **{**kwargs, "residual_scale": 1.0 - 0.5 * kwargs["residual_scale"]})
    a, _ = env.reset(seed=seed)
    b, _ = other.reset(seed=seed)
    zero = np.zeros(env.action_space.shape, dtype=np.float32)
    for _ in range(20):
        a, _, ended_a, cut_a, _ = env.step(zero)
        b, _, ended_b, cut_b, _ = other.step(zero)
        np.testing.assert_array_equal(a, b)
        assert (ended_a, cut_a) == (ended_b, cut_b)
        if ended_a or cut_a:  # e.g. a true robot far from the model loses the tip at once
            break
