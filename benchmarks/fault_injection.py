"""Fault injection: training runs (PPO and SAC) killed with SIGKILL at random moments, then resumed.

For each algorithm: one uninterrupted reference run, then ``--kills`` trials. A trial starts
``continuum-gym train`` in a subprocess, SIGKILLs it (the whole process group) after a random delay
drawn uniformly from [0.3 s, 0.9 x the reference's wall time] (so kills land before the first
checkpoint, during training and inside checkpoint writes; a delay past the end counts as not killed), then runs
``continuum-gym train --resume`` until it exits 0. Each trial must end with:

* the full step count in the final model and in the newest checkpoint unit;
* every published checkpoint unit verifying (checksums), no staging directories or temp files left;
* an evaluation history with strictly increasing steps (no duplicate or out-of-order rows);
* when the kill came before the first checkpoint (so the resume restarted from zero), a final model
  equal, parameter for parameter, to the reference.

A resume from a checkpoint does not reproduce the uninterrupted run bit for bit: SB3's saved model
carries neither the vector env's mid-episode state nor the global torch / numpy generator streams, so
the resumed run draws new episodes from the checkpoint on. That case is checked for consistency,
not equality, and counted separately.

    python benchmarks/fault_injection.py --kills 20 --json results/bench/fault_injection.json
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

VIEW = "ContinuumGym/ViewTracking-v0"
BLOCKS = {
    "ppo": {"policy": "MlpPolicy", "n_envs": 4, "n_steps": 32, "batch_size": 64, "n_epochs": 2, "n_timesteps": 2048,
            "checkpoint_freq": 128, "checkpoint_minutes": 5.0, "keep_checkpoints": 2, "eval_freq": 512,
            "n_eval_episodes": 1, "residual_scale": 0.3, "policy_kwargs": {"net_arch": [16]},
            "env_kwargs": {"task": "static", "max_episode_steps": 40}},
    "sac": {"policy": "MlpPolicy", "n_envs": 2, "buffer_size": 2000, "batch_size": 32, "learning_starts": 64,
            "train_freq": 8, "gradient_steps": 1, "n_timesteps": 768, "checkpoint_freq": 64,
            "checkpoint_minutes": 5.0, "keep_checkpoints": 2, "eval_freq": 256, "n_eval_episodes": 1,
            "burn_in_steps": 128, "policy_kwargs": {"net_arch": [16]},
            "env_kwargs": {"task": "static", "max_episode_steps": 40}},
}
RUN = "ViewTracking_{algo}_dimension_reduced_seed0"


#: Runs the trainer with a SIGKILL at the n-th checkpoint publish: every file of the unit is written to
#: its staging directory, the atomic rename has not happened.
KILL_IN_WRITE = (
    "import os, signal, sys\n"
    "from continuum_gym.agents import checkpoint\n"
    "from continuum_gym.cli import main\n"
    "real, calls, target = checkpoint.publish, [], int(sys.argv[1])\n"
    "def publish(staging, final):\n"
    "    calls.append(final)\n"
    "    if len(calls) == target:\n"
    "        os.kill(os.getpid(), signal.SIGKILL)\n"
    "    real(staging, final)\n"
    "checkpoint.publish = publish\n"
    "sys.exit(main(sys.argv[2:]))\n")


def command(algo: str, out: Path, hyperparams: Path, resume: bool, kill_in_write: int | None = None) -> list[str]:
    argv = ["train", "--env", VIEW, "--algo", algo, "--seed", "0", "--out", str(out), "--hyperparams",
            str(hyperparams), "--no-progress"] + (["--resume"] if resume else [])
    if kill_in_write is not None:
        return [sys.executable, "-c", KILL_IN_WRITE, str(kill_in_write), *argv]
    return [sys.executable, "-m", "continuum_gym.cli", *argv]


def run(argv: list[str], kill_after: float | None = None) -> tuple[int, float]:
    """(return code, seconds); SIGKILL the process group after ``kill_after`` seconds if still running."""
    started = time.perf_counter()
    process = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    try:
        process.wait(timeout=kill_after)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()
    return process.returncode, time.perf_counter() - started


def parameters(model_zip: Path, algo: str) -> tuple[dict, int]:
    from stable_baselines3 import PPO, SAC

    model = {"ppo": PPO, "sac": SAC}[algo].load(model_zip, device="cpu")
    return {key: value.detach().numpy().copy() for key, value in model.policy.state_dict().items()}, model.num_timesteps


def check_run(run_dir: Path, algo: str, total: int) -> dict:
    """The consistency checks of one finished run (see the module docstring); raises AssertionError."""
    from continuum_gym.agents.checkpoint import list_units, verify

    params, steps = parameters(run_dir / "model.zip", algo)
    assert steps == total, f"final model at {steps} steps, expected {total}"
    folder = run_dir / "checkpoints"
    units = list_units(folder)
    assert units and units[-1].step == total, f"newest unit at {units[-1].step if units else None}"
    for unit in units:
        problem = verify(unit)
        assert problem is None, f"unit {unit.step}: {problem}"
    leftovers = [p.name for p in folder.iterdir() if p.name.startswith(".")]
    leftovers += [p.name for p in run_dir.iterdir() if p.name.endswith(".tmp")]
    assert not leftovers, f"left behind: {leftovers}"
    timesteps = np.load(run_dir / "evaluations.npz")["timesteps"].tolist()
    assert all(a < b for a, b in zip(timesteps, timesteps[1:])), f"evaluation steps not increasing: {timesteps}"
    return params


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kills", type=int, default=20, help="killed trials per algorithm (default 20)")
    parser.add_argument("--algos", nargs="+", default=["ppo", "sac"], choices=sorted(BLOCKS))
    parser.add_argument("--seed", type=int, default=0, help="seed of the kill times")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    report = {}
    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)
        for algo in args.algos:
            hp = scratch / f"{algo}.yml"
            hp.write_text(yaml.safe_dump({VIEW: BLOCKS[algo]}))
            total = BLOCKS[algo]["n_timesteps"]
            code, reference_seconds = run(command(algo, scratch / "reference", hp, False))
            assert code == 0, f"{algo} reference run failed"
            reference = check_run(scratch / "reference" / RUN.format(algo=algo), algo, total)
            rows = []
            for trial in range(args.kills):
                out = scratch / f"{algo}_{trial}"
                # Odd trials die inside a checkpoint write (a random unit), even ones at a random moment.
                units_total = total // BLOCKS[algo]["checkpoint_freq"]
                in_write = int(rng.integers(1, units_total + 1)) if trial % 2 else None
                delay = float(rng.uniform(0.3, 0.9 * reference_seconds))
                code, _ = run(command(algo, out, hp, False, in_write), kill_after=None if in_write else delay)
                run_dir = out / RUN.format(algo=algo)
                units_at_kill = len(list((run_dir / "checkpoints").glob("step_*"))) if run_dir.exists() else 0
                staging = len(list((run_dir / "checkpoints").glob(".tmp-*"))) if run_dir.exists() else 0
                resumes = 0
                while code != 0:
                    resumes += 1
                    assert resumes <= 3, f"{algo} trial {trial}: resume keeps failing"
                    code, _ = run(command(algo, out, hp, True))
                params = check_run(run_dir, algo, total)
                restarted = units_at_kill == 0
                equal = all(np.array_equal(params[k], reference[k]) for k in reference)
                if restarted:
                    assert equal, f"{algo} trial {trial}: restarted from zero but differs from the reference"
                killed = resumes > 0
                rows.append({"kill": f"in write {in_write}" if in_write else f"at {delay:.2f} s", "killed": killed,
                             "units_at_kill": units_at_kill, "inside_write": staging > 0,
                             "restarted_from_zero": killed and restarted, "equal": equal})
                how = ("finished before the kill" if not killed else
                       f"{units_at_kill} units{', inside a write' if staging else ''}, "
                       f"{'restarted' if restarted else 'resumed'}")
                print(f"{algo} trial {trial:2d}: kill {rows[-1]['kill']}: {how} -> complete"
                      f"{', equal to the reference' if equal else ''}", flush=True)
            report[algo] = {"reference_seconds": round(reference_seconds, 1), "trials": rows,
                            "killed": sum(r["killed"] for r in rows),
                            "before_first_checkpoint": sum(r["restarted_from_zero"] for r in rows),
                            "resumed_equal_to_reference": sum(r["killed"] and not r["restarted_from_zero"]
                                                              and r["equal"] for r in rows),
                            "inside_write": sum(r["inside_write"] for r in rows),
                            "complete_and_consistent": len(rows)}
            print(json.dumps({k: v for k, v in report[algo].items() if k != "trials"}))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
