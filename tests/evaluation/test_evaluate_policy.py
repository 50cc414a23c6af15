"""evaluate_policy and ``evaluate --policy``: any policy, scored exactly like the baselines and SB3 runs."""

from __future__ import annotations

import json
import sys
import textwrap

import numpy as np
import pytest
import torch

from continuum_gym.cli import main
from continuum_gym.evaluation import evaluate_policy
from continuum_gym.evaluation.evaluate import evaluate_methods, write_results
from continuum_gym.evaluation.methods import MethodRun
from continuum_gym.evaluation.policies import (
    PolicyError,
    as_predictor,
    load_entry_point,
)
from continuum_gym.evaluation.rollout import make_core, run_episodes

VIEW = "ContinuumGym/ViewTracking-v0"
OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
STATS = ("mean", "iqm", "ci_low", "ci_high")


def rows_equal(a: dict, b: dict) -> bool:
    metrics = [m for m in a if isinstance(a[m], dict) and all(k in a[m] for k in STATS)]  # not e.g. the
    return all(a[m][k] == b[m][k] for m in metrics for k in STATS)  # probability of improvement (learned rows only)


def test_a_zero_callable_gives_exactly_the_headline_baselines_row(tmp_path):
    table = evaluate_policy(lambda obs: np.zeros((obs.shape[0], 6)), VIEW, name="zero", episodes=2, grid=3,
                            progress=False, out=tmp_path)
    assert set(table) >= {"resolved_rate", "dimension_reduced", "zero"}
    assert rows_equal(table["dimension_reduced"], table["zero"])
    assert not rows_equal(table["resolved_rate"], table["zero"])
    # headroom of a policy equal to its base is zero by definition (when the optimum differs from the base)
    written = json.loads((tmp_path / "results.json").read_text())
    assert written[VIEW]["zero"]["mean_or"] == table["zero"]["mean_or"]
    meta = written["metadata"][VIEW]
    assert meta["protocol"] == "benchmark-v1" and meta["split"] == "test"
    assert meta["task_sets"]["coverage"]["instances"] == 9 and meta["task_sets"]["random"]["instances"] == 2
    assert "zero" in (tmp_path / "results.md").read_text()


class CleanRLActor(torch.nn.Module):
    """The actor of a CleanRL-style PPO agent, holding the weights of an SB3 policy."""

    def __init__(self, model):
        super().__init__()
        self.actor_mean = torch.nn.Sequential(*model.policy.mlp_extractor.policy_net, model.policy.action_net)

    def forward(self, obs):
        return self.actor_mean(obs)


def numpy_policy(model):
    """The same weights as a plain numpy callable (float32, like torch)."""
    layers = [m for m in (*model.policy.mlp_extractor.policy_net, model.policy.action_net)
              if isinstance(m, torch.nn.Linear)]
    weights = [(layer.weight.detach().numpy().T.copy(), layer.bias.detach().numpy().copy()) for layer in layers]

    def act(obs):
        x = obs.astype(np.float32)
        for i, (w, b) in enumerate(weights):
            x = x @ w + b
            if i < len(weights) - 1:
                x = np.tanh(x)
        return x
    return act


def test_torch_numpy_and_sb3_wrappings_of_the_same_weights_give_the_same_numbers():
    """Same weights, three wrappings. torch and SB3 run the same float32 graph: equal to the bit. numpy sums
    in another order (actions 1e-9 apart), equal to 1e-9 on OcclusionAvoidance, whose closed loop is smooth.
    (On ViewTracking the bases' clamping and dimension-reduced IK amplify a 1e-9 action difference to
    ~1e-2 OR within 100 steps, so only bit-identical policies give bit-identical rows there.)"""
    from stable_baselines3 import PPO

    from continuum_gym.envs.sb3 import ContinuumSB3VecEnv

    vec = ContinuumSB3VecEnv(OCCLUSION, num_envs=2, seed=0)
    model = PPO("MlpPolicy", vec, seed=3, device="cpu", policy_kwargs={"net_arch": [32, 32]})
    with torch.no_grad():  # actions large enough to change the result
        model.policy.action_net.weight.mul_(20.0)
    extra = [("sb3", [MethodRun(model, {})]), ("torch", [MethodRun(CleanRLActor(model), {})]),
             ("numpy", [MethodRun(numpy_policy(model), {})])]
    table, _, meta = evaluate_methods(OCCLUSION, extra, episodes=2, progress=False, references=False)
    assert rows_equal(table["sb3"], table["torch"])
    for metric in ("mean_voi", "mean_tip_error_m", "tip_in_view_fraction"):
        assert table["numpy"][metric]["mean"] == pytest.approx(table["sb3"][metric]["mean"], rel=1e-8, abs=1e-9)
    assert abs(table["sb3"]["mean_voi"]["mean"] - table["projected_gradient"]["mean_voi"]["mean"]) > 1e-5
    assert meta["action_clipped_fraction"]["torch"] == meta["action_clipped_fraction"]["numpy"]


def test_actions_outside_the_box_are_clipped_and_counted():
    rows = [0, 1]
    inside = run_episodes(make_core(VIEW, 2, task="random", task_split="validation"),
                          lambda obs: np.ones((obs.shape[0], 6)), rows)
    outside = run_episodes(make_core(VIEW, 2, task="random", task_split="validation"),
                           lambda obs: np.tile([2.0, 1.0, 1.0, 1.0, 1.0, 5.0], (obs.shape[0], 1)), rows)
    assert np.array_equal(inside["mean_or"], outside["mean_or"])
    assert np.all(inside["action_clipped_fraction"] == 0.0)
    assert np.allclose(outside["action_clipped_fraction"], 2 / 6)


@pytest.mark.parametrize("answer, message", [
    (lambda obs: np.zeros((obs.shape[0], 5)), r"shape \(2, 5\).*expected \(2, 6\)"),
    (lambda obs: np.full((obs.shape[0], 6), np.nan), "non-finite action at step 0, row 0"),
    (lambda obs: [["a"] * 6] * obs.shape[0], "not numbers"),
])
def test_a_bad_answer_is_a_named_error(answer, message):
    core = make_core(VIEW, 2, task="random", task_split="validation")
    with pytest.raises(PolicyError, match="'mine'.*" + message):
        run_episodes(core, as_predictor(answer, "mine"), [0, 1])


def test_a_policy_that_fails_is_reported_not_a_crash_of_the_other_methods():
    calls = []

    def fails_later(obs):
        calls.append(1)
        return np.zeros((obs.shape[0], 6)) if len(calls) < 5 else np.full((obs.shape[0], 6), np.inf)

    table, _, meta = evaluate_methods(VIEW, [("flaky", [MethodRun(fails_later, {}, "lab/flaky.zip")])], episodes=1, grid=2,
                                      progress=False, references=False)
    assert "flaky" not in table and "dimension_reduced" in table
    assert "non-finite" in meta["skipped"]["flaky[0]"] and "from lab/flaky.zip" in meta["skipped"]["flaky[0]"]
    with pytest.raises(PolicyError, match="non-finite"):
        evaluate_policy(lambda obs: np.full((obs.shape[0], 6), np.inf), VIEW, episodes=1, grid=2, progress=False)


def test_a_variant_gets_its_own_optimum_and_the_validation_split(tmp_path, monkeypatch):
    from continuum_gym.robots.mbcr import MultiBackboneRobot

    monkeypatch.setenv("CONTINUUM_GYM_CACHE", str(tmp_path))
    robot = MultiBackboneRobot(lengths=(0.03, 0.025))
    kwargs = {"robot": robot, "base_controller": "projected_gradient", "task": "mixed"}
    table = evaluate_policy(lambda obs: np.zeros((obs.shape[0], 6)), OCCLUSION, env_kwargs=kwargs, episodes=2,
                            split="validation", progress=False)
    assert rows_equal(table["projected_gradient"], table["policy"])
    assert table["offline_optimum"]["mean_voi"]["n_tasks"] == 2
    # the ceiling is at most what the base controller reaches on the same validation hold tasks
    assert table["offline_optimum"]["mean_voi"]["mean"] <= table["projected_gradient"]["mean_voi"]["mean"] + 1e-9
    assert table["policy"]["headroom_closed"]["mean"] == pytest.approx(0.0, abs=1e-12)
    cached = sorted((tmp_path / "optimum").glob("OcclusionAvoidance-*.json"))
    assert len(cached) == 1


def test_results_are_written_and_listed_once_when_json_names_the_same_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out, summary, meta = tmp_path / "out", {VIEW: {"m": {"mean": 1.0}}}, {VIEW: {}}
    for same in (out / "results.json", "out/results.json", "out/../out/results.json"):
        assert write_results(out, summary, meta, ["# table"], same) == [out / "results.md", out / "results.json"]
    elsewhere = tmp_path / "elsewhere.json"
    assert write_results(out, summary, meta, ["# table"], elsewhere)[-1] == elsewhere
    assert json.loads(elsewhere.read_text()) == json.loads((out / "results.json").read_text())


def test_cli_evaluates_an_entry_point_policy_with_env_kwargs(tmp_path, monkeypatch, capsys):
    (tmp_path / "my_lab_policy.py").write_text(textwrap.dedent("""
        import numpy as np

        def make_policy():
            return lambda obs: np.zeros((obs.shape[0], 6))

        POLICY = object()
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    out = tmp_path / "out"
    args = ["evaluate", "--env", VIEW, "--policy", "my_lab_policy:make_policy", "--name", "mine", "--episodes", "1",
            "--grid", "2", "--policies", str(tmp_path), "--out", str(out), "--no-progress", "--json",
            str(out / "results.json"), "--env-kwargs", json.dumps({"base_controller": "resolved_rate", "task": "random"})]
    assert main(args) == 0
    wrote = [line for line in capsys.readouterr().out.splitlines() if line.startswith("wrote ")]
    assert len(wrote) == len(set(wrote)) and f"wrote {out / 'results.json'}" in wrote  # --json as make demo passes it
    result = json.loads((out / "results.json").read_text())
    assert rows_equal(result[VIEW]["mine"], result[VIEW]["resolved_rate"])
    assert result["metadata"][VIEW]["ignored_env_kwargs"] == {"task": "random"}
    assert result["metadata"][VIEW]["methods"]["mine"]["env_kwargs"] == [{"base_controller": "resolved_rate"}]
    module = sys.modules["my_lab_policy"]
    assert load_entry_point("my_lab_policy:POLICY") is module.POLICY  # an object is returned as it is


@pytest.mark.parametrize("extra, message", [
    (["--policy", "no_colon"], "expected 'package.module:function'"),
    (["--policy", "surely_missing_module_xyz:make"], "cannot import module"),
    (["--env-kwargs", "{not json"], "--env-kwargs: not valid JSON"),
    (["--env-kwargs", "[1, 2]"], "expected a JSON object"),
    (["--env-kwargs", '{"residual_scale": -1}'], "residual_scale"),
    (["--env-kwargs", '{"residual_scale": 0.5}', "--env", VIEW, OCCLUSION], "need one environment"),
    (["--episodes", "0"], "episodes must be an integer >= 1"),
    (["--grid", "1"], "grid must be an integer >= 2"),
])
def test_cli_bad_input_is_a_named_error(extra, message, capsys, tmp_path):
    args = ["evaluate", "--out", str(tmp_path), "--no-progress"]
    if "--env" not in extra:
        args += ["--env", VIEW]
    assert main(args + extra) == 2
    assert message in capsys.readouterr().err


def test_unusable_runs_are_reported_and_skipped_and_an_empty_directory_warns(tmp_path, capsys):
    runs = tmp_path / "runs"
    (runs / "no_model").mkdir(parents=True)
    (runs / "no_model" / "config.yml").write_text(f"env_id: {VIEW}\n")
    (runs / "empty_config").mkdir()
    (runs / "empty_config" / "config.yml").write_text("")
    (runs / "empty_config" / "model.zip").write_bytes(b"")
    (runs / "garbage_model").mkdir()
    (runs / "garbage_model" / "config.yml").write_text(f"env_id: {VIEW}\nbase_controller: dimension_reduced\n")
    (runs / "garbage_model" / "model.zip").write_bytes(b"not a zip at all")
    out = tmp_path / "out"
    args = ["evaluate", "--env", VIEW, "--episodes", "1", "--grid", "2", "--out", str(out), "--no-progress"]
    assert main(args + ["--policies", str(runs)]) == 0  # the baselines are still evaluated
    err = capsys.readouterr().err
    for name in ("no_model", "empty_config", "garbage_model"):
        assert f"skipping {runs / name}" in err
    result = json.loads((out / "results.json").read_text())
    assert "dimension_reduced" in result[VIEW] and "residual_dimension_reduced" not in result[VIEW]
    assert set(result["metadata"][VIEW]["skipped"]) == {str(runs / n) for n in ("no_model", "empty_config",
                                                                                "garbage_model")}
    assert "**Skipped**" in (out / "results.md").read_text()
    (tmp_path / "nothing").mkdir()
    assert main(args + ["--policies", str(tmp_path / "nothing")]) == 0
    assert "holds no trained run" in capsys.readouterr().err


def test_a_folder_of_links_to_chosen_runs_finds_each_run_once(tmp_path):
    """Runs gathered by symbolic links are found (``Path.rglob`` skips linked folders), a link cycle ends."""
    import yaml

    from continuum_gym.evaluation.methods import discover_policies

    for seed in (0, 1):
        run = tmp_path / "campaign" / f"run{seed}"
        run.mkdir(parents=True)
        (run / "config.yml").write_text(yaml.safe_dump(
            {"env_id": "ContinuumGym/ViewTracking-v0", "algo": "ppo", "base_controller": "dimension_reduced"}))
        (run / "model.zip").write_bytes(b"")
    chosen = tmp_path / "chosen"
    chosen.mkdir()
    for seed in (0, 1):
        (chosen / f"seed{seed}").symlink_to(tmp_path / "campaign" / f"run{seed}", target_is_directory=True)
    (chosen / "loop").symlink_to(chosen, target_is_directory=True)
    found = discover_policies(chosen)["ContinuumGym/ViewTracking-v0"]
    assert sorted(path.name for path in found["residual_dimension_reduced"]) == ["seed0", "seed1"]


def test_learned_rows_are_named_by_base_and_algorithm_and_say_how_many_seeds(tmp_path):
    """PPO keeps the headline names; SAC and TD3 rows carry their algorithm; every learned row says it."""
    import yaml

    from continuum_gym.evaluation.methods import discover_policies, method_name

    assert method_name("projected_gradient", "ppo") == "residual_projected_gradient"
    assert method_name("my_lab.plugins:mylab_dls", "sac") == "residual_mylab_dls_sac"
    assert method_name(None, "ppo") == "pure_rl" and method_name(None, "td3") == "pure_rl_td3"
    runs = {"a": ("dimension_reduced", "ppo"), "b": ("dimension_reduced", "sac"), "c": ("dimension_reduced", "sac"),
            "d": (None, "sac")}
    for name, (base, algo) in runs.items():
        (tmp_path / name).mkdir()
        (tmp_path / name / "config.yml").write_text(yaml.safe_dump(
            {"env_id": "ContinuumGym/ViewTracking-v0", "algo": algo, "base_controller": base}))
        (tmp_path / name / "model.zip").write_bytes(b"")
    found = discover_policies(tmp_path)["ContinuumGym/ViewTracking-v0"]
    assert {method: len(paths) for method, paths in found.items()} == {
        "residual_dimension_reduced": 1, "residual_dimension_reduced_sac": 2, "pure_rl_sac": 1}
    table = evaluate_policy(lambda obs: np.zeros((obs.shape[0], 6)), "ContinuumGym/ViewTracking-v0", name="zero",
                            episodes=1, grid=2, split="validation", progress=False)
    assert table["zero"]["n_seeds"] == 1 and table["zero"]["algo"] is None
    assert "n_seeds" not in table["dimension_reduced"]  # an analytic baseline is no learned row
