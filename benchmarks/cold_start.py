"""Cold start: seconds from a clean interpreter to the first ``step()`` with an empty compiler cache.

Each environment is timed in its own subprocess whose ``NUMBA_CACHE_DIR`` is a fresh temporary
directory, so nothing compiled by an earlier run (or by the test suite) is reused; this is what a
new user, a CI job, a container or a Ray worker on a new node pays. Three runs per env:

- ``precompiled``: with the install's precompiled kernel set (``continuum-gym precompile``, which
  ``make setup`` runs), as a user of an installed package starts;
- ``jit``: the same with the set ignored (``CONTINUUM_GYM_PRECOMPILED=0``): every kernel compiled by
  numba on first use, the cost the set moves to install time;
- ``warm``: a second JIT run on the cache the first one filled.

Each run also counts the kernels numba compiled at run time (the data files it left in the empty cache).

    python benchmarks/cold_start.py [--json results/bench/cold_start.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

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


def probe(env_id: str, cache_dir: str, precompiled: bool) -> dict:
    environ = dict(os.environ, NUMBA_CACHE_DIR=cache_dir, CONTINUUM_GYM_PRECOMPILED="1" if precompiled else "0")
    before = compiled_count(cache_dir)
    out = subprocess.run(
        [sys.executable, "-c", _PROBE, env_id], env=environ, capture_output=True, text=True, check=True
    )
    result = json.loads(out.stdout.strip().splitlines()[-1])
    result["kernels_compiled"] = compiled_count(cache_dir) - before
    return result


def compiled_count(cache_dir: str) -> int:
    """Compiled kernels numba saved in ``cache_dir`` (one ``.nbc`` data file per kernel and signature)."""
    return sum(1 for _ in Path(cache_dir).rglob("*.nbc"))


def precompiled_status() -> str:
    out = subprocess.run([sys.executable, "-m", "continuum_gym.cli", "precompile", "--check"],
                         capture_output=True, text=True)
    return out.stdout.strip()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", default=None, help="write the results to this JSON file")
    args = parser.parse_args(argv)
    status = precompiled_status()
    print(status)
    results = {"machine": machine(), "precompiled_set": status, "envs": {}}
    rows = []
    for env_id in ENV_IDS:
        with tempfile.TemporaryDirectory(prefix="numba-cold-") as cache_dir:
            precompiled = probe(env_id, cache_dir, precompiled=True)
        with tempfile.TemporaryDirectory(prefix="numba-cold-") as cache_dir:
            jit = probe(env_id, cache_dir, precompiled=False)
            warm = probe(env_id, cache_dir, precompiled=False)
        results["envs"][env_id] = {"precompiled": precompiled, "jit": jit, "warm": warm}
        rows.append((env_id, f"{precompiled['import_s']:.1f}",
                     f"{precompiled['first_step_s']:.1f} ({precompiled['kernels_compiled']})",
                     f"{jit['first_step_s']:.1f} ({jit['kernels_compiled']})", f"{warm['first_step_s']:.1f}"))
    print_table(rows, ("env", "import (s)", "first step (s), precompiled set (kernels compiled)",
                       "same, JIT only", "JIT, cache warm"))
    return finish(results, args.json)


if __name__ == "__main__":
    sys.exit(main())
