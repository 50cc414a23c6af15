"""What every tool of continuum-gym reads about ``MyLab/EndoscopeReach-v0``; registered on import."""

from __future__ import annotations

from continuum_gym.envs import register_env
from continuum_gym.envs.spec import EnvSpec, EpisodeMetric, Metric, TaskSet
from my_reach.config import ReachConfig

SPEC = register_env(EnvSpec(
    env_id=ReachConfig.env_id,
    config_class=ReachConfig,
    core="my_reach.core:ReachCore",
    entry_point="my_reach.core:EndoscopeReachEnv",
    vector_entry_point="my_reach.core:EndoscopeReachVectorEnv",
    max_episode_steps=200,
    baselines=ReachConfig.baselines,
    headline_baseline="jacobian_transpose",
    headline_metric="final_distance_m",
    metrics=(Metric("final_distance_m", "final distance to the goal", "m", False, "mm", 1e3),
             Metric("mean_distance_m", "mean distance to the goal", "m", False, "mm", 1e3)),
    episode_metrics=(EpisodeMetric("final_distance_m", "distance", "final"),
                     EpisodeMetric("mean_distance_m", "distance")),
    task_sets=(TaskSet("reach"),),
    diagnostics=(),
    policy_keys=("base_controller", "residual_scale"),
    references=(),  # no offline optimum is known for this toy
    optimum_tasks=(),
    headroom=("reach", "final_distance_m"),
    trace_task="reach",
    trace_value="distance",
    cameras=("external",),
    record_task="reach",
    record_value="distance_m",
))
ENV_ID = SPEC.env_id
