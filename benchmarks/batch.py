"""Batch throughput on all cores: the native vector env at N = 64, 1024, 4096 beside Gymnasium's SyncVectorEnv.

    python benchmarks/batch.py [--json PATH] [--quick]

The figures issue 18 sets goals for, measured as a user gets them: ``gym.make_vec(id, num_envs=N,
vectorization_mode="vector_entry_point", num_threads=T)`` with T = 1 and T = every core (numba's thread
count), stepped with zero actions (the baseline's own command) and with seeded random actions in
[-1, 1] (what a policy in training sends: the residual, its null-space projection and the visibility
guard act), best of several timed windows. ``sync64`` is ``SyncVectorEnv`` of 64 single envs, the
reference the native env is compared to (``ratio64``: native N = 64 on all cores / sync).

Only public names are used, so ``compare.py`` and ``paired.py`` run this copy against older trees
(``revisions.PORTABLE_SCRIPTS``).

JSON keys (steps per second): ``native.<id>.<N>.<threads>t.<zero|random>``, ``sync64.<id>``,
``ratio64.<id>`` (derived).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import gymnasium as gym
import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import finish, machine, print_table, vector_env_rate  # noqa: E402

import continuum_gym  # noqa: E402

ENV_IDS = ("ContinuumGym/OcclusionAvoidance-v0", "ContinuumGym/ViewTracking-v0")
UNITS = {"native.*": "steps/s", "sync64.*": "steps/s", "ratio64.*": "(derived)", "peak_rss_mib": "MiB",
         "machine.*": "info"}


def action_sets(space_shape: tuple, n: int) -> dict:
    rng = np.random.default_rng(0)
    return {"zero": np.zeros((1, n) + space_shape, dtype=np.float32),
            "random": rng.uniform(-1.0, 1.0, (16, n) + space_shape).astype(np.float32)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", help="write results to this JSON file")
    parser.add_argument("--quick", action="store_true", help="short timings (smoke test)")
    args = parser.parse_args(argv)
    seconds = 0.3 if args.quick else 2.0
    sizes = (64, 256) if args.quick else (64, 1024, 4096)
    all_threads = numba.config.NUMBA_NUM_THREADS
    thread_counts = sorted({1, all_threads})
    results = {"machine": machine(), "unit": "environment steps per second", "units": UNITS,
               "source": continuum_gym.__file__, "threads": thread_counts}
    rows = []
    for env_id in ENV_IDS:
        sync = gym.make_vec(env_id, num_envs=64, vectorization_mode="sync")
        sync_rate = vector_env_rate(sync, action_sets(sync.single_action_space.shape, 64)["zero"], seconds)
        sync.close()
        results[f"sync64.{env_id}"] = sync_rate
        rows.append((env_id, "SyncVectorEnv N=64, 1 thread", "zero", f"{sync_rate:,.0f}", "1.00x"))
        for n in sizes:
            for threads in thread_counts:
                venv = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", num_threads=threads)
                for kind, actions in action_sets(venv.single_action_space.shape, n).items():
                    value = vector_env_rate(venv, actions, seconds)
                    results[f"native.{env_id}.{n}.{threads}t.{kind}"] = value
                    rows.append((env_id, f"native N={n}, {threads} thread(s)", kind, f"{value:,.0f}",
                                 f"{value / sync_rate:.2f}x"))
                venv.close()
        results[f"ratio64.{env_id}"] = results[f"native.{env_id}.64.{all_threads}t.zero"] / sync_rate
    print_table(rows, ["environment", "vector env", "actions", "steps/s", "vs sync N=64"])
    return finish(results, args.json)


if __name__ == "__main__":
    sys.exit(main())
