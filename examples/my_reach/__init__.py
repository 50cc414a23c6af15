"""A third environment in a package of its own, in three files: ``MyLab/EndoscopeReach-v0``.

The continuum endoscope of ViewTracking points its view at a goal: its visual target point (12 cm in front of the
camera) must reach a point drawn per episode; the base is a Jacobian-transpose controller and the policy's action a
residual on its joint rates. ``config.py`` holds its keyword arguments, task family and the columns its rows write,
``kernel.py`` what one row does in a step, and this file what the environment is (its ``EnvSpec``, registered on
import). The library does the rest: the batched loop and its threads, the arrays, autoreset, ``info``, plug-ins,
training, evaluation (docs/tutorials/extend.md, "Add a third environment")::

    import my_reach, gymnasium as gym
    env = gym.make("MyLab/EndoscopeReach-v0")
"""

from continuum_gym.envs import register_env
from continuum_gym.envs.spec import EnvSpec
from my_reach.config import Flag, Metric, ReachConfig

SPEC = register_env(EnvSpec(
    env_id=ReachConfig.env_id, config_class=ReachConfig, rows="my_reach.kernel:ROWS",
    entry_point="my_reach.kernel:EndoscopeReachEnv", vector_entry_point="my_reach.kernel:EndoscopeReachVectorEnv",
    baselines=ReachConfig.baselines, columns=(Metric, Flag),
    metrics=("final_distance_m", "mean_distance_m")))
ENV_ID = SPEC.env_id
