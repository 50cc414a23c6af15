"""The comparison tables: per-episode results aggregated per method (mean, IQM, 95 % CIs), the
offline optimum's reference rows, ``headroom_closed``, and the Markdown the CLI prints."""

from __future__ import annotations

from typing import Any

import numpy as np

from continuum_gym.envs.benchmark import benchmark_of
from continuum_gym.envs.spec import EnvSpec, Metric, get_spec

#: headroom_closed, computed for learned methods, is better when higher.
HEADROOM = "headroom_closed"


def clipped_fractions(results: dict) -> dict:
    """{method: fraction of action components its policy returned outside [-1, 1] (clipped)}."""
    out = {}
    for method, tasks in results.items():
        values = [np.concatenate(t["scores"]["action_clipped_fraction"]) for t in tasks.values()]
        out[method] = float(np.mean(np.concatenate(values))) if values else 0.0
    return out


def grid_scores(task_result: dict, metric: Metric) -> np.ndarray:
    """(seeds, grid points) of [grid metric > threshold]: its mean x 100 is e.g. the coverage percentage."""
    return np.stack(task_result["scores"][metric.grid_metric]) > metric.threshold


def aggregate(env_id: str, results: dict, optimum: dict | None = None, grid: int | None = None,
              bases: dict | None = None) -> dict:
    """<method> -> <metric> -> {mean, iqm, ci_low, ci_high, ...}, over the env's test tasks.

    ``bases`` ({method: base controller}) names the baseline each learned method's ``headroom_closed`` is
    measured against (default: the env's headline baseline); ``baselines`` lists the analytic rows.
    """
    from continuum_gym.evaluation.statistics import summarize

    spec = get_spec(env_id)
    table = {}
    for method, tasks in results.items():
        row = {}
        for metric in table_metrics(spec, results):
            if metric.grid_metric:
                grid_tasks = [t for t in tasks.values() if t["grid"]]
                if grid_tasks:
                    row[metric.name] = summarize(100.0 * grid_scores(grid_tasks[0], metric))
                continue
            scores = [np.stack(t["scores"][metric.name]) for t in tasks.values()
                      if not t["grid"] and metric.name in t["scores"]]
            if scores:  # a pixel metric only where it was measured (image policies; evaluate --pixel-metrics)
                row[metric.name] = summarize(_concat_tasks(scores))
        table[method] = row
    if optimum:
        table.update(reference_rows(spec, results, optimum, grid))
    add_headroom(spec, table, results, bases)
    return table


def _concat_tasks(score_list):
    """Concatenate task sets along the task axis; methods with fewer seeds repeat their single row."""
    runs = max(s.shape[0] for s in score_list)
    return np.concatenate([np.repeat(s, runs // s.shape[0], axis=0) if s.shape[0] != runs else s
                           for s in score_list], axis=1)


def reference_rows(spec: EnvSpec, results: dict, optimum: dict, grid: int | None) -> dict:
    """Rows from the offline-optimum cache (``spec.references``) that match this evaluation's tasks."""
    from continuum_gym.evaluation.statistics import summarize

    rows: dict = {}
    for ref in benchmark_of(spec).references:
        cached = optimum.get(ref.cache_key)
        if not cached or ref.values not in cached:
            continue
        values = np.asarray(cached[ref.values], dtype=float)
        row: dict[str, Any]
        if ref.kind == "coverage":
            metric = spec.metric(ref.metric)
            if grid is not None and cached.get("grid") != grid:
                continue
            row = {ref.metric: summarize(100.0 * (values[None] > metric.threshold)),
                   metric.grid_metric: summarize(values[None])}
        else:
            n = len(np.stack(next(iter(results.values()))[ref.task]["scores"][ref.metric])[0])
            if len(values) < n:
                continue
            # The optimum holds each task's best configuration for the whole episode.
            row = {ref.metric: summarize(values[:n][None]), "note": ref.note}
        rows.setdefault(ref.method, {}).update(row)
    return rows


def method_value(spec: EnvSpec, results: dict, method: str, task: str, metric_name: str) -> float:
    """Mean of a metric over a method's seeds and the episodes of one task set."""
    metric = spec.metric(metric_name)
    if metric.grid_metric:
        return float(np.mean(grid_scores(results[method][task], metric)) * 100)
    return float(np.mean(np.stack(results[method][task]["scores"][metric_name])))


def add_headroom(spec: EnvSpec, table: dict, results: dict, bases: dict | None = None) -> None:
    """headroom_closed = (method - base) / (optimum - base) for every learned method, on the benchmark's
    ``headroom`` (none where it declares none).

    A method's base is the controller it was trained on (``bases``), when that controller has a row;
    otherwise, and for pure RL, the env's headline baseline. Analytic rows (``bases[m] == m``) get none.
    """
    headroom = benchmark_of(spec).headroom
    if headroom is None:
        return
    task, metric = headroom
    bases = bases or {}
    if "offline_optimum" not in table or metric not in table["offline_optimum"]:
        return
    optimum = table["offline_optimum"][metric]["mean"]
    for method in results:
        if method in spec.baselines or bases.get(method) == method:
            continue
        base = bases.get(method)
        if base is None or base not in results:
            base = benchmark_of(spec).headline_baseline
        if base not in results or task not in results[base]:
            continue
        reference = method_value(spec, results, base, task, metric)
        if abs(optimum - reference) < 1e-12:
            continue
        where = f"{task} grid, {metric}" if results[base][task]["grid"] else f"{task} tasks, {metric}"
        closed = (method_value(spec, results, method, task, metric) - reference) / (optimum - reference)
        table[method][HEADROOM] = {"mean": closed, "iqm": closed, "ci_low": closed, "ci_high": closed, "on": where}


# ---------------------------------------------------------------------- report
def markdown(env_id: str, table: dict, results: dict) -> str:
    spec = get_spec(env_id)
    metrics = [m.name for m in table_metrics(spec, results)] + [HEADROOM]
    lines = [f"### {env_id}", "", "| method | " + " | ".join(metrics) + " |", "|---|" + "---|" * len(metrics)]
    for method, row in table.items():
        cells = []
        for name in metrics:
            s = row.get(name)
            if not isinstance(s, dict) or "mean" not in s:
                cells.append("-")
            elif name == HEADROOM:
                cells.append(f"{s['mean']:.2f}")
            else:
                cells.append(f"{fmt(spec, name, s['mean'])} [{fmt(spec, name, s['ci_low'])}, "
                             f"{fmt(spec, name, s['ci_high'])}] (IQM {fmt(spec, name, s['iqm'])})")
        lines.append(f"| {method} | " + " | ".join(cells) + " |")
    columns = [m.name for m in spec.metrics if not m.grid_metric][:3] + list(benchmark_of(spec).diagnostics)
    lines += ["", "Per task set (mean over seeds and episodes):", "",
              "| method | task | " + " | ".join(columns) + " |", "|---|---|" + "---|" * len(columns)]
    for method, tasks in results.items():
        for task, t in tasks.items():
            if t["grid"]:
                continue
            values = [fmt(spec, m, float(np.mean(np.stack(t["scores"][m])))) for m in columns]
            lines.append(f"| {method} | {task} | " + " | ".join(values) + " |")
    return "\n".join(lines) + "\n"


def table_metrics(spec: EnvSpec, results: dict) -> tuple[Metric, ...]:
    """The table's columns: the spec's metrics, with the env's pixel metric beside the headline one when the
    episodes measured it (``evaluate --pixel-metrics``, ``envs/pixels.py``)."""
    from continuum_gym.envs.pixels import PIXEL_SPECS, pixel_spec

    if spec.env_id not in PIXEL_SPECS:
        return spec.metrics
    measured = {key for tasks in results.values() for t in tasks.values() for key in t.get("scores", {})}
    extra = tuple(m for m in pixel_spec(spec.env_id).table_metrics if m.name in measured)
    return spec.metrics[:1] + extra + spec.metrics[1:]


def fmt(spec: EnvSpec, name: str, value: float) -> str:
    """A metric value as the tables show it (lengths in mm, percentages with one decimal)."""
    metric: Metric | None
    try:
        metric = spec.metric(name)
    except KeyError:
        metric = _pixel_metric(spec, name)
    if metric is not None and metric.display_unit:
        return f"{value * metric.display_scale:.3f} {metric.display_unit}"
    if metric is not None and metric.unit == "%":
        return f"{value:.1f} %"
    return f"{value:.3g}" if abs(value) < 0.01 else f"{value:.3f}"


def _pixel_metric(spec: EnvSpec, name: str) -> Metric | None:
    """The pixel metric column ``name`` of the env (``envs/pixels.py``), or None."""
    from continuum_gym.envs.pixels import PIXEL_SPECS, pixel_spec

    if spec.env_id not in PIXEL_SPECS:
        return None
    return next((m for m in pixel_spec(spec.env_id).table_metrics if m.name == name), None)
