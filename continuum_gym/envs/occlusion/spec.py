"""The ``EnvSpec`` of ``ContinuumGym/OcclusionAvoidance-v0``: what every tool of the library reads about it (registered on import)."""

from __future__ import annotations

from continuum_gym.envs.occlusion.config import OcclusionConfig
from continuum_gym.envs.registration import register_env
from continuum_gym.envs.spec import EnvSpec, EpisodeMetric, Metric, ReferenceRow, TaskSet

SPEC = register_env(EnvSpec(
    env_id=OcclusionConfig.env_id,
    config_class=OcclusionConfig,
    core="continuum_gym.envs.occlusion.core:OcclusionCore",
    scene="continuum_gym.render.occlusion_scene:OcclusionScene",
    entry_point="continuum_gym.envs.occlusion:OcclusionAvoidanceEnv",
    vector_entry_point="continuum_gym.envs.occlusion:OcclusionAvoidanceVectorEnv",
    max_episode_steps=1000,
    baselines=OcclusionConfig.baselines,
    headline_baseline="projected_gradient",
    headline_metric="mean_voi",
    metrics=(
        Metric("mean_voi", "mean visual occlusion index (VOI)", "", False),
        Metric("tip_in_view_fraction", "tip in view (within 0.7 of the half-angle)", "", True),
        Metric("mean_tip_error_m", "mean tip position error", "m", False, "mm", 1e3),
        Metric("mean_orientation_error_rad", "mean tip orientation error", "rad", False),
    ),
    episode_metrics=(
        EpisodeMetric("mean_voi", "voi"),
        EpisodeMetric("tip_in_view_fraction", "in_view"),
        EpisodeMetric("mean_tip_error_m", "tip_error"),
        EpisodeMetric("mean_orientation_error_rad", "orientation_error"),
        EpisodeMetric("visibility_guarded_fraction", "guarded"),
    ),
    task_sets=(TaskSet("hold"), TaskSet("random"), TaskSet("circle", episodes=1)),
    diagnostics=("visibility_guarded_fraction",),
    policy_keys=("base_controller", "residual_scale", "residual_space", "visibility_guard", "observe_target",
                 "arc_plan"),
    references=(ReferenceRow("offline_optimum", "hold_test", "optimum_voi", "mean_voi", "per_task", "hold",
                             "hold test tasks only: lowest VOI on the self-motion arc x feasible gamma"),
                # the optimum is a configuration; an episode starts elsewhere and travels at the rate limits
                ReferenceRow("rate_limited_bound", "hold_test_rate_bound", "mean_voi_bound", "mean_voi", "per_task",
                             "hold", "hold test tasks only: no controller that holds the tip at the rate limits "
                             "scores an episode below it"),
                ReferenceRow("planned_trajectory", "hold_test_rate_bound", "mean_voi_plan", "mean_voi", "per_task",
                             "hold", "hold test tasks only: a feasible trajectory along the self-motion arc, "
                             "planned offline")),
    optimum_tasks=("hold", "circle"),
    headroom=("hold", "mean_voi"),
    trace_task="circle",
    trace_value="voi",
    cameras=("external", "endoscope"),
    record_task="circle",
    record_value="voi",
    goal_id="ContinuumGym/OcclusionAvoidanceGoal-v0",
    goal_entry_point="continuum_gym.envs.occlusion.goal:OcclusionAvoidanceGoalEnv",
    robot_class="continuum_gym.robots.mbcr:MultiBackboneRobot",
    controller_module="continuum_gym.envs.occlusion.controller",
    physics=("robot", "cone", "max_bend", "insertion"),
    optimum="continuum_gym.evaluation.optimum.occlusion:env_optimum",
    warm_ups=("continuum_gym.evaluation.reproduction:warm_up_occlusion",),
))
ENV_ID = SPEC.env_id

__all__ = ["SPEC", "ENV_ID"]
