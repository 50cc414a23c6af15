"""Typed, frozen configurations of the environments: what they share, built and validated in one place.

Each environment's config (``OcclusionConfig`` in ``envs/occlusion/config.py``, ``ViewTrackingConfig`` in
``envs/view_tracking/config.py``) subclasses ``EnvConfig`` and holds everything that defines it: robot,
endoscope (cone / da Vinci), limits, task, baseline, residual, reward weights and timing. Users keep
passing the flat keyword arguments of ``gym.make(id, **kwargs)`` (and rl-zoo's ``env_kwargs``); the
env builds its config from them with ``from_kwargs``, which validates every value once and says which
parameter is wrong and what is valid. ``to_dict`` writes plain YAML values (each training run's
``config.yml``), ``from_dict`` reads them back (``continuum-gym evaluate``), and ``arguments_table``
is the docstring's Arguments table (name, type, default, unit, meaning).

A config may also be passed whole: ``gym.make(id, config=OcclusionConfig(task="random"))``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

import numpy as np

from continuum_gym.validation import (
    choice,
    closest,
    describe,
    integer,
    number,
    weights,
)

if TYPE_CHECKING:
    from continuum_gym.envs.task_sources import TaskSource

_Robot = TypeVar("_Robot")

TASK_SPLITS = ("train", "validation", "test")
class UnknownArgumentError(TypeError, ValueError):
    """An env keyword argument that does not exist.

    A ``TypeError`` like Python's own "unexpected keyword argument" (clients such as torchrl probe
    optional keywords and catch it), and a ``ValueError`` like every other bad input of the library.
    """


#: Largest control step (s): every task lasts at least 1.5 s, so an episode has at least 15 steps.
MAX_CONTROL_DT = 0.1
MAX_SUBSTEPS = 1000
MAX_RESIDUAL_SCALE = 10.0
#: Reward weights are scale factors of terms of order 1; beyond this the reward overflows to inf.
MAX_REWARD_WEIGHT = 1e6
MAX_GRID = 401


def spec(unit: str = "", doc: str = "", type_name: str = "") -> dict:
    """Field metadata read by ``arguments_table``."""
    return {"unit": unit, "doc": doc, "type": type_name}


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return None


def model_error_field() -> Any:
    """The ``model_error`` keyword of every env (one definition; a dataclass field cannot be shared)."""
    return field(default="none", metadata=spec(
        doc="the true robot's difference from the model the controller uses: `none`, `mild`, `severe` (presets) or "
            "a `ModelError` (docs/model-error.md)", type_name="str or ModelError"))


def randomize_field() -> Any:
    """The ``randomize_model_error`` keyword of every env."""
    return field(default=False, metadata=spec(
        doc="draw a new model error per episode within the preset's ranges (else fixed per split and task id)",
        type_name="bool"))


@dataclass(frozen=True)
class EnvConfig:
    """What both configurations share: the keyword interface, serialisation and the Arguments table."""

    #: Gymnasium id the configuration belongs to (set by subclasses).
    env_id: ClassVar[str] = ""
    baselines: ClassVar[tuple] = ()
    #: "module:name"s of registered controllers the package ships as bases, also valid by their bare names (the
    #: module registers the controller when first named); ``continuum-gym evaluate`` gives each a row beside the
    #: analytic baselines
    packaged_controllers: ClassVar[tuple] = ()
    #: Keywords whose objects (robot, endoscope, model error) may also be given as ``to_dict()`` writes them.
    object_keywords: ClassVar[tuple] = ("robot", "model_error")
    #: "module:Class" of the robots the env takes (``registry.register_robot`` checks a plug-in against it)
    robot_class: ClassVar[str] = ""
    #: The trajectory class of the env's tasks (``TipTrajectory`` / ``DaVinciTrajectory``), as "module:Class".
    trajectory_class: ClassVar[str] = ""
    default_weights: ClassVar[dict] = {}  #: the built-in reward terms' default weights
    residual_spaces: ClassVar[tuple] = ()  #: the values of ``residual_space``
    builtin_tasks: ClassVar[tuple] = ()  #: the built-in task families
    test_only_tasks: ClassVar[tuple] = ()  #: ... of which these are fixed evaluation tasks (test split only)

    #: What a NaN or an inf in a row does (``envs/faults.py``): a field of every env, the library's own and yours.
    on_non_finite: str = field(default="raise", kw_only=True, metadata=spec(
        doc="what a value that is not finite (NaN or inf, e.g. from a plug-in) does: `raise` a `NonFiniteError` "
            "naming the plug-in, the row and the step, or `truncate`: the episode ends as truncated with "
            "`info['non_finite']` True and NaN metrics (never a score; `evaluate` refuses such episodes)",
        type_name="str"))

    #: What the env observes (issue 56, ``envs/pixels.py``): fields of every env, read by the front ends, never by
    #: the core, so that a run's ``config.yml`` and ``save_config`` rebuild a pixel policy's env.
    obs_mode: str = field(default="state", kw_only=True, metadata=spec(
        doc="the observation: `state` (the flat Box), or a Dict of images and the measured `state`: `rgb`, `depth`, "
            "`segmentation`, `rgbd`, `rgb+depth+segmentation` (docs/rendering.md)", type_name="str"))
    image_size: Any = field(default=64, kw_only=True, metadata=spec(
        unit="pixels", doc="side of a square image, or (H, W); each in [16, 512] (image modes only)",
        type_name="int or (int, int)"))

    if TYPE_CHECKING:  # fields every subclass defines (declared for mypy only: here they would be fields)
        task: Any  # a task family's name, recorded trajectories or a TaskSource
        task_split: str
        base_controller: str | None
        residual_scale: float
        reward_weights: dict
        control_dt: float
        substeps: int
        max_episode_steps: int | None
        robot: Any
        model_error: Any  # a preset's name or a ModelError
        randomize_model_error: bool

    @classmethod
    def keyword_names(cls) -> tuple:
        return tuple(f.name for f in fields(cls))

    @classmethod
    def from_kwargs(cls, **kwargs: Any) -> EnvConfig:
        """Build from the keyword arguments of ``gym.make``; an unknown name raises ``UnknownArgumentError``."""
        names = cls.keyword_names()
        for key in list(kwargs):
            if key not in names:
                raise UnknownArgumentError(f"{cls.env_id} got an unexpected keyword argument {key!r}"
                                           f"{closest(key, names)}; valid arguments: {sorted(names)}")
            elif key in cls.object_keywords and isinstance(kwargs[key], dict) and "type" in kwargs[key]:
                kwargs[key] = cls._build_object(key, dict(kwargs[key]))  # as config.yml writes it
        return cls(**kwargs)

    def replace(self, **changes: Any) -> EnvConfig:
        """A copy with ``changes`` applied (validated again)."""
        return type(self).from_kwargs(**{**self.as_kwargs(), **changes})

    def as_kwargs(self) -> dict:
        """The field values as keyword arguments (objects, not serialised)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def to_dict(self, recorded: str = "describe") -> dict:
        """Plain YAML/JSON values of every field (objects as their ``to_dict()`` with a ``type`` key).

        A recorded task is written as its description (``recorded="describe"``: name, counts and a digest, as
        in a run's ``config.yml``) or with its samples inline (``"inline"``: nested lists, so that ``from_dict``
        rebuilds it, as a Minari dataset stores it).
        """
        choice(recorded, ("describe", "inline"), "recorded")
        out = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if hasattr(value, "to_dict"):
                value = {"type": type(value).__name__, **value.to_dict()}
            elif f.name == "task" and not isinstance(value, str) and recorded == "inline":
                from continuum_gym.envs.trajectories import samples_of

                value = {"type": "recorded", "data": [{name: (v.tolist() if isinstance(v, np.ndarray) else v)
                                                       for name, v in samples_of(t).items()}
                                                      for t in self.task_source.trajectories]}  # type: ignore[attr-defined]
            elif f.name == "task" and not isinstance(value, str):
                value = {"type": "recorded", "description": self.task_source.describe()}
            elif f.name in ("task", "base_controller") and isinstance(value, str):
                value = self._reference(f.name, value)
            elif isinstance(value, tuple):
                value = list(value)
            elif isinstance(value, dict):
                value = dict(value)
            out[f.name] = value
        modules = _plugin_modules(self)
        if modules:
            out["plugins"] = modules
        return out

    def _reference(self, key: str, name: str) -> str:
        """A registered task family or controller as ``"module:name"`` (another process imports the module)."""
        from continuum_gym.envs import registered

        kind, table = ("task", registered.TASKS) if key == "task" else ("controller", registered.CONTROLLERS)
        return registered.reference_of(kind, self.env_id, name) if name in table[self.env_id] else name

    def __reduce__(self):
        # Pickles carry the plug-ins' modules: unpickling imports them (registering the plug-ins) and
        # rebuilds the config through its checks, in any process.
        kwargs = self.as_kwargs()
        for key in ("task", "base_controller"):
            if isinstance(kwargs[key], str):
                kwargs[key] = self._reference(key, kwargs[key])
        return _config_from_pickle, (type(self), kwargs, _plugin_modules(self))

    @classmethod
    def from_dict(cls, data: dict) -> EnvConfig:
        """Inverse of ``to_dict`` (objects are rebuilt from their dicts)."""
        if not isinstance(data, dict):
            raise ValueError(f"an env config must be a mapping of argument -> value; got {describe(data)}")
        data = dict(data)
        if "plugins" in data:  # the modules that register the config's plug-ins
            from continuum_gym import plugins

            plugins.import_modules(data.pop("plugins") or [], "plugins (a module of the config)")
        kwargs = {}
        for key, value in data.items():
            if isinstance(value, dict) and "type" in value:
                value = cls._build_object(key, dict(value))
            kwargs[key] = value
        return cls.from_kwargs(**kwargs)

    @classmethod
    def _build_object(cls, key: str, value: dict) -> Any:
        """Rebuild a robot, cone or da Vinci endoscope from its ``to_dict()`` (recorded tasks cannot be)."""
        from continuum_gym.envs.model_error import ModelError
        from continuum_gym.geometry.lens_cone import LensCone
        from continuum_gym.robots import (
            ContinuumEndoscope,
            DaVinciEndoscope,
            MultiBackboneRobot,
        )

        kinds = {"MultiBackboneRobot": MultiBackboneRobot, "LensCone": LensCone, "DaVinciEndoscope": DaVinciEndoscope,
                 "ModelError": ModelError}
        kind = value.pop("type")
        if kind == "recorded" and key == "task" and "data" in value:  # samples written by to_dict("inline")
            from continuum_gym.envs.trajectories import from_samples

            return [from_samples(data) for data in value["data"]]
        if kind == "ContinuumEndoscope":
            lower, upper = value.pop("joint_limits", (None, None))
            limits = None if lower is None else ([-math.inf if v is None else v for v in lower],
                                                 [math.inf if v is None else v for v in upper])
            return ContinuumEndoscope(**value, joint_limits=limits)
        if kind == "MultiBackboneRobot" and "lengths" in value:
            value["lengths"] = tuple(value["lengths"])
        if kind in kinds:
            return kinds[kind](**value)
        raise ValueError(f"{cls.env_id}: argument {key!r} was recorded as {kind!r}, which cannot be rebuilt from a "
                         "config file; pass it again")

    @property
    def task_source(self) -> TaskSource:
        """The ``TaskSource`` the task resolves to (a built-in family, recorded data or a registered family)."""
        return self._task_source  # type: ignore[attr-defined]  # set by check_common (object.__setattr__; not a field)

    @classmethod
    def all_default_weights(cls) -> dict:
        """The built-in reward terms' default weights and those of the terms registered for this env."""
        from continuum_gym.envs import registered

        terms = registered.REWARD_TERMS[cls.env_id]
        return {**cls.default_weights, **{name: term.weight for name, term in terms.items()}}

    @classmethod
    def arguments_table(cls) -> str:
        """Markdown table of the keyword arguments: name, type, default, unit, meaning."""
        rows = ["| Argument | Type | Default | Unit | Meaning |", "|---|---|---|---|---|"]
        shared = {f.name for f in fields(EnvConfig)}  # the env's own arguments first, then those every env has
        for f in sorted(fields(cls), key=lambda f: f.name in shared):
            meta = f.metadata
            default = _default(f)
            shown = "paper's" if default is None and f.name in cls.object_keywords else repr(default)
            rows.append(f"| `{f.name}` | {meta.get('type') or f.type} | `{shown}` | {meta.get('unit', '') or '-'} | "
                        f"{meta.get('doc', '')} |")
        return "\n".join(rows)


def check_common(config: EnvConfig) -> None:
    """The keywords every env shares, checked against the config's own task families (``builtin_tasks``)."""
    from continuum_gym.envs import registered
    from continuum_gym.envs.faults import ON_NON_FINITE
    from continuum_gym.envs.task_sources import resolve_task

    set_ = object.__setattr__
    choice(config.on_non_finite, ON_NON_FINITE, "on_non_finite")
    from continuum_gym.envs.obs_modes import check_image_size, check_obs_mode

    check_obs_mode(config.obs_mode)
    set_(config, "image_size", check_image_size(config.image_size))
    tasks, test_only = config.builtin_tasks, config.test_only_tasks
    if isinstance(config.task, str) and config.task not in tasks and (
            ":" in config.task or config.task in registered.TASKS[config.env_id]):
        set_(config, "task", registered.resolve("task", config.env_id, config.task))
    elif isinstance(config.task, str) and config.task not in tasks and config.task not in registered.TASKS[config.env_id]:
        from continuum_gym import plugins

        plugins.load_known()  # a task family of a plug-in module that this process has not imported yet
    source = resolve_task(config.task, config)
    set_(config, "_task_source", source)
    choice(config.task_split, TASK_SPLITS, "task_split")
    if source.test_only and config.task_split != "test":
        raise ValueError(f"task={config.task!r} is a fixed evaluation task of the paper: use task_split='test' "
                         f"(training draws from {[t for t in tasks if t not in test_only]})")
    set_(config, "base_controller", _resolve_controller(config))
    if isinstance(config.reward_weights, dict) and not set(config.reward_weights) <= set(config.all_default_weights()):
        from continuum_gym import plugins

        plugins.load_known()  # a reward term of a plug-in module that this process has not imported yet
    set_(config, "reward_weights", weights(config.reward_weights, config.all_default_weights(), high=MAX_REWARD_WEIGHT))
    set_(config, "residual_scale", number(config.residual_scale, "residual_scale", low=0.0, high=MAX_RESIDUAL_SCALE,
                                          low_open=True, unit="fraction of the action scale"))
    set_(config, "control_dt", number(config.control_dt, "control_dt", low=0.0, high=MAX_CONTROL_DT, low_open=True,
                                      unit="s"))
    set_(config, "substeps", integer(config.substeps, "substeps", low=1, high=MAX_SUBSTEPS))
    if config.max_episode_steps is not None:
        set_(config, "max_episode_steps", integer(config.max_episode_steps, "max_episode_steps", low=1, high=10**9))


def check_model_error(config: EnvConfig, env: str, n_segments: int) -> None:
    from continuum_gym.envs.model_error import check_randomize, resolve_model_error

    object.__setattr__(config, "model_error", resolve_model_error(config.model_error, env, n_segments))
    object.__setattr__(config, "randomize_model_error", check_randomize(config.randomize_model_error,
                                                                          config.model_error))


def resolve_robot(robot: Any, kind: type[_Robot], env_id: str) -> _Robot:
    """A robot instance from an instance, a registered name (or ``"module:name"``) or None (the paper's)."""
    from continuum_gym.envs import registered

    if robot is None:
        return kind()
    if isinstance(robot, str):
        try:
            return registered.ROBOTS[env_id][registered.resolve("robot", env_id, robot)]
        except ValueError as error:
            raise ValueError(f"robot {robot!r} is not registered (continuum_gym.registry.register_robot), nor a "
                             f"{kind.__name__}: {error}") from None
    if not isinstance(robot, kind):
        raise ValueError(f"robot must be a {kind.__name__}, a registered robot's name or None; got {describe(robot)}")
    return robot


def _resolve_controller(config: EnvConfig) -> str | None:
    """The base controller's name: a built-in baseline, a registered controller (or ``"module:name"``) or None."""
    from continuum_gym.envs import registered
    value = config.base_controller
    builtin = config.baselines
    if value is None or (isinstance(value, str) and value in builtin):
        return value
    if not isinstance(value, str):
        choice(value, builtin, "base_controller")
    # a controller the package ships goes by its bare name: its module registers it on first use (an entry point
    # would import it, and its compiled kernels, in every process that loads plug-ins, even for `--help`)
    packaged = {reference.rpartition(":")[2]: reference for reference in config.packaged_controllers}
    if value in packaged and value not in registered.CONTROLLERS[config.env_id]:
        value = packaged[value]
    try:
        return registered.resolve("controller", config.env_id, value)
    except ValueError as error:
        known = [*builtin, *packaged]
        raise ValueError(f"base_controller must be one of {known}, a registered controller or None"
                         f"{closest(value, known) if ':' not in value else ''}; got {value!r}. If it is your own "
                         f"controller: {error}") from None


def _plugin_modules(config: EnvConfig) -> list:
    """The importable modules of the plug-ins a config uses (controller, task family, reward terms)."""
    from continuum_gym.envs import registered

    env = config.env_id
    names = [("reward term", name) for name in registered.REWARD_TERMS[env]]
    if config.base_controller in registered.CONTROLLERS[env]:
        names.append(("controller", config.base_controller))
    if isinstance(config.task, str) and config.task in registered.TASKS[env]:
        names.append(("task", config.task))
    modules = [registered.origin_of(kind, env, name) for kind, name in names]
    return sorted({module for module in modules if module})


def _config_from_pickle(cls: type[EnvConfig], kwargs: dict, modules: list) -> EnvConfig:
    """Unpickling: import the plug-ins' modules (registering them in this process), then rebuild and check."""
    from continuum_gym import plugins

    plugins.import_modules(modules)
    return cls.from_kwargs(**kwargs)


__all__ = ["UnknownArgumentError", "EnvConfig", "TASK_SPLITS", "spec", "model_error_field", "randomize_field",
           "check_common", "check_model_error", "resolve_robot"]
