"""My lab's variant of OcclusionAvoidance, registered at import so that every process can rebuild it.

A 2-segment robot beside an endoscope with a wider view cone, a damped-least-squares controller as
the residual's base, a reward term in millimetres, a family of figure-eight tip paths, and the id
``MyLab/Occlusion2Seg-v0`` that puts them together. Importing this module registers all of them;
continuum-gym records the module, so vector-env workers, Ray trials, pickles and ``config.yml`` files
import it again wherever they run (``continuum-gym --import my_lab.plugins ...`` on the command line).
"""

from __future__ import annotations

import numpy as np
from gymnasium.envs.registration import register, registry
from numba import njit

from continuum_gym.envs import TipTrajectory
from continuum_gym.envs.occlusion.outputs import Flag, Metric
from continuum_gym.geometry import LensCone
from continuum_gym.registry import register_controller, register_reward_term, register_robot, register_task
from continuum_gym.robots import MultiBackboneRobot
from continuum_gym.robots.mbcr_kernels import make_workspace, tip_kernel

ENV_ID = "MyLab/Occlusion2Seg-v0"
BASE_ID = "ContinuumGym/OcclusionAvoidance-v0"
ROBOT = MultiBackboneRobot(lengths=(0.030, 0.025))        # two segments (m)
CONE = LensCone(d_o=5.0e-3, beta=np.radians(35.0))        # channel offset (m), wider half-angle (rad)


@njit(cache=True)  # compiled once, reused by every process that imports this module
def damped_least_squares(q, gamma, p_des, R_des, v_des, dt, robot, cone, params, out):
    """Damped least squares on the tip position error (gain params[0] in 1/s, damping params[1])."""
    ws = make_workspace(robot.lengths.shape[0])
    p, R, J = np.empty(3), np.empty((3, 3)), np.empty((6, q.shape[0]))
    tip_kernel(q, robot, ws, p, R, J)
    Jv = J[:3]
    rates = Jv.T @ np.linalg.solve(Jv @ Jv.T + params[1] * np.eye(3), params[0] * (p_des - p) + v_des)
    out[: q.shape[0]] = rates
    out[q.shape[0]] = 0.0                                 # the endoscope stays still


@njit(cache=True)  # compiled once, reused by every process that imports this module
def tip_error_mm(metrics, flags, action, rates, params):
    """Minus the tip error in mm, and a penalty when the episode ends on a lost tip."""
    return -1e3 * metrics[Metric.TIP_ERROR] - params[0] * flags[Flag.TERMINATED]


def figure_eight(task_id, split, rng):
    """A figure-eight of 2-4 mm around the tip's home pose, at a random speed (instance per split and id)."""
    q0 = ROBOT.home
    p0, R0 = ROBOT.forward_kinematics(q0)
    size, period = rng.uniform(0.002, 0.004), rng.uniform(1.5, 3.0)
    t = np.linspace(0.0, period, 31)
    phase = 2 * np.pi * t / period
    path = p0 + size * np.stack([np.sin(phase), np.sin(phase) * np.cos(phase), 0 * t], axis=1)
    return TipTrajectory(t, path, np.broadcast_to(R0, (t.size, 3, 3)), start_q=q0)


register_robot("mylab-2seg", ROBOT, replace=True)
register_controller("mylab_dls", damped_least_squares, env=BASE_ID, params=[40.0, 1e-6], replace=True)
register_reward_term("mylab_tip_mm", tip_error_mm, env=BASE_ID, weight=0.0, params=[100.0], replace=True)
register_task("mylab_figure_eight", figure_eight, env=BASE_ID, count=1000, replace=True)
if ENV_ID not in registry:
    register(id=ENV_ID, entry_point="continuum_gym.envs.occlusion:OcclusionAvoidanceEnv",
             vector_entry_point="continuum_gym.envs.occlusion:OcclusionAvoidanceVectorEnv",
             kwargs={"robot": "mylab-2seg", "cone": CONE, "base_controller": "mylab_dls",
                     "task": "mylab_figure_eight", "reward_weights": {"mylab_tip_mm": 0.1}})
