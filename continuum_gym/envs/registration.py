"""One registration loop for every ``ContinuumGym/`` id (string entry points, native vector entry points)."""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

# Safety bounds only: each task truncates itself at its own duration.
_ENVS = {
    "OcclusionAvoidance-v0": ("continuum_gym.envs.occlusion:OcclusionAvoidanceEnv",
                              "continuum_gym.envs.occlusion:OcclusionAvoidanceVectorEnv", 1000),
    "ViewTracking-v0": ("continuum_gym.envs.view_tracking:ViewTrackingEnv",
                        "continuum_gym.envs.view_tracking:ViewTrackingVectorEnv", 1000),
}

ENV_IDS = []


def register_envs() -> list:
    """Register every id once (importing continuum_gym twice is harmless)."""
    for name, (entry_point, vector_entry_point, max_steps) in _ENVS.items():
        env_id = f"ContinuumGym/{name}"
        if env_id not in registry:
            register(id=env_id, entry_point=entry_point, vector_entry_point=vector_entry_point,
                     max_episode_steps=max_steps)
        if env_id not in ENV_IDS:
            ENV_IDS.append(env_id)
    return ENV_IDS
