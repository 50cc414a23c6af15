"""ViewTracking (Deng, Xu et al.): one package holds all of the environment.

``config`` (its keyword arguments), ``outputs`` (the columns and the observation its rows write, declared
once), ``kernel`` (its compiled row functions, nominal and under a model error) with ``plant`` (the model-error
pieces), ``env`` (what a config builds for the rows, and the library's front ends of the env), ``tasks`` (its
built-in task families), ``controller`` (how it calls a registered controller), ``goal`` (the HER front end)
and ``spec`` (what the rest of the library reads about it, registered when this package is imported). Names load on
first use, so importing the package registers the id without compiling anything.
"""

from continuum_gym.envs.view_tracking.benchmark import BENCHMARK
from continuum_gym.envs.view_tracking.spec import SPEC
from continuum_gym.plugins import lazy_exports

_EXPORTS = {
    "ViewTrackingEnv": "env", "ViewTrackingVectorEnv": "env", "ViewTrackingCore": "env",
    "ACTION_SCALE": "env", "ViewTrackingConfig": "config", "ViewTrackingGoalEnv": "goal",
    "Metric": "outputs", "Flag": "outputs", "OBSERVATION": "outputs",
    "REWARD_TERMS": "kernel",
}
__all__ = ["SPEC", "BENCHMARK", *sorted(_EXPORTS)]

__getattr__ = lazy_exports(__name__, _EXPORTS)
