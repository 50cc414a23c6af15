"""Names that moved into the environments' own packages, still importable from where users found them.

``from continuum_gym.envs.spec import OCCLUSION_SPEC`` keeps working: the old module's ``__getattr__``
looks the name up here and imports it from its new home.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

OCCLUSION = "continuum_gym.envs.occlusion"
VIEW = "continuum_gym.envs.view_tracking"

#: old module -> {name: "new module:name"}
MOVED: dict[str, dict[str, str]] = {
    "continuum_gym.envs.spec": {"OCCLUSION_SPEC": f"{OCCLUSION}.spec:SPEC", "VIEW_SPEC": f"{VIEW}.spec:SPEC"},
    "continuum_gym.envs.config": {
        "OcclusionConfig": f"{OCCLUSION}.config:OcclusionConfig", "ViewTrackingConfig": f"{VIEW}.config:ViewTrackingConfig",
        "OCCLUSION_TASKS": f"{OCCLUSION}.config:TASKS", "OCCLUSION_TEST_ONLY": f"{OCCLUSION}.config:TEST_ONLY",
        "VIEW_TASKS": f"{VIEW}.config:TASKS", "VIEW_TEST_ONLY": f"{VIEW}.config:TEST_ONLY",
        "MAX_GRID": f"{VIEW}.config:MAX_GRID",
    },
    "continuum_gym.envs.tasks": {
        **{name: f"{OCCLUSION}.tasks:{name}" for name in (
            "hold_start_pool", "circle_start", "occlusion_tasks", "occlusion_task_count", "VISIBILITY_FRACTION",
            "HOLD_POOL_SIZE", "HOLD_VOI_WINDOW", "HOLD_SEARCH_DRAWS", "OCCLUSION_DURATION_S")},
        **{name: f"{VIEW}.tasks:{name}" for name in ("view_tasks", "view_task_count", "VIEW_DURATION_S")},
    },
    "continuum_gym.envs.goal": {"OcclusionAvoidanceGoalEnv": f"{OCCLUSION}.goal:OcclusionAvoidanceGoalEnv",
                                "ViewTrackingGoalEnv": f"{VIEW}.goal:ViewTrackingGoalEnv"},
    "continuum_gym.registry": {"OCCLUSION": f"{OCCLUSION}.spec:ENV_ID", "VIEW": f"{VIEW}.spec:ENV_ID"},
    "continuum_gym.envs.custom": {"occlusion_slot_rates": f"{OCCLUSION}.controller:occlusion_slot_rates",
                                  "view_slot_rates": f"{VIEW}.controller:view_slot_rates",
                                  "OCCLUSION_RATES_DOC": f"{OCCLUSION}.controller:RATES_DOC",
                                  "VIEW_RATES_DOC": f"{VIEW}.controller:RATES_DOC"},
}


def moved(module: str, name: str) -> Any:
    """``name`` of ``module`` from its new home; ``AttributeError`` (as Python's own) if it never was there."""
    target = MOVED.get(module, {}).get(name)
    if target is None:
        raise AttributeError(f"module {module!r} has no attribute {name!r}")
    new_module, new_name = target.split(":")
    return getattr(importlib.import_module(new_module), new_name)


def lazy_exports(package: str, exports: dict[str, str]) -> Callable[[str], Any]:
    """A package's module ``__getattr__``: ``name`` from its submodule ``exports[name]``, imported on first use."""
    def __getattr__(name: str) -> Any:
        if name in exports:
            return getattr(importlib.import_module(f"{package}.{exports[name]}"), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__


__all__ = ["MOVED", "moved", "lazy_exports"]
