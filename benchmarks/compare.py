"""Time the current working tree against an older git revision in the same run.

    python benchmarks/compare.py [--compare REV] [--new REV | --in-place] [--scripts envs kinematics]
                                 [--repeats 3] [--quick] [--all] [--json PATH] [--old-tree PATH]
                                 [--idle-below CORES] [--idle-wait SECONDS] [--retries N]

``--compare`` defaults to ``d737a5f``, the last revision before the inside refactor (issue 14, stage 0).
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
CartPole), so their speed shows how much the machine itself drifted. Peak RSS per tree is the ``peak_rss_mib`` key (minimum over repeats).

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
import fnmatch
import hashlib
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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_REV = "d737a5f"
FLAG_BELOW = 0.95

#: direction of a unit: +1 higher is better, -1 lower is better, 0 no direction (shown, not judged)
HIGHER, LOWER, NONE = 1, -1, 0


# ---------------------------------------------------------------------------------------------- git
def git(*args: str, cwd: Path = ROOT) -> str:
    """Output of one git command in ``cwd`` (stripped); raises with git's message on failure."""
    done = subprocess.run(["git", *args], check=False, cwd=cwd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"git {' '.join(args)} failed: {done.stderr.strip()}")
    return done.stdout.strip()


def resolve(rev: str) -> str:
    """Full commit id of ``rev`` (a clear error for a typo, before any worktree exists)."""
    try:
        return git("rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}")
    except RuntimeError:
        raise RuntimeError(f"{rev!r} is not a commit of {ROOT}") from None


def working_tree_fingerprint(root: Path = ROOT) -> str:
    """A hash of HEAD, the uncommitted diff and the untracked files' names and contents.

    Others may edit the working tree while this runs; comparing the fingerprint before and after says
    whether the timed "new" tree was one state of the code.
    """
    digest = hashlib.sha256(git("rev-parse", "HEAD", cwd=root).encode())
    digest.update(subprocess.run(["git", "diff", "HEAD"], check=False, cwd=root, capture_output=True).stdout)
    for name in git("ls-files", "--others", "--exclude-standard", cwd=root).splitlines():
        path = root / name
        digest.update(name.encode())
        if path.is_file():
            digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


@dataclass
class Tree:
    """One source tree under test: where it is, what it is, and whether this run created it."""

    label: str  # "old" / "new"
    path: Path
    description: str
    commit: str
    created: bool = False  # a worktree this run added (and must remove)
    dirty: bool = False

    def as_json(self) -> dict:
        return {"path": str(self.path), "description": self.description, "commit": self.commit,
                "dirty": self.dirty}


def add_worktree(label: str, rev: str, trees: list[Tree]) -> Tree:
    """A detached worktree of ``rev`` in a fresh temporary directory, appended to ``trees`` first.

    Appending before ``git worktree add`` means an interrupt at any point still leaves the directory
    in the list that the caller cleans up.
    """
    commit = resolve(rev)
    path = Path(tempfile.mkdtemp(prefix=f"continuum-gym-{label}-{commit[:8]}-"))
    tree = Tree(label, path, f"{rev} ({commit[:8]})", commit, created=True)
    trees.append(tree)
    # git adds into an existing directory only if it is empty; mkdtemp's is.
    git("worktree", "add", "--detach", str(path), commit)
    return tree


def snapshot_working_tree(trees: list[Tree]) -> Tree:
    """The working tree as it is now, frozen: a worktree of HEAD plus the uncommitted edits copied in.

    Timing /work/main in place is at the mercy of whoever edits it meanwhile: numba keys its cache on
    each source file's modification time, so even a save that changes nothing recompiles inside a
    timed run (seen: a 52 s run and +170 MiB peak RSS), and a real edit would time other code.
    """
    head = git("rev-parse", "HEAD")
    tree = add_worktree("new", head, trees)
    changed = git("diff", "--name-only", "--no-renames", "HEAD").splitlines()
    untracked = git("ls-files", "--others", "--exclude-standard").splitlines()
    for name in changed + untracked:
        source, target = ROOT / name, tree.path / name
        if source.is_file():
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target)
        elif target.exists():  # deleted in the working tree
            target.unlink()
    tree.dirty = bool(changed or untracked)
    tree.description = f"working tree at {head[:8]}" + (
        f" + {len(changed)} changed, {len(untracked)} untracked files (snapshot)" if tree.dirty else " (snapshot)")
    return tree


def remove_worktree(tree: Tree) -> None:
    """Remove a worktree this run added; --force because numba's caches are untracked files."""
    if not tree.created:
        return
    try:
        git("worktree", "remove", "--force", str(tree.path))
    except RuntimeError as error:
        # Also the path of an interrupted or failed ``worktree add``: delete, then let git forget it.
        if (tree.path / ".git").exists():
            print(f"warning: {error}; deleting {tree.path} by hand", file=sys.stderr)
        shutil.rmtree(tree.path, ignore_errors=True)
        subprocess.run(["git", "worktree", "prune"], cwd=ROOT, check=False)
    tree.created = False


# ---------------------------------------------------------------------------------------------- runs
def tree_env(tree: Tree) -> dict[str, str]:
    """The environment of a run in ``tree``: its sources first on sys.path, nothing else inherited there."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(tree.path)
    return env


def check_import(python: str, tree: Tree) -> str:
    """The ``continuum_gym`` package a run in ``tree`` imports; raises unless it is that tree's own."""
    done = subprocess.run([python, "-c", "import continuum_gym; print(continuum_gym.__file__)"],
                          check=False, cwd=tree.path, env=tree_env(tree), capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{tree.label} tree: cannot import continuum_gym:\n{done.stderr[-2000:]}")
    source = Path(done.stdout.strip()).resolve()
    if not source.is_relative_to(tree.path.resolve()):
        raise RuntimeError(f"{tree.label} tree {tree.path} imports continuum_gym from {source}, not its own copy")
    return str(source)


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


@dataclass
class Run:
    """One finished benchmark run and how busy the rest of the machine was meanwhile."""

    script: str
    tree: str
    seconds: float
    load_before: float  # 1-min load average
    others_before: float  # cores used by other processes just before (1 s sample)
    others_during: float  # mean cores used by other processes during the run
    results: dict[str, Any]
    busy: bool = False  # others used more than --idle-below cores during it (set by the caller)


def run_script(python: str, tree: Tree, script: str, quick: bool, workdir: Path, others_before: float = math.nan
               ) -> Run:
    """Run ``<tree>/benchmarks/<script>.py --json <tmp>`` in a fresh subprocess; its parsed JSON."""
    path = tree.path / "benchmarks" / f"{script}.py"
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


# ---------------------------------------------------------------------------------------------- keys
def flatten(results: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """{dotted key: leaf} of a nested JSON object."""
    flat: dict[str, Any] = {}
    for key, value in results.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flatten(value, name + "."))
        else:
            flat[name] = value
    return flat


def numeric(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def unit_of(key: str, units: dict[str, str], rate_default: bool) -> str:
    """Unit of a flattened key: the first matching ``units`` pattern, else a guess from its name."""
    if key in units:
        return units[key]
    for pattern, unit in units.items():
        if fnmatch.fnmatchcase(key, pattern):
            return unit
    leaf = key.rsplit(".", 1)[-1]
    if key.startswith(("machine.", "load_average")) or leaf in ("cpus", "bodies"):
        return "info"
    if leaf == "ratio":
        return "x (derived)"
    if leaf.endswith(("per_second", "per_cpu_second")):
        return "1/s"
    if leaf.endswith("_us") or leaf == "microseconds":
        return "us"
    if leaf.endswith(("milliseconds", "_ms")):
        return "ms"
    if leaf.endswith("_s") or leaf == "seconds":
        return "s"
    if leaf.endswith("_mib") or key.startswith("memory."):
        return "MiB"
    if "." not in key and rate_default:
        return "1/s"
    return "?"


def direction(unit: str) -> int:
    """+1 if more of ``unit`` is better, -1 if less is, 0 for derived, control-free unknowns and info."""
    if "(derived)" in unit or unit in ("info", "?"):
        return NONE
    base = unit.split(" (")[0]
    if base.endswith("/s"):
        return HIGHER
    if base in ("us", "ms", "s", "MiB"):
        return LOWER
    return HIGHER if base == "x" else NONE


def best(values: list[float], sense: int) -> float:
    """The run least disturbed by other processes: max of a rate, min of a time; median without a sense."""
    if sense == HIGHER:
        return max(values)
    if sense == LOWER:
        return min(values)
    return statistics.median(values)


def spread(values: list[float], sense: int) -> float:
    """(worst - best) / best over the repeats, as a fraction; 0 for one run or no direction."""
    if len(values) < 2 or sense == NONE:
        return 0.0
    top = best(values, sense)
    worst = min(values) if sense == HIGHER else max(values)
    return abs(top - worst) / abs(top) if top else 0.0


@dataclass
class Row:
    """One compared key."""

    key: str
    unit: str
    sense: int
    old: list[float] = field(default_factory=list)
    new: list[float] = field(default_factory=list)

    @property
    def old_best(self) -> float | None:
        return best(self.old, self.sense) if self.old else None

    @property
    def new_best(self) -> float | None:
        return best(self.new, self.sense) if self.new else None

    @property
    def speed(self) -> float | None:
        """> 1: the new tree is better (new/old of a rate, old/new of a time or memory)."""
        old, new = self.old_best, self.new_best
        if old is None or new is None or old <= 0 or new <= 0:
            return None
        return old / new if self.sense == LOWER else new / old

    @property
    def noise(self) -> float:
        return max(spread(self.old, self.sense), spread(self.new, self.sense))

    @property
    def flagged(self) -> bool:
        return self.sense != NONE and "(control)" not in self.unit and self.speed is not None \
            and self.speed < FLAG_BELOW

    def as_json(self) -> dict:
        return {"key": self.key, "unit": self.unit,
                "better": {HIGHER: "higher", LOWER: "lower", NONE: None}[self.sense],
                "old": self.old_best, "new": self.new_best, "speed_new_vs_old": self.speed,
                "noise": self.noise, "flagged": self.flagged, "old_runs": self.old, "new_runs": self.new}


def usable(runs: list[Run]) -> list[Run]:
    """Per tree, the runs the rest of the machine left alone if there are any, else all of them."""
    kept: list[Run] = []
    for label in ("old", "new"):
        mine = [r for r in runs if r.tree == label]
        kept += [r for r in mine if not r.busy] or mine
    return kept


def compare_runs(runs: list[Run]) -> list[Row]:
    """Rows of every numeric key seen in either tree's runs of one script, in first-seen order.

    ``runs`` should already be ``usable(...)``: a busy run can only lower a best-of, but it widens the
    noise column and moves the median of the rows without a direction.
    """
    units: dict[str, str] = {}
    rate_default = False
    # The newest script's explicit units win; an old script without them falls back to the same map,
    # since the rows are matched by key.
    for run in sorted(runs, key=lambda r: r.tree != "new"):
        for pattern, unit in (run.results.get("units") or {}).items():
            units.setdefault(pattern, unit)
        rate_default |= "per second" in str(run.results.get("unit", ""))
    rows: dict[str, Row] = {}
    for run in runs:
        for key, value in flatten({k: v for k, v in run.results.items() if k not in ("units", "source")}).items():
            if not numeric(value):
                continue
            unit = unit_of(key, units, rate_default)
            if unit == "info":
                continue
            row = rows.setdefault(key, Row(key, unit, direction(unit)))
            getattr(row, run.tree).append(float(value))
    return list(rows.values())


# ---------------------------------------------------------------------------------------------- output
def fmt(value: float | None) -> str:
    if value is None:
        return "-"
    if abs(value) >= 1000:
        return f"{value:,.0f}"
    if abs(value) >= 10:
        return f"{value:.1f}"
    return f"{value:.3g}"


def print_rows(script: str, rows: list[Row], show_all: bool, note: str = "") -> None:
    shown = [r for r in rows if show_all or "(derived)" not in r.unit]
    table = [(r.key, r.unit, fmt(r.old_best), fmt(r.new_best),
              "-" if r.speed is None else f"{r.speed:.3f}x", f"{100 * r.noise:.0f}%",
              "<-- SLOWER" if r.flagged else ("(control)" if "(control)" in r.unit and r.speed else ""))
             for r in shown]
    headers = ("key", "unit", "old", "new", "speed new/old", "noise", "")
    widths = [max(len(h), *(len(t[i]) for t in table)) if table else len(h) for i, h in enumerate(headers)]
    counts = f"{max(len(r.old) for r in rows)} old / {max(len(r.new) for r in rows)} new runs" if rows else "no runs"
    print(f"\n== {script} (best of {counts}{'; ' + note if note else ''}; speed > 1 = new is faster / smaller)")
    print(" | ".join(h.ljust(w) for h, w in zip(headers, widths)).rstrip())
    print("-|-".join("-" * w for w in widths))
    for line in table:
        cells = [c.rjust(w) if 2 <= i <= 5 else c.ljust(w) for i, (c, w) in enumerate(zip(line, widths))]
        print(" | ".join(cells).rstrip())
    flagged = [r.key for r in rows if r.flagged]
    print(f"{len(flagged)} of {sum(1 for r in rows if r.sense != NONE and '(control)' not in r.unit)} judged rows "
          f"below {FLAG_BELOW}x" + (f": {', '.join(flagged)}" if flagged else ""))


def write_json_atomic(path: Path, data: dict) -> None:
    """Write through a temporary file and a rename, so a reader never sees half a file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n")
    os.replace(tmp, path)


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
                   if not (t.path / "benchmarks" / f"{s}.py").is_file()]
        if missing:  # before a minute of compiling, not after
            raise RuntimeError(f"scripts missing in a tree: {', '.join(missing)}")

        for script in args.scripts:
            for t in trees:  # numba compiles into each tree's __pycache__ on the first run
                warm = run_script(args.python, t, script, quick=True, workdir=workdir)
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
                                         others_before=quiet)
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
