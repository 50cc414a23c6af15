"""The ``EnvSpec`` of ``ContinuumGym/ViewTracking-v0``: what every tool of the library reads about it (registered on import)."""

from __future__ import annotations

from continuum_gym.envs.registration import register_env
from continuum_gym.envs.spec import EnvSpec, EpisodeMetric, Metric, ReferenceRow, TaskSet
from continuum_gym.envs.view_tracking.config import ViewTrackingConfig

SPEC = register_env(EnvSpec(
    env_id=ViewTrackingConfig.env_id,
    config_class=ViewTrackingConfig,
    core="continuum_gym.envs.view_tracking.core:ViewTrackingCore",
    scene="continuum_gym.render.view_scene:ViewTrackingScene",
    entry_point="continuum_gym.envs.view_tracking:ViewTrackingEnv",
    vector_entry_point="continuum_gym.envs.view_tracking:ViewTrackingVectorEnv",
    max_episode_steps=1000,
    baselines=ViewTrackingConfig.baselines,
    headline_baseline="dimension_reduced",
    headline_metric="mean_or",
    metrics=(
        Metric("mean_or", "mean overlap ratio (OR)", "", True),
        Metric("or_above_0.8_fraction", "steps with OR > 0.8", "", True),
        Metric("mean_position_error_m", "mean target-point error", "m", False, "mm", 1e3),
        Metric("coverage_percent", "coverage (final OR > 0.8 on the grid)", "%", True, grid_metric="final_or",
               threshold=0.8),
    ),
    episode_metrics=(
        EpisodeMetric("mean_or", "or"),
        EpisodeMetric("or_above_0.8_fraction", "or_above"),
        EpisodeMetric("mean_position_error_m", "position_error"),
        EpisodeMetric("final_or", "or", "final"),
    ),
    task_sets=(TaskSet("static"), TaskSet("random"), TaskSet("case1", episodes=1), TaskSet("case2", episodes=1),
               TaskSet("coverage", grid=True)),
    diagnostics=(),
    policy_keys=("base_controller", "residual_scale", "residual_space", "visibility_guard", "observe_target",
                 "overlap_polish"),
    references=(
        ReferenceRow("offline_optimum", "coverage", "optimum_or", "coverage_percent", "coverage", "coverage"),
        ReferenceRow("bounded_least_squares", "coverage", "bounded_least_squares_or", "coverage_percent", "coverage",
                     "coverage"),
    ),
    optimum_tasks=("coverage",),
    headroom=("coverage", "coverage_percent"),
    trace_task="case1",
    trace_value="or",
    cameras=("external", "endoscope", "davinci"),
    record_task="case1",
    record_value="overlap_ratio",
    goal_id="ContinuumGym/ViewTrackingGoal-v0",
    goal_entry_point="continuum_gym.envs.view_tracking.goal:ViewTrackingGoalEnv",
    robot_class="continuum_gym.robots.endoscope:ContinuumEndoscope",
    controller_module="continuum_gym.envs.view_tracking.controller",
    physics=("robot", "davinci"),
    optimum="continuum_gym.evaluation.optimum.view:env_optimum",
    warm_ups=("continuum_gym.evaluation.reproduction:warm_up_view",),
))
ENV_ID = SPEC.env_id

__all__ = ["SPEC", "ENV_ID"]
