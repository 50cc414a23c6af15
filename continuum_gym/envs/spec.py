"""One record per environment id: what training, evaluation, rollout, recording and the SB3 adapter read.

An ``EnvSpec`` names the config class and the batched core of an id, its analytic baselines, the
metrics a method is judged by (with their units and which direction is better), the evaluation task
sets, the per-episode reductions of the per-step values, the offline-optimum rows of the table and
what ``continuum-gym render`` records. No other module keeps a per-environment table: a third
environment is one core, one kernel and one spec here.

This module is light (no compiled code is imported until ``core_class()`` is called), so command-line
help and argument errors answer at once.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

from continuum_gym.envs.config import EnvConfig, OcclusionConfig, ViewTrackingConfig
from continuum_gym.validation import closest


@dataclass(frozen=True)
class Metric:
    """A column of the evaluation table."""

    name: str  #: key in the per-episode results and the JSON
    label: str  #: words for tables and figure axes
    unit: str  #: SI unit of the stored value ("" for ratios, "%" for percentages)
    higher_is_better: bool
    display_unit: str = ""  #: unit shown in tables and figures ("" = ``unit``)
    display_scale: float = 1.0  #: stored value x scale = shown value
    grid_metric: str = ""  #: if set: 100 x the fraction of grid episodes whose ``grid_metric`` > ``threshold``
    threshold: float = 0.0

    def axis_label(self) -> str:
        """'<label> (<unit>), lower is better' for figure axes."""
        unit = self.display_unit or self.unit
        direction = "higher is better" if self.higher_is_better else "lower is better"
        return f"{self.label}{f' ({unit})' if unit else ''}, {direction}"


@dataclass(frozen=True)
class EpisodeMetric:
    """How a per-episode metric is reduced from the per-step values of ``core.step_values()``."""

    name: str
    step_value: str
    reduce: str = "mean"  #: "mean" over the episode's steps, or "final" (the last step's value)


@dataclass(frozen=True)
class TaskSet:
    """Task instances every method is evaluated on (test split)."""

    task: str
    episodes: int | None = None  #: None: the evaluation's ``--episodes``
    grid: bool = False  #: one episode per grid point (``--grid`` squared)


@dataclass(frozen=True)
class ReferenceRow:
    """A row of the table that comes from the shipped offline-optimum cache instead of episodes."""

    method: str  #: row name, e.g. "offline_optimum"
    cache_key: str  #: top-level key of the cache
    values: str  #: key of the per-task values inside it
    metric: str  #: table column it fills
    kind: str  #: "per_task" (one value per task id of ``task``) or "coverage" (OR > threshold, in %)
    task: str  #: the task set it belongs to
    note: str = ""


@dataclass(frozen=True)
class EnvSpec:
    """Everything the library's tooling needs to know about one environment id."""

    env_id: str
    config_class: type[EnvConfig]
    core: str  #: "module:Class" of the batched core
    entry_point: str
    vector_entry_point: str
    max_episode_steps: int  #: the longest built-in task's duration at the default control_dt (not registered)
    baselines: tuple[str, ...]  #: analytic controllers that can be the residual base (table order)
    headline_baseline: str  #: the default base: the headline residual is trained on it and compared with it
    headline_metric: str  #: the held-out metric a training run is judged by
    metrics: tuple[Metric, ...]
    episode_metrics: tuple[EpisodeMetric, ...]
    task_sets: tuple[TaskSet, ...]
    diagnostics: tuple[str, ...]  #: per-task columns beside the headline metrics (Markdown only)
    policy_keys: tuple[str, ...]  #: env keywords that define how a policy's action acts (from its config)
    references: tuple[ReferenceRow, ...]
    optimum_tasks: tuple[str, ...]  #: what ``continuum-gym optimum`` computes for this env
    headroom: tuple[str, str]  #: (task, metric) on which headroom_closed is measured
    trace_task: str  #: the paper task whose per-step trace is drawn
    trace_value: str  #: the per-step value drawn
    cameras: tuple[str, ...]
    record_task: str  #: default task of ``continuum-gym render``
    record_value: str  #: per-step value shown under the recorded frames
    #: "module:Class" of the pybullet scene that draws the env (``Scene.from_core`` / ``show_row``):
    #: named, not imported, so the environments do not depend on the renderer
    scene: str = ""

    @property
    def short_name(self) -> str:
        """'OcclusionAvoidance' for 'ContinuumGym/OcclusionAvoidance-v0'."""
        return self.env_id.split("/")[-1].split("-")[0]

    def core_class(self) -> type:
        module, name = self.core.split(":")
        return getattr(importlib.import_module(module), name)

    def scene_class(self) -> type:
        module, name = self.scene.split(":")
        return getattr(importlib.import_module(module), name)

    def metric(self, name: str) -> Metric:
        for metric in self.metrics:
            if metric.name == name:
                return metric
        raise KeyError(name)

    def make_core(self, num_envs: int, **env_kwargs):
        """A batched core of ``num_envs`` rows built from the env's keyword arguments."""
        return self.core_class()(num_envs=num_envs, **env_kwargs)


OCCLUSION_SPEC = EnvSpec(
    env_id=OcclusionConfig.env_id,
    config_class=OcclusionConfig,
    core="continuum_gym.envs.occlusion:OcclusionCore",
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
    policy_keys=("base_controller", "residual_scale", "residual_space", "visibility_guard", "observe_target"),
    references=(ReferenceRow("offline_optimum", "hold_test", "optimum_voi", "mean_voi", "per_task", "hold",
                             "hold test tasks only: lowest VOI on the self-motion arc x feasible gamma"),),
    optimum_tasks=("hold", "circle"),
    headroom=("hold", "mean_voi"),
    trace_task="circle",
    trace_value="voi",
    cameras=("external", "endoscope"),
    record_task="circle",
    record_value="voi",
)

VIEW_SPEC = EnvSpec(
    env_id=ViewTrackingConfig.env_id,
    config_class=ViewTrackingConfig,
    core="continuum_gym.envs.view_tracking:ViewTrackingCore",
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
    policy_keys=("base_controller", "residual_scale", "residual_space", "visibility_guard", "observe_target"),
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
)

#: Every environment of the library, by id (the registration loop and the tests iterate over it).
ENV_SPECS = {spec.env_id: spec for spec in (OCCLUSION_SPEC, VIEW_SPEC)}


def get_spec(env_id: str) -> EnvSpec:
    """The spec of a ``ContinuumGym/`` id, or of any id registered to one of the library's entry points.

    A user's ``register(id="MyLab/...", entry_point="continuum_gym.envs.occlusion:OcclusionAvoidanceEnv",
    kwargs=...)`` resolves to the OcclusionAvoidance spec (its kwargs are the id's defaults, see
    ``registered_kwargs``).
    """
    if env_id in ENV_SPECS:
        return ENV_SPECS[env_id]
    registered = _registered(env_id)
    if registered is not None:
        entry = registered.entry_point if isinstance(registered.entry_point, str) else None
        vector = registered.vector_entry_point if isinstance(registered.vector_entry_point, str) else None
        for spec in ENV_SPECS.values():
            if entry == spec.entry_point or vector == spec.vector_entry_point:
                return spec
    raise ValueError(f"unknown env id {env_id!r}{closest(env_id, ENV_SPECS)}; valid ids: {sorted(ENV_SPECS)} "
                     "(or an id registered to their entry points)")


def registered_kwargs(env_id: str) -> dict:
    """The keyword arguments an id was registered with (empty for the library's own ids)."""
    registered = _registered(env_id)
    return dict(registered.kwargs or {}) if registered is not None else {}


def registered_base(env_id: str) -> str | None:
    """The registered controller an id was registered with as its base (its name), or None (a built-in or none)."""
    from continuum_gym.plugins import split_reference

    base = registered_kwargs(env_id).get("base_controller")
    if not isinstance(base, str) or base in get_spec(env_id).baselines:
        return None
    return split_reference(base)[1]


def _registered(env_id: str):
    from gymnasium.envs.registration import registry

    import continuum_gym  # noqa: F401  (registers the library's ids)

    return registry.get(env_id)


__all__ = ["EnvSpec", "Metric", "EpisodeMetric", "TaskSet", "ReferenceRow", "ENV_SPECS", "OCCLUSION_SPEC", "VIEW_SPEC",
           "get_spec", "registered_kwargs", "registered_base"]
