"""Environment variants a researcher registers: 1-, 2- and 4-segment robots, another cone, another endoscope."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from continuum_gym.baselines import MinimumNorm, ProjectedGradient
from continuum_gym.envs import ContinuumSB3VecEnv
from continuum_gym.geometry import LensCone
from continuum_gym.robots import (
    ContinuumEndoscope,
    DaVinciEndoscope,
    MultiBackboneRobot,
)

OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"
ROBOTS = {1: MultiBackboneRobot(lengths=(0.03,)), 2: MultiBackboneRobot(lengths=(0.03, 0.025)),
          4: MultiBackboneRobot(lengths=(0.022, 0.02, 0.018, 0.016))}
BASES = {"projected_gradient": ProjectedGradient, "minimum_norm": MinimumNorm}


@pytest.mark.parametrize("n", sorted(ROBOTS))
def test_spaces_are_sized_from_the_robot_and_both_checkers_pass(n):
    robot = ROBOTS[n]
    for base in BASES:
        env = gym.make(OCCLUSION, robot=robot, base_controller=base)
        assert env.action_space.shape == (robot.dof + 1,)
        assert env.observation_space.shape == (5 * n + 17,)
        gym_check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(gym.make(OCCLUSION, robot=robot), warn=True)


@pytest.mark.parametrize("n", sorted(ROBOTS))
def test_a_hundred_thousand_random_steps_stay_finite_and_in_their_space(n):
    venv = gym.make_vec(OCCLUSION, num_envs=100, vectorization_mode="vector_entry_point", robot=ROBOTS[n],
                        task="mixed")
    obs, _ = venv.reset(seed=n)
    rng = np.random.default_rng(n)
    low, high = venv.single_observation_space.low, venv.single_observation_space.high
    for _ in range(1000):
        obs, rewards, *_ = venv.step(rng.uniform(-1, 1, venv.action_space.shape).astype(np.float32))
        assert np.all(np.isfinite(obs)) and np.all(np.isfinite(rewards))
        assert np.all(obs >= low) and np.all(obs <= high)


@pytest.mark.parametrize("base", sorted(BASES))
@pytest.mark.parametrize("n", sorted(ROBOTS))
def test_zero_residual_is_the_baseline_bit_for_bit(n, base):
    robot = ROBOTS[n]
    env = gym.make(OCCLUSION, robot=robot, base_controller=base, task="random", task_split="test").unwrapped
    env.reset(seed=4)
    core = env.core
    q0, gamma0 = core.q[0].copy(), float(core.gamma[0])
    qs, gammas = [q0], [gamma0]
    steps = 30
    for _ in range(steps):
        env.step(np.zeros(robot.dof + 1, dtype=np.float32))
        qs.append(core.q[0].copy())
        gammas.append(float(core.gamma[0]))
    sub_dt = core.control_dt / core.substeps
    times = [k * core.control_dt + s * sub_dt for k in range(steps) for s in range(core.substeps)]
    desired = [core.desired(0, t) for t in times]
    R = np.broadcast_to(core.tasks.R_des[0], (len(times), 3, 3))
    controller = BASES[base](robot=robot, limits=core.limits, cone=core.cone)
    q_ref, g_ref = controller.rollout(q0, gamma0, np.array([d[0] for d in desired]), R,
                                      np.array([d[1] for d in desired]), dt=sub_dt)
    assert np.array_equal(np.array(qs), q_ref[::core.substeps])
    assert np.array_equal(np.array(gammas), g_ref[::core.substeps])


@pytest.mark.slow
@pytest.mark.parametrize("n", sorted(ROBOTS))
def test_ppo_trains_ten_thousand_steps_on_a_variant(n):
    from stable_baselines3 import PPO

    venv = ContinuumSB3VecEnv(OCCLUSION, 8, seed=0, robot=ROBOTS[n])
    model = PPO("MlpPolicy", venv, n_steps=128, batch_size=256, n_epochs=2, seed=0, device="cpu")
    before = [p.detach().clone() for p in model.policy.parameters()]
    model.learn(10_000)
    assert model.num_timesteps >= 10_000
    assert any(not np.allclose(a.numpy(), p.detach().numpy()) for a, p in zip(before, model.policy.parameters()))
    actions, _ = model.predict(venv.reset(), deterministic=True)
    assert actions.shape == (8, ROBOTS[n].dof + 1) and np.all(np.isfinite(actions))


def test_another_cone_changes_the_view_and_the_lens_model_must_agree():
    cone = LensCone(d_o=0.006, alpha=math.radians(45.0), beta=math.radians(35.0), lens_model="physical")
    env = gym.make(OCCLUSION, cone=cone).unwrapped
    assert env.core.cone is cone and env.core.controller.cone is cone
    env.reset(seed=0)
    default = gym.make(OCCLUSION).unwrapped
    default.reset(seed=0)
    assert env.core.metrics[0, 0] != default.core.metrics[0, 0]  # VOI at the same start differs
    with pytest.raises(ValueError, match="lens_model"):
        gym.make(OCCLUSION, cone=cone, lens_model="literal")


def test_view_tracking_takes_another_endoscope_and_da_vinci():
    robot = ContinuumEndoscope(L1=0.025, L2=0.028, joint_limits=([0.0, -math.pi, 0.0, -math.inf, 0.0, -math.inf],
                                                                 [0.08, math.pi, math.pi / 3, math.inf, math.pi / 2,
                                                                  math.inf]))
    davinci = DaVinciEndoscope(alpha=math.radians(45.0))
    env = gym.make(VIEW, robot=robot, davinci=davinci, task="case2", task_split="test").unwrapped
    gym_check_env(env, skip_render_check=True)
    env.reset(seed=0)
    assert env.core.robot is robot and env.core.davinci is davinci
    history = [env.core.q[0].copy()]
    for _ in range(40):
        env.step(np.zeros(6, dtype=np.float32))
        history.append(env.core.q[0].copy())
    from continuum_gym.baselines import DimensionReduced

    target = davinci.target_pose(env.core.davinci_configuration(0))
    solved = DimensionReduced(robot=robot).solve(history[0], target, max_steps=40, record=True)
    n = int(solved["steps"]) + 1
    assert np.array_equal(np.array(history)[:n], solved["history"][:n])
    assert np.all(np.array(history)[:, 0] <= 0.08)  # its own insertion limit


@pytest.mark.parametrize("kwargs, name", [
    ({"robot": "no-such-robot"}, "robot"), ({"robot": ContinuumEndoscope()}, "robot"), ({"cone": 3.0}, "cone"),
    ({"robot": MultiBackboneRobot(lengths=(0.02,) * 2), "task": "orbit"}, "task"),
])
def test_bad_variants_name_the_parameter(kwargs, name):
    with pytest.raises(ValueError, match=name):
        gym.make(OCCLUSION, **kwargs)
