"""Training throughput: is it set by the learner or by thread contention?

    python benchmarks/training.py [--json PATH] [--quick]

Each case trains in fresh subprocesses with the packaged hyperparameters of ``continuum-gym train``
(``continuum_gym/agents/hyperparams/<algo>.yml``) and the trainer's thread choice
(``learner_threads()``: one torch thread per process, the env stepped on the calling thread), except the rows that set torch's
intra-op threads to 2 to show what a second thread buys. "2 runs" starts two identical trainings at
once (as ``train --seeds 0 1 --parallel 2`` or a two-trial sweep does) and reports the rate of each.

Reported: PPO environment steps per second over whole rollout + update cycles; SAC and TD3 gradient
steps per second after ``learning_starts`` (shortened here, so that the timed part is the learning
part) and the environment steps per second of the same stretch.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import finish, machine, print_table, run_children_at_once  # noqa: E402

UNITS = {"*.env_steps_per_second": "steps/s", "*.gradient_steps_per_second": "gradient steps/s"}

_CHILD = r"""
import inspect, json, sys, time
import numpy as np
algo, env_id, torch_threads, steps, learning_starts = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
from continuum_gym.agents.train import learner_threads, load_hyperparams
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
venv = ContinuumSB3VecEnv(env_id, int(hp.get("n_envs", 8)), seed=0, task_split="train",
                          **dict(hp.get("env_kwargs") or {}))
model = cls(hp.get("policy", "MlpPolicy"), venv, seed=0, verbose=0, device="cpu", **kwargs)

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

#: (algo, env id, torch threads, runs at once)
CASES = (
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


def run_case(algo: str, env_id: str, torch_threads: int, runs: int, quick: bool) -> list[dict]:
    """Start ``runs`` identical trainings at once; their results (one dict each)."""
    if algo == "ppo":
        steps = 4096 * (2 if quick else 4)  # whole rollouts of 32 envs x 128 steps
        learning_starts = 0
    else:
        learning_starts = 1000
        steps = learning_starts + (1000 if quick else 4000)
    args = [sys.executable, "-c", _CHILD, algo, env_id, str(torch_threads), str(steps), str(learning_starts)]
    return run_children_at_once(args, runs, dict(os.environ), f"{algo} on {env_id}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", help="write results to this JSON file")
    parser.add_argument("--quick", action="store_true", help="shorter trainings (for smoke tests)")
    args = parser.parse_args(argv)
    results = {"machine": machine(), "units": UNITS, "cases": {}}
    rows = []
    for algo, env_id, torch_threads, runs in CASES:
        per_run = run_case(algo, env_id, torch_threads, runs, args.quick)
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
    return finish(results, args.json)


if __name__ == "__main__":
    sys.exit(main())
