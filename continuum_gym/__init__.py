"""continuum-gym: Gymnasium environments for continuum surgical robots beside an endoscope.

``import continuum_gym`` registers the ``ContinuumGym/`` environment ids with Gymnasium.
"""

__version__ = "0.2.0"

from continuum_gym.envs.registration import ENV_IDS, register_envs  # noqa: E402

register_envs()

__all__ = ["__version__", "ENV_IDS"]
