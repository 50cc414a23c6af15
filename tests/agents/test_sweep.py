"""Sweeps on Ray Tune: search-space validation, a local 2-trial sweep, killed-trial resume, no overwrite."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import yaml

from continuum_gym.agents.sweep import load_search, trial_tag
from continuum_gym.cli import main

VIEW = "ContinuumGym/ViewTracking-v0"
TINY = {VIEW: {"policy": "MlpPolicy", "n_envs": 4, "n_steps": 32, "batch_size": 64, "n_epochs": 1,
               "n_timesteps": 2048, "checkpoint_freq": 256, "eval_freq": 512, "n_eval_episodes": 2,
               "residual_scale": 0.3, "learning_rate": 3.0e-4, "policy_kwargs": {"net_arch": [16]},
               "env_kwargs": {"task": "static", "max_episode_steps": 40}}}


@pytest.fixture()
def files(tmp_path):
    hp = tmp_path / "hp.yml"
    hp.write_text(yaml.safe_dump(TINY))
    search = tmp_path / "search.yml"
    search.write_text(yaml.safe_dump({"method": "grid", "space": {"learning_rate": {"grid": [1e-4, 3e-4]}}}))
    return hp, search


def test_unknown_search_key_fails_before_anything_starts(tmp_path, capsys):
    bad = tmp_path / "bad.yml"
    bad.write_text(yaml.safe_dump({"space": {"learning_rat": {"grid": [1e-4]}}}))
    assert main(["sweep", "--env", VIEW, "--search", str(bad), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "learning_rat" in err and "learning_rate" in err
    assert not (tmp_path / "out").exists()
    with pytest.raises(ValueError, match="unknown keys"):
        (tmp_path / "b2.yml").write_text(yaml.safe_dump({"spaces": {}}))
        load_search(tmp_path / "b2.yml", "ppo", VIEW)
    with pytest.raises(ValueError, match="kind"):
        (tmp_path / "b3.yml").write_text(yaml.safe_dump({"space": {"learning_rate": {"normal": [0, 1]}}}))
        load_search(tmp_path / "b3.yml", "ppo", VIEW)


def test_a_budget_that_trains_nothing_fails_before_any_trial_starts(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["sweep", "--env", VIEW, "--algo", "sac", "--steps", "10000", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--steps 10000 trains nothing" in err and "burn_in_steps: 20000" in err and not out.exists()


def test_missing_ray_says_how_to_install(tmp_path, files, monkeypatch, capsys):
    hp, search = files
    monkeypatch.setitem(sys.modules, "ray", None)
    assert main(["sweep", "--env", VIEW, "--hyperparams", str(hp), "--out", str(tmp_path / "o")]) == 2
    assert "pip install" in capsys.readouterr().err


def test_trial_tags_are_stable_and_distinct():
    a = trial_tag({"learning_rate": 1e-4, "seed": 0})
    assert a == trial_tag({"seed": 0, "learning_rate": 1e-4})
    assert a != trial_tag({"learning_rate": 3e-4, "seed": 0}) and a != trial_tag({"learning_rate": 1e-4, "seed": 1})


@pytest.mark.slow
def test_local_two_trial_sweep_writes_its_table_and_refuses_to_overwrite(tmp_path, files):
    import ray  # noqa: F401  (a test extra: missing, the test fails rather than skips)
    hp, search = files
    out = tmp_path / "sweeps"
    argv = ["sweep", "--env", VIEW, "--seeds", "0", "--search", str(search), "--hyperparams", str(hp), "--out",
            str(out), "--name", "s"]
    assert main(argv) == 0
    summary = json.loads((out / "s" / "sweep_results.json").read_text())
    assert len(summary["trials"]) == 2 and all(t["mean_or"] is not None for t in summary["trials"])
    assert all(t["timesteps"] >= 2048 for t in summary["trials"])
    assert "| config |" in (out / "s" / "sweep_results.md").read_text()
    best = yaml.safe_load((out / "s" / "best_hyperparams.yml").read_text())[VIEW]
    assert best["learning_rate"] in (1e-4, 3e-4) and best["n_envs"] == 4
    runs = list((out / "s" / "trials").glob("*/ViewTracking_ppo_dimension_reduced_seed0/tb"))
    assert len(runs) == 2  # TensorBoard logs per trial
    before = (out / "s" / "sweep_results.json").stat().st_mtime_ns
    assert main(argv) == 2  # exists: nothing overwritten without --resume
    assert (out / "s" / "sweep_results.json").stat().st_mtime_ns == before
    # Resuming a finished sweep (Tune's restore) re-runs no trial: the trained models are untouched.
    models = {p: p.stat().st_mtime_ns for p in (out / "s" / "trials").glob("*/*/model.zip")}
    assert len(models) == 2
    assert main(argv + ["--resume"]) == 0
    assert models == {p: p.stat().st_mtime_ns for p in (out / "s" / "trials").glob("*/*/model.zip")}


@pytest.mark.slow
def test_killed_trial_resumes_from_its_checkpoint(tmp_path, files):
    hp, _ = files
    code = ("import sys; from continuum_gym.agents.sweep import run_trial; "
            f"run_trial({{'learning_rate': 3e-4, 'seed': 1}}, {VIEW!r}, 'ppo', 'dimension_reduced', None, "
            f"{str(tmp_path / 'sw')!r}, {str(hp)!r})")
    run_dir = tmp_path / "sw" / "trials" / trial_tag({"learning_rate": 3e-4, "seed": 1}) / \
        "ViewTracking_ppo_dimension_reduced_seed1"
    from continuum_gym.agents.checkpoint import find_resumable

    folder = run_dir / "checkpoints"
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 240
    while find_resumable(folder)[0] is None and time.time() < deadline and proc.poll() is None:
        time.sleep(0.2)
    assert find_resumable(folder)[0] is not None
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    killed_at = find_resumable(folder)[0].state()["num_timesteps"]
    assert killed_at < 2048 and not (run_dir / "model.zip").exists()
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    final = find_resumable(folder)[0].state()["num_timesteps"]
    assert final >= 2048 and (run_dir / "model.zip").exists()
    curve = np.load(run_dir / "evaluations.npz")
    assert curve["timesteps"][-1] == final


def _ray_trial_workers(root: int) -> list[int]:
    """Pids of the Ray worker processes running a trial (title ``ray::ImplicitFunc...``) that descend from
    process ``root``: only this test's sweep, never another Ray job on the machine (a user's campaign)."""
    from pathlib import Path

    parents, titles = {}, {}
    for proc in Path("/proc").iterdir():
        if proc.name.isdigit():
            try:
                titles[int(proc.name)] = (proc / "cmdline").read_bytes().split(b"\0")[0]
                stat = (proc / "stat").read_text()
            except OSError:
                continue
            parents[int(proc.name)] = int(stat.rsplit(")", 1)[1].split()[1])

    def descends(pid: int) -> bool:
        for _ in range(64):
            if pid == root:
                return True
            if pid not in parents or pid <= 1:
                return False
            pid = parents[pid]
        return False

    return [pid for pid, title in titles.items() if title.startswith(b"ray::ImplicitFunc") and descends(pid)]


def test_a_sweep_whose_trial_worker_is_killed_resumes_the_trial_from_its_checkpoint(tmp_path, files):
    """Ray's FailureConfig path: SIGKILL the trial's worker process mid-training; Tune restarts the
    trial, which resumes from its newest checkpoint unit and finishes; the sweep exits 0."""
    from continuum_gym.agents.checkpoint import find_resumable

    hp, _ = files
    out = tmp_path / "sweeps"
    sweep = subprocess.Popen([sys.executable, "-m", "continuum_gym.cli", "sweep", "--env", VIEW, "--seeds", "0",
                              "--hyperparams", str(hp), "--out", str(out), "--name", "k", "--steps", "2048"],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 300
    folder = None
    while time.time() < deadline and sweep.poll() is None:
        runs = list((out / "k" / "trials").glob("*/ViewTracking_ppo_dimension_reduced_seed0"))
        if runs and find_resumable(runs[0] / "checkpoints")[0] is not None:
            folder = runs[0]
            break
        time.sleep(0.2)
    assert folder is not None, "the trial never wrote a checkpoint"
    workers = _ray_trial_workers(sweep.pid)
    assert workers, "no Ray trial worker found"
    killed_at = find_resumable(folder / "checkpoints")[0].step
    for pid in workers:
        os.kill(pid, signal.SIGKILL)
    _, stderr = sweep.communicate(timeout=600)
    assert sweep.returncode == 0, stderr[-3000:]
    summary = json.loads((out / "k" / "sweep_results.json").read_text())
    (trial,) = summary["trials"]
    assert trial["error"] is None and trial["timesteps"] >= 2048
    assert killed_at < 2048
    start = yaml.safe_load((folder / "args.yml").read_text())["start"]
    assert start.startswith("resume from step") and int(start.split()[-1]) >= killed_at
    timesteps = np.load(folder / "evaluations.npz")["timesteps"].tolist()
    assert all(a < b for a, b in zip(timesteps, timesteps[1:])) and timesteps[-1] == 2048


def test_an_interrupted_sweeps_summary_names_the_trials_that_never_started(tmp_path):
    """Ray reports the trials an interruption left pending without a config: the summary lists them as not
    started (with how to continue) instead of failing with a TypeError and losing the finished trials' table."""
    from types import SimpleNamespace

    from continuum_gym.agents.sweep import summarise

    done = SimpleNamespace(config={"seed": 0, "learning_rate": 1e-4}, metrics={"mean_voi": 0.12, "timesteps": 4096},
                           error=None)
    pending = SimpleNamespace(config=None, metrics=None, error=None)
    summary = summarise([done, pending], "mean_voi", "min", "ContinuumGym/OcclusionAvoidance-v0", "ppo", tmp_path)
    assert summary["trials"][0]["mean_voi"] == 0.12 and summary["best_config"] == {"learning_rate": 1e-4}
    assert "not started" in summary["trials"][1]["error"] and "--resume" in summary["trials"][1]["error"]
    assert "not started" in (tmp_path / "sweep_results.md").read_text()
