"""Regenerate the docs' reference-results page from the committed reference runs: ``make reference-results``.

    python scripts/reference_results.py [--from-json docs/reference-results.json] [--out results/reference]

1. ``continuum-gym evaluate --policies reference-runs`` on the test split (default episodes and grid), timed:
   the tables, probability of improvement, training cost per run and every figure, into ``--out``;
2. its JSON (with the evaluation's wall time and the sizes below) into ``docs/reference-results.json``;
3. the learning curves, performance profiles and distributions (and ViewTracking's coverage maps) as
   small PNGs (<= 150 kB, a 256-colour palette) into ``docs/img/reference/``;
4. ``docs/reference-results.md`` from that JSON.

``--from-json`` skips the evaluation and rewrites only the page (and the learning-curve figures, drawn
from the runs' own files) from a stored JSON: the test split is evaluated once, for the final numbers.
Sizes: ``reference-runs/`` (bytes of its files) and the package (a wheel built from ``git archive HEAD``,
so without locally compiled kernels, and the package's source files in that archive).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RUNS = ROOT / "reference-runs"
DOCS = ROOT / "docs"
PAGE = DOCS / "reference-results.md"
DATA = DOCS / "reference-results.json"
IMAGES = DOCS / "img" / "reference"
MAX_PNG_BYTES = 150_000
ENVS = ("ContinuumGym/OcclusionAvoidance-v0", "ContinuumGym/ViewTracking-v0")
FIGURES = ("learning_curves", "performance_profiles", "distribution", "coverage_maps")
LEARNED_ORDER = ("residual_{base}", "residual_{base}_sac", "residual_{base}_td3", "pure_rl", "pure_rl_sac")


def evaluate(out: Path) -> tuple[dict, float]:
    """(the evaluation's JSON, its wall-clock seconds) of every reference run on the test split."""
    from continuum_gym.cli import main

    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    code = main(["evaluate", "--policies", str(RUNS), "--out", str(out), "--json", str(out / "results.json"),
                 "--split", "test"])
    seconds = time.perf_counter() - started
    if code != 0:
        raise SystemExit(f"reference_results: continuum-gym evaluate failed ({code})")
    return json.loads((out / "results.json").read_text()), seconds


def sizes() -> dict:
    """Bytes of ``reference-runs/`` and of the package (wheel and sources of a clean ``git archive HEAD``)."""
    runs = sum(p.stat().st_size for p in RUNS.rglob("*") if p.is_file())
    out = {"reference_runs_bytes": runs, "reference_runs_files": sum(1 for p in RUNS.rglob("*") if p.is_file())}
    with tempfile.TemporaryDirectory() as tmp:
        source = Path(tmp) / "src"
        source.mkdir()
        archive = subprocess.run(["git", "archive", "HEAD"], cwd=ROOT, capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(source)], input=archive, check=True)
        out["package_source_bytes"] = sum(p.stat().st_size for p in (source / "continuum_gym").rglob("*")
                                          if p.is_file())
        built = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                                "-w", str(Path(tmp) / "wheel"), str(source)], capture_output=True, text=True)
        wheels = list((Path(tmp) / "wheel").glob("*.whl"))
        out["wheel_bytes"] = wheels[0].stat().st_size if built.returncode == 0 and wheels else None
        out["wheel"] = wheels[0].name if wheels else None
    return out


def small_png(source: Path, target: Path) -> Path:
    """``source`` as a palette PNG at ``target``, asserting it stays under ``MAX_PNG_BYTES``."""
    from PIL import Image

    target.parent.mkdir(parents=True, exist_ok=True)
    with Image.open(source) as image:
        image.convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT).save(target, optimize=True)
    if target.stat().st_size > MAX_PNG_BYTES:
        raise SystemExit(f"reference_results: {target} is {target.stat().st_size} bytes (> {MAX_PNG_BYTES})")
    return target


def copy_figures(out: Path) -> list:
    written = []
    for env_id in ENVS:
        short = env_id.split("/")[-1].rsplit("-v", 1)[0]
        for name in FIGURES:
            source = out / f"{short}_{name}.png"
            if source.is_file():
                written.append(small_png(source, IMAGES / source.name))
    return written


def redraw_learning_curves() -> list:
    """The learning-curve figures need only the runs' files: redrawn on every regeneration."""
    from continuum_gym.envs.spec import get_spec
    from continuum_gym.evaluation.figures import draw_learning_curves
    from continuum_gym.evaluation.methods import discover_policies

    policies = discover_policies(RUNS)
    written = []
    with tempfile.TemporaryDirectory() as tmp:
        for env_id in ENVS:
            short = env_id.split("/")[-1].rsplit("-v", 1)[0]
            path = draw_learning_curves(get_spec(env_id), policies, Path(tmp) / f"{short}_learning_curves.png", env_id)
            written.append(small_png(path, IMAGES / path.name))
    return written


# ---------------------------------------------------------------------- the page
def _stat(spec, name: str, s) -> str:
    from continuum_gym.evaluation.tables import fmt

    if not isinstance(s, dict) or "mean" not in s:
        return "-"
    cell = f"{fmt(spec, name, s['mean'])} [{fmt(spec, name, s['ci_low'])}, {fmt(spec, name, s['ci_high'])}]"
    return cell + (f" (IQM {fmt(spec, name, s['iqm'])})" if "iqm" in s and s.get("n_tasks", 2) > 1 else "")


def ordered_rows(spec, table: dict) -> list:
    from continuum_gym.envs.benchmark import benchmark_of

    base = benchmark_of(spec).headline_baseline
    learned = [pattern.format(base=base) for pattern in LEARNED_ORDER]
    packaged = [reference.rpartition(":")[2] for reference in spec.config_class.packaged_controllers]
    rows = [m for m in table if m in spec.baselines or m in packaged]
    rows += [m for m in learned if m in table]
    rows += [m for m in table if m not in rows and m not in ("offline_optimum", "bounded_least_squares")]
    rows += [m for m in ("offline_optimum", "bounded_least_squares") if m in table]
    return rows


def env_section(env_id: str, table: dict, meta: dict) -> str:
    from continuum_gym.envs.benchmark import benchmark_of
    from continuum_gym.envs.spec import get_spec
    from continuum_gym.evaluation.comparison import IMPROVEMENT, TRAINING
    from continuum_gym.evaluation.tables import HEADROOM

    spec = get_spec(env_id)
    short = env_id.split("/")[-1].rsplit("-v", 1)[0]
    metric = spec.metric(benchmark_of(spec).headline_metric)
    metrics = [m.name for m in spec.metrics if m.name in {k for row in table.values() for k in row}]
    direction = "higher is better" if metric.higher_is_better else "lower is better"
    where = next((row[HEADROOM]["on"] for row in table.values() if HEADROOM in row), "-")
    lines = [f"## {env_id}", "",
             f"Headline metric `{benchmark_of(spec).headline_metric}` ({metric.label}, {direction}); headline baseline "
             f"`{benchmark_of(spec).headline_baseline}`; `{HEADROOM}` on the {where}.",
             "", "| method | algo | seeds | " + " | ".join(metrics) + f" | {HEADROOM} |",
             "|---|---|---|" + "---|" * (len(metrics) + 1)]
    rows = ordered_rows(spec, table)
    for method in rows:
        row = table[method]
        cells = [_stat(spec, name, row.get(name)) for name in metrics]
        cells.append(f"{row[HEADROOM]['mean']:.2f}" if HEADROOM in row else "-")
        seeds = row.get("n_seeds", 1 if method in spec.baselines else "-")
        lines.append(f"| {method} | {row.get('algo') or '-'} | {seeds} | " + " | ".join(cells) + " |")
    lines += ["", f"Learned rows: probability of improvement over `{benchmark_of(spec).headline_baseline}` (rliable: "
                  f"P(the row's `{benchmark_of(spec).headline_metric}` is {'higher' if metric.higher_is_better else 'lower'} than "
                  "the baseline's on the same test episode), averaged over the non-grid test episodes; 95 % "
                  "stratified-bootstrap CI over episodes and seeds), the budget and the wall-clock of each "
                  "training run:", "",
              "| method | P(improvement) [95 % CI] | env steps per run | wall-clock per run, s: mean (min-max) |",
              "|---|---|---|---|"]
    for method in rows:
        row = table[method]
        if IMPROVEMENT not in row and TRAINING not in row:
            continue
        p = row.get(IMPROVEMENT)
        training = row.get(TRAINING, {})
        steps = sorted(set(training.get("env_steps_per_run", [])) - {None})
        clocks = [c for c in training.get("wall_clock_s_per_run", []) if c is not None]
        clock = f"{sum(clocks) / len(clocks):.0f} ({min(clocks):.0f}-{max(clocks):.0f})" if clocks else "-"
        lines.append(f"| {method} | " + (f"{p['mean']:.3f} [{p['ci_low']:.3f}, {p['ci_high']:.3f}]" if p else "-")
                     + f" | {', '.join(f'{s:,}' for s in steps) or '-'} | {clock} |")
    skipped = meta.get("skipped") or {}
    if skipped:
        lines += ["", "Skipped (not in the table): " + "; ".join(f"`{k}`: {v}" for k, v in skipped.items())]
    lines += ["", f"![{short} learning curves](img/reference/{short}_learning_curves.png)", "",
              f"![{short} performance profiles](img/reference/{short}_performance_profiles.png)", "",
              f"![{short} distributions](img/reference/{short}_distribution.png)", ""]
    if (IMAGES / f"{short}_coverage_maps.png").is_file():
        lines += [f"![{short} coverage maps](img/reference/{short}_coverage_maps.png)", ""]
    return "\n".join(lines)


def page(data: dict) -> str:
    size = data["sizes"]
    mb = 1e6
    wheel = (f"{size['wheel_bytes'] / mb:.1f} MB (`{size['wheel']}`, built from `git archive HEAD`, without "
             "locally compiled kernels)") if size.get("wheel_bytes") else "not measured"
    meta = data["evaluation"]["metadata"]
    first = meta[ENVS[0]]
    learned = [row for env_id in ENVS for row in data["evaluation"].get(env_id, {}).values()
               if isinstance(row, dict) and "training" in row]
    runs = sum(row.get("n_seeds", 0) for row in learned)
    spreads = [(max(c) / min(c), min(c), max(c)) for row in learned
               for c in [[x for x in row["training"]["wall_clock_s_per_run"] if x]] if len(c) > 1]
    spread = max(spreads) if spreads else (1.0, 0.0, 0.0)
    head = f"""# Reference results

<!-- Generated by `make reference-results` (scripts/reference_results.py) from reference-runs/; do not edit by hand. -->

Every learned run of the reference campaign (issue 35), evaluated once on the **test split**:
residual PPO, SAC and TD3 on each env's headline baseline (5 seeds each) and pure-RL PPO and SAC
(3 seeds each), beside the analytic baselines, the packaged bases (ViewTracking's `distilled_optimum`, a controller
distilled from the offline optimum: [the lab notebook](../experiments/notebook.md#campaign-12-2026-12-07)) and the
offline optimum. Hyperparameters were chosen on
the validation split only (`continuum_gym/agents/hyperparams/*.yml`, each choice commented with its
measurement); budgets and protocol: [benchmark protocol](protocol.md). Regenerate this page (tables,
figures, sizes) with one command:

```bash
make reference-results     # = python scripts/reference_results.py: continuum-gym evaluate --policies reference-runs, then this page
```

or reproduce the tables alone from a fresh clone with
`continuum-gym evaluate --policies reference-runs --json results.json`.

**How the numbers were obtained.** `continuum-gym evaluate` on the {first['split']} split: {first['episodes']} episodes per
task set and the {first['grid']} x {first['grid']} coverage grid, every method on the same task instances.
Each cell: mean [95 % stratified-bootstrap CI over seeds x episodes] (IQM), rliable, 2000 resamples;
`headroom_closed` = (method - base) / (optimum - base) on the task named above each table, against the
controller the row was trained on (pure RL: the headline baseline). The evaluation of all {runs} runs and the
baselines took **{data['evaluation_seconds'] / 60:.1f} minutes** of wall-clock on one core of the campaign's machine
(`OMP_NUM_THREADS=1`, niced, beside other work). The last digit of some cells depends on the CPU's vector
instructions (README, "Which machine made these digits"): the baselines' rows here are this machine's
and can differ in the last digit from the README's table.

**Training cost.** Env steps per run are the runs' own counts (PPO rounds up to whole rollouts).
These runs were trained before `continuum-gym train` recorded its cost (the `wall_s` and `cpu_s` columns of
`evaluations.npz` since 0.3), so the wall-clock per run and the learning curves against
wall-clock are derived from the Ray Tune trial of each run (`experiments/reference_runs/collect_wall_clock.py` wrote
`wall_clock.csv` beside each run's `evaluations.npz`): the running sum of Tune's `time_this_iter_s`
over the trial's reports, i.e. the trial process's wall-clock including start-up, the 16-task validation
evaluations and checkpoints; a trial killed and resumed counts both sessions, not the work lost between
its last report and the kill. The machine had 2 cores and other work on it, and the PPO rows ran two
trials at once: the times are upper bounds of what one free core needs and vary between seeds of the same
row by up to {spread[0]:.1f}x ({spread[1]:.0f} to {spread[2]:.0f} s). CPU-seconds on a quiet core are in
[performance](performance.md) and in the comments of the hyperparameter files.

**Sizes.** `reference-runs/`: {size['reference_runs_bytes'] / mb:.1f} MB in {size['reference_runs_files']} files
(model, config, arguments, command, validation curve and wall-clock per run; no optimizer checkpoints or
replay buffers). The package: a wheel of {wheel}; its sources {size['package_source_bytes'] / mb:.1f} MB (of which the
shipped policies of `continuum_gym/agents/policies/` are most).

The learning curves are the training-time validation check (16 validation tasks, every 100 k steps),
not the test numbers; the performance profiles and distributions are on the test episodes.

"""
    table = data["evaluation"]
    return head + "\n".join(env_section(env_id, table[env_id], meta[env_id]) for env_id in ENVS if env_id in table)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--from-json", default=None, help="rewrite the page from this stored JSON (no evaluation)")
    parser.add_argument("--out", default=str(ROOT / "results" / "reference"), help="the evaluation's own output")
    args = parser.parse_args(argv)
    if args.from_json:
        data = json.loads(Path(args.from_json).read_text())
        data["sizes"] = sizes()
    else:
        evaluation, seconds = evaluate(Path(args.out))
        data = {"evaluation_seconds": seconds, "sizes": sizes(), "evaluation": evaluation}
        for path in copy_figures(Path(args.out)):
            print(f"wrote {path}")
    for path in redraw_learning_curves():
        print(f"wrote {path}")
    DATA.write_text(json.dumps(data, indent=1) + "\n")
    PAGE.write_text(page(data))
    print(f"wrote {DATA}\nwrote {PAGE}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
