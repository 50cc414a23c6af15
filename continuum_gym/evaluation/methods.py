"""The methods ``continuum-gym evaluate`` compares: analytic baselines, trained runs found on disk, a user's policy.

A method is a row of the tables and a list of runs (``MethodRun``: a policy, the env keywords it acts with and
the helpers that act after it). Its name says what acts (docs/protocol.md): ``projected_gradient`` (a base with a
zero residual), ``residual_arc_plan`` (a residual trained on the ``arc_plan`` base), ``pure_rl``, an algorithm
other than PPO as a suffix (``residual_dimension_reduced_sac``) and each helper after a ``+``
(``residual_dimension_reduced+overlap_polish``). A learned row that runs with helpers gets its base beside it with
the same helpers and a zero residual (``dimension_reduced+overlap_polish``), and itself without them, so that the
table shows what learning adds and what the helper adds.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from continuum_gym.envs.benchmark import benchmark_of
from continuum_gym.envs.helpers import row_name
from continuum_gym.envs.obs_modes import OBSERVATION_KEYWORDS
from continuum_gym.envs.spec import EnvSpec, registered_base

if TYPE_CHECKING:
    from stable_baselines3.common.base_class import BaseAlgorithm

POLICY_DIR = Path(__file__).resolve().parents[1] / "agents" / "policies"


@dataclass
class MethodRun:
    """One run (training seed) of a method: its policy (None: the analytic baseline) and its env keywords."""

    policy: Any
    env_kwargs: dict
    source: str | None = None  #: the policy's file or entry point (named when it fails)
    algo: str | None = None  #: the algorithm that trained it (``ppo``, ``sac``, ``td3``), if known
    #: the helpers that act after the policy, in order (``envs/helpers.py``): the run's ``config.yml`` names them
    helpers: tuple = field(default=())


def _config_files(directory: Path) -> list[Path]:
    """Every ``config.yml`` under ``directory``, through symbolic links too (a folder of links to chosen runs
    is a common way to evaluate a selection; ``Path.rglob`` skips linked folders before Python 3.13). A
    folder reached twice, e.g. by a link cycle, is read once."""
    found, seen = [], set()
    for root, dirs, files in os.walk(directory, followlinks=True):
        real = os.path.realpath(root)
        if real in seen:
            dirs[:] = []
            continue
        seen.add(real)
        if "config.yml" in files:
            found.append(Path(root) / "config.yml")
    return sorted(found)


def discover_policies(directory: str | Path, skipped: dict | None = None) -> dict[str, dict[str, list[Path]]]:
    """{env_id: {method: [run dirs]}} from ``<dir>/**/config.yml`` + ``model.zip``.

    A run whose ``config.yml`` is unreadable, names no env or has no ``model.zip`` beside it is reported
    on stderr and in ``skipped`` ({run: reason}); the other runs are still found. A directory that holds
    no run at all is a warning: only the baselines (and ``--policy``) are evaluated then.
    """
    import yaml

    found: dict[str, dict[str, list[Path]]] = {}
    skipped = {} if skipped is None else skipped
    directory = Path(directory)
    if not directory.is_dir():
        raise FileNotFoundError(f"--policies: no directory {directory}")
    for config_path in _config_files(directory):
        run = config_path.parent
        try:
            if not (run / "model.zip").is_file():
                raise ValueError("config.yml but no model.zip")
            config = read_run_config(run, yaml.safe_load(config_path.read_text()))
        except (OSError, ValueError, yaml.YAMLError) as error:
            skipped[str(run)] = str(error).splitlines()[0]
            print(f"continuum-gym evaluate: skipping {run}: {skipped[str(run)]}", file=sys.stderr)
            continue
        env_config = config.get("env_config") or config.get("env_kwargs") or {}
        method = method_name(config.get("base_controller"), config.get("algo"), config.get("helpers") or (),
                             env_config.get("obs_mode"))
        found.setdefault(config["env_id"], {}).setdefault(method, []).append(run)
    if not found and not skipped:
        print(f"continuum-gym evaluate: warning: --policies {directory} holds no trained run (config.yml + "
              "model.zip); evaluating the baselines only", file=sys.stderr)
    return found


def sb3_algo(policy: Any) -> str | None:
    """``ppo``, ``sac`` or ``td3`` for a stable-baselines3 model of those classes, else None."""
    name = type(policy).__name__.lower()
    return name if name in ("ppo", "sac", "td3") and hasattr(policy, "predict") else None


def method_name(base: str | None, algo: str | None, helpers: tuple | list = (), obs_mode: str | None = None) -> str:
    """A learned method's row: ``residual_<base>`` / ``pure_rl`` for PPO (the headline rows), else with
    ``_<algo>`` appended (``residual_<base>_sac``, ``pure_rl_td3``); a policy that sees images has its
    ``obs_mode`` appended (``residual_projected_gradient_rgbd``, ``+`` as ``_``); its helpers after ``+``."""
    from continuum_gym.plugins import split_reference

    name = f"residual_{split_reference(base)[1]}" if base else "pure_rl"
    name = name if algo in (None, "ppo") else f"{name}_{algo}"
    name = name if obs_mode in (None, "state") else f"{name}_{str(obs_mode).replace('+', '_')}"
    return row_name(name, helpers)


def read_run_config(run: str | Path, config: Any) -> dict:
    """A run's ``config.yml`` (as loaded) checked, and a 0.2 run's options read as the parts they became.

    0.2 ran two research aids as env options; 0.3 names them (CHANGELOG): ``arc_plan: true`` is the base
    ``arc_plan`` (a run trained with it loads as ``residual_arc_plan``), ``overlap_polish`` the helper
    ``overlap_polish``. Other keys are returned as they are.
    """
    if not isinstance(config, dict) or "env_id" not in config:
        raise ValueError("config.yml is empty or names no env_id")
    config = dict(config)
    blocks = [key for key in ("env_kwargs", "env_config") if isinstance(config.get(key), dict)]
    planned = any(config[key].get("arc_plan") for key in blocks)
    polished = any(config[key].get("overlap_polish") is not None for key in blocks)
    for key in blocks:
        config[key] = {k: v for k, v in config[key].items() if k not in ("arc_plan", "overlap_polish")}
        if planned:
            config[key]["base_controller"] = "arc_plan"
    if planned:
        config["base_controller"] = "arc_plan"
    if polished and "overlap_polish" not in (config.get("helpers") or ()):
        config["helpers"] = [*(config.get("helpers") or ()), "overlap_polish"]
    hyper = config.get("hyperparams")
    if isinstance(hyper, dict) and isinstance(hyper.get("env_kwargs"), dict):
        config["hyperparams"] = {**hyper, "env_kwargs": {k: v for k, v in hyper["env_kwargs"].items()
                                                         if k not in ("arc_plan", "overlap_polish")}}
    helpers = config.get("helpers")
    if helpers is not None and (not isinstance(helpers, list) or not all(isinstance(h, str) for h in helpers)):
        raise ValueError(f"config.yml of {run}: helpers must be a list of helper names; got {helpers!r}")
    return config


def load_policy(run: Path) -> tuple[BaseAlgorithm, dict[str, Any]]:
    """(SB3 model, its run's config dict) of a run directory."""
    import yaml
    from stable_baselines3 import PPO, SAC, TD3

    config = read_run_config(run, yaml.safe_load((Path(run) / "config.yml").read_text()))
    algorithms: dict[str, type[BaseAlgorithm]] = {"ppo": PPO, "sac": SAC, "td3": TD3}
    if config.get("algo") not in algorithms:
        raise ValueError(f"policy {run}: algo must be one of {sorted(algorithms)}, got {config.get('algo')!r}")
    return algorithms[config["algo"]].load(run / "model.zip", device="cpu"), config


def policy_env_kwargs(spec: EnvSpec, config: dict) -> dict:
    """The env keywords of a run's config that define how its policy acts (``spec.policy_keys``).

    Runs write their full env config (``env_config``); older runs only their keyword arguments
    (``env_kwargs``). Task keywords are not taken: every method runs on the same test tasks.
    """
    source = config.get("env_config") or config.get("env_kwargs") or {}
    # what the policy acts on (its benchmark's policy_keys) and what it sees (obs_mode, image_size)
    keys = (*benchmark_of(spec).policy_keys, *OBSERVATION_KEYWORDS)
    picked = {key: value for key, value in source.items() if key in keys}
    spec.config_class.from_kwargs(**picked)  # the same checks as the env's: a broken config fails here, named
    return picked


def split_env_kwargs(spec: EnvSpec, env_kwargs: dict | None) -> tuple[dict, dict, dict]:
    """(environment, policy, ignored) keywords of ``env_kwargs``.

    The environment part (robot, cone, limits, timing, rewards) is the env every method runs in; the
    policy part (``spec.policy_keys``: base controller, residual scale and space, ...) only the evaluated
    policy's; task, split and grid are set by the protocol and recorded as ignored.
    """
    from continuum_gym.evaluation.benchmark import PROTOCOL_KEYS

    env_kwargs = dict(env_kwargs or {})
    try:  # named errors before anything runs
        spec.config_class.from_kwargs(**env_kwargs)
    except ValueError as error:
        raise type(error)(f"env_kwargs (--env-kwargs): {error}") from None
    ignored = {k: env_kwargs.pop(k) for k in PROTOCOL_KEYS if k in env_kwargs}
    keys = (*benchmark_of(spec).policy_keys, *OBSERVATION_KEYWORDS)
    policy = {k: env_kwargs.pop(k) for k in list(env_kwargs) if k in keys}
    return env_kwargs, policy, ignored


def baseline_methods(spec: EnvSpec, own: list | tuple = ()) -> list:
    """[(baseline, [MethodRun])] in table order: the residual env with a zero residual is the baseline.

    ``own``: registered controllers (names or ``"module:name"``) that get a row of their own after the
    built-in baselines, named by the controller (a residual trained on one is ``residual_<name>``).
    """
    from continuum_gym.plugins import split_reference

    names = list(spec.baselines)
    rows = [(base, [MethodRun(None, {"base_controller": base})]) for base in spec.baselines]
    for reference in own:
        name = split_reference(reference)[1]
        if name not in names:
            names.append(name)
            rows.append((name, [MethodRun(None, {"base_controller": reference})]))
    return rows


def own_bases(spec: EnvSpec, env_id: str, methods: list, environment: dict | None = None) -> list:
    """The registered controllers in play: the env's packaged bases (fitted to the paper's robots: only when
    ``environment`` changes none of ``spec.physics``), the id's own base and those the learned methods were
    trained on."""
    nominal = not any(key in (environment or {}) for key in benchmark_of(spec).physics)
    candidates = [*(spec.config_class.packaged_controllers if nominal else ()), registered_base(env_id)]
    candidates += [run.env_kwargs.get("base_controller") for _, runs in methods for run in runs]
    return [c for c in dict.fromkeys(candidates) if isinstance(c, str) and c not in spec.baselines]


def trained_bases(methods: list) -> dict:
    """{method: its base's row name} of each method whose runs say what they were trained on: the base
    controller with the run's helpers (``dimension_reduced+overlap_polish``)."""
    from continuum_gym.plugins import split_reference

    out = {}
    for name, runs in methods:
        base = runs[0].env_kwargs.get("base_controller") if runs else None
        if isinstance(base, str):
            out[name] = row_name(split_reference(base)[1], runs[0].helpers)
    return out


def beside_rows(methods: list) -> tuple[list, list]:
    """The rows a learned method with helpers needs beside it: its base with the same helpers and a zero residual
    (the first run's policy keywords: the helper's reach depends on the residual scale), and the method without
    its helpers: (bases, ablations). Rows already in ``methods`` are not repeated."""
    from continuum_gym.plugins import split_reference

    names = {name for name, _ in methods}
    bases: list = []
    ablations: list = []
    for name, runs in methods:
        if not runs or not runs[0].helpers:
            continue
        first = runs[0]
        base = first.env_kwargs.get("base_controller")
        plain = name.split("+", 1)[0]
        if isinstance(base, str):
            row = row_name(split_reference(base)[1], first.helpers)
            if row not in names:
                names.add(row)
                bases.append((row, [MethodRun(None, dict(first.env_kwargs), helpers=first.helpers)]))
        if plain not in names:
            names.add(plain)
            ablations.append((plain, [MethodRun(run.policy, run.env_kwargs, run.source, run.algo) for run in runs]))
    return bases, ablations


def discovered_methods(spec: EnvSpec, policies: dict, skipped: dict, env_id: str | None = None) -> list:
    """[(method, [MethodRun])] of the SB3 runs found by :func:`discover_policies` for ``env_id`` (``spec``'s env).

    A run that cannot be loaded is reported on stderr and in ``skipped`` ({run: reason}), not fatal.
    """
    out = []
    for method, runs in sorted(policies.get(env_id or spec.env_id, {}).items()):
        entries = []
        for run in runs:
            try:
                model, config = load_policy(run)
                entries.append(MethodRun(model, policy_env_kwargs(spec, config), str(Path(run) / "model.zip"),
                                         config.get("algo"), tuple(config.get("helpers") or ())))
            except Exception as error:  # noqa: BLE001 - any broken run is reported and skipped, the rest runs
                skipped[str(run)] = f"{type(error).__name__}: {error}"
                print(f"continuum-gym evaluate: skipping {run}: {error}", file=sys.stderr)
        if entries:
            out.append((method, entries))
    return out


