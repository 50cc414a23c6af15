"""The versioned benchmark protocol: what every evaluation runs, so that results from two labs compare.

``benchmark v1`` fixes, per environment id (see ``docs/protocol.md``):

* the task sets and their instance ids: for split ``test`` every task set of the spec (the papers'
  fixed tasks only here), for ``validation`` those drawn from the validation family (the fixed tasks
  have no validation instances). Instance ``k`` of a set is task id ``k`` of that split, ids
  ``0 .. episodes - 1`` (``grid**2`` for a grid set, one for a fixed task);
* the seeds: task instances are a pure function of (family, split, id); the policy acts
  deterministically; a method with several trained runs contributes one row per run ("seed");
* the metrics (the spec's, reduced per episode as ``EnvSpec.episode_metrics`` says) and the
  aggregation: mean and IQM with 95 % stratified-bootstrap CIs (rliable, 2000 resamples, seed 0) over
  runs x episodes of all non-grid task sets; grid metrics as a percentage over grid points;
* the reference rows: the offline optimum on the same instances, and ``headroom_closed`` against the
  env's headline baseline.

A change to any of these bumps :data:`PROTOCOL_VERSION`; every JSON result records it with the package
version, the git revision and the env keyword arguments.
"""

from __future__ import annotations

import platform
import subprocess
from pathlib import Path

from continuum_gym.envs.benchmark import TaskSet, benchmark_of
from continuum_gym.envs.config import TASK_SPLITS
from continuum_gym.envs.spec import EnvSpec

PROTOCOL_VERSION = "benchmark-v1"
#: Splits an evaluation may run on: ``validation`` for model selection, ``test`` for final numbers only.
EVALUATION_SPLITS = ("validation", "test")
#: Env keywords the protocol sets itself; a caller's values for them are recorded as ignored.
PROTOCOL_KEYS = ("task", "task_split", "grid")


def task_sets(spec: EnvSpec, split: str) -> tuple[TaskSet, ...]:
    """The task sets of ``split`` for ``spec``'s environment (see the module docstring)."""
    if split not in EVALUATION_SPLITS:
        raise ValueError(f"split must be one of {list(EVALUATION_SPLITS)} (train tasks are for training), "
                         f"got {split!r}")
    if split == "test":
        return benchmark_of(spec).task_sets
    test_only = set(spec.config_class.test_only_tasks)
    return tuple(t for t in benchmark_of(spec).task_sets if t.task not in test_only)


def episode_count(task_set: TaskSet, episodes: int, grid: int) -> int:
    """How many instances of ``task_set`` an evaluation with ``episodes`` and ``grid`` runs."""
    return grid * grid if task_set.grid else (task_set.episodes or episodes)


def git_revision() -> str | None:
    """The git revision of the package's checkout (with ``-dirty`` if modified), or None (installed wheel)."""
    root = Path(__file__).resolve().parents[2]
    if not (root / ".git").exists():
        return None
    try:
        revision = subprocess.run(["git", "-C", str(root), "describe", "--always", "--dirty", "--abbrev=40"],
                                  capture_output=True, text=True, timeout=10, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return revision or None


def metadata(spec: EnvSpec, split: str, episodes: int, grid: int, env_kwargs: dict, ignored: dict | None = None,
             methods: dict | None = None) -> dict:
    """What a JSON result records beside the table so that it can be compared and reproduced."""
    import continuum_gym

    sets = task_sets(spec, split)
    return {
        "protocol": PROTOCOL_VERSION,
        "package_version": continuum_gym.__version__,
        "git_revision": git_revision(),
        "python": platform.python_version(),
        "env_id": spec.env_id,
        "split": split,
        "episodes": int(episodes),
        "grid": int(grid),
        "task_sets": {t.task: {"instances": episode_count(t, episodes, grid), "grid": t.grid} for t in sets},
        "env_kwargs": _plain(env_kwargs),
        "ignored_env_kwargs": _plain(ignored or {}),
        "methods": methods or {},
    }


def _plain(kwargs: dict) -> dict:
    """JSON-able keyword values (objects such as robots by their repr)."""
    out = {}
    for key, value in kwargs.items():
        out[key] = value if isinstance(value, (int, float, str, bool, type(None), list, tuple, dict)) else repr(value)
    return out


__all__ = ["PROTOCOL_VERSION", "EVALUATION_SPLITS", "PROTOCOL_KEYS", "TASK_SPLITS", "task_sets", "episode_count",
           "git_revision", "metadata"]
