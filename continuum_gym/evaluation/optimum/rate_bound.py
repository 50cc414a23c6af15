"""How low the episode-mean VOI of a hold task can go when the joints and the endoscope move at finite rates.

The hold optimum (:func:`~continuum_gym.evaluation.optimum.occlusion.hold_optimum`) is the lowest VOI of a
*configuration*: the best point of the self-motion arc of the held tip pose, with the best feasible endoscope
rotation. An episode starts elsewhere (the task's start configuration, gamma 0), and its metric is the mean
VOI over the episode's steps, so no controller reaches the hold optimum as an episode mean: the robot first has
to travel there at its rate limits. This module bounds what any controller can reach.

At step k (time k dt) a controller that holds the tip pose is on the arc of q0, at a point whose travel along
the arc from q0 is at most ``rate_j k dt`` in every joint j (the rate limits are per joint), with its
endoscope rotation within ``gamma_rate k dt`` of the start's. The lowest VOI over that reachable set
(arc points x feasible gammas) is a lower bound on the VOI of every such controller at step k, and their
mean over the steps bounds the episode mean. The bound is not always attained: the minimiser may jump along
the arc from one step to the next, which no trajectory does.

The arc and gamma are sampled (``TRACE_STEP`` on the arc, ``gamma_resolution`` in gamma), with reach
counted one sample early so that sampling does not shrink the reachable set; the hold optimum refines its
minimum further, so the bound's floor may sit about 1e-3 above it. The tip pose is taken as held exactly: the
env ends an episode only at 10 mm, and a controller that lets the tip drift by a fraction of a millimetre can
dip below the bound by about that much VOI (the shipped residual policies, tip error about 0.1-0.2 mm, by
up to about 1e-3 in their first steps).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.baselines import OcclusionLimits
from continuum_gym.baselines.arc_plan import (
    GAMMA_RESOLUTION,
    PLAN_TARGETS,
    arc_grid,
    plan_on_grid,
)
from continuum_gym.evaluation.optimum.protocol import VISIBILITY
from continuum_gym.evaluation.optimum.workers import map_jobs, positive_int, visibility_fraction
from continuum_gym.geometry import LensCone, occlusion_details
from continuum_gym.robots import MultiBackboneRobot


def arc_travel(q: np.ndarray, start: int, closed: bool) -> np.ndarray:
    """Per-joint travel (sum of |dq_j| along the arc) from point ``start`` to every point, shape (m, dof).

    On a closed arc each point is reached the shorter way round, per joint.
    """
    steps = np.abs(np.diff(q, axis=0))
    travel = np.zeros_like(q)
    travel[start + 1:] = np.cumsum(steps[start:], axis=0)
    travel[:start] = np.cumsum(steps[:start][::-1], axis=0)[::-1]
    if closed:
        loop = steps.sum(axis=0) + np.abs(q[-1] - q[0])
        travel = np.minimum(travel, loop - travel)
    return travel


def hold_rate_bound(robot: MultiBackboneRobot, q0: ArrayLike, limits: OcclusionLimits | None = None, *,
                    dt: float = 0.01, steps: int = 150, gamma0: float = 0.0, visibility: float = VISIBILITY,
                    cone: LensCone | None = None, gamma_resolution: float = GAMMA_RESOLUTION) -> dict[str, Any]:
    """Lower bound on the VOI after each of ``steps`` control steps of a hold task started at (q0, gamma0).

    Args:
        robot: a 7-DoF ``MultiBackboneRobot``; q0: (7,) start within ``limits``.
        limits: ``OcclusionLimits`` (joint limits and rate limits; None: the env's defaults).
        dt: control step (s), in (0, 0.1]; steps: episode length (control steps), >= 1.
        gamma0: endoscope rotation at the start (rad).
        visibility: the tip must stay within this fraction of the cone half-angle, in (0, 1].
        cone: ``LensCone`` (None: the paper's).
        gamma_resolution: gamma sampling (rad), in (0, 0.1].

    Returns:
        dict: ``voi_bound`` (steps,) nonincreasing, ``mean_voi_bound`` (its mean: the bound on the episode
        mean), ``static_voi`` (the lowest VOI on the sampled arc x feasible gammas, the bound's floor),
        ``steps_to_static`` (first step at which the bound reaches it), ``start_voi`` (VOI at q0, gamma0).
        NaN everywhere if no gamma keeps the tip in view.
    """
    grid = arc_grid(robot, q0, limits, dt, steps, gamma0, visibility, cone, gamma_resolution, "hold_rate_bound")
    return _bound(grid, robot, q0, float(dt), int(steps), float(gamma0), cone, float(gamma_resolution))


def _bound(grid: tuple | None, robot, q0, dt: float, steps: int, gamma0: float, cone, resolution: float) -> dict:
    """``hold_rate_bound`` on the checked inputs and ``arc_grid``'s grid."""
    start_voi = _start_voi(robot, q0, gamma0, cone)
    if grid is None:
        return {"voi_bound": np.full(steps, math.nan), "mean_voi_bound": math.nan, "static_voi": math.nan,
                "steps_to_static": -1, "start_voi": start_voi}
    arc, rates, gamma, voi, limits = grid
    # First step at which each sample can be reached (every joint within its rate budget). Both are optimistic
    # by one sample, so that the sampled sets cover the continuous reachable sets: an arc point counts as
    # reached when a neighbour is, a gamma sample when the gamma one sample nearer the start is.
    arc_step = np.ceil(np.max(arc_travel(arc.q, arc.start_index, arc.closed) / (rates * dt), axis=1) - 1e-9)
    padded = np.pad(arc_step, 1, mode="wrap" if arc.closed else "edge")
    arc_step = np.minimum(np.minimum(padded[:-2], padded[1:-1]), padded[2:])
    gamma_step = np.ceil(np.maximum(np.abs(gamma - gamma0) - resolution, 0.0) / (limits.gamma_rate * dt) - 1e-9)
    # lowest VOI among cells reachable by step k: the cell (i, g) is reachable from max(arc_step_i, gamma_step_g)
    first = np.maximum(arc_step[:, None], gamma_step[None, :]).ravel()
    order = np.argsort(first, kind="stable")
    running = np.minimum.accumulate(voi.ravel()[order])
    k = np.arange(1, steps + 1)
    last = np.searchsorted(first[order], k, side="right") - 1
    bound = np.where(last >= 0, running[np.maximum(last, 0)], math.inf)
    static = float(voi.min())
    reached = np.flatnonzero(bound <= static)
    return {"voi_bound": bound, "mean_voi_bound": float(bound.mean()), "static_voi": static,
            "steps_to_static": int(reached[0] + 1) if len(reached) else -1, "start_voi": start_voi}

def _start_voi(robot: MultiBackboneRobot | None, q0: ArrayLike, gamma0: float, cone: LensCone | None) -> float:
    robot = MultiBackboneRobot() if robot is None else robot
    return float(occlusion_details(robot, np.asarray(q0, dtype=float), float(gamma0), cone or LensCone())["voi"])


def _bound_job(job: dict) -> dict:
    """Bound and plan of one start from one traced arc and VOI grid (the expensive part, done once)."""
    robot, q0, dt, steps = job["robot"], job["q0"], float(job["dt"]), int(job["steps"])
    grid = arc_grid(robot, q0, job["limits"], dt, steps, 0.0, job["visibility"], job["cone"], GAMMA_RESOLUTION,
                     "env_hold_rate_bound")
    result = _bound(grid, robot, q0, dt, steps, 0.0, job["cone"], GAMMA_RESOLUTION)
    plan = plan_on_grid(grid, dt, steps, 0.0, PLAN_TARGETS)
    result["voi_bound"] = result["voi_bound"].tolist()
    result["voi_plan"] = plan["voi_plan"].tolist()
    result["mean_voi_plan"] = plan["mean_voi_plan"]
    return result


def env_hold_rate_bound(n_tasks: int = 32, split: str = "test", config: Any = None, visibility: float = VISIBILITY,
                        workers: int = 2, progress: bool = True, traces: bool = True) -> dict[str, Any]:
    """:func:`hold_rate_bound` and :func:`hold_arc_plan` on ids 0..n-1 of the OcclusionAvoidance env's hold tasks.

    ``config`` is an ``OcclusionConfig`` (None: the env's defaults); its limits, robot, cone, control step and
    hold duration are used, with the env's hold starts (gamma 0) of ``split``. Returns per-task lists
    (``voi_bound`` and ``voi_plan`` (n, steps), ``mean_voi_bound``, ``mean_voi_plan``, ``static_voi``,
    ``steps_to_static``, ``start_voi``) and the means over tasks ``mean_of_mean_voi_bound`` (below every
    controller's mean episode VOI on the task set), ``mean_of_mean_voi_plan`` (achieved by the planned
    trajectories) and ``mean_static_voi``. ``traces=False`` leaves out the per-step lists (the caches keep the
    per-task values only).
    """
    from continuum_gym.envs.occlusion.config import OcclusionConfig
    from continuum_gym.envs.occlusion.tasks import OCCLUSION_DURATION_S, hold_start_pool

    config = OcclusionConfig() if config is None else config
    limits, robot = config.limits, config.robot
    starts = np.asarray(hold_start_pool(split, float(limits.max_bend), tuple(limits.insertion), robot, config.cone))
    starts = starts[:positive_int(n_tasks, "n_tasks")]
    steps = int(round(OCCLUSION_DURATION_S["hold"] / config.control_dt))
    jobs = [{"robot": robot, "q0": q0, "limits": limits, "dt": config.control_dt, "steps": steps,
             "visibility": visibility, "cone": config.cone} for q0 in starts]
    results = map_jobs(_bound_job, jobs, positive_int(workers, "workers"), progress, "hold rate bound")
    out: dict[str, Any] = {"task_ids": list(range(len(starts))), "split": split, "steps": steps,
                           "dt": config.control_dt, "visibility": visibility_fraction(visibility)}
    keys = ("voi_bound", "voi_plan") if traces else ()
    for key in (*keys, "mean_voi_bound", "mean_voi_plan", "static_voi", "steps_to_static", "start_voi"):
        out[key] = [r[key] for r in results]
    out["mean_of_mean_voi_bound"] = float(np.mean(out["mean_voi_bound"]))
    out["mean_of_mean_voi_plan"] = float(np.mean(out["mean_voi_plan"]))
    out["mean_static_voi"] = float(np.mean(out["static_voi"]))
    return out
