"""What the benchmark and the reports need of an environment, declared apart from what the environment is.

``EnvSpec`` says what an env is (id, config, rows, entry points, baselines, metrics). A ``Benchmark`` says how it
is evaluated and shown: the held-out task sets, the headline baseline and metric, the offline-optimum rows and
how to compute them, headroom, the per-step trace drawn, what ``continuum-gym render`` records, the keywords that
define how a trained policy acts, the warm-ups of ``continuum-gym precompile``. Every field has a default made
from the spec, so an environment that declares none (a toy env in a package of its own) still gets ``train``,
``evaluate`` and ``render``; ``register_benchmark`` replaces the defaults. The library's two environments declare
theirs in their packages (``envs/occlusion/benchmark.py``). How an offline optimum is computed is the evaluation
layer's (``continuum_gym.evaluation.optimum.register_optimum``), named by env id, so that no environment reaches
up to it.
"""

from __future__ import annotations

from dataclasses import dataclass

from continuum_gym.envs.spec import EnvSpec, get_spec


@dataclass(frozen=True)
class TaskSet:
    """Task instances every method is evaluated on."""

    task: str
    episodes: int | None = None  #: None: the evaluation's ``--episodes``
    grid: bool = False  #: one episode per grid point (``--grid`` squared)


@dataclass(frozen=True)
class ReferenceRow:
    """A row of the table that comes from the offline-optimum cache instead of episodes."""

    method: str  #: row name, e.g. "offline_optimum"
    cache_key: str  #: top-level key of the cache
    values: str  #: key of the per-task values inside it
    metric: str  #: table column it fills
    kind: str  #: "per_task" (one value per task id of ``task``) or "coverage" (OR > threshold, in %)
    task: str  #: the task set it belongs to
    note: str = ""


@dataclass(frozen=True)
class Benchmark:
    """How an environment is evaluated and reported (see the module docstring); empty fields take defaults."""

    env_id: str
    task_sets: tuple[TaskSet, ...] = ()  #: held-out task sets (default: the first built-in task)
    headline_baseline: str = ""  #: the residual's base the headline compares with (default: the first baseline)
    headline_metric: str = ""  #: the held-out metric a training run is judged by (default: the first metric)
    diagnostics: tuple[str, ...] = ()  #: per-task columns beside the headline metrics (Markdown only)
    #: env keywords that define how a policy's action acts (read from its config)
    policy_keys: tuple[str, ...] = ("base_controller", "residual_scale", "residual_space")
    references: tuple[ReferenceRow, ...] = ()  #: offline-optimum rows of the table
    headroom: tuple[str, str] | None = None  #: (task, metric) on which headroom_closed is measured
    trace_task: str = ""  #: the task whose per-step trace is drawn ("": none)
    trace_value: str = ""  #: the per-step value drawn (an ``info`` name of a declared column)
    record_task: str = ""  #: default task of ``continuum-gym render`` (default: the first built-in)
    record_value: str = ""  #: per-step value shown under the recorded frames (default: the first declared value)
    #: the longest built-in task's duration at the default control_dt, in steps (sizes the render's buffers)
    max_episode_steps: int = 1000
    optimum_tasks: tuple[str, ...] = ()  #: what ``continuum-gym optimum`` computes
    physics: tuple[str, ...] = ()  #: config fields the optimum depends on (its cache is per value of these)

    def __post_init__(self) -> None:
        spec = get_spec(self.env_id)
        set_ = object.__setattr__
        builtin = spec.config_class.builtin_tasks
        if not self.task_sets and builtin:
            set_(self, "task_sets", (TaskSet(builtin[0]),))
        if not self.headline_baseline and spec.baselines:
            set_(self, "headline_baseline", spec.baselines[0])
        if not self.headline_metric:
            set_(self, "headline_metric", spec.metrics[0].name)
        if not self.record_task and builtin:
            set_(self, "record_task", builtin[0])
        if not self.record_value:
            first = next((c.declared.info for columns in spec.columns for c in columns if c.declared.info), "")
            set_(self, "record_value", first)
        keys = spec.config_class.keyword_names()
        set_(self, "policy_keys", tuple(key for key in self.policy_keys if key in keys))

    def task_set(self, task: str) -> TaskSet:
        for task_set in self.task_sets:
            if task_set.task == task:
                return task_set
        raise KeyError(task)


#: Declared benchmarks by env id (a toy env without one gets ``Benchmark(env_id)``'s defaults).
BENCHMARKS: dict[str, Benchmark] = {}


def register_benchmark(benchmark: Benchmark) -> Benchmark:
    """Declare how an environment is evaluated and reported (replaces the defaults)."""
    if not isinstance(benchmark, Benchmark):
        raise ValueError(f"register_benchmark takes a Benchmark; got {type(benchmark).__name__}")
    BENCHMARKS[benchmark.env_id] = benchmark
    return benchmark


def benchmark_of(env: str | EnvSpec) -> Benchmark:
    """The benchmark of an env id (any id registered to a library env reads that env's) or of a spec."""
    spec = env if isinstance(env, EnvSpec) else get_spec(env)
    if spec.env_id not in BENCHMARKS:
        BENCHMARKS[spec.env_id] = Benchmark(spec.env_id)
    return BENCHMARKS[spec.env_id]


__all__ = ["Benchmark", "TaskSet", "ReferenceRow", "BENCHMARKS", "register_benchmark", "benchmark_of"]
