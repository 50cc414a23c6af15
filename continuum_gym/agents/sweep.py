"""``continuum-gym sweep``: multi-seed training and hyperparameter search on Ray Tune.

Each trial is one ``continuum-gym train`` run (the same ``train()``: same checkpoints, resume and saved
config) in its own directory under ``<out>/trials/``. Ray Tune schedules the trials: a local
``ray.init()`` by default, an existing cluster with ``--address`` or ``RAY_ADDRESS`` (see
``connect()``: token authentication and plug-ins on a cluster). A trial whose worker
dies is retried and resumes from its last checkpoint; an interrupted sweep resumes with ``--resume``
(Tune's restore) without re-running finished trials. Nothing is overwritten.

Search space YAML (every key must be a hyperparameter of the algorithm's block, checked before anything
starts)::

    method: grid            # or random
    num_samples: 1          # random: configurations drawn; grid: repeats of the grid
    scheduler: none         # or asha (early stopping on the held-out metric)
    asha: {grace_period: 2, reduction_factor: 2}   # in evaluations
    space:
      learning_rate: {grid: [1.0e-4, 3.0e-4]}       # or {choice: [...]}, {uniform: [lo, hi]}, {loguniform: [lo, hi]}
      residual_scale: {grid: [0.3, 0.5]}
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import socket
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from continuum_gym.agents.cluster import connect
from continuum_gym.agents.run_inputs import hyperparams_file, output_directory, seed_number, whole_number
from continuum_gym.agents.train import (
    ALGOS,
    check_steps,
    default_base,
    headline_metric,
    load_hyperparams,
    run_name,
    train,
    validate,
)
from continuum_gym.envs.spec import ENV_SPECS, get_spec
from continuum_gym.evaluation.io import write_json_atomic, write_text_atomic
from continuum_gym.evaluation.statistics import summarize
from continuum_gym.plugins import ENV_VAR as PLUGINS_VAR
from continuum_gym.validation import number

INSTALL_HINT = "Ray Tune is an optional extra: pip install 'continuum-gym[sweep]' (or pip install 'ray[tune]')"
SPACE_KINDS = ("grid", "choice", "uniform", "loguniform")
SEARCH_KEYS = ("method", "num_samples", "scheduler", "asha", "space")
# Keys a search may vary besides the algorithm's own (they are read by train()).
TRAINER_KEYS = ("residual_scale", "burn_in_steps", "n_envs", "n_timesteps", "normalize_reward")


def load_search(path: Path | str, algo: str, env_id: str) -> dict:
    """Parse and validate a search-space YAML; unknown keys raise ``ValueError`` naming them."""
    if not Path(path).is_file():
        raise ValueError(f"--search must be a search-space YAML file; {str(path)!r} does not exist")
    spec = yaml.safe_load(Path(path).read_text()) or {}
    unknown = set(spec) - set(SEARCH_KEYS)
    if unknown:
        raise ValueError(f"search file {path}: unknown keys {sorted(unknown)}; valid: {list(SEARCH_KEYS)}")
    method = spec.get("method", "grid")
    if method not in ("grid", "random"):
        raise ValueError(f"search method must be 'grid' or 'random'; got {method!r}")
    scheduler = spec.get("scheduler", "none")
    if scheduler not in ("none", "asha"):
        raise ValueError(f"scheduler must be 'none' or 'asha'; got {scheduler!r}")
    valid = set(load_hyperparams(algo, env_id)) | set(TRAINER_KEYS)
    space = spec.get("space") or {}
    for key, entry in space.items():
        if key not in valid:
            raise ValueError(f"search space key {key!r} is not a hyperparameter of {algo} for {env_id}; "
                             f"valid: {sorted(valid)}")
        if not isinstance(entry, dict) or len(entry) != 1 or next(iter(entry)) not in SPACE_KINDS:
            raise ValueError(f"search space {key!r} must be one of {{kind: values}} with kind in {list(SPACE_KINDS)}")
        kind, values = next(iter(entry.items()))
        if method == "random" and kind == "grid":
            raise ValueError(f"{key!r}: 'grid' needs method: grid")
    return {"method": method, "num_samples": int(spec.get("num_samples", 1)), "scheduler": scheduler,
            "asha": dict(spec.get("asha") or {}), "space": space}


def tune_space(search: dict, seeds: Iterable[int]) -> dict[str, Any]:
    from ray import tune

    space: dict[str, Any] = {}
    for key, entry in search["space"].items():
        kind, values = next(iter(entry.items()))
        if kind == "grid":
            space[key] = tune.grid_search(list(values))
        elif kind == "choice":
            space[key] = tune.choice(list(values))
        elif kind == "uniform":
            space[key] = tune.uniform(*values)
        else:
            space[key] = tune.loguniform(*values)
    space["seed"] = tune.grid_search(list(seeds))
    return space


def trial_tag(config: dict) -> str:
    """A stable directory name for a trial's configuration (the same after a restore or a retry)."""
    items = {k: config[k] for k in sorted(config) if k != "seed"}
    digest = hashlib.sha1(json.dumps(items, sort_keys=True, default=float).encode()).hexdigest()[:8]
    return f"cfg{digest}_seed{config['seed']}"


def run_trial(config: dict[str, Any], env_id: str, algo: str, base: str | None, steps: int | None,
              out: Path | str, hp_file: Path | str | None,
              report: Callable[[int, float], None] | None = None) -> Path:
    """One trial = one ``train()`` run with the trial's overrides; resumes if its checkpoint exists."""
    overrides = {k: v for k, v in config.items() if k != "seed"}
    trial_dir = Path(out) / "trials" / trial_tag(config)
    trial_dir.mkdir(parents=True, exist_ok=True)
    block = load_hyperparams(algo, env_id, hp_file)
    block.update(overrides)
    hyperparams = trial_dir / "hyperparams.yml"
    write_text_atomic(hyperparams, yaml.safe_dump({env_id: block}, sort_keys=False))
    run_dir = trial_dir / run_name(env_id, algo, base, int(config["seed"]), block.get("helpers") or (),
                                   (block.get("env_kwargs") or {}).get("obs_mode"))
    if (run_dir / "model.zip").exists():
        return run_dir  # finished before an interruption
    # A retried trial continues from its newest intact checkpoint, or starts again if it had none.
    return train(env_id, algo, base, int(config["seed"]), steps=steps, out=trial_dir, resume=run_dir.exists(),
                 hyperparams=hyperparams, progress=False, report=report)


def _trainable(env_id, algo, base, steps, out, hp_file, plugin_modules=()):
    def trainable(config):
        from ray import tune

        # A trial's worker (on any node) has not run the user's registrations: import their modules first
        # (an env id's lookup does not import them on a miss), and pass them on to the worker's own children.
        from continuum_gym import plugins

        what = f"on the Ray node {socket.gethostname()}, the sweep's plug-in module"
        for module in plugins.import_modules(plugin_modules, what):
            plugins.remember(module.__name__)
        metric = headline_metric(env_id)

        def report(timesteps, value):
            tune.report({"timesteps": timesteps, metric: value})

        run_trial(config, env_id, algo, base, steps, out, hp_file, report=report)

    return trainable


def check_sweep_arguments(seeds: Sequence[int], steps: float | None, cpus_per_trial: float,
                          out: Path | str) -> tuple[list[int], int | None, float]:
    """(seeds, steps, cpus_per_trial) validated and ``out`` checked, else ``ValueError`` (``load_search``
    checks the search file)."""
    if not isinstance(seeds, (list, tuple)) or not seeds:
        raise ValueError(f"seeds must be a non-empty list of whole numbers >= 0; got {seeds!r}")
    seeds = [seed_number("seeds", seed) for seed in seeds]
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds must be distinct; got {seeds}")
    steps = None if steps is None else whole_number("steps", steps)
    cpus = number(cpus_per_trial, "cpus_per_trial", low=0.0, high=1024.0, low_open=True)
    output_directory("out", out)
    return seeds, steps, cpus


def plugin_modules() -> list[str]:
    """The plug-in modules this process knows of (``CONTINUUM_GYM_PLUGINS``): every trial imports them."""
    return [m.strip() for m in os.environ.get(PLUGINS_VAR, "").split(",") if m.strip()]


def trial_runtime_env() -> dict:
    """What every trial's worker needs to rebuild the user's plug-ins: ``CONTINUUM_GYM_PLUGINS`` and this
    process's ``PYTHONPATH`` entries (ahead of the node's own), when set. A worker of a cluster does not inherit
    this process's environment; the modules must be importable on its node."""
    env_vars = {}
    plugins = plugin_modules()
    if plugins:
        env_vars[PLUGINS_VAR] = ",".join(plugins)
        paths = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
        if paths:
            env_vars["PYTHONPATH"] = os.pathsep.join([*paths, "${PYTHONPATH}"])
    return {"env_vars": env_vars} if env_vars else {}


def sweep(env_id: str, algo: str, base: str | None, seeds: Sequence[int], steps: float | None = None,
          search: Path | str | None = None, address: str | None = None, cpus_per_trial: float = 1,
          out: Path | str = "sweeps", resume: bool = False, name: str | None = None,
          hyperparams: Path | str | None = None, max_failures: int = 2) -> dict:
    """Run the sweep; returns the results summary (also written to ``<out>/<name>/``).

    Every argument is checked before Ray starts: ``ValueError`` naming the parameter and its range.
    """
    validate(env_id, algo, base)
    seeds, steps, cpus_per_trial = check_sweep_arguments(seeds, steps, cpus_per_trial, out)
    search_spec: dict[str, Any] = load_search(search, algo, env_id) if search else {
        "method": "grid", "num_samples": 1, "scheduler": "none", "asha": {}, "space": {}}
    if not {"burn_in_steps", "learning_starts", "n_timesteps"} & set(search_spec["space"]):  # else per trial
        check_steps(algo, env_id, base, steps, hyperparams)
    try:
        import ray
        from ray import tune
    except ImportError as error:
        raise RuntimeError(INSTALL_HINT) from error
    name = name or f"{env_id.split('/')[-1].split('-')[0]}_{algo}_{base or 'pure_rl'}"
    sweep_dir = Path(out).resolve() / name
    experiment = sweep_dir / "tune"
    if sweep_dir.exists() and any(sweep_dir.iterdir()) and not resume:
        raise FileExistsError(f"{sweep_dir} exists; pass --resume to continue it (nothing is overwritten)")
    hp_file = hyperparams_file(hyperparams).resolve() if hyperparams else None
    metric = headline_metric(env_id)
    mode = "max" if get_spec(env_id).metric(metric).higher_is_better else "min"
    connect(address or os.environ.get("RAY_ADDRESS") or None, trial_runtime_env())
    sweep_dir.mkdir(parents=True, exist_ok=True)
    try:
        return _fit(tune, env_id, algo, base, seeds, steps, search_spec, cpus_per_trial, resume, sweep_dir,
                    experiment, hp_file, metric, mode, max_failures)
    finally:
        ray.shutdown()


def _fit(tune, env_id, algo, base, seeds, steps, search_spec, cpus_per_trial, resume, sweep_dir, experiment, hp_file,
         metric, mode, max_failures) -> dict:
    trainable = tune.with_resources(_trainable(env_id, algo, base, steps, sweep_dir, hp_file, plugin_modules()),
                                    {"cpu": cpus_per_trial})
    if resume and tune.Tuner.can_restore(str(experiment)):
        tuner = tune.Tuner.restore(str(experiment), trainable, resume_errored=True)
    else:
        scheduler = None
        if search_spec["scheduler"] == "asha":
            from ray.tune.schedulers import ASHAScheduler

            scheduler = ASHAScheduler(time_attr="training_iteration", **search_spec["asha"])
        tuner = tune.Tuner(
            trainable,
            param_space=tune_space(search_spec, seeds),
            tune_config=tune.TuneConfig(metric=metric, mode=mode, scheduler=scheduler,
                                        num_samples=search_spec["num_samples"]),
            run_config=tune.RunConfig(name="tune", storage_path=str(sweep_dir),
                                      failure_config=tune.FailureConfig(max_failures=max_failures)),
        )
    results = tuner.fit()
    return summarise(results, metric, mode, env_id, algo, sweep_dir, hp_file)


def summarise(results: Iterable[Any], metric: str, mode: str, env_id: str, algo: str, sweep_dir: Path,
              hp_file: Path | str | None = None) -> dict:
    """Per-trial table, per-configuration statistics over seeds, best config in the trainer's YAML format.

    ``results`` is Ray Tune's ``ResultGrid`` (or any iterable of its ``Result``s).
    """
    rows: list[dict[str, Any]] = []
    for result in results:
        if result.config is None:
            # a trial that never started before the sweep was interrupted (Ray reports it without a config);
            # `--resume` runs it
            rows.append({"config": {}, "seed": None, metric: None, "timesteps": None,
                         "error": "not started: the sweep was interrupted (continue with --resume)"})
            continue
        config = dict(result.config)
        value = (result.metrics or {}).get(metric)
        rows.append({"config": config, "seed": config.get("seed"), metric: value,
                     "timesteps": (result.metrics or {}).get("timesteps"), "error": repr(result.error) if result.error
                     else None})
    groups: dict[str, list[float]] = {}
    for row in rows:
        key = json.dumps({k: v for k, v in row["config"].items() if k != "seed"}, sort_keys=True, default=float)
        if row[metric] is not None:
            groups.setdefault(key, []).append(row[metric])
    aggregated = {key: summarize(np.asarray(values)[:, None]) for key, values in groups.items()}
    best = None
    if aggregated:
        best = (min if mode == "min" else max)(aggregated, key=lambda k: aggregated[k]["mean"])
        block = load_hyperparams(algo, env_id, hp_file)
        block.update(json.loads(best))
        write_text_atomic(sweep_dir / "best_hyperparams.yml", yaml.safe_dump({env_id: block}, sort_keys=False))
    lines = [f"| trial config | seed | {metric} | timesteps | error |", "|---|---|---|---|---|"]
    for row in rows:
        cfg = {k: v for k, v in row["config"].items() if k != "seed"} or "(defaults)"
        value = "-" if row[metric] is None else f"{row[metric]:.4f}"
        lines.append(f"| {cfg} | {row['seed']} | {value} | {row['timesteps']} | {row['error'] or ''} |")
    lines += ["", f"| config | {metric} mean [95 % CI] over seeds | seeds |", "|---|---|---|"]
    for key, stats in aggregated.items():
        lines.append(f"| {key} | {stats['mean']:.4f} [{stats['ci_low']:.4f}, {stats['ci_high']:.4f}] | "
                     f"{stats['n_runs']} |")
    table = "\n".join(lines) + "\n"
    write_text_atomic(sweep_dir / "sweep_results.md", table)
    summary = {"metric": metric, "mode": mode, "trials": rows, "per_config": aggregated,
               "best_config": json.loads(best) if best else None, "time": time.time()}
    write_json_atomic(sweep_dir / "sweep_results.json", summary)
    print(table)
    return summary


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", required=True, help=f"environment id: {sorted(ENV_SPECS)}")
    parser.add_argument("--algo", default="ppo", help=f"one of {list(ALGOS)}")
    parser.add_argument("--base", default=None, help="base controller, or 'none' for pure RL")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="seeds: one trial per seed and config")
    parser.add_argument("--steps", type=float, default=None, help="environment steps per trial")
    parser.add_argument("--search", default=None, help="search-space YAML (see the module docstring)")
    parser.add_argument("--address", default=None, help="Ray cluster address (default: RAY_ADDRESS or local)")
    parser.add_argument("--cpus-per-trial", type=float, default=1.0)
    parser.add_argument("--out", default="sweeps", help="parent directory of sweeps")
    parser.add_argument("--name", default=None, help="sweep name (default: env_algo_base)")
    parser.add_argument("--resume", action="store_true", help="continue an interrupted sweep")
    parser.add_argument("--hyperparams", default=None, help="YAML keyed by env id (default: the packaged one)")


def run(args: argparse.Namespace) -> int:
    base = None if (args.base or "").lower() == "none" else (args.base or _default_base(args.env))
    try:
        validate(args.env, args.algo, base)
        if args.search:
            load_search(args.search, args.algo, args.env)
        summary = sweep(args.env, args.algo, base, args.seeds, steps=args.steps, search=args.search,
                        address=args.address, cpus_per_trial=args.cpus_per_trial, out=args.out, resume=args.resume,
                        name=args.name, hyperparams=args.hyperparams)
    except (ValueError, FileExistsError, FileNotFoundError, RuntimeError) as error:
        print(f"continuum-gym sweep: {error}", file=sys.stderr)
        return 2
    failed = [trial for trial in summary["trials"] if trial["error"]]
    if failed:
        print(f"continuum-gym sweep: {len(failed)} of {len(summary['trials'])} trials failed; their errors are in "
              f"sweep_results.md (--resume retries them). First: {failed[0]['error']}", file=sys.stderr)
        return 1
    return 0


def _default_base(env_id: str):
    """The base ``continuum-gym train`` uses: a registered id's own controller, else the headline baseline."""
    try:
        return default_base(env_id)
    except ValueError:
        return None  # validate() reports the unknown id
