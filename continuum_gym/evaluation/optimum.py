"""Offline optima and strong references: the ceiling for every comparison (issue 8).

``continuum-gym optimum --env ID [--task coverage|hold|circle|all] [--grid N] [--json PATH] [--out DIR]``

**View tracking** (paper 001, ``ContinuumGym/ViewTracking-v0``):

- :func:`bounded_least_squares` — a pose fit within the joint limits: scipy ``least_squares`` (trf, bounds)
  on the target-point error (m) and the orientation error log(R_target R^T) (rad) scaled by
  ``LSQ_ORIENTATION_WEIGHT`` = 0.05 m/rad (1 rad of orientation error costs as much as 5 cm of
  position error; 0.05 gives 82.5 % on the 21 x 21 grid, 0.1 gives 81.2 %, 0.01 gives 71.7 %).
  One start (Psi0), like the baselines. It is the strong reference a skeptic would ask for.
- :func:`view_tracking_optimum` — the largest overlap ratio OR reachable within the joint limits:
  L-BFGS-B on -OR (OR is piecewise smooth) from the DR, RMRC and bounded-LSQ solutions and random
  starts, plus scipy's ``differential_evolution`` (vectorised population, seeded, no polish), then
  L-BFGS-B and Nelder-Mead polishing of the best. Every candidate is a real configuration within the
  limits, and the raw starts are candidates too, so the optimum is never below any of them.

  *Roll.* The frustum is square, so it is symmetric under image rolls of 90 degrees: OR does not see
  roll flips (paper-notes §4). The optimum maximises OR only; it may reach it with the continuum image
  rolled by about 90 or 180 degrees against the da Vinci image. ``roll_error`` reports that roll
  (angle of the continuum camera's x axis in the da Vinci image plane) for each solution.

**Occlusion avoidance** (paper 000, ``ContinuumGym/OcclusionAvoidance-v0``), within the env's limits
(``OcclusionLimits``: bends |pi/2 - theta| <= 90 degrees, insertion 0-40 mm) and its visibility
requirement (tip within ``visibility`` = 0.7 of the cone half-angle beta from the view axis):

- :func:`trace_self_motion` — the one-dimensional self-motion set of a held tip pose (7 joints, 6-D
  pose), traced by predictor-corrector continuation from q0 in both directions.
- :func:`hold_optimum` — the lowest VOI over the arc of that set containing q0 and the feasible
  endoscope rotations gamma (the tip is fixed, so the feasible gamma set is the same for the whole arc).
- :func:`circle_optimum` — for task (b), a time-connected lower bound: at sampled times the arc is the
  connected component reached from the previous time's optimum, minimised over the arc and gamma.

Results for the evaluation's task sets are shipped in ``data/optimum_cache.json``
(:func:`load_optimum_cache`); regenerate with
``continuum-gym optimum --env all --task all --write-cache``.
"""

from __future__ import annotations

import argparse
import ctypes
import math
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from typing import NamedTuple

import numpy as np

from numba import njit
from scipy.optimize import brentq, differential_evolution, least_squares, minimize

from continuum_gym.baselines import DimensionReduced, OcclusionLimits, ProjectedGradient, ResolvedRate
from continuum_gym.baselines.base import as_finite
from continuum_gym.baselines.scenarios import (
    CASE_STUDY_START,
    COVERAGE_THRESHOLD,
    HOLD_ITERATIONS,
    PAPER_DT,
    CircleTask,
    coverage_grid,
    sample_hold_starts,
)
from continuum_gym.evaluation.io import write_json_atomic
from continuum_gym.geometry import Frustum, LensCone, centre_distance, cone_coordinates, occlusion_details
from continuum_gym.geometry.overlap import overlap_ratio, overlap_ratio_nb
from continuum_gym.robots import ContinuumEndoscope, DaVinciEndoscope, MultiBackboneRobot
from continuum_gym.robots.endoscope import _kinematics_one
from continuum_gym.robots.mbcr import make_workspace, tip_kernel
from continuum_gym.robots.rotations import cholesky_solve_inplace, orientation_error, rotation_vector
from continuum_gym.robots.validation import positive

VIEW_TRACKING_ID = "ContinuumGym/ViewTracking-v0"
OCCLUSION_ID = "ContinuumGym/OcclusionAvoidance-v0"
#: Tasks of each environment id; ``all`` means both ids.
ENV_TASKS = {VIEW_TRACKING_ID: ("coverage",), OCCLUSION_ID: ("hold", "circle")}
TASKS = ("coverage", "hold", "circle")

#: Orientation weight of the bounded least-squares fit (m per rad of orientation error).
LSQ_ORIENTATION_WEIGHT = 0.05
#: Hold starts: ``sample_hold_starts(MultiBackboneRobot(), HOLD_N_STARTS, np.random.default_rng(HOLD_STARTS_SEED))``.
HOLD_STARTS_SEED = 2026
HOLD_N_STARTS = 59
#: Tip within this fraction of the cone half-angle from the view axis (the evaluation's requirement).
VISIBILITY = 0.7
#: Sampling interval (s) of the circle's time-connected bound.
CIRCLE_SAMPLE_DT = 0.1
#: Default coverage grid (points per axis) and global-optimality check sample size.
COVERAGE_GRID = 21
GLOBAL_CHECK_SAMPLE = 10
#: Seed of every random start and of differential evolution (per point: seed + index).
OPTIMUM_SEED = 0

CACHE_PATH = Path(__file__).resolve().parent / "data" / "optimum_cache.json"

# Search effort of the view-tracking optimum: the standard run and the heavy global-optimality check.
VIEW_EFFORT = {
    "quick": {"n_random": 1, "popsize": 6, "maxiter": 40, "de_runs": 1},
    "standard": {"n_random": 8, "popsize": 15, "maxiter": 300, "de_runs": 1},
    "heavy": {"n_random": 96, "popsize": 40, "maxiter": 2000, "de_runs": 4},
}

# Self-motion tracing: joint-space metric scales the insertion (m) by this length to compare with rad.
INSERTION_SCALE = 0.02
TRACE_STEP = 0.01
NEWTON_TOLERANCE = 1e-12
NEWTON_MAX_ITERATIONS = 12
# gamma sampling (rad): coarse grid over the feasible set, then a fine one around the best cells.
GAMMA_COARSE = math.radians(0.5)
GAMMA_FINE = math.radians(0.02)
GAMMA_SCAN = 3600


# ====================================================================== BLAS threads
_BLAS_CONTROLS: dict = {}
_BLAS_SYMBOLS = (("openblas_get_num_threads", "openblas_set_num_threads"),
                 ("scipy_openblas_get_num_threads64_", "scipy_openblas_set_num_threads64_"),
                 ("scipy_openblas_get_num_threads", "scipy_openblas_set_num_threads"))


def _blas_controls():
    """(getter, setter) of the thread count of every OpenBLAS loaded in this process (Linux; else none)."""
    try:
        with open("/proc/self/maps") as maps:
            paths = tuple(sorted({line.split()[-1] for line in maps
                                  if "openblas" in line.lower() and line.rstrip().split()[-1].startswith("/")}))
    except OSError:
        return []
    if paths not in _BLAS_CONTROLS:
        controls = []
        for path in paths:
            try:
                library = ctypes.CDLL(path)
            except OSError:
                continue
            for get_name, set_name in _BLAS_SYMBOLS:
                getter = getattr(library, get_name, None)
                setter = getattr(library, set_name, None)
                if getter is not None and setter is not None:
                    controls.append((getter, setter))
                    break
        _BLAS_CONTROLS[paths] = controls
    return _BLAS_CONTROLS[paths]


@contextmanager
def single_threaded_blas():
    """Run the block with one OpenBLAS thread (restored afterwards).

    The searches make hundreds of thousands of tiny BLAS calls (L-BFGS-B, SVDs of 6x7 matrices); a
    threaded OpenBLAS spends milliseconds per call synchronising its threads, which made the coverage
    optimum 4x slower. Without OpenBLAS (or off Linux) this does nothing.
    """
    controls = _blas_controls()
    previous = [getter() for getter, _ in controls]
    for _, setter in controls:
        setter(1)
    try:
        yield
    finally:
        for (_, setter), count in zip(controls, previous):
            setter(count)


# ====================================================================== view tracking
@njit(cache=True)
def _or_batch(Q, p_a, R_a, geom, tan_half, near, far, out):
    """OR between the da Vinci camera (p_a, R_a) and the continuum camera of each row of Q (n, 6)."""
    p_cam = np.empty(3)
    R = np.empty((3, 3))
    p_ct = np.empty(3)
    J = np.empty((6, 6))
    R1 = np.empty((3, 3))
    W1 = np.empty((3, 3))
    R2 = np.empty((3, 3))
    for i in range(Q.shape[0]):
        _kinematics_one(Q[i], geom, p_cam, R, p_ct, J, False, R1, W1, R2)
        out[i] = overlap_ratio_nb(p_a, R_a, p_cam, R, tan_half, near, far)


@njit(cache=True)
def _or_one(q, p_a, R_a, geom, tan_half, near, far):
    p_cam = np.empty(3)
    R = np.empty((3, 3))
    p_ct = np.empty(3)
    J = np.empty((6, 6))
    R1 = np.empty((3, 3))
    W1 = np.empty((3, 3))
    R2 = np.empty((3, 3))
    _kinematics_one(q, geom, p_cam, R, p_ct, J, False, R1, W1, R2)
    return overlap_ratio_nb(p_a, R_a, p_cam, R, tan_half, near, far)


def _view_bounds(robot, delta_span):
    """Joint limits (6,) with the unlimited deltas bounded to [-delta_span, delta_span]."""
    lower, upper = robot.joint_limits
    lower[[3, 5]] = -delta_span
    upper[[3, 5]] = delta_span
    return lower, upper


def _wrap_view(q, lower, upper):
    """Deltas wrapped to [-pi, pi), the rest clipped to the limits (copies)."""
    q = np.array(q, dtype=float)
    q[..., [3, 5]] = q[..., [3, 5]] - 2.0 * math.pi * np.floor((q[..., [3, 5]] + math.pi) / (2.0 * math.pi))
    return np.clip(q, lower, upper)


def _right_jacobian_inverse(e):
    """Inverse right Jacobian of SO(3) at the rotation vector e: d log(R_t R^T) = -J_r^-1(e) w dt."""
    theta = float(np.linalg.norm(e))
    K = np.array([[0.0, -e[2], e[1]], [e[2], 0.0, -e[0]], [-e[1], e[0], 0.0]])
    if theta < 1e-6:
        return np.eye(3) + 0.5 * K + K @ K / 12.0
    if theta > math.pi - 1e-9:  # log is not differentiable at pi: use the first-order term
        return np.eye(3) + 0.5 * K
    coefficient = 1.0 / theta**2 - (1.0 + math.cos(theta)) / (2.0 * theta * math.sin(theta))
    return np.eye(3) + 0.5 * K + coefficient * (K @ K)


def _lsq_one(p_target, R_target, q0, weight, robot, lower, upper):
    def residual(q):
        _, R, p_ct, _ = robot.fk_jacobian(q)
        e = rotation_vector(R_target @ R.T)
        return np.concatenate([p_ct - p_target, -weight * e])

    def jacobian(q):
        _, R, _, J = robot.fk_jacobian(q)
        e = rotation_vector(R_target @ R.T)
        return np.vstack([J[:3], weight * (_right_jacobian_inverse(e) @ J[3:])])

    start = np.clip(_wrap_view(q0, lower, upper), lower, upper)
    result = least_squares(residual, start, jac=jacobian, bounds=(lower, upper), method="trf",
                           xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=200)
    return _wrap_view(result.x, *robot.joint_limits)


def bounded_least_squares(target_p, target_R, q0=CASE_STUDY_START, orientation_weight=LSQ_ORIENTATION_WEIGHT,
                          robot=None):
    """Pose fit within the joint limits: the strong view-tracking reference (batched over targets).

    Minimises |p_ct(q) - target_p|^2 + (w |log(target_R R_ct(q)^T)|)^2 with scipy ``least_squares``
    (trf, analytic Jacobian) subject to the joint limits of ``robot``; the deltas are unlimited: they are
    bounded to [-3 pi, 3 pi] during the fit and wrapped to [-pi, pi) afterwards.

    Args:
        target_p: target point(s) (..., 3) in m (the da Vinci visual target point p_dVt).
        target_R: target rotation(s) (..., 3, 3) (R_dVt).
        q0: start configuration(s) (..., 6), default Psi0 (``CASE_STUDY_START``); clipped into the limits.
        orientation_weight: w (m/rad), default ``LSQ_ORIENTATION_WEIGHT`` = 0.05.
        robot: ``ContinuumEndoscope`` (default geometry).

    Returns:
        q (..., 6) within the joint limits.
    """
    robot = ContinuumEndoscope() if robot is None else robot
    if not isinstance(robot, ContinuumEndoscope):
        raise ValueError(f"robot must be a ContinuumEndoscope; got {type(robot).__name__}")
    weight = positive(orientation_weight, "orientation_weight", "m/rad")
    target_p = as_finite(target_p, (3,), "target_p")
    target_R = as_finite(target_R, (3, 3), "target_R")
    q0 = as_finite(q0, (6,), "q0")
    try:
        shape = np.broadcast_shapes(target_p.shape[:-1], target_R.shape[:-2], q0.shape[:-1])
    except ValueError as error:
        raise ValueError(f"target_p, target_R and q0 batch shapes do not broadcast: {error}") from error
    P = np.broadcast_to(target_p, shape + (3,)).reshape(-1, 3)
    Rs = np.broadcast_to(target_R, shape + (3, 3)).reshape(-1, 3, 3)
    Q0 = np.broadcast_to(q0, shape + (6,)).reshape(-1, 6)
    lower, upper = _view_bounds(robot, 3.0 * math.pi)
    with single_threaded_blas():
        out = np.array([_lsq_one(P[i], Rs[i], Q0[i], weight, robot, lower, upper) for i in range(P.shape[0])])
    return out.reshape(shape + (6,))


def _image_roll(R_a, R_b):
    """Angle (rad) of camera b's x axis in camera a's image plane (x_a, y_a)."""
    x_b = R_b[..., :, 0]
    return np.arctan2(np.sum(R_a[..., :, 1] * x_b, axis=-1), np.sum(R_a[..., :, 0] * x_b, axis=-1))


def _optimise_view_point(job):
    """Worker: the OR optimum for one target. ``job`` is a dict (picklable)."""
    geom = job["geom"]
    p_a, R_a = job["p_a"], job["R_a"]
    tan_half, near, far = job["frustum"]
    lower, upper = job["lower"], job["upper"]
    effort = VIEW_EFFORT[job["effort"]]
    rng = np.random.default_rng(job["seed"])
    span = 2.0 * math.pi  # local searches may cross +-pi in the deltas (wrapped afterwards)
    local_lower = lower.copy()
    local_upper = upper.copy()
    local_lower[[3, 5]] = -span
    local_upper[[3, 5]] = span
    local_bounds = list(zip(local_lower, local_upper))

    def objective(q):
        return -_or_one(np.ascontiguousarray(q, dtype=float), p_a, R_a, geom, tan_half, near, far)

    def objective_population(X):
        X = np.ascontiguousarray(np.atleast_2d(X.T), dtype=float)
        out = np.empty(X.shape[0])
        _or_batch(X, p_a, R_a, geom, tan_half, near, far, out)
        return -out

    candidates = []  # (or, q, source)

    def consider(q, source):
        q = _wrap_view(q, lower, upper)
        candidates.append((-objective(q), q, source))

    def local(q0, source, method="L-BFGS-B"):
        start = np.clip(_wrap_view(q0, lower, upper), local_lower, local_upper)
        options = {"maxfun": 4000} if method == "L-BFGS-B" else {
            "xatol": 1e-9, "fatol": 1e-12, "maxfev": 4000, "adaptive": True}
        result = minimize(objective, start, method=method, bounds=local_bounds, options=options)
        consider(result.x, source)

    for source, q in job["starts"].items():
        consider(q, source)
        local(q, source)
    for _ in range(effort["n_random"]):
        local(rng.uniform(lower, upper), "random")
    bounds = list(zip(lower, upper))
    for _ in range(effort["de_runs"]):
        result = differential_evolution(objective_population, bounds, vectorized=True, updating="deferred",
                                        seed=int(rng.integers(2**31)), popsize=effort["popsize"],
                                        maxiter=effort["maxiter"], tol=1e-8, polish=False, init="sobol")
        consider(result.x, "differential_evolution")
        local(result.x, "differential_evolution")
    best_or, best_q, best_source = max(candidates, key=lambda c: c[0])
    # final polish of the best: Nelder-Mead handles the kinks of the piecewise-smooth OR
    local(best_q, best_source, method="Nelder-Mead")
    local(candidates[-1][1], best_source)
    best_or, best_q, best_source = max(candidates, key=lambda c: c[0])
    return {"index": job["index"], "q": best_q, "overlap": best_or, "source": best_source,
            "starts": {name: (q, -objective(_wrap_view(q, lower, upper))) for name, q in job["starts"].items()}}


def _map_jobs(function, jobs, workers, progress, description):
    """Run ``function`` over ``jobs`` (in order), in ``workers`` processes, with a tqdm bar."""
    from tqdm.auto import tqdm

    results = [None] * len(jobs)
    bar = tqdm(total=len(jobs), desc=description, disable=not progress, leave=False)
    if workers <= 1 or len(jobs) <= 1:
        with single_threaded_blas():
            for k, job in enumerate(jobs):
                results[k] = function(job)
                bar.update()
    else:
        from concurrent.futures import ProcessPoolExecutor, as_completed

        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = {pool.submit(_single_threaded, function, job): k for k, job in enumerate(jobs)}
            for future in as_completed(futures):
                results[futures[future]] = future.result()
                bar.update()
    bar.close()
    return results


def _single_threaded(function, job):
    with single_threaded_blas():
        return function(job)


def view_tracking_optimum(q_davinci, robot=None, davinci=None, frustum=None, effort="standard", seed=OPTIMUM_SEED,
                          workers=1, progress=False, baselines=True):
    """The largest overlap ratio reachable within the joint limits, for each da Vinci view.

    For each target view (the da Vinci camera frame of ``q_davinci``), maximises OR(F_dV, F_ct(q)) over
    q within the continuum endoscope's joint limits (L0 in [0, 0.1] m, phi in [-pi, pi], theta1 in
    [0, pi/4], theta2 in [0, pi/2]; deltas free) by
    1. L-BFGS-B on -OR from the solutions of DR and RMRC (run from Psi0, as in the coverage map), from
       the bounded least-squares fit and from random starts;
    2. ``differential_evolution`` (vectorised population, Sobol init, seeded, no polish) + L-BFGS-B;
    3. Nelder-Mead and L-BFGS-B polishing of the best.
    The starts themselves are candidates, so the optimum is >= each baseline's OR.

    Roll: the square frustum is symmetric under 90-degree image rolls, so OR (and this optimum) does not
    see roll flips; the optimum maximises OR only. ``roll_error`` reports the image roll it ends with.

    Args:
        q_davinci: da Vinci configurations (..., 4) [L_dV (m), yaw, pitch, roll].
        robot: ``ContinuumEndoscope``; davinci: ``DaVinciEndoscope``; frustum: ``Frustum`` (defaults).
        effort: ``"standard"``, ``"heavy"`` (the global-optimality check: 96 random starts, 4 larger DE runs)
            or ``"quick"`` (tests); see ``VIEW_EFFORT``.
        seed: base seed; point k uses seed + k (results do not depend on ``workers``).
        workers: processes (``concurrent.futures.ProcessPoolExecutor``).
        progress: show a tqdm bar.
        baselines: run DR and RMRC from Psi0 as starts (and report them).

    Returns:
        dict: ``q`` (..., 6), ``overlap`` (...), ``roll_error`` (..., rad), ``source`` (list of where each
        optimum came from) and ``references``: {name: {"q", "overlap"}} for ``bounded_least_squares`` and
        (with ``baselines``) ``dimension_reduced`` and ``resolved_rate``.
    """
    robot = ContinuumEndoscope() if robot is None else robot
    davinci = DaVinciEndoscope() if davinci is None else davinci
    frustum = Frustum() if frustum is None else frustum
    if effort not in VIEW_EFFORT:
        raise ValueError(f"effort must be one of {tuple(VIEW_EFFORT)}; got {effort!r}")
    workers = _positive_int(workers, "workers")
    q_davinci = as_finite(q_davinci, (4,), "q_davinci")
    shape = q_davinci.shape[:-1]
    grid = q_davinci.reshape(-1, 4)
    n = grid.shape[0]
    p_a, R_a = davinci.forward_kinematics(grid)
    p_t, R_t = davinci.target_pose(grid)
    starts = {}
    if baselines:
        start = np.broadcast_to(CASE_STUDY_START, (n, 6))
        starts["dimension_reduced"] = DimensionReduced(robot=robot).solve(start, (p_t, R_t))["q"]
        starts["resolved_rate"] = ResolvedRate(robot=robot).solve(start, (p_t, R_t))["q"]
    lower, upper = _view_bounds(robot, math.pi)
    jobs = []
    for k in range(n):
        jobs.append({"index": k, "geom": np.array(robot.geometry), "p_a": np.ascontiguousarray(p_a[k]),
                     "R_a": np.ascontiguousarray(R_a[k]), "frustum": (frustum.tan_half, frustum.near, frustum.far),
                     "lower": lower, "upper": upper, "effort": effort, "seed": int(seed) + k,
                     "p_t": p_t[k], "R_t": R_t[k], "starts": {name: q[k] for name, q in starts.items()}})
    results = _map_jobs(_view_job_with_lsq, jobs, workers, progress, f"view-tracking optimum ({effort})")
    q = np.array([r["q"] for r in results])
    p_c, R_c = robot.forward_kinematics(q)
    overlap = overlap_ratio(p_a, R_a, p_c, R_c, frustum)
    references = {}
    for name in results[0]["starts"]:
        q_ref = np.array([r["starts"][name][0] for r in results])
        p_r, R_r = robot.forward_kinematics(q_ref)
        references[name] = {"q": q_ref.reshape(shape + (6,)),
                            "overlap": overlap_ratio(p_a, R_a, p_r, R_r, frustum).reshape(shape)}
    # the optimum is at least every start (each start is a candidate): enforce it bit for bit
    for ref in references.values():
        better = ref["overlap"].reshape(-1) > overlap
        if np.any(better):
            q[better] = ref["q"].reshape(-1, 6)[better]
            overlap[better] = ref["overlap"].reshape(-1)[better]
    p_c, R_c = robot.forward_kinematics(q)
    return {"q": q.reshape(shape + (6,)), "overlap": overlap.reshape(shape),
            "roll_error": _image_roll(R_a, R_c).reshape(shape), "source": [r["source"] for r in results],
            "references": references}


def _view_job_with_lsq(job):
    """Worker: bounded LSQ fit for the point (a start), then the OR optimum."""
    robot = ContinuumEndoscope(*job["geom"])
    lower, upper = _view_bounds(robot, 3.0 * math.pi)
    job = dict(job)
    job["starts"] = dict(job["starts"])
    job["starts"]["bounded_least_squares"] = _lsq_one(job["p_t"], job["R_t"], CASE_STUDY_START,
                                                      LSQ_ORIENTATION_WEIGHT, robot, lower, upper)
    return _optimise_view_point(job)


def coverage_optimum(grid=COVERAGE_GRID, workers=2, progress=True, global_check=GLOBAL_CHECK_SAMPLE,
                     seed=OPTIMUM_SEED):
    """Coverage of the paper's map (L_dV = 65 mm, roll 0, yaw/pitch in [-60, 60] deg, OR > 0.8).

    Returns a dict with the cache keys of ``coverage`` (percentages, mean OR, per-point OR maps of the
    optimum, bounded LSQ, DR and RMRC, yaw-major like ``coverage_grid``) and ``global_check``: the
    optimum against a heavy search (``effort="heavy"``) at ``global_check`` grid points, half of them
    those nearest the OR threshold (where a miss would change the coverage), half drawn at random.
    """
    grid = _grid_size(grid)
    q_davinci = coverage_grid(grid)
    started = time.perf_counter()
    result = view_tracking_optimum(q_davinci, effort="standard", seed=seed, workers=workers, progress=progress)
    elapsed = time.perf_counter() - started
    threshold = COVERAGE_THRESHOLD
    optimum = result["overlap"]
    refs = result["references"]

    def percent(values):
        return float(np.mean(values > threshold) * 100.0)

    out = {
        "grid": grid,
        "threshold": threshold,
        "optimum_percent": percent(optimum),
        "optimum_mean_or": float(np.mean(optimum)),
        "bounded_least_squares_percent": percent(refs["bounded_least_squares"]["overlap"]),
        "bounded_least_squares_mean_or": float(np.mean(refs["bounded_least_squares"]["overlap"])),
        "unreachable_percent": 100.0 - percent(optimum),
        "dimension_reduced_percent": percent(refs["dimension_reduced"]["overlap"]),
        "resolved_rate_percent": percent(refs["resolved_rate"]["overlap"]),
        "lsq_orientation_weight_m_per_rad": LSQ_ORIENTATION_WEIGHT,
        "optimum_or": _rounded(optimum),
        "bounded_least_squares_or": _rounded(refs["bounded_least_squares"]["overlap"]),
        "dimension_reduced_or": _rounded(refs["dimension_reduced"]["overlap"]),
        "resolved_rate_or": _rounded(refs["resolved_rate"]["overlap"]),
        "optimum_roll_error": _rounded(result["roll_error"]),
        "optimum_at_L0_zero_percent": float(np.mean(result["q"][:, 0] <= 1e-9) * 100.0),
        "seed": int(seed),
        "wall_time_s": round(elapsed, 1),
        "workers": int(workers),
    }
    if global_check:
        indices = _global_check_sample(optimum, threshold, int(global_check), seed)
        started = time.perf_counter()
        heavy = view_tracking_optimum(q_davinci[indices], effort="heavy", seed=seed + 10_000, workers=workers,
                                      progress=progress)
        gap = heavy["overlap"] - optimum[indices]
        out["global_check"] = {
            "indices": indices.tolist(),
            "standard_or": _rounded(optimum[indices]),
            "heavy_or": _rounded(heavy["overlap"]),
            "max_gap": float(gap.max()),
            "mean_gap": float(gap.mean()),
            "threshold_flips": int(np.sum((heavy["overlap"] > threshold) != (optimum[indices] > threshold))),
            "wall_time_s": round(time.perf_counter() - started, 1),
        }
    return out


def _global_check_sample(overlap, threshold, size, seed):
    """Grid indices for the heavy search: half nearest the threshold (where a miss changes coverage),
    half drawn at random (seeded) from the rest."""
    size = min(size, len(overlap))
    near = np.argsort(np.abs(overlap - threshold), kind="stable")[: (size + 1) // 2]
    rest = np.setdiff1d(np.arange(len(overlap)), near)
    drawn = np.random.default_rng(seed).choice(rest, size=size - len(near), replace=False)
    return np.sort(np.concatenate([near, drawn]))


# ====================================================================== self-motion (paper 000)
@njit(cache=True)
def _newton_project(q, p0, R0, lengths, scale, tolerance, max_iterations):
    """Newton on the 6-D tip pose error with the pseudo-inverse (scaled joints), in place.

    Returns (iterations or -1 if not converged, final max-abs error, total scaled correction length).
    """
    ws = make_workspace()
    p = np.empty(3)
    R = np.empty((3, 3))
    J = np.empty((6, 7))
    work = np.empty((3, 3))
    e_w = np.empty(3)
    e = np.empty(6)
    Js = np.empty((6, 7))
    G = np.empty((6, 6))
    y = np.empty((6, 1))
    moved = 0.0
    err = math.inf
    for it in range(max_iterations + 1):
        tip_kernel(q, lengths, ws, p, R, J)
        for a in range(3):
            e[a] = p0[a] - p[a]
        orientation_error(R0, R, work, e_w)
        for a in range(3):
            e[3 + a] = e_w[a]
        err = 0.0
        for a in range(6):
            err = max(err, abs(e[a]))
        if err < tolerance:
            return it, err, moved
        if it == max_iterations or not math.isfinite(err):
            break
        for a in range(6):
            for k in range(7):
                Js[a, k] = J[a, k] * scale[k]
        # minimum-norm step dq = Js^T (Js Js^T)^-1 e (Cholesky; a tiny damping only if it is singular)
        damping = 0.0
        for _ in range(8):
            for a in range(6):
                for b in range(6):
                    acc = 0.0
                    for k in range(7):
                        acc += Js[a, k] * Js[b, k]
                    G[a, b] = acc
                G[a, a] += damping
                y[a, 0] = e[a]
            if cholesky_solve_inplace(G, y):
                break
            damping = 1e-14 if damping == 0.0 else 100.0 * damping
        size = 0.0
        for k in range(7):
            step = 0.0
            for a in range(6):
                step += Js[a, k] * y[a, 0]
            q[k] += step * scale[k]
            size += step * step
        moved += math.sqrt(size)
    return -1, err, moved


@njit(cache=True)
def _null_direction(q, lengths, scale, previous):
    """Unit null vector of the scaled 6x7 tip Jacobian, sign-continuous with ``previous`` (scaled space).

    Near a rank drop (two small singular values) the previous direction is projected onto the 2-D null space.
    Returns (direction, smallest / largest nonzero singular value ratio).
    """
    ws = make_workspace()
    p = np.empty(3)
    R = np.empty((3, 3))
    J = np.empty((6, 7))
    tip_kernel(q, lengths, ws, p, R, J)
    Js = np.empty((6, 7))
    for a in range(6):
        for k in range(7):
            Js[a, k] = J[a, k] * scale[k]
    _, s, vt = np.linalg.svd(Js)
    t = vt[6].copy()
    if s[5] < 1e-6 * s[0]:
        a = vt[5].copy()
        b = vt[6].copy()
        ca = 0.0
        cb = 0.0
        for k in range(7):
            ca += previous[k] * a[k]
            cb += previous[k] * b[k]
        norm = math.sqrt(ca * ca + cb * cb)
        if norm > 0.0:
            for k in range(7):
                t[k] = (ca * a[k] + cb * b[k]) / norm
    dot = 0.0
    for k in range(7):
        dot += t[k] * previous[k]
    if dot < 0.0:
        for k in range(7):
            t[k] = -t[k]
    return t, s[5] / s[0]


class SelfMotion(NamedTuple):
    """A traced self-motion arc: ``q`` (M, 7) ordered along the arc, ``q[start_index]`` is q0.

    ``closed``: the arc closed into a loop (then q[0] = q0 and the last point is next to it, deltas
    modulo 2 pi). ``ends``: why each end stopped ("limit:<joint>", "loop", "max_steps", "stuck"),
    (backward end, forward end).
    """

    q: np.ndarray
    start_index: int
    closed: bool
    ends: tuple


def _limit_arrays(limits):
    if limits is None:
        return np.full(7, -np.inf), np.full(7, np.inf)
    if not isinstance(limits, OcclusionLimits):
        raise ValueError(f"limits must be an OcclusionLimits or None; got {type(limits).__name__}")
    return limits.lower, limits.upper


JOINT_NAMES = ("theta1", "delta1", "theta2", "delta2", "theta3", "delta3", "q_ins")


class _Tracer:
    """Predictor-corrector continuation on the self-motion set of the tip pose (p0, R0)."""

    def __init__(self, robot, p0, R0, lower, upper, step, tolerance):
        self.lengths = robot._lengths_array
        self.p0 = np.ascontiguousarray(p0, dtype=float)
        self.R0 = np.ascontiguousarray(R0, dtype=float)
        self.lower, self.upper = lower, upper
        self.step = step
        self.tolerance = tolerance
        self.scale = np.ones(7)
        self.scale[6] = INSERTION_SCALE

    def inside(self, q):
        return bool(np.all(q >= self.lower) and np.all(q <= self.upper))

    def violated(self, q):
        bad = np.where((q < self.lower) | (q > self.upper))[0]
        return JOINT_NAMES[bad[0]] if len(bad) else None

    def project(self, q):
        """Newton projection of q onto the manifold (copy); None if it does not converge."""
        q = np.array(q, dtype=float)
        it, _, _ = _newton_project(q, self.p0, self.R0, self.lengths, self.scale, self.tolerance,
                                   NEWTON_MAX_ITERATIONS)
        return q if it >= 0 else None

    def direction(self, q, previous):
        return _null_direction(np.ascontiguousarray(q), self.lengths, self.scale, previous)[0]

    def _corrected(self, q, t, h):
        qn = q + h * t * self.scale
        it, _, moved = _newton_project(qn, self.p0, self.R0, self.lengths, self.scale, self.tolerance,
                                       NEWTON_MAX_ITERATIONS)
        return qn if it >= 0 and moved < 0.5 * h else None

    def walk(self, q, t, max_steps, origin=None, step=None):
        """Points after q along direction t (scaled space); returns (points, reason)."""
        nominal = self.step if step is None else step
        h = nominal
        points = []
        far = False
        for _ in range(max_steps):
            while True:
                qn = self._corrected(q, t, h)
                if qn is not None:
                    tn = self.direction(qn, t)
                    if float(tn @ t) > 0.9:
                        break
                h *= 0.5
                if h < 1e-10 * nominal:
                    return points, "stuck"
            if not self.inside(qn):
                joint = self.violated(qn)
                a, b, qa = 0.0, h, None
                for _ in range(60):  # bisection onto the limit
                    m = 0.5 * (a + b)
                    qm = self._corrected(q, t, m)
                    if qm is not None and self.inside(qm):
                        a, qa = m, qm
                    else:
                        b = m
                    if b - a < 1e-12:
                        break
                if qa is not None:
                    points.append(qa)
                return points, f"limit:{joint}"
            q, t = qn, tn
            points.append(q)
            h = min(nominal, 2.0 * h)
            if origin is not None:
                d = self.distance(q, origin)
                if d > 3.0 * nominal:
                    far = True
                elif far and d < 0.75 * nominal:
                    return points, "loop"
        return points, "max_steps"

    def distance(self, a, b):
        d = (a - b) / self.scale
        d[[1, 3, 5]] = (d[[1, 3, 5]] + math.pi) % (2.0 * math.pi) - math.pi
        return float(np.linalg.norm(d))


def trace_self_motion(robot, q0, limits, step=TRACE_STEP, max_steps=20_000, tolerance=NEWTON_TOLERANCE):
    """The self-motion arc of the tip pose of q0 by predictor-corrector continuation.

    7 joints and a 6-D tip pose leave a one-dimensional set of configurations with the same tip pose.
    From q0 it is traced in both directions: predictor = unit null vector of the 6x7 tip Jacobian
    (joints scaled so that ``INSERTION_SCALE`` = 0.02 m of insertion counts as 1 rad; sign continuous;
    near a rank drop the previous direction projected on the null space), step ``step`` in that metric;
    corrector = Newton on the 6-D pose error [p0 - p; log(R0 R^T)] with the pseudo-inverse, until the
    largest error component is below ``tolerance`` (m / rad). The step halves when Newton fails or the
    direction turns by more than ~25 degrees. A direction stops at the limits (bend |pi/2 - theta_j|
    <= max_bend, insertion range; the last point is bisected onto the limit) or when the arc closes
    into a loop (back within 0.75 step of q0, deltas modulo 2 pi).

    Args:
        robot: ``MultiBackboneRobot``.
        q0: start configuration (7,), within the limits.
        limits: ``OcclusionLimits`` or None (unlimited).
        step: nominal step (rad-equivalent) of the predictor.
        max_steps: per direction.
        tolerance: Newton tolerance on the pose error.

    Returns:
        ``SelfMotion`` (q (M, 7), start_index, closed, ends).
    """
    if not isinstance(robot, MultiBackboneRobot):
        raise ValueError(f"robot must be a MultiBackboneRobot; got {type(robot).__name__}")
    q0 = as_finite(q0, (7,), "q0")
    if q0.shape != (7,):
        raise ValueError(f"q0 must have shape (7,); got {q0.shape}")
    step = positive(step, "step", "rad")
    max_steps = _positive_int(max_steps, "max_steps")
    tolerance = positive(tolerance, "tolerance", "m or rad")
    lower, upper = _limit_arrays(limits)
    if np.any(q0 < lower) or np.any(q0 > upper):
        raise ValueError(f"q0 must be within the limits; got q0 = {q0.tolist()}")
    p0, R0 = robot.forward_kinematics(q0)
    tracer = _Tracer(robot, p0, R0, lower, upper, step, tolerance)
    t0 = tracer.direction(q0, np.full(7, 7 ** -0.5))
    forward, reason_f = tracer.walk(q0.copy(), t0, max_steps, origin=q0)
    if reason_f == "loop":
        return SelfMotion(np.array([q0] + forward), 0, True, ("loop", "loop"))
    backward, reason_b = tracer.walk(q0.copy(), -t0, max_steps, origin=q0)
    q = np.array(backward[::-1] + [q0] + forward)
    return SelfMotion(q, len(backward), False, (reason_b, reason_f))


# ---------------------------------------------------------------------- gamma feasibility
def feasible_gamma_intervals(tip, visibility=VISIBILITY, cone=None, scan=GAMMA_SCAN):
    """Intervals [lo, hi] (rad, lo in [-pi, pi), hi > lo) of endoscope rotations gamma that see ``tip``
    within ``visibility`` * beta of the view axis (``cone_coordinates(tip, gamma)["angle"]``).

    Found on a ``scan``-point grid over [-pi, pi) and refined by Brent's method to 1e-13 rad.
    Returns [] if no gamma qualifies and [(-pi, pi)] if every gamma does.
    """
    cone = LensCone() if cone is None else cone
    visibility = _visibility(visibility)
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
    intervals = []
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
        for neighbour in (i - 1, i + 1):
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


def hold_optimum(robot, q0, limits, visibility=VISIBILITY, cone=None, step=TRACE_STEP, refine=True):
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
    """``hold_optimum`` and the traced arc."""
    visibility = _visibility(visibility)
    cone = LensCone() if cone is None else cone
    arc = trace_self_motion(robot, q0, limits, step=step)
    tip, _ = robot.forward_kinematics(np.asarray(q0, dtype=float))
    intervals = feasible_gamma_intervals(tip, visibility, cone)
    out = {"gamma_intervals": [list(map(float, iv)) for iv in intervals], "arc_points": int(len(arc.q)),
           "closed": bool(arc.closed), "ends": list(arc.ends)}
    if not intervals:
        out.update(voi=math.nan, q=np.full(7, np.nan), gamma=math.nan, at_visibility_bound=False)
        return out, arc
    p0, R0 = robot.forward_kinematics(arc.q[arc.start_index])
    lower, upper = _limit_arrays(limits)
    tracer = _Tracer(robot, p0, R0, lower, upper, step, NEWTON_TOLERANCE)
    voi, q, gamma = _arc_minimum(robot, tracer, arc, intervals, cone, refine)
    at_bound = any(min(abs(gamma - lo), abs(gamma - hi)) < 1e-9 for lo, hi in intervals)
    out.update(voi=voi, q=q, gamma=gamma, at_visibility_bound=bool(at_bound))
    return out, arc


def centring_gamma(robot, tips, gamma0=0.0, dt=PAPER_DT, eta2=30.0, gamma_rate=None, cone=None):
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


def projected_gradient_hold(robot, starts, limits, steps=HOLD_ITERATIONS, visibility=VISIBILITY, cone=None):
    """The projected gradient (gamma by its centring law from 0) holding each start's tip pose.

    Returns dict of per-start arrays: ``final_voi``, ``final_visible`` (tip within visibility at the end),
    ``best_visible_voi`` (min VOI over the trajectory points that satisfy limits and visibility; the
    rollout clamps to the limits), ``final_gamma``, ``max_tip_drift_m``.
    """
    cone = LensCone() if cone is None else cone
    visibility = _visibility(visibility)
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
    lower, upper = _limit_arrays(limits)
    within = np.all((q >= lower - 1e-12) & (q <= upper + 1e-12), axis=-1)
    best = np.where(visible & within, voi, np.inf).min(axis=1)
    return {"final_voi": voi[:, -1], "final_visible": visible[:, -1], "best_visible_voi": best,
            "final_gamma": gamma[:, -1], "final_q": q[:, -1],
            "max_tip_drift_m": np.linalg.norm(tip - p0[:, None], axis=-1).max(axis=1)}


def _hold_job(job):
    robot = MultiBackboneRobot()
    limits = OcclusionLimits(max_bend=job["max_bend"], insertion=tuple(job["insertion"]))
    result, arc = _hold(robot, job["q0"], limits, job["visibility"], None, TRACE_STEP, True)
    # self-motion alone at the centring gamma (the projected gradient's law)
    centred = occlusion_details(robot, arc.q, job["centring_gamma"])["voi"]
    result["centring_gamma_voi"] = float(centred.min())
    return result


def hold_study(n_starts=HOLD_N_STARTS, seed=HOLD_STARTS_SEED, limits=None, visibility=VISIBILITY, workers=2,
               progress=True):
    """Hold optimum over ``sample_hold_starts(MultiBackboneRobot(), n_starts, default_rng(seed))``,
    against the projected gradient (``OcclusionLimits()``, 1500 steps, centring gamma from 0)."""
    robot = MultiBackboneRobot()
    limits = OcclusionLimits() if limits is None else limits
    visibility = _visibility(visibility)
    started = time.perf_counter()
    starts = sample_hold_starts(robot, _positive_int(n_starts, "n_starts"), np.random.default_rng(seed))
    pg = projected_gradient_hold(robot, starts, limits, visibility=visibility)
    jobs = [{"q0": q0, "max_bend": limits.max_bend, "insertion": limits.insertion, "visibility": visibility,
             "centring_gamma": float(g)} for q0, g in zip(starts, pg["final_gamma"])]
    results = _map_jobs(_hold_job, jobs, _positive_int(workers, "workers"), progress, "hold optimum")
    voi = np.array([r["voi"] for r in results])
    start_voi = occlusion_details(robot, starts, 0.0)["voi"]
    valid = np.isfinite(voi)
    return {
        "n_starts": int(len(starts)),
        "starts_seed": int(seed),
        "starts": np.round(starts, 15).tolist(),
        "visibility": visibility,
        "limits": {"max_bend": limits.max_bend, "insertion": list(limits.insertion)},
        "start_voi": _rounded(start_voi),
        "optimum_voi": _rounded(voi),
        "optimum_gamma": _rounded(np.array([r["gamma"] for r in results])),
        "optimum_q": np.round(np.array([r["q"] for r in results]), 12).tolist(),
        "optimum_median_voi": float(np.nanmedian(voi)),
        "optimum_mean_voi": float(np.nanmean(voi)),
        "optimum_at_visibility_bound_fraction": float(np.mean([r["at_visibility_bound"] for r in results])),
        "centring_gamma_voi": _rounded(np.array([r["centring_gamma_voi"] for r in results])),
        "centring_gamma_median_voi": float(np.median([r["centring_gamma_voi"] for r in results])),
        "projected_gradient_final_voi": _rounded(pg["final_voi"]),
        "projected_gradient_median_voi": float(np.median(pg["final_voi"])),
        "projected_gradient_mean_voi": float(np.mean(pg["final_voi"])),
        "projected_gradient_final_visible_fraction": float(np.mean(pg["final_visible"])),
        "projected_gradient_best_visible_voi": _rounded(pg["best_visible_voi"]),
        "fraction_optimum_le_projected_gradient": float(np.mean(voi[valid] <= pg["final_voi"][valid])),
        "fraction_optimum_le_projected_gradient_best_visible": float(
            np.mean(voi[valid] <= pg["best_visible_voi"][valid])),
        "no_feasible_gamma": int(np.sum(~valid)),
        "wall_time_s": round(time.perf_counter() - started, 1),
    }


def circle_optimum(robot=None, task=None, limits=None, visibility=VISIBILITY, cone=None, sample_dt=CIRCLE_SAMPLE_DT,
                   step=TRACE_STEP, progress=False):
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
    visibility = _visibility(visibility)
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
    lower, upper = _limit_arrays(limits)
    chains = {"free": {"q": q_start.copy(), "voi": [], "gamma": []},
              "centring": {"q": q_start.copy(), "voi": [], "gamma": []}}
    for k in tqdm(range(n), desc="circle optimum", disable=not progress, leave=False):
        tracer = _Tracer(robot, p_des[k], R_hold, lower, upper, step, NEWTON_TOLERANCE)
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
        "times": _rounded(times),
        "optimum_mean_voi": float(np.mean(free["voi"])),
        "optimum_voi": _rounded(np.array(free["voi"])),
        "optimum_gamma": _rounded(np.array(free["gamma"])),
        "centring_gamma_mean_voi": float(np.mean(centred["voi"])),
        "centring_gamma_voi": _rounded(np.array(centred["voi"])),
        "centring_gamma": _rounded(gamma_c),
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


def trace_self_motion_from(tracer, q0, max_steps=20_000):
    """``trace_self_motion`` with an existing tracer (its pose and limits); q0 on the manifold."""
    t0 = tracer.direction(q0, np.full(7, 7 ** -0.5))
    forward, reason_f = tracer.walk(q0.copy(), t0, max_steps, origin=q0)
    if reason_f == "loop":
        return SelfMotion(np.array([q0] + forward), 0, True, ("loop", "loop"))
    backward, reason_b = tracer.walk(q0.copy(), -t0, max_steps, origin=q0)
    return SelfMotion(np.array(backward[::-1] + [q0] + forward), len(backward), False, (reason_b, reason_f))


# ====================================================================== cache
def load_optimum_cache(path=None) -> dict:
    """The shipped offline optima (nested dict; see the module docstring), or those at ``path``."""
    import json

    path = CACHE_PATH if path is None else Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no optimum cache at {path}; run `continuum-gym optimum --env all --task all "
                                "--write-cache` to create it")
    return json.loads(path.read_text())


def cache_value(cache: dict, key: str):
    """A dotted key of the cache, e.g. ``cache_value(cache, "coverage.optimum_percent")``."""
    value = cache
    for part in key.split("."):
        if not isinstance(value, dict) or part not in value:
            raise KeyError(f"optimum cache has no key {key!r}")
        value = value[part]
    return value


# ====================================================================== figures
def draw_coverage_maps(coverage: dict, path) -> Path:
    """2 x 2 OR maps (optimum, bounded LSQ, DR, RMRC) over yaw x pitch with the OR = 0.8 contour."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = int(coverage["grid"])
    axis = np.degrees(np.linspace(-math.pi / 3, math.pi / 3, n))
    panels = [("optimum", "offline optimum"), ("bounded_least_squares", "bounded least squares"),
              ("dimension_reduced", "dimension-reduced IK"), ("resolved_rate", "resolved rate (RMRC)")]
    fig, axes = plt.subplots(2, 2, figsize=(10, 9), constrained_layout=True)
    image = None
    for ax, (key, title) in zip(axes.ravel(), panels):
        values = np.asarray(coverage[f"{key}_or"]).reshape(n, n)  # [yaw, pitch]
        image = ax.imshow(values.T, origin="lower", extent=(axis[0], axis[-1], axis[0], axis[-1]),
                          vmin=0.0, vmax=1.0, cmap="viridis", interpolation="nearest", aspect="equal")
        ax.contour(axis, axis, values.T, levels=[coverage.get("threshold", COVERAGE_THRESHOLD)], colors="w",
                   linewidths=1.2)
        percent = float(np.mean(values > coverage.get("threshold", COVERAGE_THRESHOLD)) * 100)
        ax.set_title(f"{title}: {percent:.1f} % (mean OR {values.mean():.3f})")
        ax.set_xlabel("yaw (deg)")
        ax.set_ylabel("pitch (deg)")
    fig.colorbar(image, ax=axes, shrink=0.8, label="overlap ratio OR")
    fig.suptitle(f"Coverage {n} x {n} (L_dV = 65 mm, roll 0); white: OR = 0.8")
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def draw_hold(hold: dict, path) -> Path:
    """Per-start VOI: start, projected gradient (final), self-motion at centring gamma, optimum."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    optimum = np.asarray(hold["optimum_voi"], dtype=float)
    order = np.argsort(np.nan_to_num(optimum, nan=np.inf))
    x = np.arange(len(order))
    fig, ax = plt.subplots(figsize=(11, 4.5), constrained_layout=True)
    ax.plot(x, np.asarray(hold["start_voi"])[order], "k.", label="start (gamma 0)")
    ax.plot(x, np.asarray(hold["projected_gradient_final_voi"])[order], "o", mfc="none", color="tab:red",
            label=f"projected gradient, final (median {hold['projected_gradient_median_voi']:.3f})")
    ax.plot(x, np.asarray(hold["centring_gamma_voi"])[order], "s", mfc="none", color="tab:blue", ms=4,
            label=f"self-motion optimum, centring gamma (median {hold['centring_gamma_median_voi']:.3f})")
    ax.bar(x, optimum[order], color="tab:green", alpha=0.7,
           label=f"offline optimum, gamma free (median {hold['optimum_median_voi']:.3f})")
    ax.set_xlabel("hold start (sorted by optimum)")
    ax.set_ylabel("VOI")
    ax.set_title(f"Hold: {hold['n_starts']} starts (seed {hold['starts_seed']}), bends <= "
                 f"{math.degrees(hold['limits']['max_bend']):.0f} deg, tip within {hold['visibility']} beta")
    ax.legend(fontsize=8)
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def draw_circle(circle: dict, path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.asarray(circle["times"])
    fig, ax = plt.subplots(figsize=(8, 4), constrained_layout=True)
    ax.plot(t, circle["optimum_voi"], color="tab:green",
            label=f"optimum, gamma free (mean {circle['optimum_mean_voi']:.3f})")
    ax.plot(t, circle["centring_gamma_voi"], color="tab:blue",
            label=f"optimum, centring gamma (mean {circle['centring_gamma_mean_voi']:.3f})")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("VOI")
    ax.set_title("Circle (task b): time-connected lower bound within the env limits")
    ax.legend()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


# ====================================================================== CLI
def resolve_tasks(env, task="all"):
    """Tasks to run for an env id (or ``all``) and a task name (or ``all``); ValueError names the bad one."""
    valid_envs = (*ENV_TASKS, "all")
    if env not in valid_envs:
        raise ValueError(f"env must be one of {', '.join(valid_envs)}; got {env!r}")
    available = TASKS if env == "all" else ENV_TASKS[env]
    if task == "all":
        return tuple(available)
    if task not in TASKS:
        raise ValueError(f"task must be one of {', '.join((*TASKS, 'all'))}; got {task!r}")
    if task not in available:
        raise ValueError(f"task {task!r} does not belong to env {env!r}; its tasks: {', '.join(available)}")
    return (task,)


def env_hold_test_optimum(n_tasks=32, limits=None, visibility=VISIBILITY, workers=2, progress=True):
    """Hold optimum on the OcclusionAvoidance environment's held-out hold tasks (test ids 0..n-1).

    These are the instances ``continuum-gym evaluate`` scores, so ``headroom_closed`` compares each
    method with the best configuration-and-gamma on exactly the same tasks.
    """
    from continuum_gym.envs.tasks import hold_start_pool

    limits = OcclusionLimits() if limits is None else limits
    starts = np.asarray(hold_start_pool("test", float(limits.max_bend), tuple(limits.insertion)))
    starts = starts[:_positive_int(n_tasks, "n_tasks")]
    jobs = [{"q0": q0, "max_bend": limits.max_bend, "insertion": limits.insertion, "visibility": _visibility(visibility),
             "centring_gamma": 0.0} for q0 in starts]
    results = _map_jobs(_hold_job, jobs, _positive_int(workers, "workers"), progress, "env hold tasks")
    voi = np.array([r["voi"] for r in results])
    return {"task_ids": list(range(len(starts))), "optimum_voi": _rounded(voi),
            "optimum_gamma": _rounded(np.array([r["gamma"] for r in results])),
            "optimum_mean_voi": float(np.nanmean(voi)), "visibility": visibility,
            "limits": {"max_bend": limits.max_bend, "insertion": list(limits.insertion)}}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", required=True,
                        help=f"environment id: {VIEW_TRACKING_ID} (coverage), {OCCLUSION_ID} (hold, circle) or all")
    parser.add_argument("--task", default="all", help="coverage, hold, circle or all (default: the env's tasks)")
    parser.add_argument("--grid", type=int, default=COVERAGE_GRID, help="coverage grid points per axis (default 21)")
    parser.add_argument("--json", help="write the results as nested JSON to this path")
    parser.add_argument("--out", help="directory for the figures (PNG)")
    parser.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    parser.add_argument("--write-cache", action="store_true",
                        help=f"merge the results into the shipped cache {CACHE_PATH.name}")
    parser.add_argument("--n-starts", type=int, default=HOLD_N_STARTS, help="hold starts (default 59)")
    parser.add_argument("--seed", type=int, default=HOLD_STARTS_SEED, help="hold-start seed (default 2026)")
    parser.add_argument("--global-check", type=int, default=GLOBAL_CHECK_SAMPLE,
                        help="grid points re-solved by a heavy search to measure the optimality gap (0: skip)")
    parser.add_argument("--env-hold-tasks", type=int, default=32,
                        help="held-out hold tasks of the environment to solve (default 32, evaluate's --episodes)")
    parser.add_argument("--no-progress", action="store_true", help="hide progress bars")


def run(args) -> int:
    try:
        tasks = resolve_tasks(args.env, args.task)
        if "coverage" in tasks:
            _grid_size(args.grid)
        workers = _positive_int(args.workers, "workers")
        n_starts = _positive_int(args.n_starts, "n_starts")
        if args.global_check < 0:
            raise ValueError(f"global_check must be >= 0; got {args.global_check}")
    except ValueError as error:
        print(f"continuum-gym optimum: error: {error}", file=sys.stderr)
        return 2
    progress = not args.no_progress
    results = {}
    started = time.perf_counter()
    if "coverage" in tasks:
        results["coverage"] = coverage_optimum(args.grid, workers=workers, progress=progress,
                                               global_check=args.global_check)
    if "hold" in tasks:
        results["hold"] = hold_study(n_starts, args.seed, workers=workers, progress=progress)
        results["hold_test"] = env_hold_test_optimum(args.env_hold_tasks, workers=workers, progress=progress)
    if "circle" in tasks:
        t0 = time.perf_counter()
        results["circle"] = circle_optimum(progress=progress)
        results["circle"]["wall_time_s"] = round(time.perf_counter() - t0, 1)
    results["meta"] = {"command": "continuum-gym " + " ".join(sys.argv[1:]), "tasks": list(tasks),
                       "wall_time_s": round(time.perf_counter() - started, 1)}
    print(summary_table(results))
    if args.json:
        write_json_atomic(args.json, results)
        print(f"wrote {args.json}")
    if args.write_cache:
        merged = load_optimum_cache() if CACHE_PATH.exists() else {}
        merged.update({k: v for k, v in results.items() if k != "meta"})
        write_json_atomic(CACHE_PATH, merged)
        CACHE_PATH.chmod(0o644)  # a shipped package file (the atomic temp file is created 0600)
        print(f"updated {CACHE_PATH}")
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        if "coverage" in results:
            print("wrote", draw_coverage_maps(results["coverage"], out / "optimum_coverage_maps.png"))
        if "hold" in results:
            print("wrote", draw_hold(results["hold"], out / "optimum_hold.png"))
        if "circle" in results:
            print("wrote", draw_circle(results["circle"], out / "optimum_circle.png"))
    return 0


def summary_table(results: dict) -> str:
    """A short Markdown table of the headline numbers."""
    rows = ["| task | quantity | value |", "|---|---|---|"]
    if "coverage" in results:
        c = results["coverage"]
        rows += [f"| coverage {c['grid']}x{c['grid']} | offline optimum, OR > 0.8 | {c['optimum_percent']:.1f} % "
                 f"(mean OR {c['optimum_mean_or']:.3f}) |",
                 f"| | unreachable (optimum OR <= 0.8) | {c['unreachable_percent']:.1f} % |",
                 f"| | bounded least squares | {c['bounded_least_squares_percent']:.1f} % |",
                 f"| | dimension-reduced IK / RMRC | {c['dimension_reduced_percent']:.1f} % / "
                 f"{c['resolved_rate_percent']:.1f} % |"]
        if "global_check" in c:
            g = c["global_check"]
            rows.append(f"| | heavy-search gap on {len(g['indices'])} points | max {g['max_gap']:.2e}, "
                        f"mean {g['mean_gap']:.2e} |")
        rows.append(f"| | wall time | {c['wall_time_s']:.0f} s ({c['workers']} workers) |")
    if "hold" in results:
        h = results["hold"]
        rows += [f"| hold ({h['n_starts']} starts) | optimum VOI median / mean | {h['optimum_median_voi']:.3f} / "
                 f"{h['optimum_mean_voi']:.3f} |",
                 f"| | projected gradient median / mean | {h['projected_gradient_median_voi']:.3f} / "
                 f"{h['projected_gradient_mean_voi']:.3f} |",
                 f"| | self-motion only (centring gamma) median | {h['centring_gamma_median_voi']:.3f} |",
                 f"| | optimum <= PG | {100 * h['fraction_optimum_le_projected_gradient']:.0f} % of starts |",
                 f"| | wall time | {h['wall_time_s']:.0f} s |"]
    if "circle" in results:
        c = results["circle"]
        rows += [f"| circle | optimum mean VOI (gamma free) | {c['optimum_mean_voi']:.3f} |",
                 f"| | optimum mean VOI (centring gamma) | {c['centring_gamma_mean_voi']:.3f} |",
                 f"| | wall time | {c.get('wall_time_s', float('nan')):.0f} s |"]
    return "\n".join(rows)


# ====================================================================== input checks
def _positive_int(value, name):
    if isinstance(value, bool) or int(value) != value or value < 1:
        raise ValueError(f"{name} must be an integer >= 1; got {value!r}")
    return int(value)


def _grid_size(grid):
    if isinstance(grid, bool) or not isinstance(grid, (int, np.integer)) or grid < 2:
        raise ValueError(f"grid must be an integer >= 2 (points per axis); got {grid!r}")
    return int(grid)


def _visibility(visibility):
    try:
        value = float(visibility)
    except (TypeError, ValueError) as error:
        raise ValueError(f"visibility must be a number in (0, 1]; got {visibility!r}") from error
    if not (0.0 < value <= 1.0):
        raise ValueError(f"visibility must be in (0, 1] (fraction of the cone half-angle); got {visibility!r}")
    return value


def _rounded(values, digits=6):
    return np.round(np.asarray(values, dtype=float), digits).tolist()


__all__ = [
    "bounded_least_squares", "view_tracking_optimum", "coverage_optimum", "trace_self_motion", "SelfMotion",
    "feasible_gamma_intervals", "hold_optimum", "hold_study", "circle_optimum", "centring_gamma",
    "projected_gradient_hold", "load_optimum_cache", "cache_value", "resolve_tasks", "summary_table",
    "draw_coverage_maps", "draw_hold", "draw_circle", "add_arguments", "run",
    "VIEW_TRACKING_ID", "OCCLUSION_ID", "ENV_TASKS", "LSQ_ORIENTATION_WEIGHT", "HOLD_STARTS_SEED", "HOLD_N_STARTS",
    "VISIBILITY", "CACHE_PATH",
]
