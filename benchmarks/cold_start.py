"""Cold start: seconds from a clean interpreter to the first ``step()`` with an empty compiler cache.

Each environment is timed in its own subprocess whose ``NUMBA_CACHE_DIR`` is a fresh temporary
directory, so nothing compiled by an earlier run (or by the test suite) is reused; this is what a
new user, a CI job, a container or a Ray worker on a new node pays.  A second run against the same
cache directory shows the warm start.

    python benchmarks/cold_start.py [--json results/bench/cold_start.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

from common import finish, machine, print_table

ENV_IDS = ("ContinuumGym/OcclusionAvoidance-v0", "ContinuumGym/ViewTracking-v0")

_PROBE = r"""
import json, sys, time
t0 = time.perf_counter()
import gymnasium as gym
import continuum_gym  # noqa: F401
t_import = time.perf_counter() - t0
env = gym.make(sys.argv[1])
t_make = time.perf_counter() - t0
env.reset(seed=0)
t_reset = time.perf_counter() - t0
env.step(env.action_space.sample())
t_step = time.perf_counter() - t0
print(json.dumps({"import_s": t_import, "make_s": t_make, "reset_s": t_reset, "first_step_s": t_step}))
"""


def probe(env_id: str, cache_dir: str) -> dict:
    environ = dict(os.environ, NUMBA_CACHE_DIR=cache_dir)
    out = subprocess.run(
        [sys.executable, "-c", _PROBE, env_id], env=environ, capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", default=None, help="write the results to this JSON file")
    args = parser.parse_args(argv)
    results = {"machine": machine(), "envs": {}}
    rows = []
    for env_id in ENV_IDS:
        with tempfile.TemporaryDirectory(prefix="numba-cold-") as cache_dir:
            cold = probe(env_id, cache_dir)
            warm = probe(env_id, cache_dir)
        results["envs"][env_id] = {"cold": cold, "warm": warm}
        rows.append(
            (env_id, f"{cold['import_s']:.1f}", f"{cold['first_step_s']:.1f}", f"{warm['first_step_s']:.1f}")
        )
    print_table(rows, ("env", "import (s)", "cold: first step (s)", "warm: first step (s)"))
    return finish(results, args.json)


if __name__ == "__main__":
    sys.exit(main())
