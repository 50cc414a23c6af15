"""The shipped offline-optimum cache (``data/optimum_cache.json``) and its readers."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

CACHE_PATH = Path(__file__).resolve().parents[1] / "data" / "optimum_cache.json"


# ====================================================================== cache
def load_optimum_cache(path: Path | str | None = None) -> dict:
    """The shipped offline optima (nested dict; see the module docstring), or those at ``path``."""
    path = CACHE_PATH if path is None else Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no optimum cache at {path}; run `continuum-gym optimum --env all --task all "
                                "--write-cache` to create it")
    return json.loads(path.read_text())


def cache_value(cache: dict, key: str) -> Any:
    """A dotted key of the cache, e.g. ``cache_value(cache, "coverage.optimum_percent")``."""
    value: Any = cache
    for part in key.split("."):
        if not isinstance(value, dict) or part not in value:
            raise KeyError(f"optimum cache has no key {key!r}")
        value = value[part]
    return value
