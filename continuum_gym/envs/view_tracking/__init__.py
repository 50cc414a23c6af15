"""ViewTracking (Deng, Xu et al.): one package holds all of the environment.

``config`` (its keyword arguments), ``tasks`` (its built-in task families), ``kernel`` and ``mismatch``
(the compiled step, nominal and under a model error), ``core`` (the batched core and its Gymnasium front
ends), ``controller`` (how it calls a registered controller), ``goal`` (the HER front end) and ``spec``
(what the rest of the library reads about it, registered when this package is imported). Names load on
first use, so importing the package registers the id without compiling anything.
"""

from continuum_gym.envs.pixels import register_pixels
from continuum_gym.envs.view_tracking.spec import SPEC
from continuum_gym.plugins import lazy_exports

_EXPORTS = {
    "ViewTrackingEnv": "core", "ViewTrackingVectorEnv": "core", "ViewTrackingCore": "core", "INFO_FIELDS": "core",
    "ACTION_SCALE": "core", "ViewTrackingConfig": "config", "ViewTrackingGoalEnv": "goal",
    "Metric": "outputs", "Flag": "outputs", "OBSERVATION": "outputs",
    "REWARD_TERMS": "kernel", }
__all__ = ["SPEC", *sorted(_EXPORTS)]

__getattr__ = lazy_exports(__name__, _EXPORTS)

# image observations (issue 56): loaded when an image obs_mode is first used
register_pixels(SPEC.env_id, "continuum_gym.envs.view_tracking.pixels:PIXELS")
