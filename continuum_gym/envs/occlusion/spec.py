"""The ``EnvSpec`` of ``ContinuumGym/OcclusionAvoidance-v0``: what the environment is (registered on import).

How it is evaluated and reported is its ``Benchmark`` (``continuum_gym.envs.benchmark``).
"""

from __future__ import annotations

from continuum_gym.envs.occlusion.config import OcclusionConfig
from continuum_gym.envs.occlusion.outputs import Flag, Metric
from continuum_gym.envs.spec import EnvSpec, register_env

SPEC = register_env(EnvSpec(
    env_id=OcclusionConfig.env_id,
    config_class=OcclusionConfig,
    rows="continuum_gym.envs.occlusion.env:ROWS",
    entry_point="continuum_gym.envs.occlusion:OcclusionAvoidanceEnv",
    vector_entry_point="continuum_gym.envs.occlusion:OcclusionAvoidanceVectorEnv",
    baselines=OcclusionConfig.baselines,
    columns=(Metric, Flag),
    metrics=("mean_voi", "tip_in_view_fraction", "mean_tip_error_m", "mean_orientation_error_rad"),
    goal_entry_point="continuum_gym.envs.occlusion.goal:OcclusionAvoidanceGoalEnv",
    scene="continuum_gym.render.occlusion_scene:OcclusionScene",
    cameras=("external", "endoscope"),
    pixels="continuum_gym.envs.occlusion.pixels:PIXELS",
))
ENV_ID = SPEC.env_id

__all__ = ["SPEC", "ENV_ID"]
