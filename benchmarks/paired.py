"""Time two git revisions side by side: both trees at once, each pinned to its own core, then swapped.

    python benchmarks/paired.py [--compare REV] [--new REV] [--old-tree PATH] [--scripts envs kinematics memory]
                                [--rounds 2] [--quick] [--json PATH]

On a shared 2-vCPU VM the machine's speed drifts by tens of percent within minutes, so timing one tree
after the other (``compare.py``) compares two different machines. Here each round runs the old and the
new tree's copy of a benchmark script *at the same time*, the old one pinned to core 0 and the new one
to core 1 (``taskset``), and the next round swaps the cores; both see the same drift and the same
neighbours. Every run has ``NUMBA_NUM_THREADS=1``, so this measures one thread per tree: the threaded
batch rows of ``envs.py`` are then single-threaded too, and thread scaling is not what is compared.

A tree without a portable script (``revisions.PORTABLE_SCRIPTS``: ``memory``) runs the new tree's copy.

Worktrees (``revisions.py``), the per-key best-of and the table (``ratios.py``) are those of ``compare.py``
(same keys, units and flags).
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ratios import Run, compare_runs, print_rows, write_json_atomic  # noqa: E402
from revisions import (  # noqa: E402
    DEFAULT_REV,
    Tree,
    add_worktree,
    check_import,
    git,
    remove_worktree,
    script_path,
    tree_env,
)


def start(python: str, tree: Tree, script: str, core: int, quick: bool, workdir: Path, newest: Tree):
    out = workdir / f"{script}-{tree.label}.json"
    out.unlink(missing_ok=True)
    command = ["taskset", "-c", str(core), python, str(script_path(tree, script, newest)), "--json",
               str(out)] + (["--quick"] if quick else [])
    env = dict(tree_env(tree), NUMBA_NUM_THREADS="1")
    return subprocess.Popen(command, cwd=tree.path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True), out


def finish(proc, out: Path, script: str, tree: Tree, began: float) -> Run:
    _, stderr = proc.communicate()
    if proc.returncode != 0 or not out.is_file():
        raise RuntimeError(f"{script} in the {tree.label} tree exited with {proc.returncode}:\n{stderr[-3000:]}")
    return Run(script, tree.label, time.perf_counter() - began, 0.0, 0.0, 0.0, json.loads(out.read_text()))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--compare", default=DEFAULT_REV, metavar="REV", help=f"old revision (default {DEFAULT_REV})")
    parser.add_argument("--new", default="HEAD", metavar="REV", help="new revision (default HEAD)")
    parser.add_argument("--old-tree", type=Path, help="an existing checkout of the old revision (reuses its cache)")
    parser.add_argument("--scripts", nargs="+", default=["envs", "kinematics", "memory"])
    parser.add_argument("--rounds", type=int, default=2, help="rounds per script, cores swapped each round")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error(f"--rounds must be >= 1; got {args.rounds}")
    if shutil.which("taskset") is None:
        parser.error("needs taskset (util-linux) to pin each tree to a core")
    python = sys.executable
    trees: list[Tree] = []
    report: dict = {"method": "paired, pinned, NUMBA_NUM_THREADS=1", "scripts": {}}
    try:
        if args.old_tree:
            old = Tree("old", args.old_tree.resolve(), f"{args.compare} ({args.old_tree})",
                       git("rev-parse", "HEAD", cwd=args.old_tree))
        else:
            old = add_worktree("old", args.compare, trees)
        new = add_worktree("new", args.new, trees)
        for tree in (old, new):
            print(f"{tree.label}: {tree.description}\n     imports {check_import(python, tree)}")
        with tempfile.TemporaryDirectory(prefix="paired-") as tmp:
            workdir = Path(tmp)
            for script in args.scripts:
                runs: list[Run] = []
                # Warm-up (numba compiles into each tree's __pycache__), then the timed rounds.
                for round_ in range(-1, args.rounds):
                    cores = (0, 1) if round_ % 2 == 0 else (1, 0)
                    began = time.perf_counter()
                    started = [start(python, tree, script, core, args.quick or round_ < 0, workdir, new)
                               for tree, core in zip((old, new), cores)]
                    done = [finish(proc, out, script, tree, began) for (proc, out), tree in zip(started, (old, new))]
                    label = "warm-up" if round_ < 0 else f"round {round_ + 1}/{args.rounds}"
                    print(f"{script} {label}: old on core {cores[0]}, new on core {cores[1]}, "
                          f"{time.perf_counter() - began:.0f} s", flush=True)
                    if round_ >= 0:
                        runs += done
                rows = compare_runs(runs)
                print_rows(script, rows, show_all=False, note="run side by side, one core each")
                report["scripts"][script] = [row.as_json() for row in rows]
    finally:
        for tree in trees:
            remove_worktree(tree)
    if args.json:
        write_json_atomic(args.json, report)
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
