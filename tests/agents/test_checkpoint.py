"""Runs that survive anything: checkpoint units, kills at every stage, resume continuity, input checks.

A "kill" in-process is the ``Killed`` exception raised where the next checkpoint would be written (it
derives from BaseException, so no handler in the trainer swallows it); one test kills a subprocess
with SIGKILL in the middle of publishing a unit.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import torch
import yaml

from continuum_gym.agents import checkpoint
from continuum_gym.agents.checkpoint import (
    find_resumable,
    list_units,
    verify,
    write_unit,
)
from continuum_gym.agents.residual import actor_parameters
from continuum_gym.agents.train import train
from continuum_gym.cli import main

VIEW = "ContinuumGym/ViewTracking-v0"
RUN = "ViewTracking_ppo_dimension_reduced_seed0"
ROLLOUT = 4 * 32  # n_envs * n_steps: PPO's unit of training
BLOCK = {"policy": "MlpPolicy", "n_envs": 4, "n_steps": 32, "batch_size": 64, "n_epochs": 2, "n_timesteps": 1024,
         "checkpoint_freq": 128, "checkpoint_minutes": float("inf"), "keep_checkpoints": 2, "eval_freq": 256,
         "n_eval_episodes": 1, "residual_scale": 0.3, "policy_kwargs": {"net_arch": [16]},
         "env_kwargs": {"task": "static", "max_episode_steps": 40}}
# The evaluation schedule of a 1024-step run: at the first step (4 envs), then at the first step at least
# eval_freq after the previous evaluation, and at the end.
SCHEDULE = [4, 260, 516, 772, 1024]


class Killed(BaseException):
    """Stands in for SIGKILL: raised where a checkpoint would be written, nothing after it runs."""


def _hyperparams(tmp_path, name="hp", **changes):
    path = tmp_path / f"{name}.yml"
    path.write_text(yaml.safe_dump({VIEW: {**BLOCK, **changes}}))
    return path


def _run(tmp_path, hp, out="runs", **kwargs):
    return train(VIEW, "ppo", seed=kwargs.pop("seed", 0), out=tmp_path / out, hyperparams=hp, progress=False,
                 **kwargs)


def _kill_at_write(monkeypatch, number):
    """Let ``number - 1`` units be written, then die where the next one would start."""
    real, calls = checkpoint.write_unit, []

    def write(folder, step, files, state):
        calls.append(step)
        if len(calls) == number:
            raise Killed(step)
        return real(folder, step, files, state)

    monkeypatch.setattr(checkpoint, "write_unit", write)
    return calls


def _curve(run_dir):
    return np.load(run_dir / "evaluations.npz")["timesteps"].tolist()


def _unit_steps(run_dir):
    return [unit.step for unit in list_units(run_dir / "checkpoints")]


def test_units_verify_and_torn_units_are_invisible(tmp_path):
    folder = tmp_path / "checkpoints"
    for step in (10, 20, 30):
        write_unit(folder, step, {"model.zip": lambda p, s=step: p.write_bytes(b"model %d" % s)}, {"note": step})
    assert [u.step for u in list_units(folder)] == [10, 20, 30] and all(verify(u) is None for u in list_units(folder))
    state = list_units(folder)[-1].state()
    assert state["note"] == 30 and state["num_timesteps"] == 30 and state["time"] > 0
    # A unit whose writer died before its rename is invisible; a damaged newest one is skipped with a reason.
    (folder / ".tmp-step_000000000040").mkdir()
    (folder / ".tmp-step_000000000040" / "model.zip").write_bytes(b"half")
    newest = folder / "step_000000000030" / "model.zip"
    newest.write_bytes(b"model 31")  # same size, other bytes
    unit, damaged = find_resumable(folder)
    assert unit.step == 20 and [(d.step, "checksum" in why) for d, why in damaged] == [(30, True)]
    newest.write_bytes(b"model")
    assert "bytes" in verify(list_units(folder)[-1])
    (folder / "step_000000000020" / "manifest.json").unlink()
    assert find_resumable(folder)[0].step == 10
    assert [p.name for p in checkpoint.clean_temporary(folder)] == [".tmp-step_000000000040"]
    assert checkpoint.prune(folder, 1) == [folder / "step_000000000010", folder / "step_000000000020"]
    assert sorted(p.name for p in folder.iterdir()) == ["step_000000000030"]


def test_a_run_stopped_before_its_first_checkpoint_starts_again(tmp_path, monkeypatch, capsys):
    hp = _hyperparams(tmp_path, checkpoint_freq=10**6)  # the only unit would be the final one
    for seed, resume in ((0, False), (1, True)):
        with monkeypatch.context() as patch:
            _kill_at_write(patch, 1)
            with pytest.raises(Killed):
                _run(tmp_path, hp, seed=seed)
        run_dir = tmp_path / "runs" / RUN.replace("seed0", f"seed{seed}")
        # Killed at the final save: trained and evaluated to the end, but nothing to resume from.
        assert (run_dir / "config.yml").is_file() and _curve(run_dir) == SCHEDULE
        assert find_resumable(run_dir / "checkpoints")[0] is None and not (run_dir / "model.zip").exists()
        capsys.readouterr()
        assert _run(tmp_path, hp, seed=seed, resume=resume) == run_dir
        assert "starting it again from step 0" in capsys.readouterr().err
        # A fresh start: the stopped attempt's curve is replaced, not appended to.
        assert _curve(run_dir) == SCHEDULE and (run_dir / "model.zip").is_file()
        assert len((run_dir / "command.txt").read_text().splitlines()) == 2


def test_the_progress_bar_of_a_resumed_run_counts_from_its_checkpoint_to_the_step_it_ends_at(tmp_path, monkeypatch,
                                                                                              capsys):
    """Resumed at step 256 towards 1000 steps: PPO trains whole rollouts of 128, so the run ends at 1024. The bar
    starts at 256/1024 and ends at 1024/1024, never past its total (SB3's own read 768/744 here)."""
    import re

    from stable_baselines3 import PPO

    hp = _hyperparams(tmp_path, n_timesteps=1000)
    with monkeypatch.context() as patch:
        _kill_at_write(patch, 3)
        with pytest.raises(Killed):
            _run(tmp_path, hp)
    capsys.readouterr()
    run_dir = train(VIEW, "ppo", seed=0, out=tmp_path / "runs", hyperparams=hp, progress=True, resume=True)
    err = capsys.readouterr().err
    shown = [(int(n), int(total)) for n, total in re.findall(r"(\d+)/(\d+) steps", err.replace(",", ""))]
    assert shown and shown[0] == (256, 1024) and shown[-1] == (1024, 1024), shown
    assert all(n <= total for n, total in shown)
    assert "ends at step 1024" in err and "whole rollouts of 128" in err
    assert PPO.load(run_dir / "model.zip", device="cpu").num_timesteps == 1024


def test_a_run_records_what_it_cost_and_a_resume_continues_the_count(tmp_path, monkeypatch):
    """``wall_s`` and ``cpu_s`` at each evaluation: increasing, never more CPU than the training process spent,
    and a resumed run counts on from its checkpoint's cost, not from zero."""
    from continuum_gym.evaluation.comparison import training_cost

    hp = _hyperparams(tmp_path)
    started = time.process_time()
    with monkeypatch.context() as patch:
        _kill_at_write(patch, 3)
        with pytest.raises(Killed):
            _run(tmp_path, hp)
    spent_first = time.process_time() - started
    run_dir = tmp_path / "runs" / RUN
    state = find_resumable(run_dir / "checkpoints")[0].state()
    assert state["num_timesteps"] == 256 and 0 < state["cpu_s"] <= spent_first and state["elapsed_s"] > 0
    started = time.process_time()
    _run(tmp_path, hp, resume=True)
    spent_second = time.process_time() - started
    curve = np.load(run_dir / "evaluations.npz")
    assert curve["timesteps"].tolist() == SCHEDULE
    cpu, wall = curve["cpu_s"], curve["wall_s"]
    assert np.all(np.diff(cpu) > 0) and np.all(np.diff(wall) > 0) and np.all(cpu > 0)
    assert cpu[0] < state["cpu_s"] < cpu[1]  # the row before the checkpoint, then the resumed run's first
    assert cpu[-1] <= state["cpu_s"] + spent_second
    cost = training_cost(run_dir)
    assert cost["cpu_s"] == cpu[-1] and cost["wall_clock_s"] == wall[-1] and cost["env_steps"] == 1024


def test_sigkill_while_publishing_a_unit_keeps_the_previous_one(tmp_path, capsys):
    hp = _hyperparams(tmp_path)
    script = (
        "import os, signal, sys\n"
        "from continuum_gym.agents import checkpoint\n"
        "from continuum_gym.agents.train import train\n"
        "real, calls = checkpoint.publish, []\n"
        "def publish(staging, final):\n"
        "    calls.append(final)\n"
        "    if len(calls) == 3:\n"
        "        assert (staging / 'model.zip').is_file()\n"
        "        os.kill(os.getpid(), signal.SIGKILL)\n"
        "    real(staging, final)\n"
        "checkpoint.publish = publish\n"
        f"train({VIEW!r}, 'ppo', seed=0, out=sys.argv[1], hyperparams=sys.argv[2], progress=False)\n")
    killed = subprocess.run([sys.executable, "-c", script, str(tmp_path / "runs"), str(hp)], check=False,
                            capture_output=True, text=True, timeout=240)
    assert killed.returncode == -signal.SIGKILL, killed.stderr[-2000:]
    run_dir = tmp_path / "runs" / RUN
    folder = run_dir / "checkpoints"
    assert _unit_steps(run_dir) == [128, 256] and (folder / ".tmp-step_000000000384" / "model.zip").is_file()
    assert _curve(run_dir) == [4, 260]  # evaluated after the newest unit: a row the resume must drop
    (run_dir / ".config.yml.99999.tmp").write_text("what a killed atomic write leaves")
    capsys.readouterr()
    _run(tmp_path, hp, resume=True)
    assert "from step 256" in capsys.readouterr().err
    assert not [p for p in folder.iterdir() if p.name.startswith(".")]
    assert not (run_dir / ".config.yml.99999.tmp").exists()
    assert _curve(run_dir) == SCHEDULE  # strictly increasing, 260 once
    assert json.loads((folder / "step_000000001024" / "state.json").read_text())["evaluations"]["timesteps"] == SCHEDULE


def test_a_damaged_newest_unit_is_detected_and_resume_falls_back(tmp_path, monkeypatch, capsys):
    hp = _hyperparams(tmp_path)
    with monkeypatch.context() as patch:
        _kill_at_write(patch, 3)
        with pytest.raises(Killed):
            _run(tmp_path, hp)
    run_dir = tmp_path / "runs" / RUN
    assert _unit_steps(run_dir) == [128, 256]
    model = run_dir / "checkpoints" / "step_000000000256" / "model.zip"
    data = bytearray(model.read_bytes())
    data[len(data) // 2] ^= 0xFF
    model.write_bytes(bytes(data))
    capsys.readouterr()
    _run(tmp_path, hp, resume=True)
    err = capsys.readouterr().err
    assert "step_000000000256" in err and "damaged (model.zip does not match its checksum)" in err
    assert "falling back to step_000000000128" in err and "from step 128" in err
    assert _unit_steps(run_dir) == [896, 1024] and all(verify(u) is None for u in list_units(run_dir / "checkpoints"))
    assert _curve(run_dir) == SCHEDULE


def test_ppo_units_sit_on_rollout_boundaries_and_the_newest_k_are_kept(tmp_path, monkeypatch):
    from stable_baselines3 import PPO

    hp = _hyperparams(tmp_path, checkpoint_freq=100, keep_checkpoints=3)  # 100 is no multiple of a rollout
    written = _kill_at_write(monkeypatch, 0)  # never killed: records the steps
    run_dir = _run(tmp_path, hp)
    assert written == [128, 256, 384, 512, 640, 768, 896, 1024]
    assert _unit_steps(run_dir) == written[-3:]
    for unit in list_units(run_dir / "checkpoints"):
        model = PPO.load(unit.file("model.zip"), device="cpu")
        # Trained on every step it counts: one update of n_epochs per rollout.
        assert model.num_timesteps == unit.step == unit.state()["num_timesteps"]
        assert model._n_updates == BLOCK["n_epochs"] * unit.step // ROLLOUT


def test_burn_in_holds_the_actor_across_a_resume(tmp_path, monkeypatch):
    from stable_baselines3 import PPO

    hp = _hyperparams(tmp_path, burn_in_steps=384, keep_checkpoints=10, n_timesteps=768)
    with monkeypatch.context() as patch:
        _kill_at_write(patch, 3)
        with pytest.raises(Killed):
            _run(tmp_path, hp)
    run_dir = _run(tmp_path, hp, resume=True)
    units = list_units(run_dir / "checkpoints")
    assert [u.step for u in units] == [128, 256, 384, 512, 640, 768]
    actors = {u.step: [p.detach().clone() for p in actor_parameters(PPO.load(u.file("model.zip"), device="cpu"))]
              for u in units}
    initial = actors[128]
    assert not initial[-2].any()  # zero-initialised residual: action_net weight
    for step, actor in actors.items():
        held = all(torch.equal(a, b) for a, b in zip(actor, initial))
        assert held == (step <= 384), step
        assert (units[[u.step for u in units].index(step)].file("burn_in_actor.pt") is not None) == (step <= 384)


def test_off_policy_units_hold_every_counted_transition_across_a_resume(tmp_path, monkeypatch):
    from stable_baselines3 import SAC

    block = {"policy": "MlpPolicy", "n_envs": 2, "buffer_size": 1000, "batch_size": 32, "learning_starts": 64,
             "train_freq": 8, "gradient_steps": 1, "n_timesteps": 384, "checkpoint_freq": 64,
             "checkpoint_minutes": float("inf"), "keep_checkpoints": 10, "eval_freq": 256, "n_eval_episodes": 1,
             "burn_in_steps": 192, "normalize_reward": True, "policy_kwargs": {"net_arch": [16]},
             "env_kwargs": {"task": "static", "max_episode_steps": 40}}
    hp = tmp_path / "sac.yml"
    hp.write_text(yaml.safe_dump({VIEW: block}))
    with monkeypatch.context() as patch:
        _kill_at_write(patch, 3)
        with pytest.raises(Killed):
            train(VIEW, "sac", seed=0, out=tmp_path / "runs", hyperparams=hp, progress=False)
    run_dir = train(VIEW, "sac", seed=0, out=tmp_path / "runs", hyperparams=hp, progress=False, resume=True)
    units = list_units(run_dir / "checkpoints")
    assert [u.step for u in units] == [64, 128, 192, 256, 320, 384]
    initial = None
    for unit in units:
        assert unit.file("vecnormalize.pkl") is not None
        model = SAC.load(unit.file("model.zip"), device="cpu")
        model.load_replay_buffer(unit.file("replay_buffer.pkl"))
        # Every counted step is in the buffer (one row per step of all envs) and trained on: one gradient
        # step per train_freq rollout of 8 x 2 steps once past learning_starts.
        assert model.replay_buffer.pos == unit.step // 2
        assert model._n_updates == max(0, (unit.step - 64) // 16)
        actor = [p.detach().clone() for p in actor_parameters(model)]
        initial = initial or actor
        assert all(torch.equal(a, b) for a, b in zip(actor, initial)) == (unit.step <= 192), unit.step


def test_wall_time_trigger_checkpoints_early_and_changes_no_result(tmp_path):
    hp_time = _hyperparams(tmp_path, "by_time", checkpoint_freq=10**6, checkpoint_minutes=1e-6, keep_checkpoints=100)
    hp_steps = _hyperparams(tmp_path, "by_steps", checkpoint_freq=10**6, keep_checkpoints=100)
    by_time = _run(tmp_path, hp_time, out="time")
    by_steps = _run(tmp_path, hp_steps, out="steps")
    assert _unit_steps(by_time) == list(range(128, 1025, 128))  # long before checkpoint_freq
    assert _unit_steps(by_steps) == [1024]
    # Same seed, same result: checkpointing reads the model and never disturbs it.
    from stable_baselines3 import PPO

    a, b = (PPO.load(d / "model.zip", device="cpu").policy.state_dict() for d in (by_time, by_steps))
    assert all(torch.equal(a[k], b[k]) for k in a)
    curves = [np.load(d / "evaluations.npz") for d in (by_time, by_steps)]
    from continuum_gym.agents.evaluation_callback import COST_COLUMNS

    assert set(COST_COLUMNS) < set(curves[0].files)  # what each run cost differs; its results do not
    assert all(np.array_equal(curves[0][k], curves[1][k]) for k in curves[0].files if k not in COST_COLUMNS)


def test_a_finished_run_is_never_overwritten(tmp_path, capsys):
    hp = _hyperparams(tmp_path, n_timesteps=256)
    run_dir = _run(tmp_path, hp)
    before = {p: p.stat().st_mtime_ns for p in run_dir.rglob("*")}
    with pytest.raises(FileExistsError, match="finished"):
        _run(tmp_path, hp)
    assert main(["train", "--env", VIEW, "--hyperparams", str(hp), "--out", str(tmp_path / "runs"),
                 "--no-progress"]) == 2
    capsys.readouterr()
    _run(tmp_path, hp, resume=True)  # nothing left to do
    assert "nothing to do" in capsys.readouterr().err
    assert before == {p: p.stat().st_mtime_ns for p in run_dir.rglob("*")}
    _run(tmp_path, hp, resume=True, steps=384)  # an explicit --resume to more steps continues it
    assert _unit_steps(run_dir) == [256, 384] and _curve(run_dir) == [4, 256, 384]


def test_a_run_with_the_old_single_file_checkpoint_resumes(tmp_path, monkeypatch, capsys):
    hp = _hyperparams(tmp_path)
    with monkeypatch.context() as patch:
        _kill_at_write(patch, 3)
        with pytest.raises(Killed):
            _run(tmp_path, hp)
    run_dir = tmp_path / "runs" / RUN
    folder = run_dir / "checkpoints"
    # The layout before units: latest.zip and state.json side by side; old resumes also duplicated rows.
    (folder / "step_000000000256" / "model.zip").rename(folder / "latest.zip")
    (folder / "state.json").write_text(json.dumps({"num_timesteps": 256, "time": 0.0}))
    for unit in list_units(folder):
        checkpoint.discard(unit)
    np.savez(run_dir / "evaluations.npz", timesteps=np.array([4, 260, 4]), mean_return=np.zeros(3), mean_or=np.zeros(3))
    with pytest.raises(FileExistsError, match="--resume"):
        _run(tmp_path, hp)
    capsys.readouterr()
    _run(tmp_path, hp, resume=True)
    assert "from step 256" in capsys.readouterr().err
    assert not (folder / "latest.zip").exists() and not (folder / "state.json").exists()
    assert _unit_steps(run_dir) == [896, 1024] and _curve(run_dir) == SCHEDULE
    # the old state kept no cost: the run's cost stays unknown rather than counting this session only
    curve = np.load(run_dir / "evaluations.npz")
    assert np.isnan(curve["cpu_s"]).all() and np.isnan(curve["wall_s"]).all()


def _write(path, text):
    path.write_text(text)
    return path


@pytest.mark.parametrize("flags, block, needles", [
    (["--steps", "-5"], {}, ["--steps", ">= 1", "'-5'"]),
    (["--steps", "0"], {}, ["--steps", "'0'"]),
    (["--steps", "inf"], {}, ["--steps", "finite", "'inf'"]),
    (["--steps", "2000.5"], {}, ["--steps", "whole", "'2000.5'"]),
    (["--n-envs", "0"], {}, ["--n-envs", ">= 1", "'0'"]),
    (["--n-envs", "two"], {}, ["--n-envs", "'two'"]),
    (["--seed", "-1"], {}, ["--seed", "'-1'"]),
    (["--seeds", "0", "x"], {}, ["--seeds", "'x'"]),
    (["--seeds", "1", "1"], {}, ["--seeds", "distinct"]),
    (["--seeds", "0", "1", "--parallel", "0"], {}, ["--parallel", ">= 1", "'0'"]),
    ([], {"n_steps": "sixty-four"}, ["n_steps", "whole number >= 1", "'sixty-four'"]),
    ([], {"batch_size": 0}, ["batch_size", ">= 1", "got 0"]),
    ([], {"n_step": 32}, ["'n_step'", "did you mean 'n_steps'", "valid:"]),
    ([], {"checkpoint_minutes": 0}, ["checkpoint_minutes", "> 0", "got 0"]),
    ([], {"checkpoint_freq": -1}, ["checkpoint_freq", ">= 1", "got -1"]),
    ([], {"keep_checkpoints": 0}, ["keep_checkpoints", ">= 1", "got 0"]),
    ([], {"gamma": 1.5}, ["gamma", "[0, 1]", "1.5"]),
    ([], {"use_sde": "yes"}, ["use_sde", "true or false", "'yes'"]),
    ([], {"seed": 3}, ["'seed'", "--seed"]),
    ([], {"env_kwargs": {"task": "nope"}}, ["env_kwargs", "task", "'nope'"]),
])
def test_bad_input_exits_2_naming_the_parameter_and_writes_nothing(tmp_path, capsys, flags, block, needles):
    hp = _hyperparams(tmp_path, **block)
    out = tmp_path / "out"
    assert main(["train", "--env", VIEW, "--hyperparams", str(hp), "--out", str(out), "--no-progress", *flags]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("continuum-gym train: ") and len(err.splitlines()) == 1
    for needle in needles:
        assert needle in err
    assert not out.exists()


@pytest.mark.parametrize("algo", ["sac", "td3"])
def test_a_budget_below_the_packaged_burn_in_fails_naming_steps_the_value_and_the_fix(algo, tmp_path, capsys):
    """The packaged off-policy blocks hold the residual's actor for 20000 steps: 10000 would train nothing."""
    out = tmp_path / "out"
    assert main(["train", "--env", VIEW, "--algo", algo, "--steps", "10000", "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("continuum-gym train: ") and len(err.splitlines()) == 1
    for needle in ("--steps 10000", "trains nothing", "burn_in_steps: 20000", f"{algo}.yml", "above 20000",
                   "--hyperparams"):
        assert needle in err, needle
    assert not out.exists()


@pytest.mark.parametrize("block, steps, needles", [
    ({"learning_starts": 5000, "burn_in_steps": 0}, 5000, ["learning_starts: 5000", "above 5000"]),
    ({"learning_starts": 100, "burn_in_steps": 300}, 200, ["burn_in_steps: 300", "above 300"]),
])
def test_an_off_policy_budget_at_or_below_learning_starts_or_burn_in_fails(tmp_path, capsys, block, steps, needles):
    hp = tmp_path / "sac.yml"
    hp.write_text(yaml.safe_dump({VIEW: {"n_envs": 2, **block}}))
    out = tmp_path / "out"
    assert main(["train", "--env", VIEW, "--algo", "sac", "--steps", str(steps), "--hyperparams", str(hp),
                 "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    for needle in (f"--steps {steps}", "trains nothing", *needles):
        assert needle in err, needle
    assert not out.exists()


def test_a_budget_that_trains_the_actor_for_less_than_its_burn_in_warns_and_trains(tmp_path, capsys):
    from stable_baselines3 import SAC

    block = {"policy": "MlpPolicy", "n_envs": 2, "buffer_size": 1000, "batch_size": 32, "learning_starts": 64,
             "train_freq": 8, "gradient_steps": 1, "n_timesteps": 256, "checkpoint_freq": 10**6, "eval_freq": 10**6,
             "n_eval_episodes": 1, "burn_in_steps": 192, "policy_kwargs": {"net_arch": [16]},
             "env_kwargs": {"task": "static", "max_episode_steps": 40}}
    hp = tmp_path / "sac.yml"
    hp.write_text(yaml.safe_dump({VIEW: block}))
    run_dir = train(VIEW, "sac", seed=0, out=tmp_path / "runs", hyperparams=hp, progress=False)
    err = capsys.readouterr().err
    assert "only the last 64 of 256 steps train the actor" in err and "burn_in_steps: 192" in err
    assert SAC.load(run_dir / "model.zip", device="cpu").num_timesteps == 256
    # A pure-RL run has no burn-in: only learning_starts counts, and 256 steps are plenty past 64.
    capsys.readouterr()
    train(VIEW, "sac", base=None, seed=0, out=tmp_path / "runs", hyperparams=hp, progress=False)
    assert "train the actor" not in capsys.readouterr().err


@pytest.mark.parametrize("text, needle", [
    ("", "is empty"),
    ("ContinuumGym/ViewTracking-v0: {n_steps: [1, 2}\n", "not valid YAML"),
    ("- 1\n", "must map env ids"),
    ("ContinuumGym/ViewTracking-v0: 3\n", "must be a mapping"),
])
def test_unusable_hyperparameter_files_exit_2(tmp_path, capsys, text, needle):
    hp = _write(tmp_path / "hp.yml", text)
    assert main(["train", "--env", VIEW, "--hyperparams", str(hp), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert needle in err and str(hp) in err and not (tmp_path / "out").exists()


def test_out_pointing_at_a_file_exits_2_and_leaves_it(tmp_path, capsys):
    hp = _hyperparams(tmp_path)
    target = _write(tmp_path / "notes.txt", "keep me")
    assert main(["train", "--env", VIEW, "--hyperparams", str(hp), "--out", str(target)]) == 2
    assert "--out" in capsys.readouterr().err and target.read_text() == "keep me"
    with pytest.raises(ValueError, match="steps"):
        train(VIEW, steps=0, out=tmp_path / "api", hyperparams=hp)
    assert not (tmp_path / "api").exists()


def test_a_run_directory_is_trained_by_one_process_at_a_time(tmp_path, capsys):
    import fcntl
    import os

    hp = _hyperparams(tmp_path)
    run_dir = tmp_path / "runs" / RUN
    run_dir.mkdir(parents=True)
    fd = os.open(run_dir, os.O_RDONLY)  # what a live trainer of this run holds
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        assert main(["train", "--env", VIEW, "--hyperparams", str(hp), "--out", str(tmp_path / "runs")]) == 2
        assert "being trained by another process" in capsys.readouterr().err
        assert list(run_dir.iterdir()) == []
    finally:
        os.close(fd)
