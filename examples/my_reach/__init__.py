"""A third environment, in a package of its own: ``MyLab/EndoscopeReach-v0``.

The continuum endoscope of ViewTracking points its view at a goal: its visual target point (12 cm in
front of the camera) must reach a point drawn per episode. The analytic base is a Jacobian-transpose
controller; the policy's action is a residual on its joint rates. Nothing outside this package is
edited: ``spec.py`` registers the environment with ``continuum_gym.envs.register_env``, and every tool
of the library (train, evaluate, the vector env, the SB3 adapter, the workers) reads that spec.
Walked through in docs/tutorials/extend.md, "Add a third environment".

    import my_reach, gymnasium as gym
    env = gym.make("MyLab/EndoscopeReach-v0")
"""

from my_reach.spec import ENV_ID, SPEC

__all__ = ["ENV_ID", "SPEC"]
