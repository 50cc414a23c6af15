"""Training throughput and time-to-threshold: the packaged configs against the previous ones, and threads.

    python benchmarks/training.py [--json PATH] [--quick] [--only configs|threads] [--env ID ...]
                                  [--algo ppo sac td3] [--steps N | --fraction F]

**Old against new packaged configs** (``configs``): for each algorithm (PPO, SAC, TD3) and environment,
the algorithm trains once with its previous packaged block (``benchmarks/<algo>_previous.yml``: ``ppo.yml``,
``sac.yml``, ``td3.yml`` as they were before issue 35) and once with today's
(``continuum_gym/agents/hyperparams/<algo>.yml``), each in a fresh subprocess through
``continuum_gym.agents.train.train`` (what ``continuum-gym train`` runs: the native vector env,
VecNormalize, checkpoints, the periodic validation evaluation), one after the other, never at once.
Each run's clock starts after its first evaluation (of the untrained residual, at the first step), so
that start-up (imports, compiled kernels, env construction) is left out; from there it includes
everything a user waits for: rollouts, updates, checkpoints and the periodic evaluations. Reported:

* end-to-end env steps/s (wall-clock) and env steps per CPU-second of the process (the same rate, but
  not slowed down by other processes on a shared machine); gradient steps/s over the same stretch
  (SB3's update count of the saved model: SAC / TD3 one per gradient step, PPO one per epoch, times
  the minibatches of a rollout);
* time-to-threshold: wall-clock (and CPU) seconds until the validation headline metric (the training
  evaluation: ``n_eval_episodes`` validation tasks, the same ids for both configs) first reaches 90 % of
  that run's final score; for a lower-is-better metric (OcclusionAvoidance's mean VOI) the threshold
  is final / 0.9;
* the final score and the steps of each run (each config's own ``n_timesteps``, or ``--steps``;
  ``--fraction F``: a reduced budget, each config's own ``n_timesteps`` and ``eval_freq`` times F, so
  that both configs keep their ratio of budgets and their number of evaluations; ``--quick``: 100k steps
  each, evaluated every 25k, a smoke run whose scores mean nothing).

The full PPO comparison trains the previous configs for their 3M steps: ~5 CPU-minutes for ViewTracking
and ~13 for OcclusionAvoidance on the machine of issue 35, against ~3 and ~2 for today's; SAC and TD3
take ~4-7 CPU-minutes per run at either config. One seed per config: for the spread between seeds, and
the search behind the packaged values, see the comments in ``ppo.yml``, ``sac.yml`` and ``td3.yml``.

**Threads** (``threads``): each case trains in fresh subprocesses with the packaged hyperparameters and
the trainer's thread choice (``learner_threads()``: one torch thread per process, the env stepped on the
calling thread), except the rows that set torch's intra-op threads to 2 to show what a second thread
buys. "2 runs" starts two identical trainings at once (as ``train --seeds 0 1 --parallel 2`` or a
two-trial sweep does) and reports the rate of each: PPO environment steps per second over whole
rollout + update cycles; SAC and TD3 gradient steps per second after ``learning_starts`` (shortened
here, so that the timed part is the learning part) and the environment steps per second of the same
stretch.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import finish, machine, print_table, run_children_at_once  # noqa: E402

HERE = Path(__file__).resolve().parent
PREVIOUS = {algo: HERE / f"{algo}_previous.yml" for algo in ("ppo", "sac", "td3")}
UNITS = {"*.env_steps_per_second": "steps/s", "*.gradient_steps_per_second": "gradient steps/s",
         "*.env_steps_per_cpu_second": "steps per CPU-second", "*.seconds_to_threshold": "s",
         "*.cpu_seconds_to_threshold": "CPU-s"}
CONFIG_ENVS = ("ContinuumGym/ViewTracking-v0", "ContinuumGym/OcclusionAvoidance-v0")

# One training run through the trainer; prints its learning curve against wall-clock and CPU time, and
# its gradient steps (SB3's update count of the saved model; PPO's counts epochs: times the minibatches).
_TRAIN_CHILD = r"""
import json, math, sys, tempfile, time, zipfile
algo, env_id, hyperparams, steps, eval_freq = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4], sys.argv[5]
import continuum_gym.agents.train as trainer
curve = []
def report(timesteps, value):
    curve.append({"steps": timesteps, "value": value, "wall": time.perf_counter(), "cpu": time.process_time()})
with tempfile.TemporaryDirectory() as out:
    block = trainer.load_hyperparams(algo, env_id, hyperparams)
    if eval_freq != "-":  # --quick / --fraction: a copy of the block with eval_freq (and the budget) changed
        import yaml
        changed = {"eval_freq": int(float(eval_freq))}
        if steps.startswith("x"):  # a fraction of the block's own budget
            changed["n_timesteps"] = int(float(block["n_timesteps"]) * float(steps[1:]))
            changed["eval_freq"] = int(float(block["eval_freq"]) * float(steps[1:]))
            steps = "-"
        hyperparams = out + "/changed.yml"
        open(hyperparams, "w").write(yaml.safe_dump({env_id: {**block, **changed}}))
    hp = trainer.resolve_hyperparams(algo, env_id, hyperparams)
    run = trainer.train(env_id, algo, seed=0, steps=None if steps == "-" else int(steps), out=out + "/runs",
                        hyperparams=hyperparams, progress=False, report=report)
    data = json.loads(zipfile.ZipFile(run / "model.zip").read("data"))
updates = int(data["_n_updates"])
if algo == "ppo":
    updates *= math.ceil(int(hp.get("n_envs", 1)) * int(hp["n_steps"]) / int(hp["batch_size"]))
print(json.dumps({"curve": curve, "gradient_steps": updates,
                  "hyperparams": {k: v for k, v in hp.items() if k != "env_kwargs"}}))
"""


def time_to_threshold(curve: list[dict], higher_is_better: bool, fraction: float = 0.9) -> dict:
    """Summary of one run's curve (``steps``, ``value``, ``wall``, ``cpu`` per evaluation; clocks absolute).

    The clock starts at the first evaluation (the untrained residual); the threshold is ``fraction`` of
    the final value (``final / fraction`` when lower is better), reached at the first evaluation at or past it.
    """
    first, last = curve[0], curve[-1]
    final = last["value"]
    threshold = fraction * final if higher_is_better else final / fraction
    reached = next(p for p in curve if (p["value"] >= threshold if higher_is_better else p["value"] <= threshold))
    steps = last["steps"] - first["steps"]
    return {
        "steps": last["steps"], "final_score": final, "threshold": threshold,
        "wall_seconds": last["wall"] - first["wall"], "cpu_seconds": last["cpu"] - first["cpu"],
        "env_steps_per_second": steps / max(last["wall"] - first["wall"], 1e-9),
        "env_steps_per_cpu_second": steps / max(last["cpu"] - first["cpu"], 1e-9),
        "steps_to_threshold": reached["steps"],
        "seconds_to_threshold": reached["wall"] - first["wall"],
        "cpu_seconds_to_threshold": reached["cpu"] - first["cpu"],
    }


def run_config(env_id: str, hyperparams: Path, quick: bool, steps: int | None = None, algo: str = "ppo",
               fraction: float | None = None) -> dict:
    """Train ``env_id`` with the ``algo`` block of ``hyperparams`` in a fresh process; its curve summary.

    ``fraction``: a reduced budget, the block's own ``n_timesteps`` and ``eval_freq`` times ``fraction``.
    """
    from continuum_gym.agents.train import headline_metric
    from continuum_gym.envs.spec import get_spec

    budget, eval_freq = ("100000", "25000") if quick else ("-", "-")
    steps = str(steps) if steps is not None else budget
    if fraction is not None:
        steps, eval_freq = f"x{fraction}", "0"
    args = [sys.executable, "-c", _TRAIN_CHILD, algo, env_id, str(hyperparams), steps, eval_freq]
    proc = subprocess.run(args, capture_output=True, text=True, env=dict(os.environ))
    if proc.returncode != 0:
        raise RuntimeError(f"training {algo} on {env_id} with {hyperparams} failed:\n{proc.stderr[-3000:]}")
    child = json.loads(proc.stdout.strip().splitlines()[-1])
    higher = get_spec(env_id).metric(headline_metric(env_id)).higher_is_better
    summary = time_to_threshold(child["curve"], higher)
    summary["gradient_steps"] = child["gradient_steps"]
    summary["gradient_steps_per_second"] = child["gradient_steps"] / max(summary["wall_seconds"], 1e-9)
    summary["gradient_steps_per_cpu_second"] = child["gradient_steps"] / max(summary["cpu_seconds"], 1e-9)
    return {**summary, "algo": algo, "metric": headline_metric(env_id),
            "hyperparams": child["hyperparams"], "curve": [{"steps": p["steps"], "value": p["value"],
                                                            "wall": p["wall"] - child["curve"][0]["wall"]}
                                                           for p in child["curve"]]}


#: (algo, env id, torch threads, runs at once)
THREAD_CASES = (
    ("ppo", "ContinuumGym/ViewTracking-v0", 1, 1),
    ("ppo", "ContinuumGym/ViewTracking-v0", 2, 1),
    ("ppo", "ContinuumGym/ViewTracking-v0", 1, 2),
    ("ppo", "ContinuumGym/OcclusionAvoidance-v0", 1, 1),
    ("sac", "ContinuumGym/ViewTracking-v0", 1, 1),
    ("sac", "ContinuumGym/ViewTracking-v0", 2, 1),
    ("sac", "ContinuumGym/ViewTracking-v0", 1, 2),
    ("td3", "ContinuumGym/ViewTracking-v0", 1, 1),
    ("td3", "ContinuumGym/ViewTracking-v0", 1, 2),
)

_THREADS_CHILD = r"""
import inspect, json, sys, time
import numpy as np
algo, env_id, torch_threads, steps, learning_starts = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
from continuum_gym.agents.train import RUN_DEFAULTS, learner_threads, load_hyperparams
threads = learner_threads()
import torch
torch.set_num_threads(torch_threads)
import stable_baselines3 as sb3
from stable_baselines3.common.callbacks import BaseCallback
from continuum_gym.envs.sb3 import ContinuumSB3VecEnv
hp = load_hyperparams(algo, env_id)
cls = {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3}[algo]
accepted = set(inspect.signature(cls.__init__).parameters)
kwargs = {k: v for k, v in hp.items() if k in accepted and k not in ("policy", "env")}
if "train_freq" in kwargs and isinstance(kwargs["train_freq"], list):
    kwargs["train_freq"] = tuple(kwargs["train_freq"])
if algo != "ppo":
    kwargs["learning_starts"] = learning_starts
n_envs = int(hp.get("n_envs", RUN_DEFAULTS["n_envs"]))
venv = ContinuumSB3VecEnv(env_id, n_envs, seed=0, task_split="train", **dict(hp.get("env_kwargs") or {}))
model = cls(hp.get("policy", "MlpPolicy"), venv, seed=0, verbose=0, device="cpu", **kwargs)
if algo == "ppo":  # whole rollouts: at least 4 (2 with --quick) of the packaged size
    steps = max(steps, int(sys.argv[6]) * n_envs * int(hp["n_steps"]))

class Clock(BaseCallback):
    def __init__(self):
        super().__init__()
        self.mark = None
    def _on_step(self):
        if self.mark is None and self.num_timesteps >= learning_starts:
            self.mark = (time.perf_counter(), self.num_timesteps, self.model._n_updates)
        return True

clock = Clock()
start = time.perf_counter()
model.learn(total_timesteps=steps, callback=clock)
end = time.perf_counter()
if algo == "ppo":
    out = {"env_steps_per_second": model.num_timesteps / (end - start)}
else:
    t0, n0, u0 = clock.mark
    out = {"env_steps_per_second": (model.num_timesteps - n0) / (end - t0),
           "gradient_steps_per_second": (model._n_updates - u0) / (end - t0)}
out["threads"] = {**threads, "torch": torch.get_num_threads()}
print(json.dumps(out))
"""


def run_thread_case(algo: str, env_id: str, torch_threads: int, runs: int, quick: bool) -> list[dict]:
    """Start ``runs`` identical trainings at once; their results (one dict each)."""
    rollouts = 2 if quick else 4
    if algo == "ppo":
        steps, learning_starts = 0, 0  # whole rollouts of the packaged n_envs x n_steps
    else:
        learning_starts = 1000
        steps = learning_starts + (1000 if quick else 4000)
    args = [sys.executable, "-c", _THREADS_CHILD, algo, env_id, str(torch_threads), str(steps), str(learning_starts),
            str(rollouts)]
    return run_children_at_once(args, runs, dict(os.environ), f"{algo} on {env_id}")


def configs_section(envs, quick: bool, results: dict, steps: int | None = None, algos=("ppo",),
                    fraction: float | None = None) -> None:
    from continuum_gym.agents.run_inputs import HYPERPARAMS_DIR

    rows = []
    for algo in algos:
        for env_id in envs:
            short = env_id.split("/")[-1]
            pair = {}
            for label, path in (("previous", PREVIOUS[algo]), ("packaged", HYPERPARAMS_DIR / f"{algo}.yml")):
                summary = run_config(env_id, path, quick, steps, algo, fraction)
                pair[label] = summary
                results["configs"][f"{algo}.{short}.{label}"] = summary
                print(f"  {algo} {short} {label}: {summary['steps']:,} steps, "
                      f"{summary['env_steps_per_second']:,.0f} env steps/s "
                      f"({summary['env_steps_per_cpu_second']:,.0f} per CPU-s), "
                      f"{summary['gradient_steps_per_second']:,.1f} gradient steps/s, {summary['metric']} "
                      f"{summary['final_score']:.3f}, threshold {summary['threshold']:.3f} at "
                      f"{summary['seconds_to_threshold']:.0f} s ({summary['steps_to_threshold']:,} steps)", flush=True)
            old, new = pair["previous"], pair["packaged"]

            def ratio(key):  # None when the previous run was at its threshold from the first evaluation on
                return new[key] / old[key] if old[key] > 0 else None

            ratios = {key: ratio(key) for key in ("env_steps_per_second", "env_steps_per_cpu_second",
                                                  "gradient_steps_per_second", "seconds_to_threshold",
                                                  "cpu_seconds_to_threshold")}
            results["configs"][f"{algo}.{short}.new_over_previous"] = ratios
            for label, s in pair.items():
                rows.append((algo, short, label, f"{s['steps']:,}", f"{s['env_steps_per_second']:,.0f}",
                             f"{s['env_steps_per_cpu_second']:,.0f}", f"{s['gradient_steps_per_second']:,.1f}",
                             f"{s['final_score']:.3f}",
                             f"{s['seconds_to_threshold']:.0f} / {s['cpu_seconds_to_threshold']:.0f}",
                             f"{s['wall_seconds']:.0f} / {s['cpu_seconds']:.0f}"))
            times = {key: "-" if ratios[key] is None else f"x{ratios[key]:.2f}" for key in ratios}
            rows.append((algo, short, "packaged / previous", "", times["env_steps_per_second"],
                         times["env_steps_per_cpu_second"], times["gradient_steps_per_second"], "",
                         f"{times['seconds_to_threshold']} / {times['cpu_seconds_to_threshold']}", ""))
    print_table(rows, ("algo", "env", "config", "steps", "env steps/s", "per CPU-s", "gradient steps/s",
                       "final (validation)", "to 90 % of final: s / CPU-s", "whole run: s / CPU-s"))


def threads_section(quick: bool, results: dict) -> None:
    rows = []
    for algo, env_id, torch_threads, runs in THREAD_CASES:
        per_run = run_thread_case(algo, env_id, torch_threads, runs, quick)
        key = f"{algo}.{env_id.split('/')[-1]}.torch{torch_threads}.runs{runs}"
        results["cases"][key] = {
            "env_steps_per_second": min(r["env_steps_per_second"] for r in per_run),
            "per_run": per_run,
        }
        grad = ""
        if "gradient_steps_per_second" in per_run[0]:
            results["cases"][key]["gradient_steps_per_second"] = min(r["gradient_steps_per_second"] for r in per_run)
            grad = " / ".join(f"{r['gradient_steps_per_second']:.0f}" for r in per_run)
        env_rate = " / ".join(f"{r['env_steps_per_second']:,.0f}" for r in per_run)
        rows.append((algo, env_id.split("/")[-1], torch_threads, runs, env_rate, grad))
        print(f"  {key}: env steps/s {env_rate}" + (f", gradient steps/s {grad}" if grad else ""), flush=True)
    print_table(rows, ("algo", "env", "torch threads", "runs at once", "env steps/s (each run)",
                       "gradient steps/s (each run)"))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", help="write results to this JSON file")
    parser.add_argument("--quick", action="store_true", help="short trainings (a smoke run; scores mean nothing)")
    parser.add_argument("--steps", type=int, default=None,
                        help="env steps of every old-against-new training (default: each config's n_timesteps)")
    parser.add_argument("--only", choices=("configs", "threads"), help="one part only (default: both)")
    parser.add_argument("--env", nargs="+", choices=CONFIG_ENVS, default=list(CONFIG_ENVS),
                        help="environments of the old-against-new part (default: both)")
    parser.add_argument("--algo", nargs="+", choices=tuple(PREVIOUS), default=list(PREVIOUS),
                        help="algorithms of the old-against-new part (default: ppo sac td3)")
    parser.add_argument("--fraction", type=float, default=None,
                        help="reduced budget: each config's own n_timesteps and eval_freq times this (e.g. 0.25)")
    args = parser.parse_args(argv)
    results = {"machine": machine(), "units": UNITS, "configs": {}, "cases": {}}
    if args.only in (None, "configs"):
        if args.fraction is not None and (args.steps is not None or args.quick or not 0 < args.fraction <= 1):
            parser.error("--fraction: a number in (0, 1], not with --steps or --quick")
        configs_section(args.env, args.quick, results, args.steps, args.algo, args.fraction)
    if args.only in (None, "threads"):
        threads_section(args.quick, results)
    return finish(results, args.json)


if __name__ == "__main__":
    sys.exit(main())
