"""What is registered: the plug-in tables the environments read, and the records of where each came from.

``continuum_gym.registry`` is the public module that fills these tables (its ``register_*`` functions check
what they are given with the environments' own code); the environments only read them, so this module sits below
both and imports no environment module.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from continuum_gym import plugins


@dataclass(frozen=True)
class CustomController:
    """A registered controller: its compiled rate function, parameters and an SB3-style ``predict``."""

    name: str
    env_id: str
    rates: Any
    params: np.ndarray
    doc: str = ""
    #: the env's module that compiles, checks and calls it (``RowFunctions.controller``)
    module: str = ""

    def predict(self, observation: dict[str, Any], state: tuple[np.ndarray, ...] | None = None,
                episode_start: np.ndarray | None = None, deterministic: bool = False
                ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """SB3 ``predict`` on a controller observation dict (``core.controller_observation(row)``)."""
        from continuum_gym.envs.custom import controller_predict

        return controller_predict(self, observation), state


@dataclass(frozen=True)
class RewardTerm:
    """A registered reward term: compiled (per row, inside the step) or batched numpy (after it)."""

    name: str
    env_id: str
    fn: Any
    weight: float
    compiled: bool
    params: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: What the step calls: ``fn`` itself, or a compiled ``fn`` without ``rates`` wrapped into the signature.
    call: Any = field(default=None, repr=False, compare=False)
    #: Whether the numpy ``fn`` takes the applied rates (its third argument).
    with_rates: bool = True


# One table per kind, keyed by env id (an env's entry appears on first use: any registered env has one).
ROBOTS: defaultdict[str, dict[str, Any]] = defaultdict(dict)
TASKS: defaultdict[str, dict[str, Any]] = defaultdict(dict)
CONTROLLERS: defaultdict[str, dict[str, CustomController]] = defaultdict(dict)
REWARD_TERMS: defaultdict[str, dict[str, RewardTerm]] = defaultdict(dict)
#: The importable module each plug-in was registered from (None: __main__, a notebook), per env and name.
ORIGINS: defaultdict[str, dict[tuple[str, str], str | None]] = defaultdict(dict)
TABLES = {"robot": ROBOTS, "task": TASKS, "controller": CONTROLLERS, "reward term": REWARD_TERMS}


def record(kind: str, env: str, name: str, origin: str | None) -> None:
    """Remember that ``origin`` (an importable module, or None) registered the ``kind`` ``name`` of ``env``."""
    ORIGINS[env][(kind, name)] = origin
    plugins.remember(origin)


def origin_of(kind: str, env: str, name: str) -> str | None:
    """The module that registered the ``kind`` (robot, task, controller, reward term) ``name`` of ``env``."""
    return ORIGINS.get(env, {}).get((kind, name))


def reference_of(kind: str, env: str, name: str) -> str:
    """``"module:name"`` for a plug-in registered at import of an importable module, else ``name``."""
    return plugins.reference(name, origin_of(kind, env, name))


def resolve(kind: str, env: str, value: str) -> str:
    """The registered name that ``value`` (a name or ``"module:name"``) refers to, importing its module."""
    return plugins.lookup(TABLES[kind][env], value, f"{kind}", env)


def add_controller(name: str, env: str, rates: Any, params: np.ndarray, doc: str, module: str,
                   origin: str | None) -> CustomController:
    """File a controller after checking it (compiled for its env's signature and tried once): ``registry``'s
    ``register_controller`` does this for a researcher's, an env package for a controller it ships."""
    from continuum_gym.envs.custom import check_controller

    controller = CustomController(name, env, rates, params, doc, module)
    check_controller(controller)
    CONTROLLERS[env][name] = controller
    record("controller", env, name, origin)
    return controller


def robot_names(env_id: str) -> tuple:
    return tuple(ROBOTS.get(env_id, {}))


def controller_names(env_id: str) -> tuple:
    return tuple(CONTROLLERS.get(env_id, {}))


__all__ = ["add_controller", "TABLES", "record", "CustomController", "RewardTerm", "ROBOTS", "TASKS", "CONTROLLERS",
           "REWARD_TERMS", "ORIGINS", "origin_of", "reference_of", "resolve", "robot_names", "controller_names"]
