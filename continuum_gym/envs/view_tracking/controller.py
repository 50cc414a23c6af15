"""How ViewTracking calls a registered controller (``registry.register_controller``): its call convention,
numba signature, trial call and ``predict``; and the compiled call into its slot."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numba import typeof, types

from continuum_gym.envs.custom import record_fault
from continuum_gym.robots.compiled import kernel

if TYPE_CHECKING:
    from numba.core.typing.templates import Signature

    from continuum_gym.envs.registered import CustomController

F64 = types.float64[::1]
F64_2D = types.float64[:, ::1]
RATES_DOC = "rates(q (6,), p_target (3,), R_target (3, 3), dt, robot, params (m,), out (6,)) -> None"
#: Control step a ``predict`` observation without "dt" is taken at (the paper's IK step), s.
DEFAULT_DT = 0.01


def rates_signature() -> Signature:
    """The numba signature of a controller's ``rates`` (see ``RATES_DOC``)."""
    from continuum_gym.robots import ContinuumEndoscope

    return types.void(F64, F64, F64_2D, types.float64, typeof(ContinuumEndoscope().kernel_args()), F64, F64)


def trial_rates(controller: CustomController) -> np.ndarray:
    """The controller's joint rates at the paper's home configuration (NaN where it wrote nothing)."""
    from continuum_gym.robots import ContinuumEndoscope

    endoscope = ContinuumEndoscope()
    q = endoscope.home
    p, R = endoscope.target_pose(q)
    out = np.full(6, np.nan)
    controller.rates(q, p, np.ascontiguousarray(R), 0.01, endoscope.kernel_args(), controller.params, out)
    return out


def predict(controller: CustomController, observation: dict) -> np.ndarray:
    """The controller's joint rates (..., 6) for a controller observation (``core.controller_observation``)."""
    from continuum_gym.robots import ContinuumEndoscope

    q = np.ascontiguousarray(observation["q"], dtype=np.float64)
    dt = float(observation.get("dt", DEFAULT_DT))
    rows = q.reshape(-1, q.shape[-1])
    robot = observation.get("robot") or ContinuumEndoscope()
    out = np.empty((rows.shape[0], 6))
    p = np.broadcast_to(np.asarray(observation["p_target"], dtype=float), (rows.shape[0], 3))
    R = np.broadcast_to(np.asarray(observation["R_target"], dtype=float), (rows.shape[0], 3, 3))
    for i in range(rows.shape[0]):
        controller.rates(rows[i], np.ascontiguousarray(p[i]), np.ascontiguousarray(R[i]), dt, robot.kernel_args(),
                         controller.params, out[i])
    return out.reshape(q.shape[:-1] + (out.shape[-1],))


# See envs/occlusion/controller.py: a slot's call is a kernel of its own, with reference counting.
@kernel
def view_slot_rates(custom, q, p_target, R_target, dt, robot, out):
    """The registered ViewTracking controller of slot ``custom``: its joint rates (6,) into ``out``."""
    custom.rates[0](q, p_target, R_target, dt, robot, custom.params, out)
    record_fault(custom, out)


__all__ = ["RATES_DOC", "DEFAULT_DT", "rates_signature", "trial_rates", "predict", "view_slot_rates"]
