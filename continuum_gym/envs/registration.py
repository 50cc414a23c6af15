"""How an environment joins the library: ``register_env(spec)`` files its ``EnvSpec`` and its Gymnasium ids.

The library's own environments are packages that register themselves on import (``BUILTIN_ENVS``); a
researcher's environment does the same from its own package (see docs/tutorials/extend.md, "Add a third
environment"), and every tool (``train``, ``evaluate``, ``render``, the workers) then reads its spec.
"""

from __future__ import annotations

import importlib

from gymnasium.envs.registration import register, registry

from continuum_gym.envs.spec import ENV_SPECS, EnvSpec

#: The library's environment packages, imported (in this order) when ``continuum_gym`` is.
BUILTIN_ENVS = ("continuum_gym.envs.occlusion", "continuum_gym.envs.view_tracking")

ENV_IDS: list[str] = []


def register_env(spec: EnvSpec) -> EnvSpec:
    """Add an environment: its spec to ``ENV_SPECS``, its id (and goal id) to Gymnasium's registry.

    Registering the same spec again is harmless; another spec under a taken id is an error.
    """
    if not isinstance(spec, EnvSpec):
        raise ValueError(f"register_env takes an EnvSpec; got {type(spec).__name__}")
    known = ENV_SPECS.get(spec.env_id)
    if known is not None and known != spec:
        raise ValueError(f"env id {spec.env_id!r} is already registered with another EnvSpec; pick another id")
    ENV_SPECS[spec.env_id] = spec
    if spec.env_id not in registry:
        # No TimeLimit: each task truncates itself at its own duration (hold 150 steps, random 500-600,
        # circle and the case studies 1000 at the default control_dt; a recording or another control_dt
        # its own), so any registered bound would be wrong for some task. ``env.unwrapped.episode_steps``
        # gives the current episode's length for clients that size buffers.
        register(id=spec.env_id, entry_point=spec.entry_point, vector_entry_point=spec.vector_entry_point,
                 max_episode_steps=None)
    if spec.goal_id and spec.goal_id not in registry:  # goal-conditioned front end (HER); no vector version
        register(id=spec.goal_id, entry_point=spec.goal_entry_point, max_episode_steps=None)
    if spec.env_id not in ENV_IDS:
        ENV_IDS.append(spec.env_id)
    return spec


def register_envs() -> list:
    """Import the library's environment packages (each registers itself once); the registered ids."""
    for package in BUILTIN_ENVS:
        importlib.import_module(package)
    return ENV_IDS
