"""One record per environment id: what training, evaluation, rollout, recording and the SB3 adapter read.

An ``EnvSpec`` names the config class and the batched core of an id, its analytic baselines, the
metrics a method is judged by (with their units and which direction is better), the evaluation task
sets, the per-episode reductions of the per-step values, the offline-optimum rows of the table and
what ``continuum-gym render`` records, and the hooks (goal front end, robot class, controller module,
optimum, precompile warm-ups) by which the rest of the library reaches the environment. Each environment's
package registers its own spec (``envs/occlusion/spec.py``, ``envs/view_tracking/spec.py``) with
``register_env``; this module is generic and names no environment.

This module is light (no compiled code is imported until ``core_class()`` is called), so command-line
help and argument errors answer at once.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from continuum_gym.envs.config import EnvConfig
from continuum_gym.plugins import ENTRY_POINT_GROUP, ENV_VAR
from continuum_gym.plugins import load_object as load
from continuum_gym.validation import closest

if TYPE_CHECKING:
    from continuum_gym.envs.batched import BatchedCore


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
    # What the rest of the library asks of an environment, named here so that no module outside its package
    # branches on its id. Each "module:name" is imported on first use; an empty value: the env lacks it.
    goal_id: str = ""  #: id of the goal-conditioned front end (HER), registered beside ``env_id``
    goal_entry_point: str = ""  #: "module:Class" of that front end
    robot_class: str = ""  #: "module:Class" of the robots ``registry.register_robot`` files under this env
    #: the module a registered controller is compiled, checked and called through (``envs/custom.py``'s
    #: ``controller_module``)
    controller_module: str = ""
    #: config fields the offline optimum depends on (the task, rewards and base controller do not); ():
    #: no optimum is known for the env
    physics: tuple[str, ...] = ()
    #: "module:function" computing the optimum cache of a variant:
    #: ``fn(config, *, episodes, grid, split, progress, workers) -> dict`` keyed by ``references``' cache keys
    optimum: str = ""
    #: "module:function"s that call the env's library API (batched kinematics, baselines) once, so that
    #: ``continuum-gym precompile`` compiles what ``continuum-gym reproduce`` runs
    warm_ups: tuple[str, ...] = ()

    @property
    def short_name(self) -> str:
        """'OcclusionAvoidance' for 'ContinuumGym/OcclusionAvoidance-v0'."""
        return self.env_id.split("/")[-1].split("-")[0]

    def core_class(self) -> type:
        return load(self.core)

    def scene_class(self) -> type:
        return self.hook("scene")

    def hook(self, name: str) -> Any:
        """The object a "module:name" field names (``spec.hook("optimum")``), imported now."""
        reference = getattr(self, name)
        if not reference:
            raise ValueError(f"{self.short_name} has no {name} (its EnvSpec leaves {name} empty)")
        return load(reference)

    def metric(self, name: str) -> Metric:
        for metric in self.metrics:
            if metric.name == name:
                return metric
        raise KeyError(name)

    def make_core(self, num_envs: int, **env_kwargs: Any) -> BatchedCore:
        """A batched core of ``num_envs`` rows built from the env's keyword arguments."""
        return self.core_class()(num_envs=num_envs, **env_kwargs)


#: Every environment of the library, by id: filled by ``envs.registration.register_env`` as each environment's
#: package is imported (``import continuum_gym`` imports the library's own).
ENV_SPECS: dict[str, EnvSpec] = {}


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
        for spec in ENV_SPECS.values():
            if _names(registered.entry_point, spec.entry_point, spec.goal_entry_point) \
                    or _names(registered.vector_entry_point, spec.vector_entry_point):
                return spec
        raise ValueError(f"env id {env_id!r} is registered to {registered.entry_point!r}, not to the entry point of "
                         f"one of continuum-gym's environments {sorted(ENV_SPECS)}: register it with "
                         "entry_point=... of one of them (docs/tutorials/variant.md)")
    raise ValueError(f"unknown env id {env_id!r}{closest(env_id, ENV_SPECS)}; valid ids: {sorted(ENV_SPECS)}, or an "
                     f"id registered to their entry points. {REGISTER_HINT}")


#: How a user's id becomes known to a process (and to the processes it starts).
REGISTER_HINT = ("A user's id must be registered at import of an importable module (gymnasium's register() in it), and "
                 "that module imported: `continuum-gym --import MODULE` on the command line, an entry point in "
                 f"the group '{ENTRY_POINT_GROUP}' of an installed package, or the environment variable "
                 f"{ENV_VAR}=MODULE (in Python: import MODULE before gym.make, or gym.make('MODULE:ID'))")


def _names(entry: Any, *references: str) -> bool:
    """Whether a registered entry point (a "module:name" string or the object) is one of ``references``: the same
    string, or another path to the same class (``continuum_gym.envs.occlusion:OcclusionAvoidanceGoalEnv`` is
    ``continuum_gym.envs.occlusion.goal:OcclusionAvoidanceGoalEnv``)."""
    if entry is None:
        return False
    references = tuple(r for r in references if r)
    if isinstance(entry, str) and entry in references:
        return True
    try:
        target = load(entry) if isinstance(entry, str) else entry
        return any(target is load(reference) for reference in references)
    except (ImportError, AttributeError, ValueError):
        return False


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


__all__ = ["EnvSpec", "Metric", "EpisodeMetric", "TaskSet", "ReferenceRow", "ENV_SPECS", "get_spec",
           "registered_kwargs", "registered_base"]
