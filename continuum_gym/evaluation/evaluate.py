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
from typing import Any

import numpy as np

from continuum_gym.envs.benchmark import benchmark_of
from continuum_gym.envs.spec import (
    ENV_SPECS,
    EnvSpec,
    get_spec,
    registered_kwargs,
)
from continuum_gym.evaluation.methods import (
    POLICY_DIR,
    MethodRun,
    baseline_methods,
    beside_rows,
    discover_policies,
    discovered_methods,
    own_bases,
    sb3_algo,
    split_env_kwargs,
    trained_bases,
)
from continuum_gym.evaluation.tables import (
    aggregate,
    clipped_fractions,
    markdown,
)


# ---------------------------------------------------------------------- evaluation
def evaluate_env(env_id: str, methods: list, episodes: int, grid: int, progress: bool = True,
                 env_kwargs: dict | None = None, split: str = "test", skipped: dict | None = None,
                 pixel_metrics: bool = False) -> dict:
    """Per method: per task set, scores (runs x episodes) of each metric, plus traces for figures.

    ``methods`` is [(name, [MethodRun])]; every run acts in the env built from ``env_kwargs`` (the
    protocol env: robot, limits, ...) plus its own policy keywords, on the protocol's task sets of ``split``.
    A run whose observations do not fit, or whose policy fails, is reported and recorded in ``skipped``.
    ``pixel_metrics``: every method's episodes also measure the env's pixel metrics (rendered every step).
    """
    from tqdm.auto import tqdm

    from continuum_gym.envs.helpers import make_helpers
    from continuum_gym.evaluation.benchmark import episode_count, task_sets
    from continuum_gym.evaluation.policies import PolicyError, as_predictor
    from continuum_gym.evaluation.rollout import ZeroResidual, make_core, run_episodes

    spec = get_spec(env_id)
    skipped = {} if skipped is None else skipped
    results: dict = {}
    work = [(name, index, run, task_set, episode_count(task_set, episodes, grid))
            for name, runs in methods for index, run in enumerate(runs) for task_set in task_sets(spec, split)]
    # No rate and no remaining time: the items differ in cost by two orders of magnitude (a baseline on a
    # case study, a learned policy on the coverage grid), so any extrapolation from those done would be wrong.
    bar = tqdm(work, desc=spec.short_name, disable=not progress,
               bar_format="{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} [{elapsed}{postfix}]")
    failed: set = set()
    for name, index, run, task_set, count in bar:
        if name in failed:
            continue
        bar.set_postfix_str(f"{name} {task_set.task}")
        kwargs = dict(env_kwargs or {}, **run.env_kwargs, task=task_set.task, task_split=split)
        if task_set.grid:
            kwargs["grid"] = grid
        core = make_core(env_id, count, **kwargs)
        action_dim = core.single_action_space.shape[0]
        policy = ZeroResidual(action_dim) if run.policy is None else as_predictor(run.policy, name, run.source)
        declared = getattr(policy, "observation_shape", None)
        try:
            if declared is not None and declared != core.single_observation_space.shape \
                    and core.config.obs_mode == "state":
                built = {k: v for k, v in kwargs.items() if k not in ("task", "task_split", "grid")}
                robot = core.config.to_dict().get("robot")
                raise PolicyError(f"policy {name!r} expects observations of shape {declared}, the env gives "
                                  f"{core.single_observation_space.shape}: {env_id} built with {built} (robot "
                                  f"{robot}); pass the keywords it was trained with "
                                  "(--env-kwargs, or its registered id with --import)")
            result = run_episodes(core, policy, np.arange(count), record=task_set.task == benchmark_of(spec).trace_task,
                                  helpers=make_helpers(env_id, run.helpers, core.config), pixel_metrics=pixel_metrics)
        except PolicyError as error:
            failed.add(name)
            skipped[f"{name}[{index}]"] = str(error)
            print(f"continuum-gym evaluate: skipping {name} (run {index}): {error}", file=sys.stderr)
            continue
        entry = results.setdefault(name, {}).setdefault(task_set.task, {"scores": {}, "traces": [],
                                                                        "grid": task_set.grid})
        for key, value in result.items():
            if not key.startswith("trace_"):
                entry["scores"].setdefault(key, []).append(np.asarray(value))
        if task_set.task == benchmark_of(spec).trace_task:
            entry["traces"].append({k: v[:, 0] for k, v in result.items() if k.startswith("trace_")})
    for name in failed:  # a method is compared on every task set of every run, or not at all
        results.pop(name, None)
    return results


# ---------------------------------------------------------------------- API
def evaluate_methods(env_id: str, extra: list, policies: dict | None = None, *, env_kwargs: dict | None = None,
                     episodes: int = 32, grid: int = 21, split: str = "test", progress: bool = True,
                     references: bool = True, pixel_metrics: bool = False) -> tuple[dict, dict, dict]:
    """(table, results, metadata) of the baselines, the SB3 runs in ``policies`` and ``extra`` methods.

    ``extra`` is [(name, [MethodRun])]; ``env_kwargs`` the protocol env every method runs in (its policy
    keywords go to the ``extra`` methods only). The table has every baseline, the offline optimum of
    this env (computed once and cached for a variant), each method and ``headroom_closed``; with
    ``pixel_metrics`` also the env's pixel metric (``mean_image_occlusion``, ``mean_view_centre_error_pct``) of
    every method beside the headline metric.
    """
    from continuum_gym.evaluation.benchmark import metadata
    from continuum_gym.evaluation.comparison import add_improvement, add_training
    from continuum_gym.evaluation.references import load_references

    spec = get_spec(env_id)
    check_sizes(episodes, grid)
    # A user's registered id: its keywords define the env (robot, cone, ...) and its base, as gym.make's.
    environment, policy_kwargs, ignored = split_env_kwargs(spec, {**registered_kwargs(env_id), **(env_kwargs or {})})
    extra = [(name, [MethodRun(run.policy, {**policy_kwargs, **run.env_kwargs}, run.source,
                               run.algo or sb3_algo(run.policy), run.helpers) for run in runs])
             for name, runs in extra]
    skipped: dict = {}
    learned = discovered_methods(spec, policies or {}, skipped, env_id) + extra
    baselines = applicable(spec, baseline_methods(spec, own_bases(spec, env_id, learned, environment)), environment,
                           skipped)
    bases, ablations = beside_rows(baselines + learned)  # a learned row's base with its helpers, the row without
    methods = baselines + bases + learned + ablations
    results = evaluate_env(env_id, methods, episodes, grid, progress, environment, split, skipped, pixel_metrics)
    optimum = load_references(spec, environment, episodes, grid, split, progress=progress) if references else None
    table = aggregate(env_id, results, optimum, grid, trained_bases(methods))
    for name, runs in learned:  # which algorithm, and over how many seeds, beside a learned row's metrics
        if name in table:
            table[name].update(algo=runs[0].algo, n_seeds=len(runs))
    add_improvement(spec, table, results, [name for name, _ in learned])
    add_training(table, [(name, [Path(run.source).parent for run in runs
                                 if run.source and Path(run.source).name == "model.zip"]) for name, runs in learned])
    described = {name: {"runs": len(runs), "env_kwargs": [run.env_kwargs for run in runs]} for name, runs in methods}
    meta = metadata(spec, split, episodes, grid, environment, ignored, described)
    meta["skipped"] = skipped
    meta["action_clipped_fraction"] = clipped_fractions(results)
    return table, results, meta


def applicable(spec: EnvSpec, baselines: list, environment: dict, skipped: dict) -> list:
    """The baseline rows the protocol env can build: a base made for the paper's robot (``arc_plan`` plans on the
    7-DoF arc) has no row on a variant it does not fit, and ``skipped`` says why."""
    out = []
    for name, runs in baselines:
        try:
            spec.config_class.from_kwargs(**environment, **runs[0].env_kwargs)
        except ValueError as error:
            skipped[name] = f"not applicable to this env: {error}"
            continue
        out.append((name, runs))
    return out


def evaluate_policy(policy: Any, env_id: str, *, name: str = "policy", env_kwargs: dict | None = None,
                    episodes: int = 32, grid: int = 21, split: str = "test", progress: bool = True,
                    out: str | Path | None = None, helpers: list | tuple = ()) -> dict:
    """The benchmark table of ``policy`` beside every baseline and the offline optimum of ``env_id``.

    Args:
        policy: a batched callable ``obs (N, d) -> actions (N, k)`` (numpy), an SB3 model, a
            ``torch.nn.Module`` (forward: observations -> deterministic actions) or an object with
            ``predict(obs)``; for ViewTracking ``d = 22`` and ``k = 6``, for OcclusionAvoidance ``d = 32``
            and ``k = 8`` (the paper's robots; a zero policy gives exactly the base controller's row).
        env_id: a ``ContinuumGym/`` id (or one registered to the library's entry points).
        name: the policy's row in the table.
        env_kwargs: the env keyword arguments the policy was trained with. Physics keywords (robot,
            cone, limits; lengths in m) define the env every method runs in; ``spec.policy_keys``
            (base controller, residual scale and space, ...) only the policy's; task keywords are set by
            the protocol (recorded as ignored).
        episodes: held-out episodes per random task set (>= 1).
        grid: coverage grid points per axis (>= 2).
        split: ``"validation"`` for model selection, ``"test"`` for final numbers only.
        progress: progress bars.
        out: a directory to also write ``results.md`` and ``results.json`` (the CLI's files) into.
        helpers: names of the env's helpers that act after the policy (``envs/helpers.py``), e.g.
            ``["overlap_polish"]``; the row is then named with them (``policy+overlap_polish``), and the base
            with the same helpers and a zero residual, and the policy without them, get rows beside it.

    Returns:
        ``{method: {metric: {"mean", "iqm", "ci_low", "ci_high", ...}}}``, the per-env object of the CLI's JSON.
    """
    from continuum_gym.envs.helpers import check_helpers, row_name

    helpers = check_helpers(env_id, helpers)
    name = row_name(str(name), helpers)
    table, results, meta = evaluate_methods(env_id, [(name, [MethodRun(policy, {}, helpers=helpers)])], None,
                                            env_kwargs=env_kwargs, episodes=episodes, grid=grid, split=split,
                                            progress=progress)
    if name not in results:
        from continuum_gym.evaluation.policies import PolicyError

        raise PolicyError(meta["skipped"].get(f"{name}[0]", f"policy {name!r} was not evaluated"))
    if out is not None:
        write_results(Path(out), {env_id: table}, {env_id: meta}, [markdown(env_id, table, results)])
    return table


def check_sizes(episodes: int, grid: int) -> None:
    """Named errors for evaluation sizes out of range."""
    from continuum_gym.validation import integer

    integer(episodes, "episodes", low=1)
    integer(grid, "grid", low=2)


def write_results(out: Path, summary: dict, meta: dict, report: list, json_path: str | Path | None = None,
                  seconds: float | None = None) -> list:
    """Write ``results.md`` and ``results.json`` (``json_path`` too) atomically; returns the paths written.

    ``json_path`` may name ``out/results.json`` itself (``make demo`` does): it is then written, and listed, once.
    """
    from continuum_gym.evaluation.io import write_json_atomic, write_text_atomic

    out.mkdir(parents=True, exist_ok=True)
    text = "\n".join(report) + (f"\nEvaluation wall time: {seconds:.0f} s\n" if seconds is not None else "")
    document = {**summary, "metadata": meta}
    written = [write_text_atomic(out / "results.md", text), write_json_atomic(out / "results.json", document)]
    if json_path and Path(json_path).resolve() != (out / "results.json").resolve():
        written.append(write_json_atomic(json_path, document))
    return written


# ---------------------------------------------------------------------- CLI
def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--policies", default=str(POLICY_DIR),
                        help="directory of trained SB3 runs (config.yml + model.zip; default: the shipped ones)")
    parser.add_argument("--policy", default=None, metavar="MODULE:FUNCTION",
                        help="also evaluate the policy returned by this function (any batched callable, SB3 model, "
                             "torch.nn.Module or object with predict), e.g. my_pkg.agents:make_policy")
    parser.add_argument("--name", default="policy", help="table row of --policy (default: policy)")
    parser.add_argument("--helpers", nargs="+", default=(), metavar="NAME",
                        help="helpers that act after --policy, in order (e.g. overlap_polish for ViewTracking; "
                             "docs/protocol.md): its row is named NAME+helper, and its base with them gets a row")
    parser.add_argument("--env-kwargs", default=None, metavar="JSON",
                        help="env keyword arguments (JSON object) the evaluated env is built with, e.g. the ones "
                             "--policy was trained with; physics keywords apply to every method")
    parser.add_argument("--model-error", default=None, choices=("none", "mild", "severe"),
                        help="evaluate every method on robots that differ from the model its controller uses "
                             "(docs/model-error.md): the preset's error, fixed per task instance; the offline "
                             "optimum stays the nominal task's")
    parser.add_argument("--split", default="test", choices=("validation", "test"),
                        help="task split: validation for model selection, test for final numbers (default)")
    parser.add_argument("--episodes", type=int, default=32, help="held-out episodes per task set (default 32)")
    parser.add_argument("--grid", type=int, default=21, help="coverage grid points per axis (default 21)")
    parser.add_argument("--out", default="results/evaluate", help="directory for tables and figures")
    parser.add_argument("--json", default=None, help="also write the JSON (<env> -> <method> -> <metric> -> stats, "
                                                     "plus metadata) here")
    parser.add_argument("--env", nargs="+", default=None, help="environment ids (default: all, or the one of "
                                                                "--policy's --env-kwargs)")
    parser.add_argument("--pixel-metrics", action="store_true",
                        help="also measure each method's pixel metric (OcclusionAvoidance: mean pixel occlusion of "
                             "the endoscope image; ViewTracking: mean view-centre error, %% of the image width), "
                             "rendering every step with the batched renderer")
    parser.add_argument("--no-progress", action="store_true")


def model_error_note(env_kwargs: dict) -> str:
    """A line under the table naming the model error every method faced (empty without one)."""
    error = env_kwargs.get("model_error", "none")
    if error == "none":
        return ""
    return (f"\n**Model error: {error}** (docs/model-error.md): every method's controller uses the nominal model, "
            "the robots move by true ones fixed per task instance; the offline optimum is the nominal task's.\n")


def skipped_notes(skipped: dict) -> str:
    """Markdown lines naming each policy that failed and was left out of the table, with the reason."""
    if not skipped:
        return ""
    lines = "\n".join(f"- `{name}`: {reason}" for name, reason in skipped.items())
    return f"\n**Skipped** (not in the table above):\n{lines}\n"


def comparison_notes(env_id: str, table: dict) -> str:
    """Markdown of the learned rows' probability of improvement and training cost, after the tables."""
    from continuum_gym.evaluation.comparison import comparison_markdown

    text = comparison_markdown(get_spec(env_id), table)
    return f"\n{text}" if text else ""


def parse_env_kwargs(text: str | None) -> dict:
    """The ``--env-kwargs`` JSON object, or a named error."""
    if text is None:
        return {}
    try:
        value = json.loads(text)
    except json.JSONDecodeError as error:
        raise ValueError(f"--env-kwargs: not valid JSON ({error})") from error
    if not isinstance(value, dict):
        raise ValueError(f"--env-kwargs: expected a JSON object of env keyword arguments, got {type(value).__name__}")
    return value


def run(args: argparse.Namespace) -> int:
    try:
        env_ids = list(args.env or ENV_SPECS)
        for env_id in env_ids:
            get_spec(env_id)
        check_sizes(args.episodes, args.grid)
        env_kwargs = parse_env_kwargs(args.env_kwargs)
        if (args.policy or env_kwargs) and len(env_ids) != 1:
            raise ValueError("--policy and --env-kwargs need one environment: pass --env <id>")
        if args.model_error:  # a physics keyword of every env and method (its table notes it)
            env_kwargs["model_error"] = args.model_error
        for env_id in env_ids:
            split_env_kwargs(get_spec(env_id), env_kwargs)
        unusable: dict = {}
        policies = discover_policies(args.policies, unusable)
        extra = []
        if args.policy:
            from continuum_gym.envs.helpers import check_helpers, row_name
            from continuum_gym.evaluation.policies import as_predictor, load_entry_point

            helpers = check_helpers(env_ids[0], args.helpers)
            extra = [(row_name(args.name, helpers), [MethodRun(as_predictor(load_entry_point(args.policy), args.name,
                                                                            args.policy), {}, args.policy,
                                                               helpers=helpers)])]
        elif args.helpers:
            raise ValueError("--helpers acts after --policy: pass --policy MODULE:FUNCTION")
    except (ValueError, TypeError, FileNotFoundError) as error:
        print(f"continuum-gym evaluate: {error}", file=sys.stderr)
        return 2
    from continuum_gym.evaluation.figures import draw

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    summary, meta, report = {}, {}, []
    for env_id in env_ids:
        table, results, meta[env_id] = evaluate_methods(
            env_id, extra, policies, env_kwargs=env_kwargs, episodes=args.episodes, grid=args.grid,
            split=args.split, progress=not args.no_progress, pixel_metrics=args.pixel_metrics)
        summary[env_id] = table
        meta[env_id]["skipped"] = {**unusable, **meta[env_id].get("skipped", {})}
        report.append(markdown(env_id, table, results) + model_error_note(env_kwargs) + comparison_notes(env_id, table)
                      + skipped_notes(meta[env_id]["skipped"]))
        for path in draw(env_id, results, table, policies, out, args.split):
            print(f"wrote {path}")
    seconds = time.perf_counter() - started
    print("\n".join(report) + f"\nEvaluation wall time: {seconds:.0f} s\n")
    for path in write_results(out, summary, meta, report, args.json, seconds):
        print(f"wrote {path}")
    return 0
