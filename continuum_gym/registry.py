"""Plug-ins for researchers: their robots, task families, controllers and reward terms, by name.

    from continuum_gym.registry import register_robot, register_task, register_controller, register_reward_term

- ``register_robot(name, robot)``: a ``MultiBackboneRobot`` (1-4 segments) for OcclusionAvoidance or a
  ``ContinuumEndoscope`` for ViewTracking, then ``gym.make(id, robot=name)``.
- ``register_task(name, sampler, env=...)``: a family of tasks drawn per task id and split:
  ``sampler(task_id, split, rng) -> TipTrajectory | DaVinciTrajectory``; then ``gym.make(id, task=name)``.
- ``register_controller(name, rates, env=..., params=())``: a compiled rate function (the signatures
  below) that runs as the residual base inside the compiled step; then ``base_controller=name``.
- ``register_reward_term(name, fn, env=..., weight=1.0)``: a compiled per-row term or a batched numpy
  function of the per-step metrics; it is added to the reward (and to ``info["reward_terms"][name]``) of every
  env of that id made afterwards, with ``reward_weights={name: w}`` to change or zero its weight.

Compiled signatures (numba ``njit`` functions; arrays float64 and C-contiguous):

- OcclusionAvoidance controller: ``rates(q (dof,), gamma, p_des (3,), R_des (3, 3), v_des (3,), dt, robot,
  cone, params (m,), out (dof + 1,)) -> None`` writes the joint rates (rad/s; m/s for q_ins) and the
  endoscope rate (rad/s) into ``out``; ``robot`` is ``MultiBackboneRobot.kernel_args()``, ``cone`` is
  ``LensCone.kernel_args()``, ``dt`` the substep (s).
- ViewTracking controller: ``rates(q (6,), p_target (3,), R_target (3, 3), dt, robot, params (m,), out (6,))
  -> None``; ``robot`` is ``ContinuumEndoscope.kernel_args()``.
- Reward term (compiled): ``term(metrics (n_metrics,), flags (n_flags,) int64, action (k,), rates (k,),
  params (m,)) -> float64``, with the env's metric and flag columns (``Metric.*``, ``Flag.*`` of its
  ``outputs`` module) and the joint rates the
  robot applied over the step (base and residual, after rate and joint limits; the action's index layout).
  ``term(metrics, flags, action, params)`` (no rates) works too.
- Reward term (numpy, ``compiled=False``): ``fn(metrics: dict[str, (N,) array], actions (N, k), rates (N, k))
  -> (N,)`` (``rates`` optional), metrics named as in ``info``; applied once per batch step.

Every entry point checks its input and raises ``ValueError`` naming the parameter and the valid range.

Each registration records the importable module that made it (``origin_of``): configs, pickles and
``config.yml`` files refer to a plug-in as ``"module:name"``, so another process rebuilds it by importing
that module (``continuum_gym.plugins``). Anything registered at import of such a module travels.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from continuum_gym import plugins
from continuum_gym.envs.registered import (
    CONTROLLERS,
    ORIGINS,
    REWARD_TERMS,
    ROBOTS,
    TABLES,
    TASKS,
    CustomController,
    RewardTerm,
    controller_names,
    origin_of,
    record,
    reference_of,
    resolve,
    robot_names,
)
from continuum_gym.validation import closest, describe, number

if TYPE_CHECKING:
    from continuum_gym.robots import ContinuumEndoscope, MultiBackboneRobot

_NAME_HINT = "a non-empty string of letters, digits, '_' or '-'"


def _env(env: str | None) -> str:
    """The env id a registration is for; None: the library's first environment (OcclusionAvoidance)."""
    from continuum_gym.envs.spec import ENV_SPECS, get_spec

    return next(iter(ENV_SPECS)) if env is None else get_spec(env).env_id


def _name(name: Any, taken: Collection[str], what: str, replace: bool) -> str:
    if not isinstance(name, str) or not name or not all(c.isalnum() or c in "_-" for c in name):
        raise ValueError(f"name must be {_NAME_HINT}; got {describe(name)}")
    if name in taken and not replace:
        raise ValueError(f"name {name!r} is already a {what}; pick another name or pass replace=True")
    return name


def register_robot(name: str, robot: MultiBackboneRobot | ContinuumEndoscope, *, replace: bool = False) -> None:
    """Make ``robot`` available as ``gym.make(id, robot=name)``.

    A ``MultiBackboneRobot`` serves OcclusionAvoidance, a ``ContinuumEndoscope`` ViewTracking.
    """
    from continuum_gym.envs.spec import ENV_SPECS
    from continuum_gym.plugins import load_object as load

    kinds = {spec.env_id: load(spec.robot_class) for spec in ENV_SPECS.values() if spec.robot_class}
    env = next((env_id for env_id, kind in kinds.items() if isinstance(robot, kind)), None)
    if env is None:
        names = " or ".join(sorted({f"a {kind.__name__}" for kind in kinds.values()}))
        raise ValueError(f"robot must be {names}; got {describe(robot)}")
    ROBOTS[env][_name(name, ROBOTS[env], "registered robot", replace)] = robot
    record("robot", env, name, plugins.caller_origin())


def register_task(name: str, sampler: Callable, *, env: str | None = None, count: int | None = None,
                  replace: bool = False) -> None:
    """A family of tasks, one instance per task id and split: ``sampler(task_id, split, rng)``.

    Args:
        name: the task's name, passed as ``gym.make(env, task=name)``.
        sampler: returns a ``TipTrajectory`` (OcclusionAvoidance) or a ``DaVinciTrajectory`` (ViewTracking);
            ``rng`` is a ``numpy.random.Generator`` seeded from (name, split, task_id), so draws repeat.
        env: the environment id the family belongs to.
        count: number of distinct instances (None: unbounded).
    """
    from continuum_gym.envs.spec import get_spec
    from continuum_gym.envs.task_sources import SampledTasks
    from continuum_gym.plugins import load_object as load

    env = _env(env)
    if name in get_spec(env).config_class.builtin_tasks:
        raise ValueError(f"name {name!r} is a built-in task of {env}; pick another name")
    if not callable(sampler):
        raise ValueError(f"sampler must be callable as sampler(task_id, split, rng); got {describe(sampler)}")
    if count is not None:
        count = int(number(count, "count (task instances)", low=1))
    kind = load(get_spec(env).config_class.trajectory_class)
    source = SampledTasks(_name(name, TASKS[env], "registered task", replace), sampler, kind, count)
    source.draw("train", 0)  # fails now, naming the problem, rather than at the first reset
    TASKS[env][name] = source
    record("task", env, name, plugins.caller_origin())


def register_controller(name: str, rates: Callable[..., None], *, env: str | None = None, params: Sequence[float] = (),
                        doc: str = "", replace: bool = False) -> CustomController:
    """A compiled rate function as the residual base: ``gym.make(env, base_controller=name)``.

    The function is compiled for the documented signature here (``ValueError`` if it does not fit) and
    called once on a test state, which must give a finite command.
    """
    from continuum_gym.envs.registered import add_controller
    from continuum_gym.envs.spec import get_spec

    env = _env(env)
    if name in get_spec(env).baselines:
        raise ValueError(f"name {name!r} is a built-in baseline of {env}; pick another name")
    name = _name(name, CONTROLLERS[env], "registered controller", replace)
    values = np.ascontiguousarray(np.asarray(params, dtype=np.float64).reshape(-1))
    if not np.all(np.isfinite(values)):
        raise ValueError(f"params must be finite numbers; got {describe(values)}")
    module = get_spec(env).row_functions().controller
    if not module:
        raise ValueError(f"{env} takes no registered controllers (its RowFunctions name no controller module)")
    return add_controller(name, env, rates, values, doc, module, plugins.caller_origin())


def register_reward_term(name: str, fn: Callable[..., Any], *, env: str | None = None, weight: float = 1.0,
                         compiled: bool = True, params: Sequence[float] = (), replace: bool = False) -> RewardTerm:
    """A named reward term, added (times ``weight``) to the reward of every env of ``env`` made afterwards.

    ``compiled=True``: ``fn(metrics (n_metrics,), flags (n_flags,) int64, action (k,), rates (k,), params (m,))
    -> float``, a numba function run per row after the step; ``compiled=False``: ``fn(metrics: dict of (N,)
    arrays, actions (N, k), rates (N, k)) -> (N,)``, a batched numpy function (once per batch step).
    ``rates`` are the joint rates the robot applied over the step, base and residual together, after rate
    limits and joint limits (rad/s, m/s for insertion; OcclusionAvoidance adds the endoscope's rotation
    rate last), in the action's index layout; both signatures may leave ``rates`` out.
    """
    from continuum_gym.envs.custom import check_reward_term, takes_rates
    from continuum_gym.envs.spec import get_spec

    env = _env(env)
    builtin = get_spec(env).config_class.default_weights
    if name in builtin:
        raise ValueError(f"name {name!r} is a built-in reward term of {env}; pick another name")
    name = _name(name, REWARD_TERMS[env], "registered reward term", replace)
    weight = number(weight, "weight", low=0.0, high=1e6)
    values = np.ascontiguousarray(np.asarray(params, dtype=np.float64).reshape(-1))
    call = check_reward_term(RewardTerm(name, env, fn, weight, bool(compiled), values))
    term = RewardTerm(name, env, fn, weight, bool(compiled), values, call=call,
                      with_rates=bool(compiled) or takes_rates(fn, 2))
    REWARD_TERMS[env][name] = term
    record("reward term", env, name, plugins.caller_origin())
    return term


def unregister(name: str, env: str | None = None) -> None:
    """Remove a registered robot, task, controller or reward term of ``env`` by name."""
    env = _env(env)
    for table in (ROBOTS, TASKS, CONTROLLERS, REWARD_TERMS):
        if name in table[env]:
            del table[env][name]
            for key in [key for key in ORIGINS[env] if key[1] == name and table is TABLES[key[0]]]:
                del ORIGINS[env][key]
            return
    known = [*ROBOTS[env], *TASKS[env], *CONTROLLERS[env], *REWARD_TERMS[env]]
    raise ValueError(f"nothing named {name!r} is registered for {env}{closest(name, known)}; registered: {known}")


__all__ = ["register_robot", "register_task", "register_controller", "register_reward_term", "unregister",
           "origin_of", "reference_of", "resolve", "robot_names", "controller_names", "CustomController", "RewardTerm",
           "ROBOTS", "TASKS", "CONTROLLERS", "REWARD_TERMS", "ORIGINS"]
