"""How ``ContinuumGym/ViewTracking-v0`` is evaluated and reported (``envs/benchmark.py``), declared on import."""

from __future__ import annotations

from continuum_gym.envs.benchmark import Benchmark, ReferenceRow, TaskSet, register_benchmark
from continuum_gym.envs.view_tracking.spec import ENV_ID

BENCHMARK = register_benchmark(Benchmark(
    env_id=ENV_ID,
    task_sets=(TaskSet("static"), TaskSet("random"), TaskSet("case1", episodes=1), TaskSet("case2", episodes=1),
               TaskSet("coverage", grid=True)),
    headline_baseline="dimension_reduced",
    headline_metric="mean_or",
    policy_keys=("base_controller", "residual_scale", "residual_space", "observe_target"),
    references=(
        ReferenceRow("offline_optimum", "coverage", "optimum_or", "coverage_percent", "coverage", "coverage"),
        ReferenceRow("bounded_least_squares", "coverage", "bounded_least_squares_or", "coverage_percent", "coverage",
                     "coverage"),
    ),
    headroom=("coverage", "coverage_percent"),
    trace_task="case1", trace_value="overlap_ratio", record_task="case1", record_value="overlap_ratio",
    optimum_tasks=("coverage",), physics=("robot", "davinci"),
))

__all__ = ["BENCHMARK"]
