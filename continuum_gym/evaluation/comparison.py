"""Comparisons beyond the table's per-row statistics: rliable's probability of improvement of each learned
row over the env's headline baseline, performance profiles, and what each learned row cost to train.

Scores are the headline metric per episode on the non-grid task sets, arranged as (runs x episodes) like
the table's: every method runs on the same test task instances, so episode ``j`` is the same task for
all of them and a comparison per episode is paired. A deterministic baseline is one run.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.envs.benchmark import benchmark_of
from continuum_gym.envs.spec import EnvSpec

#: The key of a learned row's probability of improvement in the table (and the JSON).
IMPROVEMENT = "probability_of_improvement"
#: The key of a learned row's training cost (env steps, wall-clock per run), when its runs record it.
TRAINING = "training"
WALL_CLOCK_FILE = "wall_clock.csv"


def headline_scores(spec: EnvSpec, results: dict, method: str) -> np.ndarray:
    """(runs, episodes) of ``spec.headline_metric`` over ``method``'s non-grid task sets, in task-set order."""
    tasks = [t for t in results[method].values() if not t["grid"]]
    return np.concatenate([np.stack(t["scores"][benchmark_of(spec).headline_metric]) for t in tasks], axis=1)


def _improvement(x: np.ndarray, y: np.ndarray) -> float:
    """P(X > Y) per task (column), ties counted one half, averaged over tasks: rliable's definition."""
    greater = (x[:, None, :] > y[None, :, :]).mean(axis=(0, 1))
    ties = (x[:, None, :] == y[None, :, :]).mean(axis=(0, 1))
    return float(np.mean(greater + 0.5 * ties))


def probability_of_improvement(x: ArrayLike, y: ArrayLike, higher_is_better: bool = True, reps: int = 2000,
                               seed: int = 0) -> dict[str, float]:
    """rliable's probability of improvement of X over Y, with a 95 % stratified-bootstrap CI.

    ``x`` (runs_x, tasks) and ``y`` (runs_y, tasks) are scores on the same tasks. The point estimate is
    ``rliable.metrics.probability_of_improvement`` (a Mann-Whitney U per task over the runs, averaged over
    tasks); for a lower-is-better metric X improves where its score is lower. The CI resamples the tasks
    and, within each task, each method's runs (as the table's CIs do); it is the 2.5 / 97.5 percentiles
    of ``reps`` resamples drawn from ``numpy.random.default_rng(seed)``.
    """
    from rliable import metrics

    x, y = np.atleast_2d(np.asarray(x, dtype=float)), np.atleast_2d(np.asarray(y, dtype=float))
    if x.shape[1] != y.shape[1] or x.shape[1] == 0:
        raise ValueError(f"x and y must be scores on the same tasks, got shapes {x.shape} and {y.shape}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError("scores must be finite")
    if not higher_is_better:
        x, y = -x, -y
    point = float(metrics.probability_of_improvement(x, y))
    rng = np.random.default_rng(seed)
    tasks: int = x.shape[1]
    draws = np.empty(reps)
    for r in range(reps):
        columns = rng.integers(tasks, size=tasks)[None, :]
        draws[r] = _improvement(x[rng.integers(x.shape[0], size=x.shape), columns],
                                y[rng.integers(y.shape[0], size=y.shape), columns])
    low, high = np.percentile(draws, [2.5, 97.5])
    return {"mean": point, "ci_low": float(low), "ci_high": float(high),
            "n_runs": int(x.shape[0]), "n_tasks": int(tasks)}


def add_improvement(spec: EnvSpec, table: dict, results: dict, learned: list) -> None:
    """``table[m][IMPROVEMENT]`` for each learned method ``m`` in ``learned``: P(m better than the headline
    baseline) on the headline metric per episode (non-grid task sets)."""
    baseline = benchmark_of(spec).headline_baseline
    if baseline not in results:
        return
    higher = spec.metric(benchmark_of(spec).headline_metric).higher_is_better
    reference = headline_scores(spec, results, baseline)
    for method in learned:
        if method not in results or method not in table:
            continue
        estimate = probability_of_improvement(headline_scores(spec, results, method), reference, higher)
        table[method][IMPROVEMENT] = {**estimate, "over": baseline,
                                      "on": f"{benchmark_of(spec).headline_metric} per episode, non-grid test task sets"}


def training_cost(run_dir: str | Path) -> dict[str, float | None]:
    """{env_steps, wall_clock_s, cpu_s} of one run: the last evaluation's step count (``evaluations.npz``, else
    ``config.yml``'s ``total_timesteps``), the wall-clock at it (``wall_clock.csv``, else the run's own ``wall_s``
    column) and the CPU seconds (its ``cpu_s`` column); None where the run did not record them."""
    import yaml

    run_dir = Path(run_dir)
    steps: int | None = None
    recorded: dict[str, float | None] = {"wall_s": None, "cpu_s": None}
    if (run_dir / "evaluations.npz").is_file():
        with np.load(run_dir / "evaluations.npz") as data:
            steps = int(data["timesteps"][-1])
            for key in recorded:
                if key in data.files and len(data[key]) and np.isfinite(data[key][-1]):
                    recorded[key] = float(data[key][-1])
    elif (run_dir / "config.yml").is_file():
        steps = (yaml.safe_load((run_dir / "config.yml").read_text()) or {}).get("total_timesteps")
    clock = read_wall_clock(run_dir)
    return {"env_steps": None if steps is None else int(steps),
            "wall_clock_s": recorded["wall_s"] if clock is None else float(clock[1][-1]), "cpu_s": recorded["cpu_s"]}


def read_wall_clock(run_dir: str | Path) -> tuple[np.ndarray, np.ndarray] | None:
    """(timesteps, elapsed seconds) of a run's ``wall_clock.csv``, or None when the run has none."""
    path = Path(run_dir) / WALL_CLOCK_FILE
    if not path.is_file():
        return None
    with path.open() as handle:
        rows = list(csv.DictReader(handle))
    return (np.array([int(r["timesteps"]) for r in rows]), np.array([float(r["elapsed_s"]) for r in rows]))


def add_training(table: dict, learned: list) -> None:
    """``table[m][TRAINING]`` for each learned (method, [run dirs]) whose runs are directories on disk."""
    for method, run_dirs in learned:
        if method not in table or not run_dirs:
            continue
        per_run = [training_cost(run) for run in run_dirs]
        steps = [r["env_steps"] for r in per_run]
        clocks = [r["wall_clock_s"] for r in per_run]
        entry: dict[str, Any] = {"env_steps_per_run": steps, "wall_clock_s_per_run": clocks}
        if None not in clocks:
            entry["wall_clock_s_mean"] = float(np.mean(cast(list[float], clocks)))
        cpus = [r["cpu_s"] for r in per_run]
        if any(c is not None for c in cpus):  # runs trained before the cost was recorded keep their entry as it was
            entry["cpu_s_per_run"] = cpus
        table[method][TRAINING] = entry


def _spread(values: list, scale: float, fmt: str) -> str:
    """"mean (range min-max)" of the recorded ``values`` times ``scale`` (None: not recorded), or "-"."""
    known = [v * scale for v in values if v is not None]
    if not known:
        return "-"
    low, high = (fmt.format(v) for v in (min(known), max(known)))
    return f"{fmt.format(np.mean(known))} (range {low}-{high})"


def comparison_markdown(spec: EnvSpec, table: dict) -> str:
    """Markdown of the learned rows' probability of improvement and training cost ("" if none has either)."""
    rows = [(m, row) for m, row in table.items() if IMPROVEMENT in row or TRAINING in row]
    if not rows:
        return ""
    timed = any("cpu_s_per_run" in row.get(TRAINING, {}) for _, row in rows)
    direction = "higher" if spec.metric(benchmark_of(spec).headline_metric).higher_is_better else "lower"
    lines = [f"Learned rows against `{benchmark_of(spec).headline_baseline}`: probability of improvement P(row's "
             f"{benchmark_of(spec).headline_metric} {direction} than the baseline's on the same episode) [95 % CI], and training "
             "cost per run:", "",
             "| method | algo | seeds | P(improvement) | env steps per run | wall-clock per run (s) |"
             + (" CPU per run (core-hours) |" if timed else ""), "|---|---|---|---|---|---|" + ("---|" if timed else "")]
    for method, row in rows:
        p = row.get(IMPROVEMENT)
        cell = f"{p['mean']:.3f} [{p['ci_low']:.3f}, {p['ci_high']:.3f}]" if p else "-"
        training = row.get(TRAINING, {})
        steps = sorted(set(s for s in training.get("env_steps_per_run", []) if s is not None))
        clock = _spread(training.get("wall_clock_s_per_run", []), 1.0, "{:.0f}")
        cpu = _spread(training.get("cpu_s_per_run", []), 1 / 3600, "{:.2f}")  # seconds -> core-hours
        lines.append(f"| {method} | {row.get('algo') or '-'} | {row.get('n_seeds', '-')} | {cell} | "
                     f"{', '.join(f'{s:,}' for s in steps) or '-'} | {clock} |" + (f" {cpu} |" if timed else ""))
    return "\n".join(lines) + "\n"


__all__ = ["IMPROVEMENT", "TRAINING", "add_improvement", "add_training", "comparison_markdown", "headline_scores",
           "probability_of_improvement", "read_wall_clock", "training_cost"]
