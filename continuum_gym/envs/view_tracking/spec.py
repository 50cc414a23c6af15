"""The ``EnvSpec`` of ``ContinuumGym/ViewTracking-v0``: what the environment is (registered on import).

How it is evaluated and reported is its ``Benchmark`` (``continuum_gym.envs.benchmark``).
"""

from __future__ import annotations

from continuum_gym.envs.spec import EnvSpec, register_env
from continuum_gym.envs.view_tracking.config import ViewTrackingConfig
from continuum_gym.envs.view_tracking.outputs import Flag, Metric

SPEC = register_env(EnvSpec(
    env_id=ViewTrackingConfig.env_id,
    config_class=ViewTrackingConfig,
    rows="continuum_gym.envs.view_tracking.env:ROWS",
    entry_point="continuum_gym.envs.view_tracking:ViewTrackingEnv",
    vector_entry_point="continuum_gym.envs.view_tracking:ViewTrackingVectorEnv",
    baselines=ViewTrackingConfig.baselines,
    columns=(Metric, Flag),
    metrics=("mean_or", "or_above_0.8_fraction", "mean_position_error_m", "coverage_percent"),
    goal_entry_point="continuum_gym.envs.view_tracking.goal:ViewTrackingGoalEnv",
    scene="continuum_gym.render.view_scene:ViewTrackingScene",
    cameras=("external", "endoscope", "davinci"),
    pixels="continuum_gym.envs.view_tracking.pixels:PIXELS",
))
ENV_ID = SPEC.env_id

__all__ = ["SPEC", "ENV_ID"]
