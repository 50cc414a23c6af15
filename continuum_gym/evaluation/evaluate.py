"""``continuum-gym evaluate``: analytic baselines and learned policies through one path, on held-out tasks.

Every method runs in the same batched environment core through SB3's ``predict``: a baseline is the
residual environment with a zero residual (which equals the baseline exactly), a residual policy is
its SB3 model in that environment, ``pure_rl`` runs with ``base_controller=None``. All methods see the
same test-split task instances. Statistics: mean and IQM with 95 % stratified-bootstrap CIs (rliable)
over seeds x episodes.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import yaml

from continuum_gym.evaluation.io import write_json_atomic, write_text_atomic
from continuum_gym.evaluation.rollout import ZeroResidual, make_core, run_episodes
from continuum_gym.evaluation.statistics import summarize

OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"
POLICY_DIR = Path(__file__).resolve().parents[1] / "agents" / "policies"
OPTIMUM_CACHE = Path(__file__).resolve().parent / "data" / "optimum_cache.json"
BASELINES = {OCCLUSION: ("minimum_norm", "projected_gradient"), VIEW: ("resolved_rate", "dimension_reduced")}
# Env keywords that define how a policy's action acts: taken from its training config. Task keywords are not:
# every method runs on the same test tasks.
POLICY_ENV_KEYS = ("base_controller", "residual_scale", "residual_space", "visibility_guard", "observe_target")
HEADLINE_BASE = {OCCLUSION: "projected_gradient", VIEW: "dimension_reduced"}
# Task sets: (task name, number of instances or None for the --episodes default).
TASK_SETS = {OCCLUSION: (("hold", None), ("random", None), ("circle", 1)),
             VIEW: (("static", None), ("random", None), ("case1", 1), ("case2", 1))}
METRICS = {OCCLUSION: ("mean_voi", "tip_in_view_fraction", "mean_tip_error_m", "mean_orientation_error_rad"),
           VIEW: ("mean_or", "or_above_0.8_fraction", "mean_position_error_m", "coverage_percent")}
# Per-task diagnostics shown beside the headline metrics (Markdown only): how often the visibility guard cut
# a residual's endoscope rotation.
TASK_DIAGNOSTICS = {OCCLUSION: ("visibility_guarded_fraction",), VIEW: ()}
HIGHER_IS_BETTER = {"mean_voi": False, "tip_in_view_fraction": True, "mean_tip_error_m": False,
                    "mean_orientation_error_rad": False, "mean_or": True, "or_above_0.8_fraction": True,
                    "mean_position_error_m": False, "coverage_percent": True, "headroom_closed": True}


# ---------------------------------------------------------------------- methods
def discover_policies(directory) -> dict:
    """{env_id: {method: [run dirs]}} from ``<dir>/**/config.yml`` + ``model.zip``."""
    found = {}
    directory = Path(directory)
    if not directory.exists():
        raise FileNotFoundError(f"--policies: no directory {directory}")
    for config_path in sorted(directory.rglob("config.yml")):
        run = config_path.parent
        if not (run / "model.zip").exists():
            raise FileNotFoundError(f"policy {run} has config.yml but no model.zip")
        config = yaml.safe_load(config_path.read_text())
        base = config.get("base_controller")
        method = f"residual_{base}" if base else "pure_rl"
        found.setdefault(config["env_id"], {}).setdefault(method, []).append(run)
    return found


def load_policy(run: Path):
    from stable_baselines3 import PPO, SAC, TD3

    config = yaml.safe_load((run / "config.yml").read_text())
    cls = {"ppo": PPO, "sac": SAC, "td3": TD3}[config["algo"]]
    return cls.load(run / "model.zip", device="cpu"), config


def method_runs(env_id, policies):
    """[(method, [(policy, env_kwargs)])]: baselines first, then learned methods (one entry per seed)."""
    out = []
    for base in BASELINES[env_id]:
        out.append((base, [(None, {"base_controller": base})]))
    for method, runs in sorted(policies.get(env_id, {}).items()):
        entries = []
        for run in runs:
            model, config = load_policy(run)
            kwargs = {k: v for k, v in config.get("env_kwargs", {}).items() if k in POLICY_ENV_KEYS}
            entries.append((model, kwargs))
        out.append((method, entries))
    return out


# ---------------------------------------------------------------------- evaluation
def evaluate_env(env_id, policies, episodes, grid, progress=True) -> dict:
    """Per method: per task set, scores (seeds x episodes) of each metric, plus traces for figures."""
    from tqdm.auto import tqdm

    results = {}
    methods = method_runs(env_id, policies)
    work = []
    for method, entries in methods:
        for seed_index, (model, kwargs) in enumerate(entries):
            for task, count in TASK_SETS[env_id]:
                work.append((method, seed_index, model, kwargs, task, count or episodes))
            if env_id == VIEW:
                work.append((method, seed_index, model, kwargs, "coverage", grid * grid))
    bar = tqdm(work, desc=env_id.split("/")[-1], disable=not progress)
    for method, seed_index, model, kwargs, task, count in bar:
        bar.set_postfix_str(f"{method} {task}")
        env_kwargs = dict(kwargs, task=task, task_split="test")
        if task == "coverage":
            env_kwargs["grid"] = grid
        core = make_core(env_id, count, **env_kwargs)
        policy = model if model is not None else ZeroResidual(core.single_action_space.shape[0])
        ids = np.arange(count)
        traces = task in ("circle", "case1", "case2")
        result = run_episodes(core, policy, ids, record=traces)
        entry = results.setdefault(method, {}).setdefault(task, {"scores": {}, "traces": []})
        for key, value in result.items():
            if key.startswith("trace_"):
                continue
            entry["scores"].setdefault(key, []).append(np.asarray(value))
        if traces:
            entry["traces"].append({k: v[:, 0] for k, v in result.items() if k.startswith("trace_")})
    return results


def coverage_scores(task_result) -> np.ndarray:
    """(seeds, grid points) of 100 * [final OR > 0.8]: its mean is the coverage percentage."""
    return np.stack(task_result["scores"]["final_or"]) > 0.8


def aggregate(env_id, results, optimum=None) -> dict:
    """<method> -> <metric> -> {mean, iqm, ci_low, ci_high, ...}, over the env's test tasks."""
    table = {}
    for method, tasks in results.items():
        row = {}
        for metric in METRICS[env_id]:
            if metric == "coverage_percent":
                if "coverage" in tasks:
                    row[metric] = summarize(100.0 * coverage_scores(tasks["coverage"]))
                continue
            scores = [np.stack(t["scores"][metric]) for name, t in tasks.items() if name != "coverage"]
            row[metric] = summarize(_concat_tasks(scores))
        table[method] = row
    if optimum:
        table.update(optimum_rows(env_id, results, optimum))
    add_headroom(env_id, table, results)
    return table


def _concat_tasks(score_list):
    """Concatenate task sets along the task axis; methods with fewer seeds repeat their single row."""
    runs = max(s.shape[0] for s in score_list)
    return np.concatenate([np.repeat(s, runs // s.shape[0], axis=0) if s.shape[0] != runs else s
                           for s in score_list], axis=1)


def optimum_rows(env_id, results, optimum) -> dict:
    rows = {}
    if env_id == VIEW and "coverage" in optimum:
        cov = optimum["coverage"]
        for name, key in (("offline_optimum", "optimum_or"), ("bounded_least_squares", "bounded_least_squares_or")):
            if key in cov:
                ratios = np.asarray(cov[key], dtype=float)[None]
                rows[name] = {"coverage_percent": summarize(100.0 * (ratios > 0.8)),
                              "final_or": summarize(ratios)}
    if env_id == OCCLUSION and "hold_test" in optimum:
        n = len(np.stack(next(iter(results.values()))["hold"]["scores"]["mean_voi"])[0])
        voi = np.asarray(optimum["hold_test"]["optimum_voi"], dtype=float)
        if len(voi) >= n:
            # The optimum holds each start's best configuration and gamma for the whole episode.
            rows["offline_optimum"] = {"mean_voi": summarize(voi[:n][None]),
                                       "note": "hold test tasks only: lowest VOI on the self-motion arc x feasible gamma"}
    return rows


def add_headroom(env_id, table, results) -> None:
    """headroom_closed = (method - base) / (optimum - base) for learned methods.

    OcclusionAvoidance: mean VOI on the hold test tasks (where the optimum is known); ViewTracking:
    coverage percentage on the grid.
    """
    base = HEADLINE_BASE[env_id]
    if "offline_optimum" not in table or base not in results:
        return
    if env_id == OCCLUSION:
        if "mean_voi" not in table["offline_optimum"] or "hold" not in results[base]:
            return
        optimum = table["offline_optimum"]["mean_voi"]["mean"]

        def value(method):
            return float(np.mean(np.stack(results[method]["hold"]["scores"]["mean_voi"])))
    else:
        if "coverage_percent" not in table["offline_optimum"] or "coverage" not in results[base]:
            return
        optimum = table["offline_optimum"]["coverage_percent"]["mean"]

        def value(method):
            return float(np.mean(coverage_scores(results[method]["coverage"])) * 100)

    reference = value(base)
    if abs(optimum - reference) < 1e-12:
        return
    for method in results:
        if method.startswith(("residual_", "pure_rl")):
            closed = (value(method) - reference) / (optimum - reference)
            table[method]["headroom_closed"] = {"mean": closed, "iqm": closed, "ci_low": closed, "ci_high": closed,
                                                "on": "hold tasks, mean_voi" if env_id == OCCLUSION else
                                                "coverage grid, coverage_percent"}


# ---------------------------------------------------------------------- report
def markdown(env_id, table, results) -> str:
    metrics = [m for m in METRICS[env_id]] + ["headroom_closed"]
    lines = [f"### {env_id}", "", "| method | " + " | ".join(metrics) + " |",
             "|---|" + "---|" * len(metrics)]
    for method, row in table.items():
        cells = []
        for metric in metrics:
            s = row.get(metric)
            if not isinstance(s, dict) or "mean" not in s:
                cells.append("-")
            elif metric == "headroom_closed":
                cells.append(f"{s['mean']:.2f}")
            else:
                cells.append(f"{_fmt(metric, s['mean'])} [{_fmt(metric, s['ci_low'])}, {_fmt(metric, s['ci_high'])}] "
                             f"(IQM {_fmt(metric, s['iqm'])})")
        lines.append(f"| {method} | " + " | ".join(cells) + " |")
    columns = METRICS[env_id][:3] + TASK_DIAGNOSTICS[env_id]
    lines += ["", "Per task set (mean over seeds and episodes):", "",
              "| method | task | " + " | ".join(columns) + " |", "|---|---|" + "---|" * len(columns)]
    for method, tasks in results.items():
        for task, t in tasks.items():
            if task == "coverage":
                continue
            values = [_fmt(m, float(np.mean(np.stack(t["scores"][m])))) for m in columns]
            lines.append(f"| {method} | {task} | " + " | ".join(values) + " |")
    return "\n".join(lines) + "\n"


def _fmt(metric, value):
    if metric.endswith("_m"):
        return f"{value * 1e3:.3f} mm"
    if metric == "coverage_percent":
        return f"{value:.1f} %"
    return f"{value:.3g}" if abs(value) < 0.01 else f"{value:.3f}"


def draw(env_id, results, table, policies, out: Path) -> list:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    short = env_id.split("/")[-1].split("-")[0]
    metric = "mean_voi" if env_id == OCCLUSION else "mean_or"
    # Distributions of the headline metric per method (all seeds x non-coverage episodes).
    fig, ax = plt.subplots(figsize=(8, 4))
    labels, data = [], []
    for method, tasks in results.items():
        labels.append(method)
        data.append(np.concatenate([np.stack(t["scores"][metric]).ravel() for k, t in tasks.items() if k != "coverage"]))
    ax.boxplot(data, showmeans=True)
    ax.set_xticks(range(1, len(labels) + 1), labels, rotation=20)
    ax.set(ylabel=metric, title=f"{short}: {metric} per episode (held-out tasks)")
    fig.tight_layout()
    paths.append(out / f"{short}_distribution.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)
    # Time traces of the fixed paper tasks.
    trace_task = "circle" if env_id == OCCLUSION else "case1"
    key = "trace_voi" if env_id == OCCLUSION else "trace_or"
    fig, ax = plt.subplots(figsize=(8, 4))
    for method, tasks in results.items():
        if trace_task in tasks and tasks[trace_task]["traces"]:
            trace = tasks[trace_task]["traces"][0][key]
            ax.plot(np.arange(len(trace)) * 0.01, trace, label=method)
    ax.set(xlabel="time (s)", ylabel=key[6:].upper(), title=f"{short}: {trace_task}, first seed")
    ax.legend(fontsize=8)
    fig.tight_layout()
    paths.append(out / f"{short}_{trace_task}_trace.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)
    # OR maps side by side.
    if env_id == VIEW:
        maps = [(m, np.stack(t["coverage"]["scores"]["final_or"]).mean(axis=0)) for m, t in results.items()
                if "coverage" in t]
        grid = int(round(np.sqrt(maps[0][1].size)))
        fig, axes = plt.subplots(1, len(maps), figsize=(4.2 * len(maps), 4), constrained_layout=True)
        for ax, (method, ratios) in zip(np.atleast_1d(axes), maps):
            image = ax.imshow(ratios.reshape(grid, grid).T, origin="lower", extent=[-60, 60, -60, 60], vmin=0, vmax=1)
            ax.set(title=f"{method}\n{np.mean(ratios > 0.8) * 100:.1f} % > 0.8", xlabel="yaw (deg)",
                   ylabel="pitch (deg)")
        fig.colorbar(image, ax=axes, label="final OR")
        paths.append(out / f"{short}_coverage_maps.png")
        fig.savefig(paths[-1], dpi=100)
        plt.close(fig)
    # Learning curves of the learned policies.
    curves = [(method, run) for method, runs in policies.get(env_id, {}).items() for run in runs
              if (run / "evaluations.npz").exists()]
    if curves:
        fig, ax = plt.subplots(figsize=(8, 4))
        for method, run in curves:
            data = np.load(run / "evaluations.npz")
            ax.plot(data["timesteps"], data[metric], label=f"{method} ({run.name.split('_')[-1]})")
        ax.set(xlabel="environment steps", ylabel=f"{metric} (held-out)", title=f"{short}: learning curves")
        ax.legend(fontsize=7)
        fig.tight_layout()
        paths.append(out / f"{short}_learning_curves.png")
        fig.savefig(paths[-1], dpi=110)
        plt.close(fig)
    return paths


# ---------------------------------------------------------------------- CLI
def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--policies", default=str(POLICY_DIR), help="directory of trained runs (default: shipped)")
    parser.add_argument("--episodes", type=int, default=32, help="held-out episodes per task set (default 32)")
    parser.add_argument("--grid", type=int, default=21, help="coverage grid points per axis (default 21)")
    parser.add_argument("--out", default="results/evaluate", help="directory for tables and figures")
    parser.add_argument("--json", default=None, help="write <env> -> <method> -> <metric> -> stats JSON here")
    parser.add_argument("--env", nargs="+", default=[OCCLUSION, VIEW], help="environment ids to evaluate")
    parser.add_argument("--no-progress", action="store_true")


def load_optimum():
    if OPTIMUM_CACHE.exists():
        return json.loads(OPTIMUM_CACHE.read_text())
    return None


def run(args) -> int:
    import sys

    for env_id in args.env:
        if env_id not in BASELINES:
            print(f"continuum-gym evaluate: unknown env {env_id!r}; valid: {sorted(BASELINES)}", file=sys.stderr)
            return 2
    if args.episodes < 1 or args.grid < 2:
        print("continuum-gym evaluate: --episodes must be >= 1 and --grid >= 2", file=sys.stderr)
        return 2
    try:
        policies = discover_policies(args.policies)
    except FileNotFoundError as error:
        print(f"continuum-gym evaluate: {error}", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    optimum = load_optimum()
    started = time.perf_counter()
    summary, report = {}, []
    for env_id in args.env:
        results = evaluate_env(env_id, policies, args.episodes, args.grid, progress=not args.no_progress)
        usable = optimum if (env_id == OCCLUSION or args.grid == (optimum or {}).get("coverage", {}).get("grid")) \
            else None
        table = aggregate(env_id, results, usable)
        summary[env_id] = table
        report.append(markdown(env_id, table, results))
        for path in draw(env_id, results, table, policies, out):
            print(f"wrote {path}")
    text = "\n".join(report) + f"\nEvaluation wall time: {time.perf_counter() - started:.0f} s\n"
    print(text)
    write_text_atomic(out / "results.md", text)
    if args.json:
        write_json_atomic(args.json, summary)
        print(f"wrote {args.json}")
    return 0
