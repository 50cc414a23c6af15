"""One registration loop for every ``ContinuumGym/`` id (string entry points, native vector entry points)."""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

from continuum_gym.envs.goal import GOAL_ENVS
from continuum_gym.envs.spec import ENV_SPECS

ENV_IDS: list[str] = []


def register_envs() -> list:
    """Register every id of ``ENV_SPECS`` once (importing continuum_gym twice is harmless)."""
    for env_id, spec in ENV_SPECS.items():
        if env_id not in registry:
            # No TimeLimit: each task truncates itself at its own duration (hold 150 steps, random 500-600,
            # circle and the case studies 1000 at the default control_dt; a recording or another control_dt
            # its own), so any registered bound would be wrong for some task. ``env.unwrapped.episode_steps``
            # gives the current episode's length for clients that size buffers.
            register(id=env_id, entry_point=spec.entry_point, vector_entry_point=spec.vector_entry_point,
                     max_episode_steps=None)
        if env_id not in ENV_IDS:
            ENV_IDS.append(env_id)
    for env_id, entry_point in GOAL_ENVS.items():  # goal-conditioned front ends (HER); no vector version
        if env_id not in registry:
            register(id=env_id, entry_point=entry_point, max_episode_steps=None)
    return ENV_IDS
