"""Time the current working tree against an older git revision in the same run.

    python benchmarks/compare.py [--compare REV] [--new REV | --in-place] [--scripts envs kinematics]
                                 [--repeats 3] [--quick] [--all] [--json PATH] [--old-tree PATH]
                                 [--idle-below CORES] [--idle-wait SECONDS] [--retries N]

``--compare`` defaults to ``revisions.DEFAULT_REV``, the last revision before the inside refactor (issue 14,
stage 0): the refactored code is judged against the code it replaced.
The old revision is checked out with ``git worktree add --detach`` into a temporary directory. The new
tree is the working tree as it is at the start, snapshotted into a second worktree (HEAD plus the
uncommitted and untracked files copied in), so edits made meanwhile by others, or a mere save that
changes a file's mtime and thereby invalidates numba's cache, cannot leak into the timed runs;
``--in-place`` times the working tree where it is instead, ``--new REV`` a committed revision. Both
worktrees are removed at the end, also on an error, Ctrl-C, SIGTERM or SIGHUP.

Each tree runs *its own copy* of each benchmark script (``<tree>/benchmarks/<name>.py``) in a fresh
subprocess with ``PYTHONPATH=<tree>`` and the working directory in that tree, so each script imports
its own tree's ``continuum_gym`` (checked before timing: the setuptools editable finder comes after
PYTHONPATH, but the current directory would come first for ``python -c``). Order:

1. warm-up: one ``--quick`` run of each script in each tree; numba caches its compiled code in
   ``__pycache__`` beside each source tree, so a fresh worktree compiles for a minute or more first;
2. ``--repeats`` rounds of old, new, old, new ... per script, each writing ``--json`` to a temp file;
3. per key and tree the best run: the maximum of a rate, the minimum of a time or of memory
   (other processes only ever slow a run down); keys without a direction take the median.

Keys are the scripts' JSON keys, flattened and joined with ``.``. Their unit comes from the ``units``
map (fnmatch patterns) that current scripts write, from either tree's JSON, else from the key's name
(``*per_second`` a rate; ``*_us``, ``*microseconds``, ``*milliseconds``, ``*_s`` a time; ``*_mib`` and
``memory.*`` memory; top-level numbers of a script whose ``unit`` says "per second" rates). The
``speed`` column is new/old for rates and old/new for times and memory, so > 1 always means the new
tree is better; below 0.95 is flagged. ``noise`` is the larger of the two trees' spread across
repeats, (worst - best) / best: a flag inside the noise is weak evidence. Units marked ``(derived)``
(differences or restatements of other rows) are hidden unless ``--all`` and never flagged;
``(control)`` rows time the same code in both trees (the plain-numpy references, Gymnasium's
CartPole), so their speed shows how much the machine itself drifted. Peak RSS per tree is the ``peak_rss_mib`` key
(minimum over repeats).

Other jobs on the machine: before each timed run the harness waits (``--idle-wait`` s at most) until
other processes use fewer than ``--idle-below`` cores, sampled from /proc/stat for a second; during
each run it measures the cores everybody else used (machine busy time minus the run's own CPU time).
A run during which they used more than ``--idle-below`` is *busy*: it is repeated (``--retries`` extra
runs per script at most) and left out of the tables when its tree has a quiet run of that script. On a
2-vCPU machine even a fraction of a core used by someone else can cost a run a third of its speed.
The 1-minute load average (which lags and counts the benchmark itself) is reported too.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import resource
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ratios import (  # noqa: E402
    FLAG_BELOW,
    LOWER,
    Run,
    best,
    compare_runs,
    numeric,
    print_rows,
    usable,
    write_json_atomic,
)
from revisions import (  # noqa: E402
    DEFAULT_REV,
    ROOT,
    Tree,
    add_worktree,
    check_import,
    git,
    remove_worktree,
    resolve,
    script_path,
    snapshot_working_tree,
    tree_env,
    working_tree_fingerprint,
)


def busy_cpu_seconds() -> float:
    """CPU seconds the whole machine has spent busy since boot (all cores; /proc/stat)."""
    with open("/proc/stat") as handle:
        fields = [int(x) for x in handle.readline().split()[1:]]
    # user nice system idle iowait irq softirq steal (guest time is already inside user)
    busy = fields[0] + fields[1] + fields[2] + sum(fields[5:8])
    return busy / os.sysconf("SC_CLK_TCK")


def children_cpu_seconds() -> float:
    """CPU seconds of this process's finished (waited-for) children."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def other_cores(seconds: float = 1.0) -> float:
    """Cores kept busy by other processes over the next ``seconds`` (this one sleeps meanwhile)."""
    before = busy_cpu_seconds()
    time.sleep(seconds)
    return max(0.0, busy_cpu_seconds() - before) / seconds


def wait_for_quiet(below: float, patience: float) -> float:
    """Wait until other processes use fewer than ``below`` cores, at most ``patience`` s; the last reading.

    The load average lags by a minute and counts this harness's own runs; a one-second sample of
    /proc/stat while nothing of ours runs measures only the others.
    """
    deadline = time.monotonic() + patience
    while True:
        busy = other_cores()
        if busy < below or time.monotonic() >= deadline:
            return busy
        time.sleep(2.0)




def run_script(python: str, tree: Tree, script: str, quick: bool, workdir: Path, others_before: float = math.nan,
               newest: Tree | None = None) -> Run:
    """Run ``<tree>/benchmarks/<script>.py --json <tmp>`` (see ``script_path``) in a fresh subprocess; its JSON."""
    path = script_path(tree, script, newest or tree)
    if not path.is_file():
        raise RuntimeError(f"{tree.label} tree ({tree.description}) has no benchmarks/{script}.py")
    out = workdir / f"{script}-{tree.label}.json"
    out.unlink(missing_ok=True)
    command = [python, str(path), "--json", str(out)] + (["--quick"] if quick else [])
    load = os.getloadavg()[0]
    busy0, child0 = busy_cpu_seconds(), children_cpu_seconds()
    start = time.perf_counter()
    done = subprocess.run(command, check=False, cwd=tree.path, env=tree_env(tree), capture_output=True, text=True)
    seconds = time.perf_counter() - start
    # Machine-wide busy time minus our child's own CPU time = what everybody else used meanwhile.
    others = max(0.0, (busy_cpu_seconds() - busy0) - (children_cpu_seconds() - child0)) / seconds
    if done.returncode != 0 or not out.is_file():
        tail = (done.stdout[-1500:] + "\n" + done.stderr[-3000:]).strip()
        raise RuntimeError(f"{script} in the {tree.label} tree exited with {done.returncode}:\n{tail}")
    return Run(script, tree.label, seconds, load, others_before, others, json.loads(out.read_text()))


# ---------------------------------------------------------------------------------------------- main
def _raise_interrupt(signum, frame):
    # SIGTERM / SIGHUP take the same path as Ctrl-C, so the worktrees are removed in the finally block.
    raise KeyboardInterrupt(f"signal {signum}")


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=__doc__.split("\n", 2)[2],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--compare", default=DEFAULT_REV, metavar="REV",
                        help=f"old git revision to time against (default {DEFAULT_REV}, before the refactor)")
    parser.add_argument("--new", metavar="REV", help="time this revision instead of the working tree")
    parser.add_argument("--in-place", action="store_true",
                        help="time the working tree where it is (shares its numba cache) instead of a snapshot")
    parser.add_argument("--scripts", nargs="+", default=["envs", "kinematics"],
                        help="benchmark scripts (names in benchmarks/, without .py); default envs kinematics")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per script and tree (default 3)")
    parser.add_argument("--quick", action="store_true", help="pass --quick to the timed runs too")
    parser.add_argument("--json", type=Path, metavar="PATH", help="write the combined comparison here")
    parser.add_argument("--all", action="store_true", help="also show derived rows")
    parser.add_argument("--old-tree", type=Path, metavar="PATH",
                        help="an existing checkout of the old revision to use (kept) instead of a new worktree")
    parser.add_argument("--python", default=sys.executable, help="interpreter for the runs (default: this one)")
    parser.add_argument("--idle-below", type=float, default=0.25, metavar="CORES",
                        help="before each timed run, wait until other processes use fewer cores; a run during "
                             "which they used more is busy (default 0.25)")
    parser.add_argument("--idle-wait", type=float, default=120.0, metavar="SECONDS",
                        help="longest wait for quiet before running anyway (default 120; 0: never wait)")
    parser.add_argument("--retries", type=int, metavar="N",
                        help="extra runs per script to replace busy ones (default: --repeats)")
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error("--repeats must be >= 1")
    if args.retries is None:
        args.retries = args.repeats
    if args.new is not None and args.in_place:
        parser.error("--new REV and --in-place both say what the new tree is; give one")
    return args


def main(argv: list[str] | None = None) -> int:
    """Warm up, time alternately, print one table per script; 0 on success (flags do not fail the run)."""
    args = parse_args(argv)
    for signum in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, _raise_interrupt)
    trees: list[Tree] = []
    workdir = Path(tempfile.mkdtemp(prefix="continuum-gym-compare-json-"))
    try:
        if args.old_tree is not None:
            path = args.old_tree.resolve()
            commit = git("rev-parse", "HEAD", cwd=path)
            if commit != resolve(args.compare):
                print(f"warning: --old-tree {path} is at {commit[:8]}, not {args.compare}", file=sys.stderr)
            old = Tree("old", path, f"{args.compare} ({commit[:8]}, {path})", commit)
            trees.append(old)
        else:
            old = add_worktree("old", args.compare, trees)
        fingerprint = working_tree_fingerprint() if args.new is None else None
        if args.new is not None:
            new = add_worktree("new", args.new, trees)
        elif args.in_place:
            head = git("rev-parse", "HEAD")
            dirty = bool(git("status", "--porcelain", "--untracked-files=no"))
            new = Tree("new", ROOT, f"working tree at {head[:8]}" + (" + uncommitted changes" if dirty else "")
                       + " (in place)", head, dirty=dirty)
            trees.append(new)
        else:
            new = snapshot_working_tree(trees)
        sources = {t.label: check_import(args.python, t) for t in trees}
        for t in trees:
            print(f"{t.label}: {t.description}\n     imports {sources[t.label]}")
        missing = [f"{t.label}: benchmarks/{s}.py" for t in trees for s in args.scripts
                   if not script_path(t, s, new).is_file()]
        if missing:  # before a minute of compiling, not after
            raise RuntimeError(f"scripts missing in a tree: {', '.join(missing)}")

        for script in args.scripts:
            for t in trees:  # numba compiles into each tree's __pycache__ on the first run
                warm = run_script(args.python, t, script, quick=True, workdir=workdir, newest=new)
                print(f"warm-up {script:<10} {t.label}: {warm.seconds:6.1f} s "
                      f"(others used {warm.others_during:.2f} cores)", flush=True)

        per_script: dict[str, list[Run]] = {s: [] for s in args.scripts}
        total = len(args.scripts) * args.repeats * len(trees)
        count = 0
        for script in args.scripts:
            retries = args.retries
            for repeat in range(args.repeats):
                for t in trees:  # alternate, so slow spells of the machine hit both trees alike
                    count += 1
                    while True:
                        quiet = (wait_for_quiet(args.idle_below, args.idle_wait) if args.idle_wait > 0
                                 else other_cores())
                        run = run_script(args.python, t, script, quick=args.quick, workdir=workdir,
                                         others_before=quiet, newest=new)
                        run.busy = run.others_during > args.idle_below
                        per_script[script].append(run)
                        print(f"[{count}/{total}] {script:<10} {t.label} run {repeat + 1}: {run.seconds:6.1f} s; "
                              f"other processes: {run.others_before:.2f} cores before, {run.others_during:.2f} "
                              f"during{' (busy)' if run.busy else ''}; load average {run.load_before:.2f}",
                              flush=True)
                        if not run.busy or retries <= 0:
                            break
                        retries -= 1  # once more, after waiting for quiet again
        timed = [r for runs in per_script.values() for r in runs]
        loads = [r.load_before for r in timed] + [os.getloadavg()[0]]
        others = [r.others_during for r in timed]

        changed = fingerprint is not None and working_tree_fingerprint() != fingerprint
        combined: dict[str, Any] = {
            "old": old.as_json(), "new": new.as_json(), "repeats": args.repeats, "quick": args.quick,
            "flag_below": FLAG_BELOW, "sources": sources, "working_tree_changed_during_run": changed,
            "load_average_1min": {"min": min(loads), "max": max(loads), "mean": statistics.fmean(loads),
                                  "samples": loads},
            "other_processes_cores": {"min": min(others), "max": max(others), "mean": statistics.fmean(others),
                                      "before": [r.others_before for r in timed], "during": others},
            "scripts": {},
        }
        print(f"\nold = {old.description}\nnew = {new.description}")
        for script, all_runs in per_script.items():
            runs = usable(all_runs)
            rows = compare_runs(runs)
            left_out = len(all_runs) - len(runs)
            kept_busy = sum(r.busy for r in runs)
            notes = ([f"{left_out} busy run(s) left out"] if left_out else []) + (
                [f"{kept_busy} busy run(s) kept: no quiet run of that tree"] if kept_busy else [])
            print_rows(script, rows, args.all, note="; ".join(notes))
            rss = {label: best([r.results["peak_rss_mib"] for r in runs if r.tree == label
                                and numeric(r.results.get("peak_rss_mib"))] or [math.nan], LOWER)
                   for label in ("old", "new")}
            print(f"peak RSS: old {rss['old']:.0f} MiB, new {rss['new']:.0f} MiB")
            combined["scripts"][script] = {
                "rows": [r.as_json() for r in rows], "peak_rss_mib": rss,
                "run_seconds": {label: [r.seconds for r in all_runs if r.tree == label] for label in ("old", "new")},
                "other_processes_cores": {label: [r.others_during for r in all_runs if r.tree == label]
                                          for label in ("old", "new")},
                "busy_runs": {label: [r.busy for r in all_runs if r.tree == label] for label in ("old", "new")},
                "machine": runs[-1].results.get("machine"),
            }
        print(f"\nother processes during the timed runs: mean {statistics.fmean(others):.2f} cores "
              f"(min {min(others):.2f}, max {max(others):.2f}) of {os.cpu_count()}; 1-min load average before "
              f"the runs: min {min(loads):.2f}, mean {statistics.fmean(loads):.2f}, max {max(loads):.2f} "
              f"(includes the benchmark itself)")
        if changed:
            print("WARNING: the working tree changed during the run; " + (
                "the new runs may have timed different code" if args.in_place else
                "the new runs timed the snapshot taken at the start"), file=sys.stderr)
        if args.json:
            write_json_atomic(args.json, combined)
            print(f"wrote {args.json}")
        return 0
    except KeyboardInterrupt:
        print("\ninterrupted; removing worktrees", file=sys.stderr)
        return 130
    except RuntimeError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    finally:
        for t in trees:
            remove_worktree(t)
        shutil.rmtree(workdir, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
