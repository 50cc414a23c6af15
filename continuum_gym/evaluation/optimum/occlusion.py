"""Occlusion optima (paper 000) within the environment's limits: the hold optimum (self-motion arc x
feasible endoscope rotation), the circle's time-connected bound, and the projected-gradient references."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import brentq

from continuum_gym.baselines import OcclusionLimits, ProjectedGradient
from continuum_gym.baselines.scenarios import (
    HOLD_ITERATIONS,
    PAPER_DT,
    CircleTask,
    sample_hold_starts,
)
from continuum_gym.baselines.self_motion import (
    NEWTON_TOLERANCE,
    TRACE_STEP,
    SelfMotionTracer,
    limit_arrays,
    sample_self_motion,
    trace_self_motion,
    trace_self_motion_from,
)
from continuum_gym.evaluation.optimum.protocol import (
    CIRCLE_SAMPLE_DT,
    ENV_HOLD_TASKS,
    HOLD_N_STARTS,
    HOLD_STARTS_SEED,
    VISIBILITY,
)
from continuum_gym.evaluation.optimum.rate_bound import env_hold_rate_bound
from continuum_gym.evaluation.optimum.workers import (
    map_jobs,
    positive_int,
    rounded,
    visibility_fraction,
)
from continuum_gym.geometry import (
    LensCone,
    centre_distance,
    cone_coordinates,
    occlusion_details,
)
from continuum_gym.robots import MultiBackboneRobot
from continuum_gym.validation import as_finite, positive

# gamma sampling (rad): coarse grid over the feasible set, then a fine one around the best cells.
GAMMA_COARSE = math.radians(0.5)
GAMMA_FINE = math.radians(0.02)
GAMMA_SCAN = 3600


# ---------------------------------------------------------------------- gamma feasibility
def feasible_gamma_intervals(tip: ArrayLike, visibility: float = VISIBILITY, cone: LensCone | None = None,
                             scan: int = GAMMA_SCAN) -> list[tuple[float, float]]:
    """Intervals [lo, hi] (rad, lo in [-pi, pi), hi > lo) of endoscope rotations gamma that see ``tip``
    within ``visibility`` * beta of the view axis (``cone_coordinates(tip, gamma)["angle"]``).

    Found on a ``scan``-point grid over [-pi, pi) and refined by Brent's method to 1e-13 rad.
    Returns [] if no gamma qualifies and [(-pi, pi)] if every gamma does.
    """
    cone = LensCone() if cone is None else cone
    visibility = visibility_fraction(visibility)
    tip = as_finite(tip, (3,), "tip")
    bound = visibility * cone.beta
    grid = np.linspace(-math.pi, math.pi, int(scan), endpoint=False)
    ok = cone_coordinates(tip, grid, cone)["angle"] <= bound
    if not ok.any():
        return []
    if ok.all():
        return [(-math.pi, math.pi)]

    def margin(gamma):
        return float(cone_coordinates(tip, gamma, cone)["angle"]) - bound

    n = len(grid)
    first_bad = int(np.argmin(ok))
    order = (np.arange(n) + first_bad) % n
    step = 2.0 * math.pi / n
    intervals: list[tuple[float, float]] = []
    i = 0
    while i < n:
        if ok[order[i]]:
            j = i
            while j + 1 < n and ok[order[j + 1]]:
                j += 1
            g_in0 = grid[order[i]]
            g_out0 = g_in0 - step
            g_in1 = grid[order[j]]
            g_out1 = g_in1 + step
            lo = brentq(margin, g_out0, g_in0, xtol=1e-13)
            hi = brentq(margin, g_in1, g_out1, xtol=1e-13)
            if hi < lo:
                hi += 2.0 * math.pi
            lo_wrapped = (lo + math.pi) % (2.0 * math.pi) - math.pi
            intervals.append((lo_wrapped, lo_wrapped + (hi - lo)))
            i = j + 1
        else:
            i += 1
    return intervals


def _gamma_samples(intervals, spacing):
    if not intervals:
        return np.empty(0)
    parts = [np.linspace(lo, hi, max(2, int(math.ceil((hi - lo) / spacing)) + 1)) for lo, hi in intervals]
    return np.concatenate(parts)


def _in_intervals(gamma, intervals):
    gamma = np.asarray(gamma, dtype=float)
    ok = np.zeros(gamma.shape, dtype=bool)
    for lo, hi in intervals:
        shifted = lo + (gamma - lo) % (2.0 * math.pi)
        ok |= shifted <= hi + 1e-15
    return ok


def _arc_minimum(robot, tracer, arc, intervals, cone, refine=True):
    """(voi, q, gamma) of the lowest VOI over the arc points x feasible gammas, refined locally."""
    gammas = _gamma_samples(intervals, GAMMA_COARSE)
    Q = arc.q
    V = occlusion_details(robot, Q[:, None, :], gammas[None, :], cone)["voi"]
    i, j = np.unravel_index(int(np.argmin(V)), V.shape)
    best = (float(V[i, j]), Q[i].copy(), float(gammas[j]))
    if not refine:
        return best
    # refine around the few best cells: finer arc (re-walked with step/8) x finer gamma window
    flat = np.argsort(V, axis=None)[:4]
    for cell in flat:
        i, j = np.unravel_index(int(cell), V.shape)
        local_q = [Q[i]]
        for neighbour in (i - 1, i + 1) if tracer is not None else ():  # sampled sets: refine gamma only
            if 0 <= neighbour < len(Q):
                t = tracer.direction(Q[i], (Q[neighbour] - Q[i]) / tracer.scale)
                points, _ = tracer.walk(Q[i].copy(), t, 8, step=tracer.step / 8.0)
                local_q.extend(points)
        window = np.arange(gammas[j] - 2.0 * GAMMA_COARSE, gammas[j] + 2.0 * GAMMA_COARSE + GAMMA_FINE / 2, GAMMA_FINE)
        window = np.concatenate([window[_in_intervals(window, intervals)],
                                 [g for lo, hi in intervals for g in (lo, hi)
                                  if abs(((g - gammas[j]) + math.pi) % (2 * math.pi) - math.pi) <= 2.5 * GAMMA_COARSE]])
        if len(window) == 0:
            continue
        LQ = np.array(local_q)
        LV = occlusion_details(robot, LQ[:, None, :], window[None, :], cone)["voi"]
        a, b = np.unravel_index(int(np.argmin(LV)), LV.shape)
        if LV[a, b] < best[0]:
            best = (float(LV[a, b]), LQ[a].copy(), float(window[b]))
    return best


def hold_optimum(robot: MultiBackboneRobot, q0: ArrayLike, limits: OcclusionLimits | None,
                 visibility: float = VISIBILITY, cone: LensCone | None = None, step: float = TRACE_STEP,
                 refine: bool = True) -> dict[str, Any]:
    """Lowest VOI reachable while holding the tip pose of q0: self-motion arc x feasible gamma.

    The arc of the self-motion set that contains q0 within ``limits`` (:func:`trace_self_motion`) is
    combined with every endoscope rotation gamma that keeps the tip within ``visibility`` * beta of the
    view axis. The tip is fixed on the arc, so that gamma set (:func:`feasible_gamma_intervals`) is the
    same for every arc point: computed once, sampled every 0.5 degrees and at its exact ends; VOI is
    evaluated over (arc points x gammas) in one batch, then refined around the best cells (arc
    re-walked at step/8, gamma every 0.02 degrees).

    Args:
        robot: ``MultiBackboneRobot``; q0: (7,) start within ``limits``; limits: ``OcclusionLimits`` or None.
        visibility: fraction of the cone half-angle, in (0, 1].
        cone: ``LensCone`` (None: the paper's, literal lens).

    Returns:
        dict: ``voi`` (NaN if no gamma sees the tip), ``q`` (7,), ``gamma`` (rad), ``gamma_intervals``,
        ``arc_points``, ``closed``, ``ends``, ``at_visibility_bound`` (gamma at an interval end).
    """
    return _hold(robot, q0, limits, visibility, cone, step, refine)[0]


def _hold(robot, q0, limits, visibility, cone, step, refine):
    """``hold_optimum`` and the traced arc (the sampled self-motion set for a robot whose DoF is not 7)."""
    visibility = visibility_fraction(visibility)
    cone = LensCone() if cone is None else cone
    sampled = robot.dof != 7
    arc = sample_self_motion(robot, q0, limits) if sampled else trace_self_motion(robot, q0, limits, step=step)
    tip, _ = robot.forward_kinematics(np.asarray(q0, dtype=float))
    intervals = feasible_gamma_intervals(tip, visibility, cone)
    out = {"gamma_intervals": [list(map(float, iv)) for iv in intervals], "arc_points": int(len(arc.q)),
           "closed": bool(arc.closed), "ends": list(arc.ends)}
    if not intervals:
        out.update(voi=math.nan, q=np.full(robot.dof, np.nan), gamma=math.nan, at_visibility_bound=False)
        return out, arc
    p0, R0 = robot.forward_kinematics(arc.q[arc.start_index])
    lower, upper = limit_arrays(limits, robot.n_segments)
    tracer = None if sampled else SelfMotionTracer(robot, p0, R0, lower, upper, step, NEWTON_TOLERANCE)
    voi, q, gamma = _arc_minimum(robot, tracer, arc, intervals, cone, refine)
    at_bound = any(min(abs(gamma - lo), abs(gamma - hi)) < 1e-9 for lo, hi in intervals)
    out.update(voi=voi, q=q, gamma=gamma, at_visibility_bound=bool(at_bound))
    return out, arc


def centring_gamma(robot: MultiBackboneRobot, tips: ArrayLike, gamma0: float = 0.0, dt: float = PAPER_DT,
                   eta2: float = 30.0, gamma_rate: float | None = None, cone: LensCone | None = None) -> np.ndarray:
    """gamma(t) of the centring law (eq 24: gamma_dot = -eta2 dd_c/dgamma) along tip positions (T, 3).

    Explicit Euler from ``gamma0``; ``gamma_rate`` caps |gamma_dot| (rad/s; the env's limit is 3).
    Returns gamma (T + 1,) — the value before each step, then the final one.
    """
    tips = as_finite(tips, (3,), "tips").reshape(-1, 3)
    out = np.empty(len(tips) + 1)
    gamma = float(gamma0)
    out[0] = gamma
    for k, tip in enumerate(tips):
        _, slope = centre_distance(tip, gamma, cone)
        rate = -eta2 * float(slope)
        if gamma_rate is not None:
            rate = max(-gamma_rate, min(gamma_rate, rate))
        gamma = gamma + rate * dt
        out[k + 1] = gamma
    return out


def projected_gradient_hold(robot: MultiBackboneRobot, starts: ArrayLike, limits: OcclusionLimits | None,
                            steps: int = HOLD_ITERATIONS, visibility: float = VISIBILITY,
                            cone: LensCone | None = None) -> dict[str, np.ndarray]:
    """The projected gradient (gamma by its centring law from 0) holding each start's tip pose.

    Returns dict of per-start arrays: ``final_voi``, ``final_visible`` (tip within visibility at the end),
    ``best_visible_voi`` (min VOI over the trajectory points that satisfy limits and visibility; the
    rollout clamps to the limits), ``final_gamma``, ``max_tip_drift_m``.
    """
    cone = LensCone() if cone is None else cone
    visibility = visibility_fraction(visibility)
    starts = as_finite(starts, (7,), "starts").reshape(-1, 7)
    controller = ProjectedGradient(robot=robot, cone=cone, limits=limits)
    p0, R0 = robot.forward_kinematics(starts)
    n = len(starts)
    q, gamma = controller.rollout(starts, np.zeros(n), np.broadcast_to(p0[:, None], (n, steps, 3)),
                                  np.broadcast_to(R0[:, None], (n, steps, 3, 3)), dt=PAPER_DT)
    q = q.reshape(n, steps + 1, 7)
    gamma = gamma.reshape(n, steps + 1)
    voi = occlusion_details(robot, q, gamma, cone)["voi"]
    tip, _ = robot.forward_kinematics(q)
    visible = cone_coordinates(tip, gamma, cone)["angle"] <= visibility * cone.beta
    lower, upper = limit_arrays(limits)
    within = np.all((q >= lower - 1e-12) & (q <= upper + 1e-12), axis=-1)
    best = np.where(visible & within, voi, np.inf).min(axis=1)
    return {"final_voi": voi[:, -1], "final_visible": visible[:, -1], "best_visible_voi": best,
            "final_gamma": gamma[:, -1], "final_q": q[:, -1],
            "max_tip_drift_m": np.linalg.norm(tip - p0[:, None], axis=-1).max(axis=1)}


def _hold_job(job):
    robot = job.get("robot") or MultiBackboneRobot()
    cone = job.get("cone")
    limits = OcclusionLimits(max_bend=job["max_bend"], insertion=tuple(job["insertion"]))
    result, arc = _hold(robot, job["q0"], limits, job["visibility"], cone, TRACE_STEP, True)
    # self-motion alone at the centring gamma (the projected gradient's law)
    centred = occlusion_details(robot, arc.q, job["centring_gamma"], cone)["voi"]
    result["centring_gamma_voi"] = float(centred.min())
    return result


def hold_study(n_starts: int = HOLD_N_STARTS, seed: int = HOLD_STARTS_SEED, limits: OcclusionLimits | None = None,
               visibility: float = VISIBILITY, workers: int = 2, progress: bool = True) -> dict[str, Any]:
    """Hold optimum over ``sample_hold_starts(MultiBackboneRobot(), n_starts, default_rng(seed))``,
    against the projected gradient (``OcclusionLimits()``, 1500 steps, centring gamma from 0)."""
    robot = MultiBackboneRobot()
    limits = OcclusionLimits() if limits is None else limits
    visibility = visibility_fraction(visibility)
    started = time.perf_counter()
    starts = sample_hold_starts(robot, positive_int(n_starts, "n_starts"), np.random.default_rng(seed))
    pg = projected_gradient_hold(robot, starts, limits, visibility=visibility)
    jobs = [{"q0": q0, "max_bend": limits.max_bend, "insertion": limits.insertion, "visibility": visibility,
             "centring_gamma": float(g)} for q0, g in zip(starts, pg["final_gamma"])]
    results = map_jobs(_hold_job, jobs, positive_int(workers, "workers"), progress, "hold optimum")
    voi = np.array([r["voi"] for r in results])
    start_voi = occlusion_details(robot, starts, 0.0)["voi"]
    valid = np.isfinite(voi)
    return {
        "n_starts": int(len(starts)),
        "starts_seed": int(seed),
        "starts": np.round(starts, 15).tolist(),
        "visibility": visibility,
        "limits": {"max_bend": limits.max_bend, "insertion": list(limits.insertion)},
        "start_voi": rounded(start_voi),
        "optimum_voi": rounded(voi),
        "optimum_gamma": rounded(np.array([r["gamma"] for r in results])),
        "optimum_q": np.round(np.array([r["q"] for r in results]), 12).tolist(),
        "optimum_median_voi": float(np.nanmedian(voi)),
        "optimum_mean_voi": float(np.nanmean(voi)),
        "optimum_at_visibility_bound_fraction": float(np.mean([r["at_visibility_bound"] for r in results])),
        "centring_gamma_voi": rounded(np.array([r["centring_gamma_voi"] for r in results])),
        "centring_gamma_median_voi": float(np.median([r["centring_gamma_voi"] for r in results])),
        "projected_gradient_final_voi": rounded(pg["final_voi"]),
        "projected_gradient_median_voi": float(np.median(pg["final_voi"])),
        "projected_gradient_mean_voi": float(np.mean(pg["final_voi"])),
        "projected_gradient_final_visible_fraction": float(np.mean(pg["final_visible"])),
        "projected_gradient_best_visible_voi": rounded(pg["best_visible_voi"]),
        "fraction_optimum_le_projected_gradient": float(np.mean(voi[valid] <= pg["final_voi"][valid])),
        "fraction_optimum_le_projected_gradient_best_visible": float(
            np.mean(voi[valid] <= pg["best_visible_voi"][valid])),
        "no_feasible_gamma": int(np.sum(~valid)),
        "wall_time_s": round(time.perf_counter() - started, 1),
    }


def circle_optimum(robot: MultiBackboneRobot | None = None, task: CircleTask | None = None,
                   limits: OcclusionLimits | None = None, visibility: float = VISIBILITY, cone: LensCone | None = None,
                   sample_dt: float = CIRCLE_SAMPLE_DT, step: float = TRACE_STEP,
                   progress: bool = False) -> dict[str, Any]:
    """Time-connected lower bound of VOI along the circle (task b) within the limits.

    From psi_b (``task.start_configuration()``), the orientation held is FK(psi_b)'s. At each sampled time
    t_k = k * sample_dt over one period, the previous optimum is projected onto the new tip pose (Newton,
    minimum norm), the self-motion arc through it within ``limits`` is traced, and the lowest VOI over
    (arc x feasible gamma) is taken (gamma free each time; tip within ``visibility`` * beta). So each
    time's arc is the connected component reachable from the previous optimum. A second chain does the
    same with gamma fixed to the centring law's gamma(t) (eq 24 from 0 along the desired tip path).

    Returns dict: ``optimum_mean_voi``, ``times``, ``optimum_voi``, ``optimum_gamma``,
    ``centring_gamma_mean_voi``, ``centring_gamma_voi``, ``centring_gamma``.
    """
    from tqdm.auto import tqdm

    robot = MultiBackboneRobot() if robot is None else robot
    task = CircleTask() if task is None else task
    limits = OcclusionLimits() if limits is None else limits
    cone = LensCone() if cone is None else cone
    visibility = visibility_fraction(visibility)
    sample_dt = positive(sample_dt, "sample_dt", "s")
    n = int(round(task.period / sample_dt))
    times = np.arange(n) * sample_dt
    p_des, _ = task.trajectory(times, cone.alpha, cone.d_o)
    q_start = task.start_configuration()
    _, R_hold = robot.forward_kinematics(q_start)
    fine_t = np.arange(int(round(task.period / PAPER_DT))) * PAPER_DT
    fine_p, _ = task.trajectory(fine_t, cone.alpha, cone.d_o)
    gamma_law = centring_gamma(robot, fine_p, 0.0, PAPER_DT, gamma_rate=limits.gamma_rate, cone=cone)
    gamma_c = gamma_law[np.round(times / PAPER_DT).astype(int)]
    lower, upper = limit_arrays(limits)
    chains: dict[str, dict[str, Any]] = {"free": {"q": q_start.copy(), "voi": [], "gamma": []},
                                         "centring": {"q": q_start.copy(), "voi": [], "gamma": []}}
    for k in tqdm(range(n), desc="circle optimum", disable=not progress, leave=False):
        tracer = SelfMotionTracer(robot, p_des[k], R_hold, lower, upper, step, NEWTON_TOLERANCE)
        for name, chain in chains.items():
            q_k = tracer.project(chain["q"])
            if q_k is None or not tracer.inside(q_k):
                q_k = _project_inside(tracer, chain)
            arc = trace_self_motion_from(tracer, q_k)
            if name == "free":
                intervals = feasible_gamma_intervals(p_des[k], visibility, cone)
                voi, q_best, gamma = _arc_minimum(robot, tracer, arc, intervals, cone)
            else:
                values = occlusion_details(robot, arc.q, gamma_c[k], cone)["voi"]
                i = int(np.argmin(values))
                voi, q_best, gamma = float(values[i]), arc.q[i].copy(), float(gamma_c[k])
            chain["q"] = q_best
            chain["arc"] = arc.q
            chain["voi"].append(voi)
            chain["gamma"].append(gamma)
    free, centred = chains["free"], chains["centring"]
    return {
        "sample_dt": sample_dt,
        "times": rounded(times),
        "optimum_mean_voi": float(np.mean(free["voi"])),
        "optimum_voi": rounded(np.array(free["voi"])),
        "optimum_gamma": rounded(np.array(free["gamma"])),
        "centring_gamma_mean_voi": float(np.mean(centred["voi"])),
        "centring_gamma_voi": rounded(np.array(centred["voi"])),
        "centring_gamma": rounded(gamma_c),
        "visibility": visibility,
        "limits": {"max_bend": limits.max_bend, "insertion": list(limits.insertion)},
    }


def _project_inside(tracer, chain):
    """Project the previous arc's points (nearest to the previous optimum first) until one lands inside."""
    arc = chain.get("arc")
    if arc is None:
        raise RuntimeError("circle_optimum: the start configuration does not project onto the first pose")
    order = np.argsort([tracer.distance(q, chain["q"]) for q in arc])
    for i in order:
        q = tracer.project(arc[i])
        if q is not None and tracer.inside(q):
            return q
    raise RuntimeError("circle_optimum: no point of the previous arc projects within the limits")


def env_hold_test_optimum(n_tasks: int = ENV_HOLD_TASKS, limits: OcclusionLimits | None = None,
                          visibility: float = VISIBILITY, workers: int = 2, progress: bool = True,
                          robot: MultiBackboneRobot | None = None, cone: LensCone | None = None,
                          split: str = "test") -> dict[str, Any]:
    """Hold optimum on the OcclusionAvoidance environment's held-out hold tasks (ids 0..n-1 of ``split``).

    These are the instances ``continuum-gym evaluate`` scores, so ``headroom_closed`` compares each
    method with the best configuration-and-gamma on exactly the same tasks. ``robot`` and ``cone`` (None:
    the paper's) give the ceiling of a variant; its hold starts are the env's own for that robot.
    """
    from continuum_gym.envs.occlusion.tasks import hold_start_pool

    limits = OcclusionLimits() if limits is None else limits
    variant = () if robot is None and cone is None else (robot or MultiBackboneRobot(), cone or LensCone())
    starts = np.asarray(hold_start_pool(split, float(limits.max_bend), tuple(limits.insertion), *variant))
    starts = starts[:positive_int(n_tasks, "n_tasks")]
    jobs = [{"q0": q0, "max_bend": limits.max_bend, "insertion": limits.insertion,
             "visibility": visibility_fraction(visibility), "centring_gamma": 0.0, "robot": robot, "cone": cone}
            for q0 in starts]
    results = map_jobs(_hold_job, jobs, positive_int(workers, "workers"), progress, "env hold tasks")
    voi = np.array([r["voi"] for r in results])
    return {"task_ids": list(range(len(starts))), "optimum_voi": rounded(voi),
            "optimum_gamma": rounded(np.array([r["gamma"] for r in results])),
            "optimum_mean_voi": float(np.nanmean(voi)), "visibility": visibility,
            "limits": {"max_bend": limits.max_bend, "insertion": list(limits.insertion)}}
def env_optimum(config: Any, *, episodes: int, grid: int, split: str, progress: bool, workers: int) -> dict:
    """The optimum cache of an OcclusionAvoidance variant (``EnvSpec.optimum``): its hold tasks' optimum, and
    the rate-limited bound and planned trajectory of the same tasks' episodes."""
    out = {"hold_test": env_hold_test_optimum(episodes, limits=config.limits, workers=workers, progress=progress,
                                              robot=config.robot, cone=config.cone, split=split)}
    if config.robot.dof == 7:  # a one-dimensional self-motion arc (other robots: the optimum only)
        out["hold_test_rate_bound"] = env_hold_rate_bound(episodes, split, config, workers=workers, progress=progress,
                                                           traces=False)
    return out


