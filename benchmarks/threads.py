"""Thread use: two processes stepping native vector envs at once, and the caller's thread settings.

    python benchmarks/threads.py [--json PATH] [--quick]

Each process steps ``gym.make_vec(id, num_envs=64, vectorization_mode="vector_entry_point")`` with
random actions for a few seconds and reports its rate. Cases per env:

- ``alone``: one process, default ``num_threads`` (numba's thread count when torch is not loaded);
- ``two``: two such processes at once on the same cores (two trainings, a sweep, a user's second job);
- ``torch.alone`` / ``torch.two``: the same with torch imported first, as under SB3, torchrl or skrl
  (the default is then 1 thread: the learner computes on the other threads).

"Collapse" is the total of two processes falling well below one process alone: two thread pools
spinning on the same cores. ``ratio`` = total rate of two / rate of one alone (1.0: the cores are
shared without loss; 2.0 would need idle cores). Each child also reports torch's and numba's thread
thread count before and after stepping (or, without torch, the count of a torch imported afterwards),
with ``OMP_NUM_THREADS=1`` set by the caller, to show that it is left as the caller set it.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import finish, machine, print_table, run_children_at_once  # noqa: E402

ENV_IDS = ("ContinuumGym/OcclusionAvoidance-v0", "ContinuumGym/ViewTracking-v0")
UNITS = {"*.alone": "steps/s", "*.two_each": "steps/s", "*.ratio": "(derived)"}

_CHILD = r"""
import json, sys, time
env_id, seconds, with_torch = sys.argv[1], float(sys.argv[2]), sys.argv[3] == "1"
before = {}
if with_torch:
    import torch
    before["torch"] = torch.get_num_threads()
import gymnasium as gym
import numpy as np
import continuum_gym  # noqa: F401
env = gym.make_vec(env_id, num_envs=64, vectorization_mode="vector_entry_point")
env.reset(seed=0)
rng = np.random.default_rng(0)
actions = rng.uniform(-1, 1, (256,) + env.action_space.shape)
for k in range(3):
    env.step(actions[k])
steps = 0
start = time.perf_counter()
while time.perf_counter() - start < seconds:
    env.step(actions[steps % 256])
    steps += 1
rate = steps * 64 / (time.perf_counter() - start)
after = {}
if with_torch:
    after["torch"] = torch.get_num_threads()
else:  # torch imported only now: it takes the process's OpenMP setting as it finds it
    import torch
    after["torch imported after"] = torch.get_num_threads()
print(json.dumps({"rate": rate, "threads_before": before, "threads_after": after,
                  "num_threads": env.unwrapped.core.num_threads if hasattr(env.unwrapped, "core") else None}))
"""


def run_at_once(env_id: str, count: int, seconds: float, with_torch: bool) -> list[dict]:
    environ = dict(os.environ, OMP_NUM_THREADS="1")
    args = [sys.executable, "-c", _CHILD, env_id, str(seconds), "1" if with_torch else "0"]
    return run_children_at_once(args, count, environ, f"{env_id} child")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", help="write results to this JSON file")
    parser.add_argument("--quick", action="store_true", help="shorter timing windows")
    args = parser.parse_args(argv)
    seconds = 2.0 if args.quick else 6.0
    results = {"machine": machine(), "units": UNITS}
    rows = []
    for env_id in ENV_IDS:
        for with_torch in (False, True):
            alone = run_at_once(env_id, 1, seconds, with_torch)[0]
            two = run_at_once(env_id, 2, seconds, with_torch)
            key = f"{'torch' if with_torch else 'plain'}.{env_id.split('/')[-1]}"
            total = sum(r["rate"] for r in two)
            results[key] = {"alone": alone["rate"], "two_each": min(r["rate"] for r in two),
                            "ratio": total / alone["rate"], "num_threads": alone["num_threads"],
                            "threads_before": alone["threads_before"], "threads_after": alone["threads_after"],
                            "runs": {"alone": alone, "two": two}}
            rows.append((env_id.split("/")[-1], "yes" if with_torch else "no", alone["num_threads"],
                         f"{alone['rate']:,.0f}", " / ".join(f"{r['rate']:,.0f}" for r in two),
                         f"{total / alone['rate']:.2f}",
                         f"{alone['threads_before']} -> {alone['threads_after']}"))
    print_table(rows, ("env (N=64)", "torch loaded", "num_threads", "alone (steps/s)", "two at once (each)",
                       "two total / alone", "threads before -> after"))
    return finish(results, args.json)


if __name__ == "__main__":
    sys.exit(main())
