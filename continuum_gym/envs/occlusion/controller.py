"""How OcclusionAvoidance calls a registered controller (``registry.register_controller``): its call
convention, numba signature, trial call and ``predict``; and the compiled call into its slot."""

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
RATES_DOC = ("rates(q (dof,), gamma, p_des (3,), R_des (3, 3), v_des (3,), dt, robot, cone, params (m,), "
             "out (dof + 1,)) -> None")
#: Control step a ``predict`` observation without "dt" is taken at (the paper's 1 ms loop), s.
DEFAULT_DT = 1e-3


def _paper_args():
    from continuum_gym.geometry.lens_cone import LensCone
    from continuum_gym.robots import MultiBackboneRobot

    return MultiBackboneRobot().kernel_args(), LensCone().kernel_args()


def rates_signature() -> Signature:
    """The numba signature of a controller's ``rates`` (see ``RATES_DOC``)."""
    robot, cone = _paper_args()
    return types.void(F64, types.float64, F64, F64_2D, F64, types.float64, typeof(robot), typeof(cone), F64, F64)


def trial_rates(controller: CustomController) -> np.ndarray:
    """The controller's command at the paper's home configuration (NaN where it wrote nothing)."""
    from continuum_gym.robots import MultiBackboneRobot

    robot, cone = _paper_args()
    q = MultiBackboneRobot().home
    p, R = MultiBackboneRobot().forward_kinematics(q)
    out = np.full(q.size + 1, np.nan)
    controller.rates(q, 0.0, p, np.ascontiguousarray(R), np.zeros(3), 1e-3, robot, cone, controller.params, out)
    return out


def predict(controller: CustomController, observation: dict) -> np.ndarray:
    """The controller's command (..., dof + 1) for a controller observation (``core.controller_observation``)."""
    from continuum_gym.geometry.lens_cone import LensCone
    from continuum_gym.robots import MultiBackboneRobot

    q = np.ascontiguousarray(observation["q"], dtype=np.float64)
    dt = float(observation.get("dt", DEFAULT_DT))
    rows = q.reshape(-1, q.shape[-1])
    robot = observation.get("robot") or MultiBackboneRobot()
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
    return out.reshape(q.shape[:-1] + (out.shape[-1],))


# The slots' typed lists need numba's reference counting, which the step kernels' rows run without
# (``kernel(borrows=True)``): so the calls into a slot are kernels of their own, with it.
@kernel
def occlusion_slot_rates(custom, q, gamma, p_des, R_des, v_des, dt, robot, cone, out):
    """The registered OcclusionAvoidance controller of slot ``custom``: its command (dof + 1,) into ``out``."""
    custom.rates[0](q, gamma, p_des, R_des, v_des, dt, robot, cone, custom.params, out)
    record_fault(custom, out)


__all__ = ["RATES_DOC", "DEFAULT_DT", "rates_signature", "trial_rates", "predict", "occlusion_slot_rates"]
