"""Which function computes an environment's offline optimum, by env id (the reference rows of its tables).

``register_optimum(env_id, fn)`` files ``fn(config, *, episodes, grid, split, progress, workers) -> dict``, keyed
by the cache keys of the env's ``Benchmark.references``; a researcher's environment registers its own from its
package. The library's two are filed here, so that no environment reaches up to the evaluation layer.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

#: env id -> the function that computes its optimum cache
OPTIMA: dict[str, Callable[..., dict]] = {}


def register_optimum(env_id: str, function: Callable[..., dict]) -> None:
    """File how ``env_id``'s offline optimum is computed (``continuum-gym optimum``, the evaluation's reference rows)."""
    if not callable(function):
        raise ValueError(f"function must be callable as fn(config, *, episodes, grid, split, progress, workers); got "
                         f"{type(function).__name__}")
    OPTIMA[env_id] = function


def optimum_of(env_id: str) -> Callable[..., dict] | None:
    """The function that computes ``env_id``'s optimum, or None (no optimum is known for it)."""
    _builtin()
    return OPTIMA.get(env_id)


def _occlusion(config: Any, **kwargs: Any) -> dict:
    from continuum_gym.evaluation.optimum.occlusion import env_optimum

    return env_optimum(config, **kwargs)


def _view(config: Any, **kwargs: Any) -> dict:
    from continuum_gym.evaluation.optimum.view import env_optimum

    return env_optimum(config, **kwargs)


def _builtin() -> None:
    from continuum_gym.envs.occlusion.spec import ENV_ID as OCCLUSION
    from continuum_gym.envs.view_tracking.spec import ENV_ID as VIEW

    OPTIMA.setdefault(OCCLUSION, _occlusion)
    OPTIMA.setdefault(VIEW, _view)


__all__ = ["OPTIMA", "register_optimum", "optimum_of"]
