"""Figures of ``continuum-gym evaluate``: distributions, traces, coverage maps, learning curves.

Each axis names its metric in words with its unit and which direction is better; box plots say what
their marks are; the offline optimum, where the table has one, is drawn as a reference line.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from continuum_gym.envs.benchmark import benchmark_of
from continuum_gym.envs.spec import EnvSpec, Metric, get_spec

#: What a per-step trace value is, for axis labels: (words, higher is better).
TRACE_LABELS = {"voi": ("VOI", False), "or": ("overlap ratio OR", True), "in_view": ("tip in view", True),
                "tip_error": ("tip error (m)", False), "position_error": ("target-point error (m)", False)}


def _direction(higher_is_better: bool) -> str:
    return "higher is better" if higher_is_better else "lower is better"


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def draw_distributions(spec: EnvSpec, results: dict, table: dict, path: Path, split: str = "test") -> Path:
    """Box plots of the headline metric per method (all seeds x non-grid episodes), optimum as a line."""
    plt = _pyplot()
    metric = spec.metric(benchmark_of(spec).headline_metric)
    fig, ax = plt.subplots(figsize=(9, 4.5))
    labels, data = [], []
    for method, tasks in results.items():
        labels.append(method)
        data.append(np.concatenate([np.stack(t["scores"][metric.name]).ravel() for t in tasks.values()
                                    if not t["grid"]]))
    ax.boxplot(data, showmeans=True, meanprops={"marker": "^", "markerfacecolor": "tab:green",
                                                "markeredgecolor": "tab:green"})
    ax.set_xticks(range(1, len(labels) + 1), labels, rotation=20, ha="right")
    handles = [plt.Line2D([], [], color="tab:orange", label="median"),
               plt.Line2D([], [], marker="^", color="tab:green", linestyle="none", label="mean"),
               plt.Rectangle((0, 0), 1, 1, fill=False, label="box: quartiles; whiskers: 1.5 IQR")]
    optimum = table.get("offline_optimum", {}).get(metric.name)
    if isinstance(optimum, dict):
        note = table["offline_optimum"].get("note", "")
        where = f" ({note.split(':')[0]})" if note else ""
        handles.append(ax.axhline(optimum["mean"], color="tab:purple", linestyle="--",
                                  label=f"offline optimum, mean{where}"))
    ax.legend(handles=handles, fontsize=8, loc="best")
    ax.set(ylabel=metric.axis_label(), title=f"{spec.short_name}: {metric.label} per episode (held-out {split} tasks)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def draw_traces(spec: EnvSpec, results: dict, path: Path, control_dt: float = 0.01) -> Path | None:
    """The per-step trace of the paper task of ``spec.trace_task``, first seed of each method (None, and no file,
    when no method ran that task: it is not in the evaluated split)."""
    plt = _pyplot()
    key = f"trace_{benchmark_of(spec).trace_value}"
    words, higher = TRACE_LABELS.get(benchmark_of(spec).trace_value, (benchmark_of(spec).trace_value, True))
    drawn = {method: tasks[benchmark_of(spec).trace_task] for method, tasks in results.items()
             if tasks.get(benchmark_of(spec).trace_task) and tasks[benchmark_of(spec).trace_task]["traces"]}
    if not drawn:  # the trace task is not in this split (the circle is test-only): no empty figure
        return None
    fig, ax = plt.subplots(figsize=(9, 4.5))
    for method, task in drawn.items():
        trace = task["traces"][0][key]
        time = np.arange(len(trace)) * control_dt
        line, = ax.plot(time, trace, label=method)
        ended = np.flatnonzero(~np.isfinite(trace))
        if ended.size and ended[0] < len(trace):
            ax.axvline(time[ended[0]], color=line.get_color(), linestyle=":", linewidth=1)
            ax.annotate(f"{method} ended at {time[ended[0]]:.2f} s", (time[ended[0]], ax.get_ylim()[1]),
                        fontsize=7, rotation=90, va="top", ha="right", color=line.get_color())
    ax.set(xlabel="time (s)", ylabel=f"{words}, {_direction(higher)}",
           title=f"{spec.short_name}: {benchmark_of(spec).trace_task} task, first seed (a dotted line marks an episode that "
                 "ended early)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def draw_coverage_maps(spec: EnvSpec, results: dict, table: dict, path: Path) -> Path | None:
    """Final-OR maps over the grid, one per method: OR averaged over seeds, titled with the table's coverage."""
    metric = next((m for m in spec.metrics if m.grid_metric), None)
    maps = [(m, t) for m, tasks in results.items() for t in tasks.values() if t["grid"]]
    if metric is None or not maps:
        return None
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(maps), figsize=(4.2 * len(maps), 4.3), constrained_layout=True)
    image = None
    for ax, (method, task) in zip(np.atleast_1d(axes), maps):
        values = np.stack(task["scores"][metric.grid_metric])
        grid = int(round(np.sqrt(values.shape[1])))
        coverage = table.get(method, {}).get(metric.name, {}).get("mean", np.mean(values > metric.threshold) * 100)
        image = ax.imshow(values.mean(axis=0).reshape(grid, grid).T, origin="lower", extent=[-60, 60, -60, 60],
                          vmin=0, vmax=1)
        seeds = values.shape[0]
        ax.set(title=f"{method}\ncoverage {coverage:.1f} % ({seeds} seed{'s' if seeds > 1 else ''})",
               xlabel="yaw (deg)", ylabel="pitch (deg)")
    fig.colorbar(image, ax=axes, label="final OR, mean over seeds (higher is better)")
    fig.suptitle(f"{spec.short_name}: coverage = mean over seeds of the % of grid points with final OR > "
                 f"{metric.threshold:g} (thresholded per seed, then averaged)", fontsize=9)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def metric_axis(metric: Metric, prefix: str = "", sep: str = ", ") -> str:
    """An axis label naming the metric, its unit ("dimensionless" if it has none) and the better direction."""
    unit = metric.display_unit or metric.unit or "dimensionless"
    return f"{prefix}{metric.label} ({unit}){sep}{_direction(metric.higher_is_better)}"


def _seed_band(values: np.ndarray, reps: int = 1000, seed: int = 0) -> tuple:
    """(mean, low, high) over axis 0 of (seeds, points): the 95 % percentile-bootstrap CI of the mean over seeds."""
    mean = values.mean(axis=0)
    if values.shape[0] < 2:
        return mean, mean, mean
    rng = np.random.default_rng(seed)
    draws = values[rng.integers(values.shape[0], size=(reps, values.shape[0]))].mean(axis=1)
    return mean, np.percentile(draws, 2.5, axis=0), np.percentile(draws, 97.5, axis=0)


def learning_curves(policies: dict, env_id: str, metric: str) -> dict:
    """{method: (steps (points,), values (seeds, points), elapsed seconds (seeds, points) or None)} of the runs'
    ``evaluations.npz`` (and ``wall_clock.csv``), over the evaluations every seed of the method has."""
    from continuum_gym.evaluation.comparison import read_wall_clock

    out = {}
    for method, runs in policies.get(env_id, {}).items():
        curves = [(run, np.load(run / "evaluations.npz")) for run in runs if (run / "evaluations.npz").exists()]
        if not curves:
            continue
        common = sorted(set.intersection(*(set(data["timesteps"].tolist()) for _, data in curves)))
        if not common:
            continue
        values, clocks = [], []
        for run, data in curves:
            index = {int(step): k for k, step in enumerate(data["timesteps"])}
            values.append([data[metric][index[step]] for step in common])
            clock = read_wall_clock(run)
            if clock is not None:
                at = dict(zip(clock[0].tolist(), clock[1].tolist()))
                clocks.append([at.get(step, np.nan) for step in common])
        elapsed = np.array(clocks) if len(clocks) == len(curves) else None
        out[method] = (np.array(common), np.array(values), elapsed)
    return out


def draw_learning_curves(spec: EnvSpec, policies: dict, path: Path, env_id: str | None = None) -> Path | None:
    """Validation headline metric of each learned row, mean over its seeds with a 95 % bootstrap CI, against
    environment steps and, when the runs record it (``wall_clock.csv``), against wall-clock seconds."""
    metric = spec.metric(benchmark_of(spec).headline_metric)
    curves = learning_curves(policies, env_id or spec.env_id, metric.name)
    if not curves:
        return None
    plt = _pyplot()
    timed = all(elapsed is not None for _, _, elapsed in curves.values())
    # Laid out at the dpi it is saved at (text sizes round to its pixels), with a y label short enough to fit
    fig, axes = plt.subplots(1, 2 if timed else 1, figsize=(11 if timed else 6.5, 4.4), squeeze=False, dpi=90)
    for method, (steps, values, elapsed) in curves.items():
        mean, low, high = _seed_band(values)
        label = f"{method} ({values.shape[0]} seed{'s' if values.shape[0] > 1 else ''})"
        line, = axes[0, 0].plot(steps, mean, label=label)
        axes[0, 0].fill_between(steps, low, high, color=line.get_color(), alpha=0.2, linewidth=0)
        if timed:
            clock = np.nanmean(elapsed, axis=0)
            axes[0, 1].plot(clock, mean, color=line.get_color(), label=label)
            axes[0, 1].fill_between(clock, low, high, color=line.get_color(), alpha=0.2, linewidth=0)
    what, direction = metric_axis(metric, "validation ", "\n").split("\n")
    ylabel = textwrap.fill(what, 34) + "\n" + direction  # a long metric name on two lines: never cut off
    axes[0, 0].set(xlabel="environment steps (summed over the vector env)", ylabel=ylabel,
                   title="against environment steps", xlim=(0, None))
    if timed:
        axes[0, 1].set(xlabel="wall-clock since the run started (s), mean over seeds", ylabel=ylabel,
                       title="against wall-clock", xlim=(0, None))
    axes[0, 0].legend(fontsize=7, title="mean; band: 95 % CI over seeds", title_fontsize=7)
    fig.suptitle(f"{spec.short_name}: learning curves on the training-time validation tasks", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def draw_performance_profiles(spec: EnvSpec, results: dict, path: Path, reps: int = 500) -> Path | None:
    """rliable performance profiles of every row: the fraction of (run, episode) scores better than tau, for
    tau over the headline metric's range, with 95 % stratified-bootstrap bands (non-grid task sets; ``reps``
    resamples: 500 keep ``make demo`` within its minute, the bands are a picture, the table has the CIs)."""
    from rliable import library

    from continuum_gym.evaluation.comparison import headline_scores

    metric = spec.metric(benchmark_of(spec).headline_metric)
    scores = {method: headline_scores(spec, results, method) for method in results}
    if not scores:
        return None
    sign = 1.0 if metric.higher_is_better else -1.0  # rliable counts scores above tau: flip a lower-is-better metric
    values = np.concatenate([s.ravel() for s in scores.values()])
    taus = np.linspace(values.min(), values.max(), 101)
    caller_state = np.random.get_state()  # rliable draws from numpy's global generator (see statistics.py)
    np.random.seed(0)
    try:
        profiles, bands = library.create_performance_profile({m: sign * s for m, s in scores.items()},
                                                             sign * taus, reps=reps)
    finally:
        np.random.set_state(caller_state)
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for method in scores:
        line, = ax.plot(taus, profiles[method], label=method)
        ax.fill_between(taus, bands[method][0], bands[method][1], color=line.get_color(), alpha=0.2, linewidth=0)
    relation = ">" if metric.higher_is_better else "<"
    ax.set(xlabel=f"threshold \u03c4: {metric_axis(metric)}",
           ylabel=f"fraction of runs x episodes\nwith {metric.name} {relation} \u03c4 (higher is better)",
           title=f"{spec.short_name}: performance profiles on held-out tasks")
    ax.legend(fontsize=7, title="band: 95 % CI", title_fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def draw(env_id: str, results: dict, table: dict, policies: dict, out: Path, split: str = "test") -> list:
    """Every figure of one env into ``out`` that has something to show; returns the paths written."""
    spec = get_spec(env_id)
    short = env_id.split("/")[-1].rsplit("-v", 1)[0]  # a registered variant's figures carry its own name
    paths = [draw_distributions(spec, results, table, out / f"{short}_distribution.png", split),
             draw_traces(spec, results, out / f"{short}_{benchmark_of(spec).trace_task}_trace.png"),
             draw_coverage_maps(spec, results, table, out / f"{short}_coverage_maps.png"),
             draw_learning_curves(spec, policies, out / f"{short}_learning_curves.png", env_id),
             draw_performance_profiles(spec, results, out / f"{short}_performance_profiles.png")]
    return [path for path in paths if path is not None]
