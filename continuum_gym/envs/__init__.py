"""Gymnasium environments: registration, single envs, native vector envs, the SB3 adapter.

Public names load on first use (``from continuum_gym.envs import TipTrajectory``), so that importing
the package registers the ids without compiling or loading any kernel.
"""

import importlib

from continuum_gym.envs.spec import ENV_IDS, register_envs

register_envs()

_EXPORTS = {
    "OcclusionConfig": "occlusion.config", "ViewTrackingConfig": "view_tracking.config", "EnvConfig": "config",
    "ENV_SPECS": "spec", "EnvSpec": "spec", "get_spec": "spec", "register_env": "spec",
    "TipTrajectory": "trajectories", "DaVinciTrajectory": "trajectories",
    "OcclusionAvoidanceEnv": "occlusion.env", "OcclusionAvoidanceVectorEnv": "occlusion.env",
    "OcclusionCore": "occlusion.env", "ViewTrackingEnv": "view_tracking.env",
    "ViewTrackingVectorEnv": "view_tracking.env", "ViewTrackingCore": "view_tracking.env",
    "ContinuumSB3VecEnv": "sb3", "NamedRewardTerms": "vector", "ModelError": "model_error",
}
__all__ = ["ENV_IDS", "register_envs", *sorted(_EXPORTS)]


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
