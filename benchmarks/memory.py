"""Memory of the native vector env at N = 4096, each figure from a clean child process.

    python benchmarks/memory.py [--json PATH] [--num-envs 4096] [--quick]

Why clean processes: the RSS a batch adds depends on what the allocator kept from earlier work in the
same process. The same 4096-robot env built again and again in one process adds less each time (the
allocator reuses what the previous one freed), while built first in a fresh process it adds the same
every time. So every figure here comes from its own child process, which first builds and steps a
64-robot env of the same id (loading the compiled kernels the big one shares), then measures.

JSON keys (MiB):
- ``memory.native4096.<id>``: RSS added (each reading after ``malloc_trim``) by ``make_vec(num_envs=4096)`` +
  ``reset`` + one ``step``;
- ``held.native4096.<id>``: Python and numpy allocations (``tracemalloc``) the 4096-robot env still
  holds after its step (a second child: tracing costs memory of its own);
- ``rss.import``: RSS after ``import continuum_gym``; ``rss.kernels.<id>``: RSS after the 64-robot
  warm-up, i.e. with that env's compiled kernels loaded.

Only public names are used (``continuum_gym.ENV_IDS``, ``gymnasium.make_vec``), so ``paired.py`` runs
this copy against revisions that predate it.
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import json
import subprocess
import sys
import tracemalloc
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import finish, machine, print_table  # noqa: E402

UNITS = {"memory.*": "MiB", "held.*": "MiB", "rss.*": "MiB", "peak_rss_mib": "MiB", "machine.*": "info"}


def trim_heap() -> None:
    """Give the allocator's free pages back to the system (glibc), so that RSS counts what is held.

    Without it the figure depends on when glibc trims by itself: kernels that allocate per step free
    enough small blocks for glibc to return pages at that step, while kernels that allocate nothing leave
    the same free pages mapped. Trimming before every reading makes the two kinds of code comparable.
    """
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc: RSS as it is
        pass


def rss_mib() -> float:
    trim_heap()
    with open("/proc/self/statm") as handle:
        return int(handle.read().split()[1]) * 4096 / 2**20


def step_once(venv) -> None:
    import numpy as np

    venv.reset(seed=0)
    venv.step(np.zeros((venv.num_envs,) + venv.single_action_space.shape, dtype=np.float32))


def child(env_id: str, num_envs: int, trace: bool) -> dict:
    """One measurement in this (fresh) process."""
    before_import = rss_mib()
    import gymnasium as gym

    import continuum_gym  # noqa: F401  (registers the ids)

    imported = rss_mib()
    warm = gym.make_vec(env_id, num_envs=64, vectorization_mode="vector_entry_point")
    step_once(warm)
    warm.close()
    del warm
    gc.collect()
    kernels = rss_mib()
    if trace:
        tracemalloc.start()
    big = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point")
    step_once(big)
    out = {"import": imported - before_import, "kernels": kernels, "added": rss_mib() - kernels}
    if trace:
        gc.collect()
        out["held"] = tracemalloc.get_traced_memory()[0] / 2**20
        tracemalloc.stop()
    return out


def run_child(env_id: str, num_envs: int, trace: bool) -> dict:
    command = [sys.executable, str(Path(__file__).resolve()), "--child", env_id, "--num-envs", str(num_envs)]
    done = subprocess.run(command + (["--trace"] if trace else []), capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"memory child for {env_id} exited with {done.returncode}:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", help="write results to this JSON file")
    parser.add_argument("--num-envs", type=int, default=4096, help="robots in the measured batch (default 4096)")
    parser.add_argument("--quick", action="store_true", help="accepted for the benchmark runners; no effect")
    parser.add_argument("--child", metavar="ENV_ID", help=argparse.SUPPRESS)
    parser.add_argument("--trace", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.num_envs < 64:
        parser.error(f"--num-envs must be >= 64 (the warm-up batch); got {args.num_envs}")
    if args.child:
        print(json.dumps(child(args.child, args.num_envs, args.trace)))
        return 0
    import continuum_gym

    key = f"native{args.num_envs}"
    results: dict = {"machine": machine(), "units": UNITS, "source": continuum_gym.__file__, "num_envs": args.num_envs,
                     "memory": {key: {}}, "held": {key: {}}, "rss": {"kernels": {}}}
    rows = []
    for env_id in continuum_gym.ENV_IDS:
        plain, traced = run_child(env_id, args.num_envs, False), run_child(env_id, args.num_envs, True)
        results["memory"][key][env_id] = plain["added"]
        results["held"][key][env_id] = traced["held"]
        results["rss"]["kernels"][env_id] = plain["kernels"]
        results["rss"]["import"] = plain["import"]
        rows.append((env_id, f"{plain['added']:.1f}", f"{traced['held']:.1f}", f"{plain['kernels']:.0f}"))
    print_table(rows, ["environment", f"RSS added by N={args.num_envs} (MiB)", "held, traced (MiB)",
                       "RSS with kernels loaded (MiB)"])
    return finish(results, args.json)


if __name__ == "__main__":
    sys.exit(main())
