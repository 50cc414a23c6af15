"""One registration loop for every ``ContinuumGym/`` id (string entry points, native vector entry points)."""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

from continuum_gym.envs.spec import ENV_SPECS

ENV_IDS: list[str] = []


def register_envs() -> list:
    """Register every id of ``ENV_SPECS`` once (importing continuum_gym twice is harmless)."""
    for env_id, spec in ENV_SPECS.items():
        if env_id not in registry:
            # A safety bound only: each task truncates itself at its own duration.
            register(id=env_id, entry_point=spec.entry_point, vector_entry_point=spec.vector_entry_point,
                     max_episode_steps=spec.max_episode_steps)
        if env_id not in ENV_IDS:
            ENV_IDS.append(env_id)
    return ENV_IDS
