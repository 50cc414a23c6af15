"""A third environment from a package of its own (``examples/my_reach``, docs/tutorials/extend.md, "Add a third
environment") goes through the library's front ends and tools with no module of the library edited.

The environment's step is checked against an independent computation (the Jacobian-transpose command from
finite differences of the robot's target point), its native vector env against its single env row by row,
and its training and evaluation through the command line, in worker processes that import it again.
"""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "examples" / "my_reach"
ENV_ID = "MyLab/EndoscopeReach-v0"


@pytest.fixture
def my_reach(monkeypatch):
    """The example package imported (registering its id), and forgotten afterwards so no other test sees it."""
    from continuum_gym.envs.spec import ENV_IDS, ENV_SPECS

    monkeypatch.syspath_prepend(str(PACKAGE.parent))
    import my_reach

    yield my_reach
    for name in [m for m in sys.modules if m == "my_reach" or m.startswith("my_reach.")]:
        del sys.modules[name]
    ENV_SPECS.pop(ENV_ID, None)
    if ENV_ID in ENV_IDS:
        ENV_IDS.remove(ENV_ID)
    gym.registry.pop(ENV_ID, None)


def test_the_package_uses_only_the_librarys_public_modules_and_no_other_environment():
    """'Touches no module outside its own package': it imports public library names, and no built-in env."""
    for path in PACKAGE.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("continuum_gym"):
                parts = node.module.split(".")
                assert not any(part.startswith("_") for part in parts), f"{path.name} imports {node.module}"
                assert not any(alias.name.startswith("_") for alias in node.names), f"{path.name}: private name"
                assert node.module.split(".")[:3] not in (["continuum_gym", "envs", "occlusion"],
                                                          ["continuum_gym", "envs", "view_tracking"]), path.name


def test_it_registers_and_passes_both_env_checkers(my_reach):
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    from continuum_gym.envs.spec import get_spec

    assert get_spec(ENV_ID) is my_reach.SPEC
    env = gym.make(ENV_ID)
    check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped)
    with pytest.raises(ValueError, match="render_mode"):
        gym.make(ENV_ID, render_mode="rgb_array")
    with pytest.raises(ValueError, match="residual_scale"):
        gym.make(ENV_ID, residual_scale=-1.0)


def _finite_difference_jacobian(robot, q: np.ndarray, h: float = 1e-7) -> np.ndarray:
    J = np.empty((3, 6))
    for k in range(6):
        step = np.zeros(6)
        step[k] = h
        J[:, k] = (robot.target_point(q + step) - robot.target_point(q - step)) / (2 * h)
    return J


def test_a_step_is_the_jacobian_transpose_command_integrated(my_reach):
    from my_reach.kernel import ACTION_SCALE, GAIN

    env = gym.make(ENV_ID).unwrapped
    core = env.core
    robot = core.robot
    obs, info = env.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = core.q[0].copy()
        goal, _ = core.desired(0, core.steps[0] * core.control_dt)
        command = GAIN * _finite_difference_jacobian(robot, q).T @ (goal - robot.target_point(q))
        np.testing.assert_allclose(core.base_cmd[0], command, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(obs[9:15], np.clip(command / ACTION_SCALE, -10, 10), rtol=1e-5, atol=1e-5)
        assert info["distance_m"] == pytest.approx(np.linalg.norm(goal - robot.target_point(q)), rel=1e-12)
        action = rng.uniform(-1, 1, 6).astype(np.float32)
        obs, reward, _, _, info = env.step(action)
        lower, upper = robot.joint_limits
        expected = np.clip(q + core.control_dt * (command + action * ACTION_SCALE), lower, upper)
        np.testing.assert_allclose(core.q[0], expected, rtol=1e-6, atol=1e-9)
        assert reward == pytest.approx(-info["distance_m"] / 0.01 - 0.01 * np.mean(np.float64(action) ** 2))


def test_the_native_vector_env_equals_the_single_env_row_by_row(my_reach):
    vector = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="vector_entry_point")
    obs, _ = vector.reset(seed=7, options={"task_ids": [5, 6, 7]})
    rng = np.random.default_rng(1)
    actions = rng.uniform(-1, 1, (40, 3, 6)).astype(np.float32)
    rows = [obs]
    for a in actions:
        rows.append(vector.step(a)[0])
    for row, task_id in enumerate((5, 6, 7)):
        env = gym.make(ENV_ID)
        single = [env.reset(seed=0, options={"task_id": task_id})[0]]
        single += [env.step(a[row])[0] for a in actions]
        np.testing.assert_array_equal(np.array(single), np.array(rows)[:, row])


def test_the_command_line_trains_in_workers_and_a_residual_beats_its_base(tmp_path):
    """``--import my_reach``: train two seeds in worker processes, then evaluate against the analytic base."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, (str(PACKAGE.parent),
                                                                     os.environ.get("PYTHONPATH"))))}
    cli = [sys.executable, "-m", "continuum_gym.cli", "--import", "my_reach"]
    subprocess.run([*cli, "train", "--env", ENV_ID, "--seeds", "0", "1", "--parallel", "2", "--steps", "60000",
                    "--hyperparams", str(PACKAGE / "ppo.yml"), "--out", str(tmp_path / "runs"), "--no-progress"],
                   check=True, env=env, cwd=tmp_path, capture_output=True, timeout=900)
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == [
        "EndoscopeReach_ppo_jacobian_transpose_seed0", "EndoscopeReach_ppo_jacobian_transpose_seed1"]
    subprocess.run([*cli, "evaluate", "--env", ENV_ID, "--split", "validation", "--episodes", "16", "--policies",
                    str(tmp_path / "runs"), "--json", str(tmp_path / "results.json"), "--no-progress"],
                   check=True, env=env, cwd=tmp_path, capture_output=True, timeout=900)
    table = json.loads((tmp_path / "results.json").read_text())[ENV_ID]
    base = table["jacobian_transpose"]["final_distance_m"]["mean"]
    residual = table["residual_jacobian_transpose"]["final_distance_m"]["mean"]
    assert 0.0 < residual < base
