"""Probability of improvement, training cost and learning curves of the reference runs (``reference-runs/``).

The reference runs are part of the repository: these tests read them, and ``continuum-gym evaluate
--policies reference-runs`` must find every row of the reference table in that layout.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rliable import metrics

from continuum_gym.envs.benchmark import benchmark_of
from continuum_gym.envs.spec import get_spec
from continuum_gym.evaluation.comparison import (
    IMPROVEMENT,
    TRAINING,
    _improvement,
    probability_of_improvement,
    read_wall_clock,
    training_cost,
)
from continuum_gym.evaluation.evaluate import evaluate_methods
from continuum_gym.evaluation.figures import draw_learning_curves, learning_curves
from continuum_gym.evaluation.methods import discover_policies

ROOT = Path(__file__).resolve().parents[2]
REFERENCE = ROOT / "reference-runs"
OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"
#: The reference table's learned rows per env: {method: (algo, seeds)}.
ROWS = {OCCLUSION: {"residual_projected_gradient": 5, "residual_projected_gradient_sac": 5,
                    "residual_projected_gradient_td3": 5, "pure_rl": 3, "pure_rl_sac": 3},
        VIEW: {"residual_dimension_reduced": 5, "residual_dimension_reduced_sac": 5,
               "residual_dimension_reduced_td3": 5, "pure_rl": 3, "pure_rl_sac": 3}}


def test_the_vectorised_improvement_is_rliables_definition():
    rng = np.random.default_rng(3)
    for runs_x, runs_y, tasks in ((5, 1, 40), (3, 4, 7), (1, 1, 12)):
        x = rng.normal(size=(runs_x, tasks)).round(1)  # rounded: ties occur and count one half
        y = rng.normal(size=(runs_y, tasks)).round(1)
        assert _improvement(x, y) == pytest.approx(metrics.probability_of_improvement(x, y), abs=1e-12)


def test_probability_of_improvement_direction_ties_and_interval():
    rng = np.random.default_rng(0)
    y = rng.normal(size=(1, 50))
    better = probability_of_improvement(y + 1.0, y)
    assert better["mean"] == 1.0 and better["ci_low"] == 1.0
    same = probability_of_improvement(y, y)
    assert same["mean"] == 0.5 and same["ci_low"] == same["ci_high"] == 0.5
    x = y + rng.normal(scale=2.0, size=(5, 50))
    up, down = probability_of_improvement(x, y), probability_of_improvement(x, y, higher_is_better=False)
    assert up["mean"] + down["mean"] == pytest.approx(1.0)  # no ties: lower-is-better is the complement
    assert 0.0 <= up["ci_low"] < up["mean"] < up["ci_high"] <= 1.0
    assert probability_of_improvement(x, y, seed=1) != probability_of_improvement(x, y, seed=2)
    assert probability_of_improvement(x, y, seed=1) == probability_of_improvement(x, y, seed=1)
    with pytest.raises(ValueError, match="same tasks"):
        probability_of_improvement(x, y[:, :10])


def state_rows(found: dict) -> dict:
    """The reference table's rows: the pixel campaign's runs (``_rgbd``, issue 56) are rows of their own."""
    return {env: {m: runs for m, runs in methods.items() if not m.endswith("_rgbd")} for env, methods in found.items()}


def test_reference_runs_hold_every_row_of_the_table_with_curves_and_wall_clock():
    found = state_rows(discover_policies(REFERENCE))
    assert set(found) == set(ROWS)
    for env_id, rows in ROWS.items():
        assert {method: len(runs) for method, runs in found[env_id].items()} == rows
        for runs in found[env_id].values():
            for run in runs:
                cost = training_cost(run)
                assert cost["env_steps"] >= 1_000_000 and 60 < cost["wall_clock_s"] < 1500
                steps, elapsed = read_wall_clock(run)
                with np.load(run / "evaluations.npz") as data:
                    assert steps.tolist() == data["timesteps"].tolist()  # one time per evaluation
                assert np.all(np.diff(elapsed) > 0)


def test_the_pixel_campaigns_runs_see_images_at_their_stated_budget():
    """Each committed run of the pixel campaign (reference-runs/README.md) was trained on rgbd images at 64 x 64
    with the packaged pixel configuration, for its budget (OcclusionAvoidance 2 M, ViewTracking 1.2 M steps)."""
    import yaml

    budget = {OCCLUSION: 2_000_000, VIEW: 1_200_000}
    runs = [(env, run) for env, methods in discover_policies(REFERENCE).items() for method, found in methods.items()
            if method.endswith("_rgbd") for run in found]
    for env_id, run in runs:
        config = yaml.safe_load((run / "config.yml").read_text())
        assert config["env_config"]["obs_mode"] == "rgbd" and config["env_config"]["image_size"] == 64
        assert config["hyperparams"]["policy_kwargs"]["features_extractor_class"].endswith("PixelEncoder")
        assert training_cost(run)["env_steps"] >= budget[env_id]
        assert (run / "model.zip").stat().st_size < 5_000_000  # the final model without its last image batch


def test_learning_curves_of_the_reference_runs_against_steps_and_wall_clock(tmp_path):
    spec = get_spec(VIEW)
    policies = state_rows(discover_policies(REFERENCE))
    curves = learning_curves(policies, VIEW, benchmark_of(spec).headline_metric)
    assert set(curves) == set(ROWS[VIEW])
    steps, values, elapsed = curves["residual_dimension_reduced_sac"]
    assert values.shape == elapsed.shape == (5, len(steps)) and steps[-1] == 1_000_000
    assert curves["residual_dimension_reduced"][0][-1] == 3_006_464  # PPO's 3M budget, whole rollouts
    path = draw_learning_curves(spec, policies, tmp_path / "curves.png", VIEW)
    assert path.is_file() and path.stat().st_size < 150_000


def test_evaluate_on_the_reference_layout_gives_every_learned_row_its_algo_seeds_improvement_and_cost():
    """One seed of each row (the layout, not the numbers: validation split, one episode per task set)."""
    found = discover_policies(REFERENCE)
    policies = {OCCLUSION: {method: runs[:1] for method, runs in found[OCCLUSION].items()}}
    table, _, meta = evaluate_methods(OCCLUSION, [], policies, episodes=1, split="validation", progress=False,
                                      references=False)
    assert not meta["skipped"]
    for method in ROWS[OCCLUSION]:
        row = table[method]
        assert row["algo"] == (method.rsplit("_", 1)[1] if method.endswith(("_sac", "_td3")) else "ppo")
        assert row["n_seeds"] == 1
        assert row[IMPROVEMENT]["over"] == "projected_gradient" and 0.0 <= row[IMPROVEMENT]["mean"] <= 1.0
        assert row[TRAINING]["env_steps_per_run"][0] >= 1_000_000
    assert IMPROVEMENT not in table["projected_gradient"] and TRAINING not in table["minimum_norm"]



def test_the_cost_a_run_recorded_reaches_the_table_and_runs_without_it_keep_their_entry(tmp_path):
    """Runs that record ``cpu_s`` (``continuum-gym train`` does) get a CPU column in core-hours; a table of runs
    that did not is what it was (the shipped policies' rows, the golden files)."""
    from continuum_gym.evaluation.comparison import add_training, comparison_markdown

    for name, cpu in (("a", [0.0, 3600.0, 7200.0]), ("b", [0.0, 1800.0, 5400.0]), ("old", None)):
        columns = {"timesteps": np.array([4, 1000, 2000]), "mean_return": np.zeros(3), "mean_or": np.zeros(3)}
        if cpu is not None:
            columns |= {"cpu_s": np.array(cpu), "wall_s": np.array(cpu) * 2}
        (tmp_path / name).mkdir()
        np.savez(tmp_path / name / "evaluations.npz", **columns)
    table = {"timed": {"algo": "ppo", "n_seeds": 2}, "untimed": {"algo": "ppo", "n_seeds": 1}}
    add_training(table, [("timed", [tmp_path / "a", tmp_path / "b"]), ("untimed", [tmp_path / "old"])])
    assert table["timed"][TRAINING] == {"env_steps_per_run": [2000, 2000], "wall_clock_s_per_run": [14400.0, 10800.0],
                                        "wall_clock_s_mean": 12600.0, "cpu_s_per_run": [7200.0, 5400.0]}
    assert table["untimed"][TRAINING] == {"env_steps_per_run": [2000], "wall_clock_s_per_run": [None]}
    text = comparison_markdown(get_spec(VIEW), table)
    assert "CPU per run (core-hours)" in text and "| 1.75 (range 1.50-2.00) |" in text
    assert "CPU per run" not in comparison_markdown(get_spec(VIEW), {"untimed": table["untimed"]})
