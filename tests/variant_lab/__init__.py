"""A researcher's variant, as issue 54 tried one: registered at import of this package, used by the round-trip
tests in fresh processes (``PYTHONPATH`` = the repository root, ``import tests.variant_lab``).

A 4-segment robot of 18 mm segments, a 45-degree lens, an own damped-least-squares controller, an own reward
term, a helix task read from CSV text, and two ids: ``LabTest/Occ4Seg-v0`` (plain) and
``LabTest/Occ4SegGoal-v0`` (goal-conditioned). Not ``examples/my_lab``: another module, so that nothing here
works only because the examples are on the path.
"""

from __future__ import annotations

import io
import math

import numpy as np
from gymnasium.envs.registration import register, registry
from numba import njit

from continuum_gym.envs import TipTrajectory
from continuum_gym.envs.occlusion.outputs import Metric
from continuum_gym.geometry import LensCone
from continuum_gym.registry import register_controller, register_reward_term, register_robot, register_task
from continuum_gym.robots import MultiBackboneRobot
from continuum_gym.robots.mbcr_kernels import make_workspace, tip_kernel

ENV_ID = "LabTest/Occ4Seg-v0"
GOAL_ID = "LabTest/Occ4SegGoal-v0"
BASE = "ContinuumGym/OcclusionAvoidance-v0"
ROBOT = MultiBackboneRobot(lengths=(0.018,) * 4)
CONE = LensCone(alpha=math.radians(45.0))


@njit(cache=True)
def dls(q, gamma, p_des, R_des, v_des, dt, robot, cone, params, out):
    """Damped least squares on the tip position error (gain params[0] 1/s, damping params[1] m^2)."""
    ws = make_workspace(robot.lengths.shape[0])
    p, R, J = np.empty(3), np.empty((3, 3)), np.empty((6, q.shape[0]))
    tip_kernel(q, robot, ws, p, R, J)
    Jv = J[:3]
    rates = Jv.T @ np.linalg.solve(Jv @ Jv.T + params[1] * np.eye(3), params[0] * (p_des - p) + v_des)
    out[: q.shape[0]] = rates
    out[q.shape[0]] = 0.0


@njit(cache=True)
def occlusion_mm(metrics, flags, action, rates, params):
    """Minus the VOI in thousandths."""
    return -1e3 * metrics[Metric.VOI] * params[0]


def helix_csv(turns: float = 1.5, radius: float = 0.002, pitch: float = 0.002, samples: int = 41) -> str:
    """A helix of the tip around its home position as a lab's CSV export: t (s), x, y, z (m)."""
    p0, _ = ROBOT.forward_kinematics(ROBOT.home)
    t = np.linspace(0.0, 3.0, samples)
    phase = 2 * math.pi * turns * t / t[-1]
    rows = np.column_stack([t, p0[0] + radius * (np.cos(phase) - 1), p0[1] + radius * np.sin(phase),
                            p0[2] + pitch * turns * t / t[-1]])
    out = io.StringIO()
    np.savetxt(out, rows, delimiter=",", header="t,x,y,z", comments="")
    return out.getvalue()


def helix(task_id, split, rng):
    """The helix read from its CSV, with a radius drawn per instance."""
    data = np.loadtxt(io.StringIO(helix_csv(radius=float(rng.uniform(0.001, 0.003)))), delimiter=",", skiprows=1)
    _, R0 = ROBOT.forward_kinematics(ROBOT.home)
    return TipTrajectory(data[:, 0], data[:, 1:], np.broadcast_to(R0, (len(data), 3, 3)), start_q=ROBOT.home)


register_robot("lab-4seg", ROBOT, replace=True)
register_controller("lab_dls", dls, env=BASE, params=[30.0, 1e-6], replace=True)
register_reward_term("lab_occlusion_mm", occlusion_mm, env=BASE, weight=0.5, params=[1.0], replace=True)
register_task("lab_helix", helix, env=BASE, count=100, replace=True)
KWARGS = {"robot": "lab-4seg", "cone": CONE, "base_controller": "lab_dls", "task": "lab_helix",
          "reward_weights": {"lab_occlusion_mm": 0.25}, "visibility_guard": 0.8}
if ENV_ID not in registry:
    register(id=ENV_ID, entry_point="continuum_gym.envs.occlusion:OcclusionAvoidanceEnv",
             vector_entry_point="continuum_gym.envs.occlusion:OcclusionAvoidanceVectorEnv", kwargs=KWARGS,
             max_episode_steps=120)
if GOAL_ID not in registry:
    register(id=GOAL_ID, entry_point="continuum_gym.envs.occlusion:OcclusionAvoidanceGoalEnv",
             kwargs={**KWARGS, "reward_type": "sparse", "tolerance_m": 2e-3}, max_episode_steps=120)
