"""One record per environment id: what the environment is.

An ``EnvSpec`` names the id, the config class, the env's row functions (``envs/core.py: RowFunctions``, imported on
first use), its front ends' entry points, its analytic baselines, the columns its rows declare and, of their
per-episode values, the ones the evaluation's tables show (``metrics``, with their units and which direction is
better). How the env is evaluated and reported (task sets, optimum, headroom, traces) is another declaration,
``continuum_gym.envs.benchmark.Benchmark``, with defaults for an env that declares none; how it is drawn
is its pybullet scene (``scene``, named, not imported, so the environments do not depend on the renderer), and
what it shows in an image ``obs_mode`` its ``PixelSpec`` (``pixels``, named too: ``envs/pixels.py``).
Each environment's package registers its own spec (``envs/occlusion/spec.py``) with ``register_env``; this module
is generic and names no environment.

This module is light (no compiled code is imported until ``core_class()`` is called), so command-line
help and argument errors answer at once.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from gymnasium.envs.registration import register, registry

from continuum_gym.envs.config import EnvConfig
from continuum_gym.envs.declared import EpisodeMetric, Metric, episode_metrics, table_metrics
from continuum_gym.plugins import ENTRY_POINT_GROUP, ENV_VAR
from continuum_gym.plugins import load_object as load
from continuum_gym.validation import closest

if TYPE_CHECKING:
    from continuum_gym.envs.core import RowFunctions


@dataclass(frozen=True)
class EnvSpec:
    """What an environment id is: everything the library needs to make, run and score it."""

    env_id: str
    config_class: type[EnvConfig]
    rows: str  #: "module:NAME" of the env's ``RowFunctions`` (its module also holds the front ends)
    entry_point: str  #: "module:Class" of the single env
    vector_entry_point: str  #: ... of the native vector env
    baselines: tuple[str, ...]  #: analytic controllers that can be the residual base (table order)
    columns: tuple = ()  #: the env's declared columns (its ``Metric`` and ``Flag``: ``envs.columns``)
    #: the evaluation table's columns, in order: names of labelled episode values of ``columns``
    metrics: tuple = ()
    goal_entry_point: str = ""  #: "module:Class" of the goal-conditioned front end (HER); its id is ``goal_id``
    #: "module:Class" of the pybullet scene that draws the env (``Scene.from_core`` / ``show_row``) and its cameras
    scene: str = ""
    cameras: tuple[str, ...] = ()
    #: "module:NAME" of the env's ``PixelSpec`` (``envs/pixels.py``: its images for every ``obs_mode`` but "state",
    #: loaded when one is first used); "": the env observes its state only
    pixels: str = ""

    def __post_init__(self) -> None:
        if self.metrics and isinstance(self.metrics[0], str):
            object.__setattr__(self, "metrics", table_metrics(self.columns, self.metrics))

    @property
    def short_name(self) -> str:
        """'OcclusionAvoidance' for 'ContinuumGym/OcclusionAvoidance-v0'."""
        return self.env_id.split("/")[-1].split("-")[0]

    @property
    def goal_id(self) -> str:
        """The id of the goal-conditioned front end (``<namespace>/<name>Goal-v<version>``), or "" if none."""
        if not self.goal_entry_point:
            return ""
        namespace, _, name = self.env_id.rpartition("/")
        base, _, version = name.rpartition("-")
        return f"{namespace + '/' if namespace else ''}{base}Goal-{version}"

    @property
    def episode_metrics(self) -> tuple[EpisodeMetric, ...]:
        """The per-episode values the evaluation reduces from the declared columns."""
        return episode_metrics(self.columns)

    def row_functions(self) -> RowFunctions:
        """The env's ``RowFunctions`` (imports its compiled code)."""
        return load(self.rows)

    def core_class(self) -> type:
        """The env's batched core class (``envs.front_ends``), its compiled code imported now."""
        return load(self.entry_point).core_class

    def scene_class(self) -> type:
        if not self.scene:
            raise ValueError(f"{self.short_name} has no pybullet scene (its EnvSpec names none): it cannot be drawn")
        return load(self.scene)

    @property
    def robot_class(self) -> str:
        """"module:Class" of the env's robots (its config's), which ``registry.register_robot`` checks against."""
        return self.config_class.robot_class

    def metric(self, name: str) -> Metric:
        for metric in self.metrics:
            if metric.name == name:
                return metric
        raise KeyError(name)

    def make_core(self, num_envs: int, **env_kwargs: Any) -> Any:
        """A batched core of ``num_envs`` rows built from the env's keyword arguments."""
        return self.core_class()(num_envs=num_envs, **env_kwargs)


#: Every environment of the library, by id: filled by ``register_env`` as each environment's package is imported
#: (``import continuum_gym`` imports the library's own).
ENV_SPECS: dict[str, EnvSpec] = {}
#: The library's environment packages, imported (in this order) when ``continuum_gym`` is.
BUILTIN_ENVS = ("continuum_gym.envs.occlusion", "continuum_gym.envs.view_tracking")

ENV_IDS: list[str] = []


def register_env(spec: EnvSpec) -> EnvSpec:
    """Add an environment: its spec to ``ENV_SPECS``, its id (and goal id) to Gymnasium's registry.

    Registering the same spec again is harmless; another spec under a taken id is an error.
    """
    if not isinstance(spec, EnvSpec):
        raise ValueError(f"register_env takes an EnvSpec; got {type(spec).__name__}")
    known = ENV_SPECS.get(spec.env_id)
    if known is not None and known != spec:
        raise ValueError(f"env id {spec.env_id!r} is already registered with another EnvSpec; pick another id")
    ENV_SPECS[spec.env_id] = spec
    if spec.pixels:
        from continuum_gym.envs.pixels import register_pixels

        register_pixels(spec.env_id, spec.pixels)
    if spec.env_id not in registry:
        # No TimeLimit: each task truncates itself at its own duration (hold 150 steps, random 500-600,
        # circle and the case studies 1000 at the default control_dt; a recording or another control_dt
        # its own), so any registered bound would be wrong for some task. ``env.unwrapped.episode_steps``
        # gives the current episode's length for clients that size buffers.
        register(id=spec.env_id, entry_point=spec.entry_point, vector_entry_point=spec.vector_entry_point,
                 max_episode_steps=None)
    if spec.goal_id and spec.goal_id not in registry:  # goal-conditioned front end (HER); no vector version
        register(id=spec.goal_id, entry_point=spec.goal_entry_point, max_episode_steps=None)
    if spec.env_id not in ENV_IDS:
        ENV_IDS.append(spec.env_id)
    return spec


def register_envs() -> list:
    """Import the library's environment packages (each registers itself once); the registered ids."""
    for package in BUILTIN_ENVS:
        importlib.import_module(package)
    return ENV_IDS




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


__all__ = ["EnvSpec", "Metric", "EpisodeMetric", "ENV_SPECS", "ENV_IDS", "BUILTIN_ENVS", "register_env",
           "register_envs", "get_spec", "registered_kwargs", "registered_base",
           "REGISTER_HINT"]
