"""Registered controllers and reward terms inside the compiled step (see ``continuum_gym.registry``).

A user's numba function is called through a first-class function pointer held in a typed list, so the
step kernels are compiled (and cached on disk) once for every function of a signature: registering a
controller compiles only the controller itself. The slots are always passed: an empty one (``active``
False, no terms) costs one branch per step and leaves the built-in arithmetic untouched.
"""

from __future__ import annotations

import inspect
from collections import namedtuple
from collections.abc import Sequence

import numpy as np
from numba import typeof, types
from numba.core.registry import CPUDispatcher
from numba.typed import List

from continuum_gym.robots.compiled import kernel
from continuum_gym.validation import describe

#: A controller slot: ``rates`` a typed list holding the function (or empty), its ``params`` and ``active``.
ControllerSlot = namedtuple("ControllerSlot", ["rates", "params", "active"])
#: Reward-term slot: typed lists of functions and of their parameter arrays, and their weights (k,).
RewardSlot = namedtuple("RewardSlot", ["fns", "params", "weights"])

_F64 = types.float64[::1]
_F64_2D = types.float64[:, ::1]
_I64 = types.int64[::1]

OCCLUSION_RATES_DOC = ("rates(q (dof,), gamma, p_des (3,), R_des (3, 3), v_des (3,), dt, robot, cone, params (m,), "
                       "out (dof + 1,)) -> None")
VIEW_RATES_DOC = "rates(q (6,), p_target (3,), R_target (3, 3), dt, robot, params (m,), out (6,)) -> None"
TERM_DOC = ("term(metrics (n_metrics,), flags (n_flags,) int64, action (k,), rates (k,), params (m,)) -> float64 "
            "(or, without rates, term(metrics, flags, action, params))")


def _paper_args(env_id: str):
    from continuum_gym.envs.ids import OCCLUSION

    if env_id == OCCLUSION:
        from continuum_gym.geometry.lens_cone import LensCone
        from continuum_gym.robots import MultiBackboneRobot

        return MultiBackboneRobot().kernel_args(), LensCone().kernel_args()
    from continuum_gym.robots import ContinuumEndoscope

    return ContinuumEndoscope().kernel_args(), None


def rates_signature(env_id: str):
    """The numba signature of an env's controller rate function."""
    robot, cone = _paper_args(env_id)
    if cone is not None:
        return types.void(_F64, types.float64, _F64, _F64_2D, _F64, types.float64, typeof(robot), typeof(cone), _F64,
                          _F64)
    return types.void(_F64, _F64, _F64_2D, types.float64, typeof(robot), _F64, _F64)


def term_signature():
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


def takes_rates(fn, without: int) -> bool:
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


def check_controller(controller) -> None:
    """Compile a registered controller for its env's signature and run it once on a paper-like state."""
    from continuum_gym.envs.ids import OCCLUSION

    occlusion = controller.env_id == OCCLUSION
    doc = OCCLUSION_RATES_DOC if occlusion else VIEW_RATES_DOC
    _compiled(controller.rates, rates_signature(controller.env_id), "rates", doc)
    robot, cone = _paper_args(controller.env_id)
    if occlusion:
        from continuum_gym.robots import MultiBackboneRobot

        q = MultiBackboneRobot().home
        p, R = MultiBackboneRobot().forward_kinematics(q)
        out = np.full(q.size + 1, np.nan)
        controller.rates(q, 0.0, p, np.ascontiguousarray(R), np.zeros(3), 1e-3, robot, cone, controller.params, out)
    else:
        from continuum_gym.robots import ContinuumEndoscope

        endoscope = ContinuumEndoscope()
        q = endoscope.home
        p, R = endoscope.target_pose(q)
        out = np.full(6, np.nan)
        controller.rates(q, p, np.ascontiguousarray(R), 0.01, robot, controller.params, out)
    if not np.all(np.isfinite(out)):
        raise ValueError(f"rates must write a finite command into every entry of out ({out.size}); at the paper's home "
                         f"configuration it wrote {out.tolist()}")


def check_reward_term(term):
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


def controller_slot(env_id: str, controller=None) -> ControllerSlot | None:
    """The slot the step kernels read: the registered controller's function, or None (the built-in bases).

    None, not an empty typed List: numba unboxes a typed List on every call (~40 us), and a None
    argument compiles a kernel specialisation in which the registered-controller branch is pruned.
    """
    if controller is None:
        return None
    rates = List.empty_list(types.FunctionType(rates_signature(env_id)))
    rates.append(controller.rates)
    return ControllerSlot(rates, controller.params, True)


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


# The slots' typed lists need numba's reference counting, which the step kernels' rows run without
# (``kernel(borrows=True)``): so the calls into a slot are kernels of their own, with it.
@kernel
def occlusion_slot_rates(custom, q, gamma, p_des, R_des, v_des, dt, robot, cone, out):
    """The registered OcclusionAvoidance controller of slot ``custom``: its command (dof + 1,) into ``out``."""
    custom.rates[0](q, gamma, p_des, R_des, v_des, dt, robot, cone, custom.params, out)


@kernel
def view_slot_rates(custom, q, p_target, R_target, dt, robot, out):
    """The registered ViewTracking controller of slot ``custom``: its joint rates (6,) into ``out``."""
    custom.rates[0](q, p_target, R_target, dt, robot, custom.params, out)


@kernel
def apply_reward_terms(slot, metrics, flags, actions, rates, active, terms, rewards, first):
    """For each row that stepped (``active`` 1): terms[i, first + k] = w_k fn_k(metrics[i], flags[i], actions[i],
    rates[i], params_k), added to rewards[i] after its built-in terms (the sum the step kernel wrote)."""
    for i in range(active.shape[0]):
        if active[i] != 1:
            continue
        total = 0.0
        for k in range(len(slot.fns)):
            value = slot.weights[k] * slot.fns[k](metrics[i], flags[i], actions[i], rates[i], slot.params[k])
            terms[i, first + k] = value
            total += value
        rewards[i] += total


def controller_predict(controller, observation) -> np.ndarray:
    """A registered controller's command for a controller observation dict (as the built-in ``predict``)."""
    from continuum_gym.envs.ids import OCCLUSION

    if not isinstance(observation, dict):
        raise ValueError(f"predict reads a dict observation (core.controller_observation(row)); got "
                         f"{describe(observation)}")
    robot = observation.get("robot")
    q = np.ascontiguousarray(observation["q"], dtype=np.float64)
    dt = float(observation.get("dt", 1e-3 if controller.env_id == OCCLUSION else 0.01))
    rows = q.reshape(-1, q.shape[-1])
    if controller.env_id == OCCLUSION:
        from continuum_gym.geometry.lens_cone import LensCone
        from continuum_gym.robots import MultiBackboneRobot

        robot = robot or MultiBackboneRobot()
        if rows.shape[1] != robot.dof:
            raise ValueError(f"observation['q'] has {rows.shape[1]} joints; the robot (observation['robot'], default the "
                             f"paper's) has {robot.dof}")
        cone = observation.get("cone") or LensCone()
        out = np.empty((rows.shape[0], rows.shape[1] + 1))
        args = [np.broadcast_to(np.asarray(observation[k], dtype=float), shape).reshape(-1, *shape[1:])
                for k, shape in (("gamma", (rows.shape[0],)), ("p_des", (rows.shape[0], 3)),
                                 ("R_des", (rows.shape[0], 3, 3)), ("v_des", (rows.shape[0], 3)))]
        for i in range(rows.shape[0]):
            controller.rates(rows[i], float(args[0][i]), np.ascontiguousarray(args[1][i]),
                             np.ascontiguousarray(args[2][i]), np.ascontiguousarray(args[3][i]), dt,
                             robot.kernel_args(), cone.kernel_args(), controller.params, out[i])
    else:
        from continuum_gym.robots import ContinuumEndoscope

        robot = robot or ContinuumEndoscope()
        out = np.empty((rows.shape[0], 6))
        p = np.broadcast_to(np.asarray(observation["p_target"], dtype=float), (rows.shape[0], 3))
        R = np.broadcast_to(np.asarray(observation["R_target"], dtype=float), (rows.shape[0], 3, 3))
        for i in range(rows.shape[0]):
            controller.rates(rows[i], np.ascontiguousarray(p[i]), np.ascontiguousarray(R[i]), dt, robot.kernel_args(),
                             controller.params, out[i])
    return out.reshape(q.shape[:-1] + (out.shape[-1],))
