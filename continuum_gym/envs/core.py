"""What an environment declares about its rows, and what its Python side builds from a config.

An environment is three parts: its config dataclass (``EnvConfig``), its per-row compiled functions with the
declarations below (this module's ``RowFunctions``, usually in the env's ``kernel.py``), and a small
``EnvSpec``. The library does everything else (``envs/batched.py``): it allocates the state and output arrays
from these declarations, runs the rows in one compiled, threaded call (``envs/rows.py``), resets and
autoresets them, runs the model-error plant and the plug-ins, and reads ``info`` from the declared columns.

The row functions have fixed signatures (``envs/rows.py`` calls them)::

    make_work(model, params, plant) -> work                                # a thread's scratch
    observe_row(i, state, tasks, model, params, custom, work, out, plant)  # baseline command, obs, metrics
    step_row(i, state, actions, tasks, model, params, custom, work, out, plant)  # a control step, then observe

``state`` and ``out`` are the env's namedtuples of per-row arrays (``q``, ``steps``, ...; ``base_cmd``, ``obs``,
``metrics``, ``terms``, ``rewards``, ``flags``, ``faults``, ...): the library fills every field, by its name
(``STANDARD_ARRAYS``) or from ``RowFunctions.arrays``. ``model`` is the tuple of the robot's (and the
controller's, cameras') kernel bundles, ``params`` the env's own step parameters, ``custom`` a registered
controller's slot or None, ``plant`` the model-error arrays (``envs/model_error.py``) or None: with None the
model-error code is compiled out, and the same observation and metric code serves both.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from continuum_gym.envs.columns import Columns, Layout
from continuum_gym.envs.rows import register_rows

#: The arrays the library allocates by name: field -> (shape after the row axis, dtype), the shape's names read
#: from the ``Built`` record (``dof``, ``command``, ``obs``) or the declarations (``metrics``, ``flags``, ``terms``).
STANDARD_ARRAYS = {
    "q": (("dof",), np.float64), "steps": ((), np.int64), "base_cmd": (("command",), np.float64),
    "obs": (("obs",), np.float64), "metrics": (("metrics",), np.float64), "flags": (("flags",), np.int64),
    "terms": (("terms",), np.float64), "rewards": ((), np.float64), "limit": ((), np.int64),
}


@dataclass(frozen=True)
class Extra:
    """A per-row array an environment adds to its state or outputs (e.g. OcclusionAvoidance's ``gamma``)."""

    shape: tuple = ()  #: after the row axis
    dtype: Any = np.float64
    start: str = ""  #: the ``TaskBatch`` field a reset copies into it ("" : zero at reset)
    joint: bool = False  #: a joint of the action's layout, after ``q`` (``core.joint_values()``)
    circular: bool = False  #: an angle on the circle (its change is wrapped to [-pi, pi))


@dataclass
class Built:
    """What an environment's Python side makes of a config, once per core (``RowFunctions.build``)."""

    model: tuple  #: the row functions' ``model``: kernel bundles of the robot, the controller, the cameras
    params: Any  #: the row functions' ``params`` (an instance of ``RowFunctions.params``)
    action_dim: int
    obs_dim: int
    command: int  #: width of the cached baseline command ``base_cmd``
    context: Any  #: what the env's task sources read (``envs.tasks.TaskContext``)
    #: named objects the rest of the library reads as ``core.<name>`` (the built-in controller, cameras, ...)
    parts: dict = field(default_factory=dict)
    #: Python layers around the compiled step (OcclusionAvoidance's ``arc_plan`` planner): objects with
    #: ``reset_rows(rows)``, ``actions(actions, active) -> (actions, memo)`` and ``after_step(actions, memo)``
    layers: tuple = ()


@dataclass(frozen=True)
class RowFunctions:
    """An environment's compiled rows and what the library must know to run them (see the module docstring)."""

    make_work: Callable[..., Any]
    observe_row: Callable[..., Any]
    step_row: Callable[..., Any]
    params: Any  #: the namedtuple class of ``params``: the rows are found by it (``envs/rows.py``)
    state: Any  #: namedtuple class of ``state`` (fields: ``q``, ``steps`` and ``arrays``' names)
    outputs: Any  #: namedtuple class of ``out`` (``base_cmd``, ``obs``, ``metrics``, ``terms``, ``rewards``, ...)
    metrics: type[Columns]  #: the columns of ``metrics`` (each a declared value: info, evaluation)
    flags: type[Columns]  #: the columns of ``flags``; the last is ``NON_FINITE``, which the library sets
    observation: Layout  #: the observation's blocks (the env docstring's table)
    reward_terms: tuple[str, ...]  #: the built-in reward terms, in the order of ``terms``' columns
    build: Callable[[Any], Built]  #: config -> ``Built``
    controller_observation: Callable[[Any, int], dict]  #: (core, row) -> the dict a controller's predict reads
    #: the module through which a registered controller is compiled, checked and called (``envs/custom.py``)
    controller: str
    model_error: str = ""  #: the model-error plant's name for this env ("occlusion", "view"; "": none)
    arrays: dict = field(default_factory=dict)  #: the env's own per-row arrays: name -> ``Extra``
    #: ``info`` entries besides the declared columns and the library's own (``base_command``, ``task_id``, ...)
    info: tuple = ()
    #: the env's own methods of its core: name -> function(core, ...) (``core.davinci_configuration(row)``)
    methods: dict = field(default_factory=dict)
    terminated: str = "TERMINATED"  #: the ``flags`` column of a row that ended in failure
    truncated: str = "TRUNCATED"  #: ... and of a row whose task is over
    parallel_min_rows: int = 32  #: batches of fewer rows are stepped on the calling thread
    claim_block: int = 1  #: rows a thread claims at a time (larger where rows are cheap)

    def __post_init__(self) -> None:
        if list(self.flags.names())[-1:] != ["NON_FINITE"]:
            raise ValueError(f"{self.flags.__name__}: the last flag must be NON_FINITE (the library sets it); got "
                             f"{self.flags.names()}")
        for name in (*self.state._fields, *self.outputs._fields):
            if name not in STANDARD_ARRAYS and name not in self.arrays and name != "faults":
                raise ValueError(f"{self.state.__name__}/{self.outputs.__name__}: field {name!r} is neither one of the "
                                 f"library's arrays {sorted(STANDARD_ARRAYS)} nor declared in arrays")
        register_rows(self.params, self.make_work, self.observe_row, self.step_row)

    @property
    def joints(self) -> tuple[str, ...]:
        """The extra arrays that are joints of the action's layout, after ``q``."""
        return tuple(name for name, extra in self.arrays.items() if extra.joint)


__all__ = ["RowFunctions", "Built", "Extra", "STANDARD_ARRAYS"]
