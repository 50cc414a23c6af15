"""Moved to ``continuum_gym.envs.view_tracking.kernel``; this module keeps imports from its old path working."""

import importlib
from typing import Any


def __getattr__(name: str) -> Any:
    return getattr(importlib.import_module("continuum_gym.envs.view_tracking.kernel"), name)
