"""A hold trajectory along the self-motion arc, planned from the start: the OcclusionAvoidance planner.

A hold task keeps the tip pose of its start configuration q0; every configuration with that tip pose lies on
the one-dimensional self-motion arc of q0 (:mod:`continuum_gym.baselines.self_motion`). :func:`hold_arc_plan`
plans how to travel along it towards a low-VOI point at the joints' and the endoscope's rate limits. It needs
only q0, the robot, the cone and the limits, so it can run when an episode starts: the env's ``arc_plan`` option
makes the residual's base track it on hold tasks, and the evaluation uses it as a reference row (with
:func:`~continuum_gym.evaluation.optimum.hold_rate_bound` below it, it brackets the best episode any controller
can make).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.baselines.occlusion import OcclusionLimits
from continuum_gym.baselines.self_motion import TRACE_STEP, trace_self_motion
from continuum_gym.geometry import LensCone, cone_coordinates, occlusion_details
from continuum_gym.robots import MultiBackboneRobot
from continuum_gym.validation import as_finite, fraction, integer, positive

#: The plans' default visibility requirement (the evaluation's, protocol.VISIBILITY): the tip within this fraction of the
#: cone half-angle from the view axis.
VISIBILITY = 0.7

#: Default gamma sampling of the bound (rad).
GAMMA_RESOLUTION = math.radians(0.25)
#: Default number of target points the planner tries along the arc.
PLAN_TARGETS = 64


def gamma_grid(gamma0: float, resolution: float) -> np.ndarray:
    """Endoscope rotations sampled every ``resolution`` over one turn, through ``gamma0`` exactly."""
    half = int(math.pi / resolution)
    return gamma0 + resolution * np.arange(-half, half + 1)


def hold_arc_plan(robot: MultiBackboneRobot, q0: ArrayLike, limits: OcclusionLimits | None = None, *,
                  dt: float = 0.01, steps: int = 150, gamma0: float = 0.0, visibility: float = VISIBILITY,
                  cone: LensCone | None = None, gamma_resolution: float = GAMMA_RESOLUTION,
                  targets: int = PLAN_TARGETS) -> dict[str, Any]:
    """A feasible hold trajectory that travels along the self-motion arc: an *achievable* episode-mean VOI.

    With :func:`hold_rate_bound` below it, it brackets the best episode any controller can make. For each of
    about ``targets`` target points spread over the arc (and the arc's best point), the joints move each step as
    far along the arc towards the target as every joint's rate limit allows (so the tip pose is held and no
    joint rate is exceeded), while the endoscope turns by at most ``gamma_rate * dt`` per step, either greedily
    (the lowest VOI within reach at the new arc point) or towards the target's best gamma; the best of these
    trajectories by mean VOI is returned. It needs only the start, the robot, the cone and the limits (about 1 s
    of Python), so an env can plan when an episode starts (OcclusionAvoidance's ``arc_plan`` option).

    Returns:
        dict: ``voi_plan`` (steps,), ``mean_voi_plan``, ``q_plan`` (steps, 7), ``gamma_plan`` (steps,),
        ``target_voi`` (static VOI at the chosen target). NaN if no gamma keeps the tip in view.
    """
    grid = arc_grid(robot, q0, limits, dt, steps, gamma0, visibility, cone, gamma_resolution, "hold_arc_plan")
    return plan_on_grid(grid, float(dt), int(steps), float(gamma0), integer(targets, "targets", low=1))


def plan_on_grid(grid: tuple | None, dt: float, steps: int, gamma0: float, targets: int) -> dict:
    """``hold_arc_plan`` on the checked inputs and ``arc_grid``'s grid."""
    if grid is None:
        return {"voi_plan": np.full(steps, math.nan), "mean_voi_plan": math.nan,
                "q_plan": np.full((steps, 7), math.nan), "gamma_plan": np.full(steps, math.nan),
                "target_voi": math.nan}
    arc, rates, gamma, voi, limits = grid
    budget = rates * dt
    turn = limits.gamma_rate * dt * (1 + 1e-12)
    # cumulative per-joint travel from the arc's first point (the planner does not wrap round a closed arc)
    along = np.vstack([np.zeros((1, 7)), np.cumsum(np.abs(np.diff(arc.q, axis=0)), axis=0)])
    best_cell = np.unravel_index(int(np.argmin(voi)), voi.shape)
    ends = np.unique(np.r_[np.linspace(0, len(arc.q) - 1, targets).round().astype(int), best_cell[0]])
    g_start = int(np.argmin(np.abs(gamma - gamma0)))
    best: tuple | None = None
    for target in ends:
        path = _arc_path(along, arc.start_index, int(target), budget, steps)
        for mode in ("greedy", "target"):
            g_path = _gamma_path(voi, gamma, path, g_start, turn, int(np.argmin(voi[target])), mode)
            values = voi[path, g_path]
            if best is None or values.mean() < best[0].mean():
                best = (values, path, g_path, target)
    assert best is not None
    values, path, g_path, target = best
    return {"voi_plan": values, "mean_voi_plan": float(values.mean()), "q_plan": arc.q[path],
            "gamma_plan": gamma[g_path], "target_voi": float(voi[target].min())}

def _arc_path(along: np.ndarray, start: int, target: int, budget: np.ndarray, steps: int) -> np.ndarray:
    """Arc index after each step: as far towards ``target`` as every joint's budget per step allows."""
    path = np.empty(steps, dtype=np.int64)
    i = start
    for k in range(steps):
        if target > i:
            reach = min(int(np.searchsorted(along[:, j], along[i, j] + budget[j], side="right")) - 1
                        for j in range(along.shape[1]))
            i = min(max(reach, i), target)
        elif target < i:
            reach = max(int(np.searchsorted(along[:, j], along[i, j] - budget[j], side="left"))
                        for j in range(along.shape[1]))
            i = max(min(reach, i), target)
        path[k] = i
    return path


def _gamma_path(voi: np.ndarray, gamma: np.ndarray, path: np.ndarray, g: int, turn: float, g_target: int,
                mode: str) -> np.ndarray:
    """Gamma index after each step, turning at most ``turn`` per step (greedy, or towards ``g_target``)."""
    out = np.empty(len(path), dtype=np.int64)
    for k, i in enumerate(path):
        lo = int(np.searchsorted(gamma, gamma[g] - turn, side="left"))
        hi = int(np.searchsorted(gamma, gamma[g] + turn, side="right"))
        if mode == "greedy":
            g = lo + int(np.argmin(voi[i, lo:hi]))
        else:
            g = min(max(g_target, lo), hi - 1)
        out[k] = g
    return out


def arc_grid(robot: MultiBackboneRobot | None, q0: ArrayLike, limits: OcclusionLimits | None, dt: float, steps: int,
             gamma0: float, visibility: float, cone: LensCone | None, gamma_resolution: float, caller: str
             ) -> tuple | None:
    """Checked inputs, the arc of q0 and VOI over (arc points x gammas that keep the tip in view); None if no
    gamma sees the tip. Returns (arc, joint rate limits, feasible gammas, VOI (m, g), limits)."""
    robot = MultiBackboneRobot() if robot is None else robot
    if robot.dof != 7:
        raise ValueError(f"robot: {caller} needs a 7-DoF robot (a one-dimensional self-motion arc); "
                         f"got dof={robot.dof}")
    limits = OcclusionLimits() if limits is None else limits
    cone = LensCone() if cone is None else cone
    q0 = as_finite(q0, (7,), "q0")
    dt = positive(dt, "dt")
    if dt > 0.1:
        raise ValueError(f"dt must be in (0, 0.1] s; got {dt!r}")
    integer(steps, "steps", low=1)
    resolution = positive(gamma_resolution, "gamma_resolution")
    if resolution > 0.1:
        raise ValueError(f"gamma_resolution must be in (0, 0.1] rad; got {gamma_resolution!r}")
    visibility = fraction(visibility, "visibility (fraction of the cone half-angle)")
    tip, _ = robot.forward_kinematics(q0)
    gamma = gamma_grid(float(gamma0), resolution)
    gamma = gamma[cone_coordinates(tip, gamma, cone)["angle"] <= visibility * cone.beta]
    if len(gamma) == 0:
        return None
    arc = trace_self_motion(robot, q0, limits, step=TRACE_STEP)
    voi = occlusion_details(robot, arc.q[:, None, :], gamma[None, :], cone)["voi"]
    return arc, np.asarray(limits.rate_limit, dtype=float)[:7], gamma, voi, limits


__all__ = ["GAMMA_RESOLUTION", "PLAN_TARGETS", "gamma_grid", "hold_arc_plan", "arc_grid", "plan_on_grid"]
