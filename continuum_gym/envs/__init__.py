"""Gymnasium environments: registration, single envs, native vector envs, the SB3 adapter."""

from continuum_gym.envs.registration import ENV_IDS, register_envs

register_envs()

__all__ = ["ENV_IDS", "register_envs"]
