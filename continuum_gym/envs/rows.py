"""The library's batched loop: one compiled call steps every row of any environment with the env's row functions.

An environment writes what one row does (``envs.core.RowFunctions``): ``make_work(model, params, plant)`` (a
thread's scratch), ``observe_row(i, ...)`` (the row's baseline command, observation, metrics and flags at its
state) and ``step_row(i, ...)`` (one control step, then the observation and the reward). This module owns
everything around them: the loop over rows, the row claims that share a batch among threads
(``envs/row_claims``), the reset rows that are only observed (``OBSERVE_ONLY``), and the check that no row
holds a NaN afterwards (``common_kernels.mark_non_finite`` is called here, for every env alike).

The loop is compiled once per environment: the row functions are found by the type of the env's ``params``
bundle (a namedtuple class the env registers with ``register_rows``), through numba's ``overload``, so
they are called directly (and inlined where they ask for it), as if the env had written the loop itself.
Its cached code depends on the row functions' modules too: their code is part of the cache key
(``rows_cache_key``), so an edited row function is compiled again, never served stale.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from numba import types
from numba.extending import overload

from continuum_gym.envs.common_kernels import OBSERVE_ONLY, mark_non_finite, mark_non_finite_reward
from continuum_gym.envs.row_claims import first_rows, next_rows
from continuum_gym.robots.compiled import kernel

#: The registered row functions: params namedtuple class -> (make_work, observe_row, step_row).
ROWS: dict[type, tuple[Callable[..., Any], Callable[..., Any], Callable[..., Any]]] = {}


def register_rows(params: type, make_work: Callable[..., Any], observe_row: Callable[..., Any],
                  step_row: Callable[..., Any]) -> None:
    """Make ``step_batch`` run these row functions for the envs whose ``params`` bundle is of class ``params``."""
    ROWS[params] = (make_work, observe_row, step_row)


def _rows_of(params_type: Any) -> tuple | None:
    key: Any = getattr(params_type, "instance_class", None)
    return ROWS.get(key)


def rows_cache_key(signature: Any) -> bytes:
    """The source code the loop compiled for ``signature`` depends on: the modules of its env's row functions."""
    import inspect

    from continuum_gym.robots.compiled import code_hash

    for argument in signature:
        rows = _rows_of(argument)
        if rows is not None:
            modules = sorted({inspect.getsourcefile(getattr(f, "py_func", f)) or "" for f in rows})
            return "".join(code_hash(open(path, "rb").read()) for path in modules if path).encode()
    return b""


def by_plant(nominal: Callable[..., Any], with_plant: Callable[..., Any]) -> Callable[..., Any]:
    """A function that numba resolves when it compiles a caller, by the type of its last argument ``plant``:
    ``nominal(...)`` where ``plant`` is None (no model error), ``with_plant(...)`` otherwise (same arguments),
    inlined into the caller.

    For what differs in *type* between the two (a thread's work, the true robot's arrays): numba prunes a branch
    ``if plant is None`` only where ``plant`` is None, so a function whose branches return different types needs
    the choice made at compile time.
    """
    import inspect

    names = list(inspect.signature(getattr(nominal, "py_func", nominal)).parameters)
    arguments = ", ".join(names)
    namespace: dict[str, Any] = {}
    exec(f"def chosen({arguments}):\n    raise NotImplementedError\n", namespace)  # noqa: S102 - our own names
    chosen = namespace["chosen"]
    exec(f"def make(function):\n    def impl({arguments}):\n        return function({arguments})\n    return impl\n",
         namespace)  # noqa: S102 - as above
    make = namespace["make"]

    def choose(*types_):
        return make(nominal if isinstance(types_[-1], types.NoneType) else with_plant)

    overload(chosen, inline="always")(_with_signature(choose, names))
    chosen.__name__ = chosen.__qualname__ = f"by_plant_{getattr(nominal, '__name__', 'nominal')}"
    return chosen


def _with_signature(function: Callable[..., Any], names: list[str]) -> Callable[..., Any]:
    """``function(*args)`` as a function of the parameters ``names`` (numba reads an overload's signature)."""
    namespace: dict[str, Any] = {"function": function}
    exec(f"def typed({', '.join(names)}):\n    return function({', '.join(names)})\n", namespace)  # noqa: S102
    return namespace["typed"]


# Stand-ins the loop calls: numba replaces each by code made for the registered env's row functions, found by the
# type of the params bundle.
def make_work(model: Any, params: Any, plant: Any) -> Any:  # pragma: no cover - typed by its overload only
    raise NotImplementedError


@overload(make_work, inline="always")
def _make_work(model, params, plant):
    rows = _rows_of(params)
    if rows is None:
        return None
    function = rows[0]

    def impl(model, params, plant):
        return function(model, params, plant)

    return impl


def step_block(state: Any, actions: Any, active: Any, tasks: Any, model: Any, params: Any, custom: Any, out: Any,  # pragma: no cover
               plant: Any, work: Any, start: int, stop: int) -> None:
    raise NotImplementedError


def _loop(observe_row: Callable[..., Any], step_row: Callable[..., Any]) -> Callable[..., Any]:
    """The loop over a block of rows [start, stop) with the env's row functions, and the library's check that no
    row holds a NaN afterwards (``common_kernels.mark_non_finite``; the env's last flag is ``NON_FINITE``)."""
    def impl(state, actions, active, tasks, model, params, custom, out, plant, work, start, stop):
        non_finite = out.flags.shape[1] - 1
        for i in range(start, stop):
            mode = active[i]
            if mode == OBSERVE_ONLY:
                observe_row(i, state, tasks, model, params, custom, work, out, plant)
                mark_non_finite(i, state.q[i], out, non_finite)
            elif mode != 0:
                step_row(i, state, actions, tasks, model, params, custom, work, out, plant)
                mark_non_finite(i, state.q[i], out, non_finite)
                mark_non_finite_reward(i, out, non_finite)

    return impl


# The loop over a block of rows is compiled once per environment as a function of its own, with the env's row
# functions inlined where they ask for it (ViewTracking: a call per row would pass every array of the bundles as
# flattened arguments, a sizeable cost against a row of ~3 us) and called where they are kernels of their own
# (OcclusionAvoidance, ~20 us a row); with the arguments' types (so that a row function's lines for the model-error
# plant are compiled out where ``plant`` is None) and without reference counts (``kernel(borrows=True)``: the rows
# only borrow the arrays of the bundles).
@overload(step_block, jit_options={"_nrt": False, "no_cpython_wrapper": True})  # type: ignore[typeddict-unknown-key]
def _step_block(state, actions, active, tasks, model, params, custom, out, plant, work, start, stop):
    rows = _rows_of(params)
    return None if rows is None else _loop(rows[1], rows[2])


@kernel(nogil=True, cache_key=rows_cache_key)
def step_batch(state, actions, active, tasks, model, params, custom, out, plant, claims, start, stop):
    """Advance every row in [start, stop) whose ``active`` is 1 by one control step, and observe a row marked
    ``OBSERVE_ONLY`` at its state (a reset). Releases the GIL: the threads of a batch each claim blocks of rows
    from ``claims`` (``envs/row_claims``; ``SERIAL``: every row on this thread); each row is computed by the
    same row function whichever thread runs it, so threaded results equal serial ones bit for bit."""
    work = make_work(model, params, plant)
    first, last = first_rows(claims, start, stop)
    while first < last:
        step_block(state, actions, active, tasks, model, params, custom, out, plant, work, first, last)
        first, last = next_rows(claims, start, stop, first, last)


__all__ = ["register_rows", "step_batch", "ROWS", "rows_cache_key", "by_plant"]
