"""How ``ContinuumGym/OcclusionAvoidance-v0`` is evaluated and reported (``envs/benchmark.py``), declared on import."""

from __future__ import annotations

from continuum_gym.envs.benchmark import Benchmark, ReferenceRow, TaskSet, register_benchmark
from continuum_gym.envs.occlusion.spec import ENV_ID

BENCHMARK = register_benchmark(Benchmark(
    env_id=ENV_ID,
    task_sets=(TaskSet("hold"), TaskSet("random"), TaskSet("circle", episodes=1)),
    headline_baseline="projected_gradient",
    headline_metric="mean_voi",
    diagnostics=("visibility_guarded_fraction",),
    policy_keys=("base_controller", "residual_scale", "residual_space", "visibility_guard"),
    references=(ReferenceRow("offline_optimum", "hold_test", "optimum_voi", "mean_voi", "per_task", "hold",
                             "hold test tasks only: lowest VOI on the self-motion arc x feasible gamma"),
                # the optimum is a configuration; an episode starts elsewhere and travels at the rate limits
                ReferenceRow("rate_limited_bound", "hold_test_rate_bound", "mean_voi_bound", "mean_voi", "per_task",
                             "hold", "hold test tasks only: no controller that holds the tip at the rate limits "
                             "scores an episode below it"),
                ReferenceRow("planned_trajectory", "hold_test_rate_bound", "mean_voi_plan", "mean_voi", "per_task",
                             "hold", "hold test tasks only: a feasible trajectory along the self-motion arc, "
                             "planned offline")),
    headroom=("hold", "mean_voi"),
    trace_task="circle", trace_value="voi", record_task="circle", record_value="voi",
    optimum_tasks=("hold", "circle"), physics=("robot", "cone", "max_bend", "insertion"),
))

__all__ = ["BENCHMARK"]
