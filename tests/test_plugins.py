"""Plug-ins, used as a researcher would: only public names of the library are imported here.

A recorded task, a registered task family, a registered controller as the residual base, compiled and
numpy reward terms, a registered robot, and bad input to each entry point.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from numba import njit
from scipy.interpolate import CubicSpline

import continuum_gym  # noqa: F401  (registers the ids)
from continuum_gym.envs import ContinuumSB3VecEnv, DaVinciTrajectory, TipTrajectory
from continuum_gym.envs.occlusion.outputs import Flag, Metric
from continuum_gym.registry import (
    register_controller,
    register_reward_term,
    register_robot,
    register_task,
    unregister,
)
from continuum_gym.robots import MultiBackboneRobot
from continuum_gym.robots.mbcr_kernels import make_workspace, tip_kernel

OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"


@pytest.fixture
def registered():
    """Names registered by a test, removed afterwards (the registry is process-wide)."""
    names = []
    yield names
    for name, env in names:
        unregister(name, env)


# ---------------------------------------------------------------------- a recorded task
def _recorded_circle(samples=41, period=4.0):
    robot = MultiBackboneRobot()
    p0, R0 = robot.forward_kinematics(robot.psi_a)
    t = np.linspace(0.0, 1.0, samples)
    w = 2 * math.pi / period
    positions = p0 + 0.002 * np.stack([np.sin(w * t), 1 - np.cos(w * t), 0 * t], axis=1)
    return TipTrajectory(t, positions, np.broadcast_to(R0, (samples, 3, 3)), start_q=robot.psi_a), positions, t


def test_a_recorded_trajectory_is_interpolated_smoothly_and_tracked():
    trajectory, positions, t = _recorded_circle()
    env = gym.make(OCCLUSION, task=trajectory).unwrapped
    obs, _ = env.reset(seed=0)
    core = env.core
    assert core.limit[0] == round(1.0 / core.control_dt)
    spline = CubicSpline(t, positions)
    for time in np.linspace(0.0, 1.0, 57):
        p, v = core.desired(0, time)
        np.testing.assert_allclose(p, spline(time), atol=1e-15)
        np.testing.assert_allclose(v, spline(time, 1), atol=1e-13)  # the feed-forward of the baseline
    k = 20  # C1 at a knot: left and right derivatives agree
    left = core.desired(0, t[k] - 1e-7)[1]
    right = core.desired(0, t[k] + 1e-7)[1]
    np.testing.assert_allclose(left, right, atol=1e-5)
    errors = []
    while True:
        obs, reward, terminated, truncated, info = env.step(np.zeros(8, dtype=np.float32))
        errors.append(info["tip_error_m"])
        if terminated or truncated:
            break
    assert truncated and not terminated and max(errors) < 1e-3  # the projected gradient tracks it within 1 mm


def test_a_recorded_orientation_turns_smoothly():
    robot = MultiBackboneRobot()
    p0, R0 = robot.forward_kinematics(robot.psi_a)
    from scipy.spatial.transform import Rotation

    t = np.linspace(0.0, 0.5, 11)
    turns = Rotation.from_rotvec(np.outer(t, [0.0, 0.0, 0.4])).as_matrix()
    rotations = np.einsum("ij,kjl->kil", R0, turns)
    env = gym.make(OCCLUSION, task=TipTrajectory(t, np.broadcast_to(p0, (11, 3)), rotations)).unwrapped
    env.reset(seed=0)
    np.testing.assert_allclose(env.core.desired_rotation(0, 0.25), R0 @ Rotation.from_rotvec([0, 0, 0.1]).as_matrix(),
                               atol=1e-12)
    q0 = env.core.q[0]
    np.testing.assert_allclose(robot.forward_kinematics(q0)[0], p0, atol=1e-7)  # start solved at the first pose


def test_a_list_of_recordings_is_one_task_per_id_and_da_vinci_recordings_drive_view_tracking():
    a, _, _ = _recorded_circle(samples=21)
    b, _, _ = _recorded_circle(samples=61, period=2.0)
    venv = gym.make_vec(OCCLUSION, num_envs=2, vectorization_mode="vector_entry_point", task=[a, b])
    venv.reset(seed=0, options={"task_ids": [0, 1]})
    assert venv.unwrapped.core.tasks.n_knots.tolist() == [21, 61]
    t = np.linspace(0, 2.0, 9)
    configurations = np.stack([np.full(9, 0.065), 0.3 * np.sin(t), 0.2 * t, np.zeros(9)], axis=1)
    env = gym.make(VIEW, task=DaVinciTrajectory(t, configurations)).unwrapped
    env.reset(seed=0)
    np.testing.assert_allclose(env.core.davinci_configuration(0), configurations[0], atol=1e-15)
    for _ in range(100):
        env.step(np.zeros(6, dtype=np.float32))
    np.testing.assert_allclose(env.core.davinci_configuration(0), CubicSpline(t, configurations)(1.0), atol=1e-12)


@pytest.mark.parametrize("kwargs, name", [
    ({"times": [0.0, 0.1, 0.1], "positions": np.zeros((3, 3))}, "times"),
    ({"times": [0.0, 0.2, 0.1], "positions": np.zeros((3, 3))}, "times"),
    ({"times": [0.0, 0.1], "positions": [[0, 0, np.nan], [0, 0, 0.05]]}, "positions"),
    ({"times": [0.0, 0.1], "positions": np.zeros((3, 3))}, "positions"),
    ({"times": [0.0, 0.1], "positions": np.zeros((2, 3)), "rotations": np.zeros((2, 3, 3))}, "rotations"),
    ({"times": [0.0, 0.1], "positions": np.zeros((2, 3))}, "start_q"),
])
def test_bad_recordings_name_the_parameter(kwargs, name):
    with pytest.raises(ValueError, match=name):
        TipTrajectory(**kwargs)


def test_a_recording_that_does_not_fit_the_robot_is_refused():
    trajectory, _, _ = _recorded_circle()
    wrong = TipTrajectory(trajectory.times, trajectory.positions, trajectory.rotations, start_q=np.zeros(5))
    with pytest.raises(ValueError, match="start_q"):
        gym.make(OCCLUSION, task=wrong)
    with pytest.raises(ValueError, match="roll"):
        DaVinciTrajectory([0.0, 1.0], [[0.06, 0, 0, -3.0], [0.06, 0, 0, 3.0]])
    with pytest.raises(ValueError, match="yaw"):
        DaVinciTrajectory([0.0, 1.0], [[0.06, 2.0, 0, 0], [0.06, 0, 0, 0]])


# ---------------------------------------------------------------------- a registered task family
def _line_sampler(task_id, split, rng):
    robot = MultiBackboneRobot()
    p0, R0 = robot.forward_kinematics(robot.psi_a)
    direction = rng.normal(size=3)
    t = np.linspace(0.0, 0.5, 6)
    return TipTrajectory(t, p0 + np.outer(t, direction / np.linalg.norm(direction) * 0.004),
                         np.broadcast_to(R0, (6, 3, 3)), start_q=robot.psi_a)


def test_a_registered_family_draws_repeatable_disjoint_instances(registered):
    register_task("lines", _line_sampler, count=50)
    registered.append(("lines", OCCLUSION))
    train = gym.make(OCCLUSION, task="lines").unwrapped
    test = gym.make(OCCLUSION, task="lines", task_split="test").unwrapped
    ends = []
    for env in (train, train, test):
        env.reset(options={"task_id": 3})
        ends.append(env.core.desired(0, 0.5)[0])
    np.testing.assert_array_equal(ends[0], ends[1])
    assert not np.allclose(ends[0], ends[2])
    assert train.core.task_count == 50
    with pytest.raises(ValueError, match="already"):
        register_task("lines", _line_sampler)
    with pytest.raises(ValueError, match="built-in"):
        register_task("hold", _line_sampler)
    with pytest.raises(ValueError, match="TipTrajectory"):
        register_task("broken", lambda task_id, split, rng: np.zeros(3))


# ---------------------------------------------------------------------- a registered controller
@njit(cache=True)
def damped_tracker(q, gamma, p_des, R_des, v_des, dt, robot, cone, params, out):
    """Damped least squares on the tip position error (gain params[0] 1/s), endoscope held still."""
    n = robot.lengths.shape[0]
    ws = make_workspace(n)
    p = np.empty(3)
    R = np.empty((3, 3))
    J = np.empty((6, q.shape[0]))
    tip_kernel(q, robot, ws, p, R, J)
    Jv = J[:3]
    A = Jv @ Jv.T + params[1] * np.eye(3)
    e = params[0] * (p_des - p) + v_des
    rates = Jv.T @ np.linalg.solve(A, e)
    for k in range(q.shape[0]):
        out[k] = rates[k]
    out[q.shape[0]] = 0.0


def _replay(core, q0, steps, params):
    """The env's substeps by hand: base command of the registered function, rate scaling, clamping."""
    lower, upper, rate = core.limits.bounds(core.robot.n_segments)
    q = q0.copy()
    dt = core.control_dt / core.substeps
    out = np.empty(q.size + 1)
    for k in range(steps):
        for s in range(core.substeps):
            p, v = core.desired(0, k * core.control_dt + s * dt)
            damped_tracker(q, 0.0, p, np.ascontiguousarray(core.tasks.R_des[0]), v, dt, core.robot.kernel_args(),
                           core.cone.kernel_args(), params, out)
            cmd = out[:-1]
            scale = min([1.0] + [rate[j] / abs(cmd[j]) for j in range(q.size) if abs(cmd[j]) > rate[j] * (1 + 1e-12)])
            q = np.minimum(np.maximum(q + scale * cmd * dt, lower), upper)
    return q


def test_a_registered_controller_is_the_residual_base_inside_the_compiled_step(registered):
    params = np.array([40.0, 1e-6])
    controller = register_controller("damped_tracker", damped_tracker, params=params)
    registered.append(("damped_tracker", OCCLUSION))
    env = gym.make(OCCLUSION, base_controller="damped_tracker", task="random", task_split="test").unwrapped
    env.reset(seed=1)
    q0 = env.core.q[0].copy()
    np.testing.assert_allclose(env.core.base_cmd[0], controller.predict(env.core.controller_observation(0))[0])
    for _ in range(5):
        env.step(np.zeros(8, dtype=np.float32))
    np.testing.assert_allclose(env.core.q[0], _replay(env.core, q0, 5, params), rtol=0, atol=1e-14)
    venv = ContinuumSB3VecEnv(OCCLUSION, 4, seed=0, base_controller="damped_tracker")
    venv.reset()
    obs, rewards, dones, infos = venv.step(np.zeros((4, 8), dtype=np.float32))
    assert np.all(np.isfinite(rewards)) and all("voi" in info for info in infos)


def test_bad_controllers_are_refused_naming_the_problem(registered):
    @njit
    def wrong_signature(q, out):
        out[0] = 1.0

    @njit
    def not_finite(q, gamma, p_des, R_des, v_des, dt, robot, cone, params, out):
        out[:] = np.nan

    with pytest.raises(ValueError, match="signature"):
        register_controller("wrong", wrong_signature)
    with pytest.raises(ValueError, match="finite"):
        register_controller("nan", not_finite)
    with pytest.raises(ValueError, match="njit"):
        register_controller("python", lambda *args: None)
    with pytest.raises(ValueError, match="built-in"):
        register_controller("projected_gradient", damped_tracker)
    with pytest.raises(ValueError, match="base_controller"):
        gym.make(OCCLUSION, base_controller="not_registered")


# ---------------------------------------------------------------------- registered reward terms
@njit(cache=True)
def tip_error_mm(metrics, flags, action, params):
    return -1e3 * metrics[Metric.TIP_ERROR] - params[0] * flags[Flag.TERMINATED]


def test_registered_reward_terms_are_added_and_reported(registered):
    register_reward_term("tip_error_mm", tip_error_mm, weight=0.5, params=[100.0])
    register_reward_term("voi_squared", lambda metrics, actions: -metrics["voi"] ** 2, weight=2.0, compiled=False)
    registered += [("tip_error_mm", OCCLUSION), ("voi_squared", OCCLUSION)]
    env = gym.make(OCCLUSION, reward_weights={"voi_squared": 3.0})
    env.reset(seed=0)
    _, reward, _, _, info = env.step(np.zeros(8, dtype=np.float32))
    terms = info["reward_terms"]
    assert terms["tip_error_mm"] == pytest.approx(0.5 * -1e3 * info["tip_error_m"], rel=1e-12)
    assert terms["voi_squared"] == pytest.approx(3.0 * -info["voi"] ** 2, rel=1e-12)
    assert reward == pytest.approx(sum(terms.values()), rel=1e-12, abs=1e-15)
    venv = gym.make_vec(OCCLUSION, num_envs=3, vectorization_mode="vector_entry_point")
    venv.reset(seed=0)
    _, rewards, _, _, infos = venv.step(np.zeros((3, 8), dtype=np.float32))
    core = venv.unwrapped.core
    np.testing.assert_allclose(infos["reward_terms"]["tip_error_mm"], 0.5 * -1e3 * core.metrics[:, Metric.TIP_ERROR])
    np.testing.assert_allclose(infos["reward_terms"]["voi_squared"], 2.0 * -core.metrics[:, Metric.VOI] ** 2)
    np.testing.assert_allclose(rewards, core.terms.sum(axis=1), rtol=1e-12)
    with pytest.raises(ValueError, match="signature"):
        register_reward_term("bad", njit(lambda metrics: 0.0))
    with pytest.raises(ValueError, match="built-in"):
        register_reward_term("voi", tip_error_mm)


# ---------------------------------------------------------------------- a registered robot
def test_a_registered_robot_is_made_by_name(registered):
    robot = MultiBackboneRobot(lengths=(0.03, 0.025))
    register_robot("two-segment", robot)
    registered.append(("two-segment", OCCLUSION))
    env = gym.make(OCCLUSION, robot="two-segment")
    assert env.unwrapped.core.robot is robot and env.action_space.shape == (6,)
    with pytest.raises(ValueError, match="robot"):
        register_robot("thing", object())
    with pytest.raises(ValueError, match="not registered"):
        gym.make(OCCLUSION, robot="three-segment")
    with pytest.raises(ValueError, match="name"):
        register_robot("", robot)
