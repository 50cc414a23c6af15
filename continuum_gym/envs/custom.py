"""Registered controllers and reward terms inside the compiled step (see ``continuum_gym.registry``).

A user's numba function is called through a first-class function pointer held in a typed list, so the
step kernels are compiled (and cached on disk) once for every function of a signature: registering a
controller compiles only the controller itself. The slots are always passed: an empty one (``active``
False, no terms) costs one branch per step and leaves the built-in arithmetic untouched.
"""

from __future__ import annotations

import inspect
import math
from collections import namedtuple
from collections.abc import Callable, Sequence
from types import ModuleType
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numba import types
from numba.core.registry import CPUDispatcher
from numba.typed import List

from continuum_gym.robots.compiled import kernel
from continuum_gym.validation import describe

if TYPE_CHECKING:
    from numba.core.typing.templates import Signature

#: A controller slot: ``rates`` a typed list holding the function (or empty), its ``params``, ``active`` and
#: ``fault`` (1,) int64, set to 1 by the step when the controller writes a NaN or an inf (``record_fault``).
ControllerSlot = namedtuple("ControllerSlot", ["rates", "params", "active", "fault"])
#: Reward-term slot: typed lists of functions and of their parameter arrays, and their weights (k,).
RewardSlot = namedtuple("RewardSlot", ["fns", "params", "weights"])

_F64 = types.float64[::1]
_F64_2D = types.float64[:, ::1]
_I64 = types.int64[::1]


class RegisteredController(Protocol):
    """What this module reads of a registered controller (``envs.registered.CustomController``, which imports
    this module: a protocol, not an import, keeps the modules' imports acyclic)."""

    @property
    def module(self) -> str: ...

    @property
    def rates(self) -> Any: ...  # a numba.njit function

    @property
    def params(self) -> np.ndarray: ...


class RegisteredTerm(Protocol):
    """What this module reads of a registered reward term (``envs.registered.RewardTerm``)."""

    @property
    def name(self) -> str: ...

    @property
    def fn(self) -> Any: ...  # a numba.njit function, or a numpy callable

    @property
    def compiled(self) -> bool: ...

    @property
    def call(self) -> Any: ...

    @property
    def params(self) -> np.ndarray: ...


TERM_DOC = ("term(metrics (n_metrics,), flags (n_flags,) int64, action (k,), rates (k,), params (m,)) -> float64 "
            "(or, without rates, term(metrics, flags, action, params))")


def controller_module(controller: RegisteredController) -> ModuleType:
    """The module through which a registered controller is compiled, checked and called.

    Its env's spec names it (``RowFunctions.controller``, recorded on the controller at registration);
    it defines ``RATES_DOC`` (the call convention of ``rates``), ``rates_signature()`` (its numba
    signature), ``trial_rates(controller)`` (its command at the paper's home state) and
    ``predict(controller, observation)``.
    """
    import importlib

    return importlib.import_module(controller.module)


def term_signature() -> Signature:
    return types.float64(_F64, _I64, _F64, _F64, _F64)


def _positional_count(fn) -> int | None:
    """How many positional arguments ``fn`` takes (None: any number, or not inspectable)."""
    try:
        parameters = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):
        return None
    if any(p.kind is p.VAR_POSITIONAL for p in parameters):
        return None
    return sum(p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) for p in parameters)


def takes_rates(fn: Callable[..., Any], without: int) -> bool:
    """Whether a reward term's function takes the applied rates: one positional argument more than ``without``."""
    count = _positional_count(getattr(fn, "py_func", fn))
    return count is None or count > without


def _with_rates(fn):
    """A compiled term of the older signature (no rates) as one of today's: the step calls one signature."""
    from numba import njit

    @njit
    def term(metrics, flags, action, rates, params):
        return fn(metrics, flags, action, params)

    return term


def _compiled(fn, signature, what: str, doc: str):
    if not isinstance(fn, CPUDispatcher):
        raise ValueError(f"{what} must be a numba.njit function {doc}; got {describe(fn)}")
    try:
        fn.compile(signature)
    except Exception as error:  # numba raises its own TypingError / LoweringError subclasses
        first = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
        raise ValueError(f"{what} does not compile for the signature {doc}: {first}") from None
    return fn


def check_controller(controller: RegisteredController) -> None:
    """Compile a registered controller for its env's signature and run it once on a paper-like state."""
    module = controller_module(controller)
    _compiled(controller.rates, module.rates_signature(), "rates", module.RATES_DOC)
    out = module.trial_rates(controller)
    if not np.all(np.isfinite(out)):
        raise ValueError(f"rates must write a finite command into every entry of out ({out.size}); at the paper's home "
                         f"configuration it wrote {out.tolist()}")


def check_reward_term(term: RegisteredTerm) -> Callable[..., Any]:
    """The function the step calls for ``term``: a compiled term compiled for today's signature (one of the
    older signature, without ``rates``, wrapped into it), or a numpy term checked to be callable."""
    if term.compiled:
        if not isinstance(term.fn, CPUDispatcher):
            raise ValueError(f"fn must be a numba.njit function {TERM_DOC}; got {describe(term.fn)}")
        fn = term.fn if takes_rates(term.fn, 4) else _with_rates(term.fn)
        return _compiled(fn, term_signature(), "fn", TERM_DOC)
    if not callable(term.fn):
        raise ValueError(f"fn must be callable as fn(metrics: dict of (N,) arrays, actions (N, k), rates (N, k)) -> "
                         f"(N,) (rates optional); got {describe(term.fn)}")
    return term.fn


def controller_slot(env_id: str, controller: RegisteredController | None = None) -> ControllerSlot | None:
    """The slot the step kernels read: the registered controller's function, or None (the built-in bases).

    None, not an empty typed List: numba unboxes a typed List on every call (~40 us), and a None
    argument compiles a kernel specialisation in which the registered-controller branch is pruned.
    """
    if controller is None:
        return None
    rates = List.empty_list(types.FunctionType(controller_module(controller).rates_signature()))
    rates.append(controller.rates)
    return ControllerSlot(rates, controller.params, True, np.zeros(1, dtype=np.int64))


def reward_slot(terms: Sequence, weights: Sequence[float]) -> RewardSlot | None:
    """The compiled reward terms the step kernels add, in order, with the env's weights (None: no terms)."""
    if not terms:
        return None
    fns = List.empty_list(types.FunctionType(term_signature()))
    params = List.empty_list(_F64)
    for term in terms:
        fns.append(term.call)
        params.append(np.ascontiguousarray(term.params, dtype=np.float64))
    return RewardSlot(fns, params, np.array(list(weights), dtype=np.float64))


@kernel(inline="always")
def record_fault(slot, out):
    """``slot.fault[0] = 1`` if the controller's command ``out`` holds a NaN or an inf.

    The command is not changed: the state it drives becomes non-finite and is flagged where the row is
    observed (``common_kernels.mark_non_finite``); this record says that the controller, not the robot or the
    task, wrote the first non-finite value, so the error can name it.
    """
    for k in range(out.shape[0]):
        if not math.isfinite(out[k]):
            slot.fault[0] = 1
            return


@kernel
def apply_reward_terms(slot, metrics, flags, actions, rates, active, terms, rewards, first, non_finite, faults):
    """For each row that stepped (``active`` 1): terms[i, first + k] = w_k fn_k(metrics[i], flags[i], actions[i],
    rates[i], params_k), added to rewards[i] after its built-in terms (the sum the step kernel wrote).

    A term that returns a NaN or an inf flags its row (``flags[i, non_finite] = 1``, counted in ``faults[0]``)."""
    for i in range(active.shape[0]):
        if active[i] != 1:
            continue
        total = 0.0
        for k in range(len(slot.fns)):
            value = slot.weights[k] * slot.fns[k](metrics[i], flags[i], actions[i], rates[i], slot.params[k])
            terms[i, first + k] = value
            total += value
        rewards[i] += total
        if not math.isfinite(total) and flags[i, non_finite] == 0:
            flags[i, non_finite] = 1
            faults[0] += 1


def controller_predict(controller: RegisteredController, observation: Any) -> np.ndarray:
    """A registered controller's command for a controller observation dict (as the built-in ``predict``)."""
    if not isinstance(observation, dict):
        raise ValueError(f"predict reads a dict observation (core.controller_observation(row)); got "
                         f"{describe(observation)}")
    return controller_module(controller).predict(controller, observation)
