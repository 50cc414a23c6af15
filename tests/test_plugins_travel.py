"""A researcher's plug-ins travel: workers, fresh interpreters, pickles, config files and the CLI rebuild
them by importing the module that registered them (``examples/my_lab/plugins.py``), with no second
registration; where that is impossible the error says why and what to do."""

from __future__ import annotations

import importlib
import os
import pickle
import subprocess
import sys
from functools import partial
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from continuum_gym.envs import NamedRewardTerms

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
BASE = "ContinuumGym/OcclusionAvoidance-v0"
MY_ID = "MyLab/Occlusion2Seg-v0"


def _drop_my_lab_modules() -> None:
    for name in [m for m in sys.modules if m == "my_lab" or m.startswith("my_lab.")]:
        del sys.modules[name]


@pytest.fixture
def registry_restored():
    """The registry's tables, origins and the id registry as they were (registrations must not leak)."""
    from continuum_gym import registry

    tables = (registry.ROBOTS, registry.TASKS, registry.CONTROLLERS, registry.REWARD_TERMS, registry.ORIGINS)
    before = [{env: dict(names) for env, names in table.items()} for table in tables]
    yield registry
    for table, saved in zip(tables, before):
        for env in list(table):
            table[env].clear()
            table[env].update(saved.get(env, {}))
    gym.registry.pop(MY_ID, None)
    _drop_my_lab_modules()


@pytest.fixture
def my_lab(registry_restored, monkeypatch):
    """``my_lab.plugins`` imported as a user's package would be (its folder on the path of every process)."""
    from continuum_gym import plugins

    monkeypatch.syspath_prepend(str(EXAMPLES))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(p for p in (str(EXAMPLES), os.environ.get("PYTHONPATH")) if p))
    monkeypatch.delenv(plugins.ENV_VAR, raising=False)
    _drop_my_lab_modules()
    return importlib.import_module("my_lab.plugins")


def _python(code: str, **env_changes) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter (the test's environment, with ``env_changes``; None removes)."""
    env = dict(os.environ)
    for key, value in env_changes.items():
        if value is None:
            env.pop(key, None)
        else:
            env[key] = value
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, env=env,
                          cwd=ROOT)


def _steps_in_a_fresh_interpreter(make: str, reset: str, expected: np.ndarray, tmp_path: Path) -> None:
    """The env built by the expression ``make`` in a new interpreter (no CONTINUUM_GYM_PLUGINS), after the
    statement ``reset``, gives ``expected`` observations under zero actions."""
    code = (f"import pickle, numpy as np, continuum_gym\nenv = {make}\n{reset}\n"
            f"obs = [env.step(np.zeros(env.action_space.shape, dtype=np.float32))[0] for _ in range({len(expected)})]\n"
            f"np.save({str(tmp_path / 'obs.npy')!r}, np.array(obs))\n")
    result = _python(code, CONTINUUM_GYM_PLUGINS=None)
    assert result.returncode == 0, result.stderr[-3000:]
    np.testing.assert_array_equal(np.load(tmp_path / "obs.npy"), expected)


def _zero_steps(env, n: int) -> np.ndarray:
    observations = []
    for _ in range(n):
        observations.append(env.step(np.zeros(env.action_space.shape, dtype=np.float32))[0])
    return np.array(observations)


def test_a_registration_records_its_module_and_configs_refer_to_it(my_lab):
    from continuum_gym import plugins, registry

    for kind, name in (("robot", "mylab-2seg"), ("controller", "mylab_dls"), ("reward term", "mylab_tip_mm"),
                       ("task", "mylab_figure_eight")):
        assert registry.origin_of(kind, BASE, name) == "my_lab.plugins", kind
    assert "my_lab.plugins" in os.environ[plugins.ENV_VAR].split(",")
    config = gym.make(MY_ID).unwrapped.config.to_dict()
    assert config["base_controller"] == "my_lab.plugins:mylab_dls"
    assert config["task"] == "my_lab.plugins:mylab_figure_eight"
    assert config["plugins"] == ["my_lab.plugins"]
    assert config["robot"]["lengths"] == [0.030, 0.025] and config["cone"]["beta"] == pytest.approx(np.radians(35))


def test_code_run_by_exec_has_no_importable_origin(registry_restored, monkeypatch):
    from continuum_gym import plugins
    from continuum_gym.robots import MultiBackboneRobot

    monkeypatch.delenv(plugins.ENV_VAR, raising=False)
    namespace = {"__name__": "notebook_cell", "robot": MultiBackboneRobot(lengths=(0.02,))}
    exec("from continuum_gym.registry import register_robot\nregister_robot('cell-robot', robot)", namespace)
    assert registry_restored.origin_of("robot", BASE, "cell-robot") is None
    assert registry_restored.reference_of("robot", BASE, "cell-robot") == "cell-robot"
    assert plugins.ENV_VAR not in os.environ


def test_a_module_reference_registers_its_plugins_in_a_fresh_process():
    code = (
        "import gymnasium as gym, numpy as np, continuum_gym\n"
        f"env = gym.make({BASE!r}, robot='my_lab.plugins:mylab-2seg', base_controller='my_lab.plugins:mylab_dls')\n"
        "env.reset(seed=0)\n"
        "obs, *_ = env.step(np.zeros(6, dtype=np.float32))\n"
        "print(env.unwrapped.config.base_controller, obs.shape, bool(np.isfinite(obs).all()))\n"
    )
    result = _python(code, PYTHONPATH=str(EXAMPLES), CONTINUUM_GYM_PLUGINS=None)
    assert result.returncode == 0, result.stderr[-3000:]
    assert result.stdout.split() == ["mylab_dls", "(27,)", "True"]


def test_an_env_pickled_with_plugins_steps_identically_in_a_fresh_interpreter(my_lab, tmp_path):
    env = gym.make(MY_ID)
    env.reset(seed=3)
    _zero_steps(env, 2)
    path = tmp_path / "env.pkl"
    path.write_bytes(pickle.dumps(env))
    expected = _zero_steps(env, 3)
    # No CONTINUUM_GYM_PLUGINS: the pickle alone names the module to import.
    _steps_in_a_fresh_interpreter(f"pickle.loads(open({str(path)!r}, 'rb').read())", "", expected, tmp_path)


def test_async_vector_env_spawn_workers_build_the_registered_id(my_lab):
    sync = gym.make_vec(MY_ID, num_envs=2, vectorization_mode="sync")
    spawned = gym.make_vec(MY_ID, num_envs=2, vectorization_mode="async", vector_kwargs={"context": "spawn"})
    native = gym.make_vec(MY_ID, num_envs=2, vectorization_mode="vector_entry_point")
    try:
        np.testing.assert_array_equal(spawned.reset(seed=5)[0], sync.reset(seed=5)[0])
        zeros = np.zeros((2, 6), dtype=np.float32)
        for _ in range(3):
            got, want = spawned.step(zeros), sync.step(zeros)
            np.testing.assert_array_equal(got[0], want[0])
            np.testing.assert_array_equal(got[1], want[1])
        # Gymnasium stacks info["reward_terms"] into a plain array; the wrapper gives it its names back,
        # the same names and values as the library's own vector env.
        assert not hasattr(got[4]["reward_terms"], "names")
        named = NamedRewardTerms(spawned)
        named.reset(seed=5)
        native.reset(seed=5)
        terms, expected = named.step(zeros)[4]["reward_terms"], native.step(zeros)[4]["reward_terms"]
        assert terms.names == expected.names and "mylab_tip_mm" in terms.names
        np.testing.assert_array_equal(terms["mylab_tip_mm"], expected["mylab_tip_mm"])
        np.testing.assert_array_equal(np.asarray(terms), np.asarray(expected))
    finally:
        spawned.close()
        sync.close()
        native.close()


def test_sb3_subproc_vec_env_workers_build_the_registered_id(my_lab):
    from stable_baselines3.common.vec_env import SubprocVecEnv

    # A fresh worker knows no ids: Gymnasium's "module:id" imports the module that registers it. The
    # library's own id with a plug-in's names: its workers import the plug-in's module on the first miss.
    makers = [partial(gym.make, f"my_lab.plugins:{MY_ID}"),
              partial(gym.make, f"continuum_gym:{BASE}", robot="mylab-2seg", cone=my_lab.CONE,
                      base_controller="mylab_dls", task="mylab_figure_eight")]
    venv = SubprocVecEnv(makers, start_method="spawn")
    try:
        venv.seed(0)
        obs = venv.reset()
        assert obs.shape == (2, 27)
        for row, seed in ((0, 0), (1, 1)):  # the same env as here, built both ways (SB3 seeds worker i with 0 + i)
            np.testing.assert_array_equal(obs[row], gym.make(MY_ID).reset(seed=seed)[0])
        obs, rewards, dones, infos = venv.step(np.zeros((2, 6), dtype=np.float32))
        assert np.isfinite(obs).all() and np.isfinite(rewards).all()
        assert "mylab_tip_mm" in infos[0]["reward_terms"]
    finally:
        venv.close()


def test_a_plugin_registered_in_main_fails_elsewhere_saying_where_to_register(registry_restored, monkeypatch, tmp_path):
    from numba import njit

    from continuum_gym import plugins
    from continuum_gym.registry import register_controller

    monkeypatch.delenv(plugins.ENV_VAR, raising=False)

    @njit(cache=False)
    def still(q, gamma, p_des, R_des, v_des, dt, robot, cone, params, out):
        out[:] = 0.0

    namespace = {"__name__": "__main__", "register_controller": register_controller, "still": still}
    exec("register_controller('cell_still', still)", namespace)  # as a script or notebook would
    config = gym.make(BASE, base_controller="cell_still").unwrapped.config
    path = tmp_path / "config.pkl"
    path.write_bytes(pickle.dumps(config))
    result = _python(f"import pickle\npickle.loads(open({str(path)!r}, 'rb').read())", CONTINUUM_GYM_PLUGINS=None)
    assert result.returncode != 0
    message = result.stderr.strip().splitlines()[-1]
    assert "'cell_still' is not registered in this process" in message
    assert "importable module (not __main__ or a notebook)" in message and "--import MODULE" in message


def test_save_config_and_make_from_config_round_trip_a_recorded_task(my_lab, tmp_path):
    import continuum_gym

    rng = np.random.default_rng(0)
    recordings = [my_lab.figure_eight(k, "train", rng) for k in range(2)]
    env = gym.make(MY_ID, task=recordings, max_episode_steps=40)
    path = continuum_gym.save_config(env, tmp_path / "variant.yml")
    assert (tmp_path / "variant.tasks.npz").is_file()
    again = continuum_gym.make_from_config(path)
    assert again.unwrapped.config.to_dict() == env.unwrapped.config.to_dict()  # the recordings' digest included
    assert again.spec.max_episode_steps == 40
    for task_id in (0, 1):
        np.testing.assert_array_equal(env.reset(seed=1, options={"task_id": task_id})[0],
                                      again.reset(seed=1, options={"task_id": task_id})[0])
        np.testing.assert_array_equal(_zero_steps(env, 4), _zero_steps(again, 4))
    # A fresh interpreter (only the folder of my_lab on its path) makes the same env from the two files.
    env.reset(seed=1, options={"task_id": 1})
    expected = _zero_steps(env, 4)
    _steps_in_a_fresh_interpreter(f"continuum_gym.make_from_config({str(path)!r})",
                                  "env.reset(seed=1, options={'task_id': 1})", expected, tmp_path)


def test_config_files_refuse_what_they_cannot_rebuild(tmp_path):
    import continuum_gym

    with pytest.raises(ValueError, match="no config file"):
        continuum_gym.make_from_config(tmp_path / "missing.yml")
    (tmp_path / "other.yml").write_text("a: 1\n")
    with pytest.raises(ValueError, match="not a config file of save_config"):
        continuum_gym.make_from_config(tmp_path / "other.yml")
    with pytest.raises(ValueError, match="must be a continuum-gym environment"):
        continuum_gym.save_config(gym.make("CartPole-v1"), tmp_path / "c.yml")


def test_every_tool_core_is_built_with_the_registered_ids_keywords(my_lab):
    from continuum_gym.evaluation.rollout import make_core

    core = make_core(MY_ID, 2)
    assert core.config == gym.make(MY_ID).unwrapped.config
    assert core.config.robot.lengths == (0.030, 0.025) and core.config.base_controller == "mylab_dls"
    assert make_core(MY_ID, 2, task="random").config.task == "random"  # explicit keywords win


def test_objects_are_taken_as_config_files_write_them():
    from continuum_gym.geometry import LensCone

    cone = LensCone(d_o=5.0e-3, beta=np.radians(35.0))
    written = gym.make(BASE, cone=cone).unwrapped.config.to_dict()["cone"]
    assert written["type"] == "LensCone"
    assert gym.make(BASE, cone=written).unwrapped.config == gym.make(BASE, cone=cone).unwrapped.config
    with pytest.raises(ValueError, match="cannot be rebuilt"):
        gym.make(BASE, cone={"type": "Unknown"})


def test_the_cli_imports_plugins_before_it_reads_any_argument(my_lab, tmp_path):
    hyperparams = tmp_path / "tiny.yml"
    hyperparams.write_text(f"{BASE}:\n  n_envs: 4\n  n_steps: 16\n  batch_size: 32\n  n_epochs: 1\n"
                           "  eval_freq: 64\n  n_eval_episodes: 2\n  checkpoint_freq: 1000\n"
                           "  env_kwargs: {task: hold, visibility_guard: 0.5}\n")
    command = [sys.executable, "-m", "continuum_gym.cli", "train", "--env", MY_ID, "--steps", "128", "--out",
               str(tmp_path / "runs"), "--no-progress", "--hyperparams", str(hyperparams)]
    from continuum_gym import plugins

    clean = {k: v for k, v in os.environ.items() if k != plugins.ENV_VAR}  # as a new shell would have it
    unknown = subprocess.run(command, capture_output=True, text=True, timeout=600, cwd=ROOT, env=clean)
    assert unknown.returncode == 2 and "unknown env id 'MyLab/Occlusion2Seg-v0'" in unknown.stderr
    missing = subprocess.run([*command, "--import", "my_lab.nothing"], capture_output=True, text=True, timeout=600,
                             cwd=ROOT, env=clean)
    assert missing.returncode == 2 and "--import module 'my_lab.nothing' cannot be imported" in missing.stderr
    result = subprocess.run([*command, "--import", "my_lab.plugins"], capture_output=True, text=True, timeout=900,
                            cwd=ROOT, env=clean)
    assert result.returncode == 0, result.stderr[-3000:]
    assert f"no block for {MY_ID!r}; using the block of {BASE!r}" in result.stderr
    import yaml

    run = tmp_path / "runs" / "Occlusion2Seg_ppo_mylab_dls_seed0"
    config = yaml.safe_load((run / "config.yml").read_text())
    assert config["base_controller"] == "mylab_dls"
    env_config = config["env_config"]
    assert env_config["base_controller"] == "my_lab.plugins:mylab_dls"
    assert env_config["task"] == "my_lab.plugins:mylab_figure_eight"  # the id's task, not the block's "hold"
    assert env_config["visibility_guard"] == 0.5  # the block's keyword the id does not set
    assert env_config["robot"]["lengths"] == [0.030, 0.025]
    history = np.load(run / "evaluations.npz")
    assert history["timesteps"].size >= 1  # the training-time evaluation ran in the variant's env


def test_evaluate_gives_a_registered_controller_its_row_and_measures_headroom_against_it(my_lab, tmp_path):
    """A residual trained on the user's controller: its baseline row, its row, headroom against that base."""
    from continuum_gym.agents.train import train
    from continuum_gym.evaluation.evaluate import evaluate_methods
    from continuum_gym.evaluation.methods import discover_policies
    from continuum_gym.evaluation.tables import HEADROOM

    hyperparams = tmp_path / "tiny.yml"
    hyperparams.write_text(f"{BASE}:\n  n_envs: 4\n  n_steps: 16\n  batch_size: 32\n  n_epochs: 1\n"
                           "  eval_freq: 1000\n  n_eval_episodes: 2\n  checkpoint_freq: 1000\n")
    train(MY_ID, steps=64, out=tmp_path / "runs", progress=False, hyperparams=hyperparams)
    table, results, _ = evaluate_methods(MY_ID, [], discover_policies(tmp_path / "runs"), episodes=2,
                                         split="validation", progress=False)
    assert list(table) == ["minimum_norm", "projected_gradient", "mylab_dls", "residual_mylab_dls", "offline_optimum"]
    assert HEADROOM not in table["mylab_dls"]
    hold = {m: float(np.mean(np.stack(results[m]["hold"]["scores"]["mean_voi"]))) for m in results}
    optimum = table["offline_optimum"]["mean_voi"]["mean"]
    expected = (hold["residual_mylab_dls"] - hold["mylab_dls"]) / (optimum - hold["mylab_dls"])
    assert table["residual_mylab_dls"][HEADROOM]["mean"] == pytest.approx(expected, rel=1e-12)
    # a base other than the headline baseline's: the projected gradient's would give another number
    assert hold["mylab_dls"] != hold["projected_gradient"]


def test_datasets_and_renders_of_a_registered_id_are_of_its_variant(my_lab, tmp_path, monkeypatch):
    """continuum-gym dataset records the id's own base by default, in the id's env; render takes its task."""
    from continuum_gym.cli import main
    from continuum_gym.evaluation.datasets import create_dataset

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    dataset = create_dataset(MY_ID, "mylab_dls", episodes=1, root=tmp_path / "minari")
    assert dataset.spec.dataset_id == "continuum-gym/Occlusion2Seg/mylab_dls-train-v0"
    episode = next(iter(dataset.iterate_episodes()))
    assert episode.observations.shape[1] == 27 and episode.actions.shape[1] == 6  # the 2-segment robot
    env = gym.make(MY_ID, base_controller="mylab_dls", task_split="train")
    first, _ = env.reset(seed=0, options={"task_id": 0})
    np.testing.assert_array_equal(episode.observations[0], first)
    with pytest.raises(ValueError, match="controller must be one of"):
        create_dataset(MY_ID, "nope", episodes=1, root=tmp_path / "minari")
    assert main(["render", "--env", MY_ID, "--steps", "2", "--out", str(tmp_path / "still.png")]) == 0
    assert main(["render", "--env", MY_ID, "--steps", "2", "--task", "circle", "--out", str(tmp_path / "c.png")]) == 2


def test_the_optimum_command_computes_a_registered_variants_own_ceiling(my_lab, tmp_path, monkeypatch):
    import json

    from continuum_gym.cli import main
    from continuum_gym.evaluation.optimum.cache import load_optimum_cache
    from continuum_gym.evaluation.optimum.occlusion import env_hold_test_optimum

    monkeypatch.setenv("CONTINUUM_GYM_CACHE", str(tmp_path / "cache"))
    path = tmp_path / "optimum.json"
    assert main(["optimum", "--env", MY_ID, "--env-hold-tasks", "3", "--no-progress", "--json", str(path)]) == 0
    got = json.loads(path.read_text())["hold_test"]["optimum_voi"]
    config = gym.make(MY_ID).unwrapped.config
    direct = env_hold_test_optimum(3, limits=config.limits, robot=my_lab.ROBOT, cone=my_lab.CONE, progress=False)
    assert got == direct["optimum_voi"]
    assert got != load_optimum_cache()["hold_test"]["optimum_voi"][:3]  # not the paper robot's ceiling
    assert main(["optimum", "--env", MY_ID, "--task", "coverage"]) == 2
