"""ViewTracking's helper ``overlap_polish``: the lookahead on the overlap ratio never lowers the next step's OR on a
static target and changes nothing below its OR threshold; it is named wherever it acts (the single env's wrapper,
the SB3 vector env, training's ``helpers`` key, evaluate's rows), and bad names are rejected by name."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from continuum_gym.envs.helpers import HelperWrapper, apply_helpers, check_helpers, make_helpers
from continuum_gym.envs.view_tracking.env import ViewTrackingCore
from continuum_gym.envs.view_tracking.outputs import Metric
from continuum_gym.envs.view_tracking.polish import POLISH_MIN_OR

ENV = "ContinuumGym/ViewTracking-v0"
N = 48


def test_polish_never_lowers_the_next_overlap_and_acts_only_above_its_threshold():
    kwargs = dict(task="static", task_split="validation", residual_scale=3.0, residual_space="joint")
    polished, plain = ViewTrackingCore(N, **kwargs), ViewTrackingCore(N, **kwargs)
    (polish,) = make_helpers(ENV, ["overlap_polish"], polished.config)
    ids = np.arange(N)
    active = np.ones(N, dtype=np.uint8)
    zero = np.zeros((N, 6))
    for core in (polished, plain):  # the same warm-up on the base alone: identical states
        core.reset_rows(ids, ids)
        for _ in range(150):
            core.step(zero, active)
    np.testing.assert_array_equal(polished.q, plain.q)
    rng = np.random.default_rng(7)
    improved = 0
    for _ in range(5):
        actions = np.clip(rng.normal(0.0, 0.3, (N, 6)), -1.0, 1.0)
        before = polished.metrics[:, Metric.OR].copy()
        polished.step(apply_helpers((polish,), polished.obs, actions, active), active)
        plain.step(actions, active)
        after, reference = polished.metrics[:, Metric.OR], plain.metrics[:, Metric.OR]
        assert np.all(after >= reference - 1e-9)
        below = before < POLISH_MIN_OR
        np.testing.assert_array_equal(after[below], reference[below])  # untouched below the threshold
        improved += int(np.sum(after > reference + 1e-6))
        # the next step starts from the same states again
        plain.q[:] = polished.q
        plain.steps[:] = polished.steps
        plain.observe_rows(ids)
    assert improved > 0  # it does act: an active lookahead that never changed anything would pass the rest


def test_the_helpers_keep_the_policys_dtype_and_skip_inactive_rows():
    core = ViewTrackingCore(4, task="static", residual_space="joint", residual_scale=3.0)
    core.reset_rows(np.arange(4), np.arange(4))
    helpers = make_helpers(ENV, ["overlap_polish"], core.config)
    actions = np.full((4, 6), 0.1, dtype=np.float32)
    out = apply_helpers(helpers, core.obs, actions, np.zeros(4, dtype=np.uint8))
    assert out.dtype == np.float32
    np.testing.assert_array_equal(out, actions)  # no active row: not a bit changed
    assert apply_helpers((), core.obs, actions, np.ones(4, dtype=np.uint8)) is actions


def test_the_wrapper_and_the_sb3_vector_env_apply_the_helper_as_evaluation_does():
    """The same polished actions, hence the same trajectories, from HelperWrapper(gym.make) and the SB3 vector env's
    ``helpers``; the env without the helper goes elsewhere."""
    from continuum_gym.envs.sb3 import ContinuumSB3VecEnv

    kwargs = dict(task="static", residual_space="joint", residual_scale=3.0)
    single = HelperWrapper(gym.make(ENV, **kwargs), ["overlap_polish"])
    vec = ContinuumSB3VecEnv(ENV, 1, seed=10, helpers=["overlap_polish"], **kwargs)
    obs_single, _ = single.reset(seed=10)
    obs_vec = vec.reset()
    np.testing.assert_array_equal(obs_single, obs_vec[0])
    bare = gym.make(ENV, **kwargs)
    bare.reset(seed=10)  # a static target the base holds at OR > 0.9 (seed 10): the lookahead acts there
    rng = np.random.default_rng(0)
    differ = 0
    for _ in range(200):
        action = rng.uniform(-0.05, 0.05, 6).astype(np.float32)  # near the base: OR above the threshold
        obs_single, *_ = single.step(action)
        obs_vec, *_ = vec.step(action[None])
        obs_bare, *_ = bare.step(action)
        np.testing.assert_array_equal(obs_single, obs_vec[0])
        differ += int(not np.array_equal(obs_single, obs_bare))
    assert differ > 0


@pytest.mark.parametrize("names, match", [(["polish"], "not a helper of .*overlap_polish"),
                                          ("overlap_polish", "a list of helper names"),
                                          ([3], "not a helper")])
def test_bad_helper_names_are_named(names, match):
    with pytest.raises(ValueError, match=match):
        check_helpers(ENV, names)


def test_polish_needs_a_joint_residual():
    core = ViewTrackingCore(1, residual_space="target")
    with pytest.raises(ValueError, match="overlap_polish.*residual_space='joint'"):
        make_helpers(ENV, ["overlap_polish"], core.config)
    with pytest.raises(ValueError, match="overlap_polish"):
        gym.make(ENV, overlap_polish=0.05)  # the 0.2 env option is gone, by name


def test_rows_say_what_acts(tmp_path):
    """A run with helpers is ``residual_<base>+<helper>``; its base row carries the helpers and a zero residual,
    and the learned row without them is beside it (evaluate's ``beside_rows``)."""
    import yaml

    from continuum_gym.evaluation.methods import (
        MethodRun,
        beside_rows,
        discover_policies,
        method_name,
        trained_bases,
    )

    assert method_name("dimension_reduced", "sac", ["overlap_polish"]) == "residual_dimension_reduced_sac+overlap_polish"
    run = tmp_path / "run"
    run.mkdir()
    (run / "model.zip").write_bytes(b"")
    # a 0.2 run: the option in env_config; read as the helper
    (run / "config.yml").write_text(yaml.safe_dump({"env_id": ENV, "algo": "ppo", "base_controller":
                                                    "dimension_reduced", "env_config": {"overlap_polish": 0.05}}))
    assert list(discover_policies(tmp_path)[ENV]) == ["residual_dimension_reduced+overlap_polish"]
    learned = [("residual_dimension_reduced+overlap_polish",
                [MethodRun("policy", {"base_controller": "dimension_reduced", "residual_scale": 2.0},
                           helpers=("overlap_polish",))])]
    bases, ablations = beside_rows(learned)
    assert [name for name, _ in bases] == ["dimension_reduced+overlap_polish"]
    base_run = bases[0][1][0]
    assert base_run.policy is None and base_run.helpers == ("overlap_polish",)
    assert base_run.env_kwargs["residual_scale"] == 2.0  # the helper's reach is the run's residual scale
    assert [name for name, _ in ablations] == ["residual_dimension_reduced"]
    assert ablations[0][1][0].helpers == () and ablations[0][1][0].policy == "policy"
    assert trained_bases(learned + bases + ablations) == {
        "residual_dimension_reduced+overlap_polish": "dimension_reduced+overlap_polish",
        "dimension_reduced+overlap_polish": "dimension_reduced+overlap_polish",
        "residual_dimension_reduced": "dimension_reduced"}


def test_training_names_its_helpers(tmp_path):
    """``helpers`` in a hyperparameter block: checked by name, in the run's folder name and its config.yml."""
    import yaml

    from continuum_gym.agents.train import train

    block = {"policy": "MlpPolicy", "n_envs": 4, "n_steps": 8, "batch_size": 32, "n_epochs": 1, "eval_freq": 32,
             "n_eval_episodes": 2, "checkpoint_freq": 1000, "residual_scale": 2.0,
             "env_kwargs": {"task": "static", "residual_space": "joint"}}
    bad = tmp_path / "bad.yml"
    bad.write_text(yaml.safe_dump({ENV: {**block, "helpers": ["polsh"]}}))
    with pytest.raises(ValueError, match="bad.yml.*'polsh' is not a helper.*overlap_polish"):
        train(ENV, "ppo", "dimension_reduced", steps=32, out=tmp_path / "runs", hyperparams=bad, progress=False)
    good = tmp_path / "good.yml"
    good.write_text(yaml.safe_dump({ENV: {**block, "helpers": ["overlap_polish"]}}))
    run = train(ENV, "ppo", "dimension_reduced", steps=32, out=tmp_path / "runs", hyperparams=good, progress=False)
    assert run.name == "ViewTracking_ppo_dimension_reduced+overlap_polish_seed0"
    config = yaml.safe_load((run / "config.yml").read_text())
    assert config["helpers"] == ["overlap_polish"]
    from continuum_gym.evaluation.methods import discover_policies

    assert list(discover_policies(tmp_path / "runs")[ENV]) == ["residual_dimension_reduced+overlap_polish"]


def test_run_folders_name_the_mode_then_the_helpers():
    from continuum_gym.agents.train import run_name

    assert run_name(ENV, "ppo", "dimension_reduced", 1, ["overlap_polish"], "rgbd") == \
        "ViewTracking_ppo_dimension_reduced_rgbd+overlap_polish_seed1"
    # the pixel campaign's folders keep their names
    assert run_name("ContinuumGym/OcclusionAvoidance-v0", "ppo", "projected_gradient", 0, (), "rgbd") == \
        "OcclusionAvoidance_ppo_projected_gradient_rgbd_seed0"
