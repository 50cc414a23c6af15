"""Residual learners, training runs (checkpoints, resume, no overwrite) and evaluation statistics."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import yaml

from continuum_gym.agents.residual import zero_init_residual
from continuum_gym.cli import main
from continuum_gym.envs.sb3 import ContinuumSB3VecEnv
from continuum_gym.evaluation.rollout import ZeroResidual, make_core, run_episodes
from continuum_gym.evaluation.statistics import summarize

OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"


def _model(algo, env_id, **kwargs):
    from stable_baselines3 import PPO, SAC, TD3

    venv = ContinuumSB3VecEnv(env_id, 4, seed=0, **kwargs)
    cls = {"ppo": PPO, "sac": SAC, "td3": TD3}[algo]
    extra = {"learning_starts": 50, "buffer_size": 1000} if algo != "ppo" else {"n_steps": 32, "batch_size": 64}
    return cls("MlpPolicy", venv, seed=0, device="cpu", **extra), venv


@pytest.mark.parametrize("algo", ["ppo", "sac", "td3"])
@pytest.mark.parametrize("env_id", [OCCLUSION, VIEW])
def test_untrained_residual_agent_equals_its_baseline_on_a_full_episode(algo, env_id):
    model, _ = _model(algo, env_id)
    zero_init_residual(model)
    task = "hold" if env_id == OCCLUSION else "case2"
    core_a = make_core(env_id, 1, task=task, task_split="test")
    core_b = make_core(env_id, 1, task=task, task_split="test")
    learned = run_episodes(core_a, model, [0], record=True)
    baseline = run_episodes(core_b, ZeroResidual(core_b.single_action_space.shape[0]), [0], record=True)
    for key in learned:
        np.testing.assert_array_equal(learned[key], baseline[key])


def test_replay_buffer_stores_the_residual_not_the_blended_command():
    from stable_baselines3 import SAC
    from stable_baselines3.common.vec_env import VecEnvWrapper

    class Recorder(VecEnvWrapper):
        def __init__(self, venv):
            super().__init__(venv)
            self.sent = []

        def step_async(self, actions):
            self.sent.append(np.array(actions))
            self.venv.step_async(actions)

        def reset(self):
            return self.venv.reset()

        def step_wait(self):
            return self.venv.step_wait()

    venv = Recorder(ContinuumSB3VecEnv(OCCLUSION, 2, seed=0, base_controller="projected_gradient"))
    model = SAC("MlpPolicy", venv, learning_starts=1000, buffer_size=1000, seed=0, device="cpu")
    zero_init_residual(model)
    model.learn(40)
    stored = model.replay_buffer.actions[:20]
    sent = np.stack(venv.sent)[:20]
    # What the env received (the residual, which it blends with the baseline itself) is what is stored.
    np.testing.assert_allclose(stored, sent, atol=1e-6)
    base = venv.venv.core.base_cmd[:, :8] / venv.venv.core.rate_scale_vec
    assert not np.allclose(stored[-1], base, atol=1e-3)


def test_save_load_round_trip_gives_identical_actions(tmp_path):
    from stable_baselines3 import PPO

    model, venv = _model("ppo", VIEW)
    model.learn(128)
    model.save(tmp_path / "m.zip")
    loaded = PPO.load(tmp_path / "m.zip", device="cpu")
    obs = venv.reset()
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0])


# ---------------------------------------------------------------- training runs
TINY = {
    "ContinuumGym/ViewTracking-v0": {
        "policy": "MlpPolicy", "n_envs": 4, "n_steps": 32, "batch_size": 64, "n_epochs": 1, "n_timesteps": 3072,
        "checkpoint_freq": 256, "eval_freq": 1024, "n_eval_episodes": 2, "residual_scale": 0.3,
        "policy_kwargs": {"net_arch": [16]}, "env_kwargs": {"task": "static", "max_episode_steps": 40},
    }
}


def _train_command(out, hyperparams, *extra):
    return [sys.executable, "-m", "continuum_gym.cli", "train", "--env", VIEW, "--algo", "ppo", "--seed", "3",
            "--out", str(out), "--hyperparams", str(hyperparams), "--no-progress", *extra]


@pytest.mark.slow
def test_killed_run_resumes_from_its_checkpoint(tmp_path):
    hyperparams = tmp_path / "ppo.yml"
    hyperparams.write_text(yaml.safe_dump(TINY))
    from continuum_gym.agents.checkpoint import find_resumable

    run_dir = tmp_path / "runs" / "ViewTracking_ppo_dimension_reduced_seed3"
    folder = run_dir / "checkpoints"
    proc = subprocess.Popen(_train_command(tmp_path / "runs", hyperparams), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    deadline = time.time() + 240
    while find_resumable(folder)[0] is None and time.time() < deadline and proc.poll() is None:
        time.sleep(0.2)
    assert find_resumable(folder)[0] is not None, "no checkpoint before the deadline"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    killed_at = find_resumable(folder)[0].state()["num_timesteps"]
    assert 0 < killed_at < 3072 and not (run_dir / "model.zip").exists()
    # Without --resume nothing is overwritten.
    before = {p: p.stat().st_mtime_ns for p in run_dir.rglob("*") if p.is_file()}
    refused = subprocess.run(_train_command(tmp_path / "runs", hyperparams), capture_output=True, text=True)
    assert refused.returncode != 0 and "--resume" in refused.stderr
    assert before == {p: p.stat().st_mtime_ns for p in run_dir.rglob("*") if p.is_file()}
    resumed = subprocess.run(_train_command(tmp_path / "runs", hyperparams, "--resume"), capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    from stable_baselines3 import PPO

    model = PPO.load(run_dir / "model.zip", device="cpu")
    assert model.num_timesteps >= 3072
    assert find_resumable(folder)[0].state()["num_timesteps"] == model.num_timesteps
    commands = (run_dir / "command.txt").read_text().splitlines()
    assert len(commands) == 2 and "--resume" in commands[1]
    curve = np.load(run_dir / "evaluations.npz")
    assert curve["timesteps"][-1] == model.num_timesteps and "mean_or" in curve.files
    assert (run_dir / "config.yml").exists() and (run_dir / "args.yml").exists() and (run_dir / "tb").is_dir()
    # The run says how it used the cores: one torch thread, the env stepped on the calling thread.
    threads = yaml.safe_load((run_dir / "config.yml").read_text())["threads"]
    assert threads["torch"] == 1 and threads["env_step_threads"] == 1 and threads["cores_visible"] >= 1


@pytest.mark.parametrize("argv, message", [
    (["train", "--env", "ContinuumGym/Nope-v0"], "unknown env"),
    (["train", "--env", VIEW, "--algo", "a2c"], "unknown algo"),
    (["train", "--env", VIEW, "--base", "projected_gradient"], "unknown base"),
    (["evaluate", "--policies", "/nonexistent/policies"], "no directory"),
    (["evaluate", "--env", "ContinuumGym/Nope-v0"], "unknown env"),
])
def test_bad_cli_input_fails_clearly(argv, message, capsys, tmp_path):
    assert main(argv + (["--out", str(tmp_path / "o")] if argv[0] == "train" else [])) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


# ---------------------------------------------------------------- statistics
def test_bootstrap_intervals_cover_a_known_mean():
    rng = np.random.default_rng(0)
    mu, sigma, n = 0.3, 0.1, 400
    covered = 0
    for trial in range(20):
        scores = rng.normal(mu, sigma, (1, n))
        s = summarize(scores, reps=500, seed=trial)
        covered += s["ci_low"] <= mu <= s["ci_high"]
        assert s["ci_high"] - s["ci_low"] == pytest.approx(2 * 1.96 * sigma / np.sqrt(n), rel=0.25)
        assert s["mean"] == pytest.approx(scores.mean())
    assert covered >= 17  # a 95 % interval misses about 1 in 20


def test_iqm_ignores_outliers():
    scores = np.concatenate([np.full(90, 1.0), np.full(10, 100.0)])[None]
    s = summarize(scores, reps=200)
    assert s["iqm"] == pytest.approx(1.0) and s["mean"] == pytest.approx(10.9)
    with pytest.raises(ValueError, match="finite"):
        summarize(np.array([[np.nan, 1.0]]))


# ---------------------------------------------------------------- evaluation end to end
@pytest.mark.slow
def test_evaluate_puts_every_method_through_one_path(tmp_path):
    """An untrained residual policy is its baseline: through the whole CLI its row must equal the baseline's."""
    import json

    policies = tmp_path / "policies"
    for env_id, base, kwargs in ((OCCLUSION, "projected_gradient", {"residual_scale": 0.5, "visibility_guard": 0.69}),
                                 (VIEW, "dimension_reduced", {"residual_scale": 1.0})):
        model, _ = _model("ppo", env_id, base_controller=base, **kwargs)
        zero_init_residual(model)
        run = policies / env_id.split("/")[-1]
        run.mkdir(parents=True)
        model.save(run / "model.zip")
        (run / "config.yml").write_text(yaml.safe_dump({"env_id": env_id, "algo": "ppo", "base_controller": base,
                                                        "env_kwargs": {"base_controller": base, **kwargs}}))
    out, path = tmp_path / "out", tmp_path / "results.json"
    assert main(["evaluate", "--policies", str(policies), "--episodes", "2", "--grid", "3", "--out", str(out),
                 "--json", str(path), "--no-progress"]) == 0
    summary = json.loads(path.read_text())
    metrics = {OCCLUSION: ("mean_voi", "tip_in_view_fraction", "mean_tip_error_m", "mean_orientation_error_rad"),
               VIEW: ("mean_or", "or_above_0.8_fraction", "mean_position_error_m", "coverage_percent")}
    for env_id, base in ((OCCLUSION, "projected_gradient"), (VIEW, "dimension_reduced")):
        table = summary[env_id]
        assert {base, f"residual_{base}"} <= set(table)
        for metric in metrics[env_id]:
            stats = table[base][metric]
            assert set(stats) >= {"mean", "iqm", "ci_low", "ci_high"}
            assert stats["ci_low"] <= stats["mean"] <= stats["ci_high"]
            assert table[f"residual_{base}"][metric]["mean"] == stats["mean"]
    # The baseline rows are the baselines themselves: a direct zero-residual rollout on the first test tasks.
    core = make_core(OCCLUSION, 2, task="hold", task_split="test", base_controller="projected_gradient")
    direct = run_episodes(core, ZeroResidual(8), [0, 1])
    report = (out / "results.md").read_text()
    assert "| projected_gradient | hold | " + f"{direct['mean_voi'].mean():.3f}" in report


def test_linear_schedules_decay_to_zero_survive_pickling_and_reject_garbage():
    import pickle

    from continuum_gym.agents.build import linear_schedule

    schedule = linear_schedule("lin_2.0e-4", "learning_rate")
    assert schedule(1.0) == pytest.approx(2e-4) and schedule(0.25) == pytest.approx(5e-5) and schedule(0.0) == 0.0
    assert pickle.loads(pickle.dumps(schedule))(0.5) == pytest.approx(1e-4)  # SB3 saves it inside model.zip
    assert linear_schedule(3e-4, "learning_rate") == 3e-4
    for bad in ("exp_1e-3", "lin_fast", "lin_-1"):
        with pytest.raises(ValueError, match="learning_rate"):
            linear_schedule(bad, "learning_rate")


def test_bootstrap_intervals_depend_on_their_seed_only():
    """rliable draws from numpy's global generator: the interval must not depend on what ran before."""
    scores = np.random.default_rng(1).random((2, 12))
    first = summarize(scores, reps=300, seed=4)
    np.random.seed(123)
    np.random.random(17)  # someone else's draws in between
    before = np.random.get_state()[1].copy()
    second = summarize(scores, reps=300, seed=4)
    assert first == second
    assert np.array_equal(np.random.get_state()[1], before)  # the caller's global state is given back
    assert summarize(scores, reps=300, seed=5)["ci_low"] != first["ci_low"]
