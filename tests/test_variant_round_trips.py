"""A researcher's variant survives every round trip, in a fresh process (issue 54, items 2, 3 and 9).

The variant is ``tests/variant_lab`` (a 4-segment robot, a 45-degree lens, an own controller, reward term and
recorded helix task, a plain and a goal id). One process makes each front end from its registered id, steps it
and writes a config file (``save_config``) and a Minari dataset of it; another process, which has never
imported the variant (no ``CONTINUUM_GYM_PLUGINS`` either), remakes each from the file alone
(``make_from_config``) or from the dataset alone (``recover_environment``) and must get the same id, the same
front end and the same observations, bit for bit.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import gymnasium as gym
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _python(code: str, tmp_path: Path, prelude: str = "", **env_changes: str) -> str:
    env = {key: value for key, value in os.environ.items() if key != "CONTINUUM_GYM_PLUGINS"}
    env.update({"PYTHONPATH": str(ROOT), "MINARI_DATASETS_PATH": str(tmp_path / "minari"), **env_changes})
    result = subprocess.run([sys.executable, "-c", prelude + textwrap.dedent(code)], cwd=tmp_path, env=env, capture_output=True,
                            text=True, timeout=900)
    assert result.returncode == 0, result.stderr[-3000:]
    return result.stdout


ROLLOUT = """
import numpy as np

def rollout(env, vector=False, steps=12):
    # the first observations of a seeded episode under seeded actions, flattened (a Dict observation by key)
    obs, _ = env.reset(seed=5)
    rng = np.random.default_rng(0)
    out = []
    for _ in range(steps):
        out.append(obs)
        shape = env.action_space.shape
        obs, *_ = env.step(rng.uniform(-0.5, 0.5, shape).astype(np.float32))
    flat = lambda o: np.concatenate([np.ravel(o[k]) for k in sorted(o)]) if isinstance(o, dict) else np.ravel(o)
    return np.stack([flat(o) for o in out])
"""


def test_config_files_and_datasets_of_a_variant_rebuild_it_in_a_fresh_process(tmp_path):
    _python("""
        import gymnasium as gym
        import continuum_gym
        import tests.variant_lab as lab
        from continuum_gym.evaluation.datasets import create_dataset

        made = {"plain": gym.make(lab.ENV_ID), "goal": gym.make(lab.GOAL_ID),
                "vector": gym.make_vec(lab.ENV_ID, num_envs=3, vectorization_mode="vector_entry_point")}
        for name, env in made.items():
            np.save(f"{name}.npy", rollout(env))
            continuum_gym.save_config(env, f"{name}.yml")
        for env_id in (lab.ENV_ID, lab.GOAL_ID):
            create_dataset(env_id, "lab_dls", episodes=2, noise=0.2, seed=7)
    """, tmp_path, ROLLOUT)
    out = _python("""
        import json, sys
        import minari
        import continuum_gym

        assert "tests.variant_lab" not in sys.modules
        report = {}
        for name in ("plain", "goal", "vector"):
            env = continuum_gym.make_from_config(f"{name}.yml")
            same = bool(np.array_equal(rollout(env), np.load(f"{name}.npy")))
            report[name] = [env.spec.id, type(env.unwrapped).__name__, getattr(env, "num_envs", 1), same]
        for dataset_id in ("continuum-gym/Occ4Seg/lab_dls-train-noise0p2-v0",
                           "continuum-gym/Occ4SegGoal/lab_dls-train-noise0p2-v0"):
            dataset = minari.load_dataset(dataset_id)
            env = dataset.recover_environment()
            replayed = []
            for k, episode in enumerate(dataset.iterate_episodes()):
                obs, _ = env.reset(seed=7 + k, options={"task_id": k})
                for action in episode.actions:
                    obs, *_ = env.step(action)
                last = episode.observations
                last = {key: value[-1] for key, value in last.items()} if isinstance(last, dict) else last[-1]
                flat = lambda o: np.concatenate([np.ravel(o[key]) for key in sorted(o)]) if isinstance(o, dict) else o
                replayed.append(bool(np.array_equal(flat(obs), flat(last))))
            report[dataset_id] = [env.spec.id, type(env.unwrapped).__name__, replayed,
                                  env.unwrapped.config.robot.n_segments, env.unwrapped.config.base_controller]
        print(json.dumps(report))
    """, tmp_path, ROLLOUT)
    report = json.loads(out.strip().splitlines()[-1])
    assert report["plain"] == ["LabTest/Occ4Seg-v0", "OcclusionAvoidanceEnv", 1, True]
    assert report["goal"] == ["LabTest/Occ4SegGoal-v0", "OcclusionAvoidanceGoalEnv", 1, True]
    assert report["vector"] == ["LabTest/Occ4Seg-v0", "OcclusionAvoidanceVectorEnv", 3, True]
    plain, goal = report["continuum-gym/Occ4Seg/lab_dls-train-noise0p2-v0"], \
        report["continuum-gym/Occ4SegGoal/lab_dls-train-noise0p2-v0"]
    assert plain == ["LabTest/Occ4Seg-v0", "OcclusionAvoidanceEnv", [True, True], 4, "lab_dls"]
    assert goal == ["LabTest/Occ4SegGoal-v0", "OcclusionAvoidanceGoalEnv", [True, True], 4,
                    "lab_dls"]


def test_a_saved_config_keeps_the_variant_id_and_goal_front_end_in_this_process(tmp_path):
    import continuum_gym

    env = gym.make("ContinuumGym/ViewTrackingGoal-v0", reward_type="sparse", or_threshold=0.7, task="pan_tilt")
    path = continuum_gym.save_config(env, tmp_path / "goal.yml")
    again = continuum_gym.make_from_config(path)
    assert again.spec.id == "ContinuumGym/ViewTrackingGoal-v0"
    assert isinstance(again.observation_space, gym.spaces.Dict)
    assert (again.unwrapped.reward_type, again.unwrapped.or_threshold) == ("sparse", 0.7)
    assert again.unwrapped.config.to_dict() == env.unwrapped.config.to_dict()


def _entry_point_dist(directory: Path, module: str) -> None:
    """An installed distribution (a .dist-info on the path) declaring ``module`` in the plug-in group."""
    info = directory / "lab_variant-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: lab-variant\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[continuum_gym.plugins]\nlab = {module}\n")


@pytest.mark.parametrize("how", ["environment variable", "entry point"])
def test_plain_python_sees_a_plugins_ids_after_import_continuum_gym(tmp_path, how):
    changes = {}
    if how == "environment variable":
        changes["CONTINUUM_GYM_PLUGINS"] = "tests.variant_lab"
    else:
        _entry_point_dist(tmp_path / "site", "tests.variant_lab")
        changes["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(tmp_path / "site")])
    out = _python("""
        import gymnasium as gym
        import continuum_gym
        env = gym.make("LabTest/Occ4Seg-v0")
        print(env.spec.id, env.unwrapped.config.robot.n_segments)
    """, tmp_path, **changes)
    assert out.split() == ["LabTest/Occ4Seg-v0", "4"]


def test_a_plugin_module_that_fails_to_import_is_named_and_the_library_still_works(tmp_path):
    out = _python("""
        import warnings
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            import continuum_gym
        import gymnasium as gym
        gym.make("ContinuumGym/ViewTracking-v0")
        print([str(w.message) for w in caught if "plug-in" in str(w.message)])
    """, tmp_path, CONTINUUM_GYM_PLUGINS="no_such_lab.plugins")
    assert "no_such_lab.plugins" in out and "cannot be imported" in out
