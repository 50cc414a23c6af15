"""``continuum-gym evaluate``: analytic baselines and learned policies through one path, on held-out tasks.

Every method runs in the same batched environment core through SB3's ``predict``: a baseline is the
residual environment with a zero residual (which equals the baseline exactly), a residual policy is
its SB3 model in that environment, ``pure_rl`` runs with ``base_controller=None``. All methods see the
same test-split task instances. Statistics: mean and IQM with 95 % stratified-bootstrap CIs (rliable)
over seeds x episodes. What is evaluated, and how, comes from each environment's spec
(``continuum_gym.envs.spec``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from continuum_gym.envs.spec import (
    ENV_SPECS,
    OCCLUSION_SPEC,
    VIEW_SPEC,
    EnvSpec,
    get_spec,
)

OCCLUSION = OCCLUSION_SPEC.env_id
VIEW = VIEW_SPEC.env_id
POLICY_DIR = Path(__file__).resolve().parents[1] / "agents" / "policies"
OPTIMUM_CACHE = Path(__file__).resolve().parent / "data" / "optimum_cache.json"
#: headroom_closed, computed for learned methods, is better when higher.
HEADROOM = "headroom_closed"


# ---------------------------------------------------------------------- methods
def discover_policies(directory) -> dict:
    """{env_id: {method: [run dirs]}} from ``<dir>/**/config.yml`` + ``model.zip``."""
    import yaml

    found: dict = {}
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
    """(SB3 model, its run's config dict) of a run directory."""
    import yaml
    from stable_baselines3 import PPO, SAC, TD3

    config = yaml.safe_load((run / "config.yml").read_text())
    cls = {"ppo": PPO, "sac": SAC, "td3": TD3}[config["algo"]]
    return cls.load(run / "model.zip", device="cpu"), config


def policy_env_kwargs(spec: EnvSpec, config: dict) -> dict:
    """The env keywords of a run's config that define how its policy acts (``spec.policy_keys``).

    Runs write their full env config (``env_config``); older runs only their keyword arguments
    (``env_kwargs``). Task keywords are not taken: every method runs on the same test tasks.
    """
    source = config.get("env_config") or config.get("env_kwargs") or {}
    picked = {key: value for key, value in source.items() if key in spec.policy_keys}
    spec.config_class.from_kwargs(**picked)  # the same checks as the env's: a broken config fails here, named
    return picked


def method_runs(env_id: str, policies: dict) -> list:
    """[(method, [(policy, env_kwargs)])]: baselines first, then learned methods (one entry per seed)."""
    spec = get_spec(env_id)
    out = []
    for base in spec.baselines:
        out.append((base, [(None, {"base_controller": base})]))
    for method, runs in sorted(policies.get(env_id, {}).items()):
        entries = []
        for run in runs:
            model, config = load_policy(run)
            entries.append((model, policy_env_kwargs(spec, config)))
        out.append((method, entries))
    return out


# ---------------------------------------------------------------------- evaluation
def evaluate_env(env_id: str, policies: dict, episodes: int, grid: int, progress: bool = True) -> dict:
    """Per method: per task set, scores (seeds x episodes) of each metric, plus traces for figures."""
    from tqdm.auto import tqdm

    from continuum_gym.evaluation.rollout import ZeroResidual, make_core, run_episodes

    spec = get_spec(env_id)
    results: dict = {}
    work = []
    for method, entries in method_runs(env_id, policies):
        for seed_index, (model, kwargs) in enumerate(entries):
            for task_set in spec.task_sets:
                count = grid * grid if task_set.grid else (task_set.episodes or episodes)
                work.append((method, model, kwargs, task_set, count))
    bar = tqdm(work, desc=spec.short_name, disable=not progress)
    for method, model, kwargs, task_set, count in bar:
        bar.set_postfix_str(f"{method} {task_set.task}")
        env_kwargs = dict(kwargs, task=task_set.task, task_split="test")
        if task_set.grid:
            env_kwargs["grid"] = grid
        core = make_core(env_id, count, **env_kwargs)
        policy = model if model is not None else ZeroResidual(core.single_action_space.shape[0])
        traces = task_set.task == spec.trace_task
        result = run_episodes(core, policy, np.arange(count), record=traces)
        entry = results.setdefault(method, {}).setdefault(task_set.task, {"scores": {}, "traces": [],
                                                                          "grid": task_set.grid})
        for key, value in result.items():
            if not key.startswith("trace_"):
                entry["scores"].setdefault(key, []).append(np.asarray(value))
        if traces:
            entry["traces"].append({k: v[:, 0] for k, v in result.items() if k.startswith("trace_")})
    return results


def grid_scores(task_result: dict, metric) -> np.ndarray:
    """(seeds, grid points) of [grid metric > threshold]: its mean x 100 is e.g. the coverage percentage."""
    return np.stack(task_result["scores"][metric.grid_metric]) > metric.threshold


def aggregate(env_id: str, results: dict, optimum: dict | None = None, grid: int | None = None) -> dict:
    """<method> -> <metric> -> {mean, iqm, ci_low, ci_high, ...}, over the env's test tasks."""
    from continuum_gym.evaluation.statistics import summarize

    spec = get_spec(env_id)
    table = {}
    for method, tasks in results.items():
        row = {}
        for metric in spec.metrics:
            if metric.grid_metric:
                grid_tasks = [t for t in tasks.values() if t["grid"]]
                if grid_tasks:
                    row[metric.name] = summarize(100.0 * grid_scores(grid_tasks[0], metric))
                continue
            scores = [np.stack(t["scores"][metric.name]) for t in tasks.values() if not t["grid"]]
            row[metric.name] = summarize(_concat_tasks(scores))
        table[method] = row
    if optimum:
        table.update(reference_rows(spec, results, optimum, grid))
    add_headroom(spec, table, results)
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
    for ref in spec.references:
        cached = optimum.get(ref.cache_key)
        if not cached or ref.values not in cached:
            continue
        values = np.asarray(cached[ref.values], dtype=float)
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


def add_headroom(spec: EnvSpec, table: dict, results: dict) -> None:
    """headroom_closed = (method - base) / (optimum - base) for learned methods, on ``spec.headroom``."""
    task, metric = spec.headroom
    base = spec.headline_baseline
    if "offline_optimum" not in table or base not in results:
        return
    if metric not in table["offline_optimum"] or task not in results[base]:
        return
    optimum = table["offline_optimum"][metric]["mean"]
    reference = method_value(spec, results, base, task, metric)
    if abs(optimum - reference) < 1e-12:
        return
    where = f"{task} grid, {metric}" if results[base][task]["grid"] else f"{task} tasks, {metric}"
    for method in results:
        if method.startswith(("residual_", "pure_rl")):
            closed = (method_value(spec, results, method, task, metric) - reference) / (optimum - reference)
            table[method][HEADROOM] = {"mean": closed, "iqm": closed, "ci_low": closed, "ci_high": closed, "on": where}


# ---------------------------------------------------------------------- report
def markdown(env_id: str, table: dict, results: dict) -> str:
    spec = get_spec(env_id)
    metrics = [m.name for m in spec.metrics] + [HEADROOM]
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
    columns = [m.name for m in spec.metrics if not m.grid_metric][:3] + list(spec.diagnostics)
    lines += ["", "Per task set (mean over seeds and episodes):", "",
              "| method | task | " + " | ".join(columns) + " |", "|---|---|" + "---|" * len(columns)]
    for method, tasks in results.items():
        for task, t in tasks.items():
            if t["grid"]:
                continue
            values = [fmt(spec, m, float(np.mean(np.stack(t["scores"][m])))) for m in columns]
            lines.append(f"| {method} | {task} | " + " | ".join(values) + " |")
    return "\n".join(lines) + "\n"


def fmt(spec: EnvSpec, name: str, value: float) -> str:
    """A metric value as the tables show it (lengths in mm, percentages with one decimal)."""
    try:
        metric = spec.metric(name)
    except KeyError:
        metric = None
    if metric is not None and metric.display_unit:
        return f"{value * metric.display_scale:.3f} {metric.display_unit}"
    if metric is not None and metric.unit == "%":
        return f"{value:.1f} %"
    return f"{value:.3g}" if abs(value) < 0.01 else f"{value:.3f}"


# ---------------------------------------------------------------------- CLI
def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--policies", default=str(POLICY_DIR), help="directory of trained runs (default: shipped)")
    parser.add_argument("--episodes", type=int, default=32, help="held-out episodes per task set (default 32)")
    parser.add_argument("--grid", type=int, default=21, help="coverage grid points per axis (default 21)")
    parser.add_argument("--out", default="results/evaluate", help="directory for tables and figures")
    parser.add_argument("--json", default=None, help="write <env> -> <method> -> <metric> -> stats JSON here")
    parser.add_argument("--env", nargs="+", default=list(ENV_SPECS), help="environment ids to evaluate")
    parser.add_argument("--no-progress", action="store_true")


def load_optimum() -> dict | None:
    """The shipped offline-optimum cache, or None."""
    if OPTIMUM_CACHE.exists():
        return json.loads(OPTIMUM_CACHE.read_text())
    return None


def run(args) -> int:
    for env_id in args.env:
        try:
            get_spec(env_id)
        except ValueError as error:
            print(f"continuum-gym evaluate: {error}", file=sys.stderr)
            return 2
    if args.episodes < 1 or args.grid < 2:
        print("continuum-gym evaluate: --episodes must be >= 1 and --grid >= 2", file=sys.stderr)
        return 2
    try:
        policies = discover_policies(args.policies)
    except FileNotFoundError as error:
        print(f"continuum-gym evaluate: {error}", file=sys.stderr)
        return 2
    from continuum_gym.evaluation.figures import draw
    from continuum_gym.evaluation.io import write_json_atomic, write_text_atomic

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    optimum = load_optimum()
    started = time.perf_counter()
    summary, report = {}, []
    for env_id in args.env:
        results = evaluate_env(env_id, policies, args.episodes, args.grid, progress=not args.no_progress)
        table = aggregate(env_id, results, optimum, args.grid)
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
