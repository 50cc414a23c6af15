"""View-tracking optimum (paper 001): the largest overlap ratio within the joint limits, and the
bounded least-squares pose fit (the strong reference)."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import differential_evolution, least_squares, minimize

from continuum_gym.baselines import DimensionReduced, ResolvedRate
from continuum_gym.baselines.scenarios import (
    CASE_STUDY_START,
    COVERAGE_THRESHOLD,
    coverage_grid,
)
from continuum_gym.evaluation.optimum.protocol import (
    COVERAGE_GRID,
    GLOBAL_CHECK_SAMPLE,
    LSQ_ORIENTATION_WEIGHT,
    OPTIMUM_SEED,
)
from continuum_gym.evaluation.optimum.workers import (
    grid_size,
    map_jobs,
    positive_int,
    rounded,
    single_threaded_blas,
)
from continuum_gym.geometry import Frustum
from continuum_gym.geometry.overlap import make_overlap_work, overlap_ratio, overlap_ratio_in, overlap_ratio_nb
from continuum_gym.robots import ContinuumEndoscope, DaVinciEndoscope
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.endoscope import (
    endoscope_kinematics,
    make_endoscope_workspace,
)
from continuum_gym.robots.rotations import rotation_vector
from continuum_gym.validation import as_finite, positive

# Search effort of the view-tracking optimum: the standard run and the heavy global-optimality check.
VIEW_EFFORT = {
    "quick": {"n_random": 1, "popsize": 6, "maxiter": 40, "de_runs": 1},
    "standard": {"n_random": 8, "popsize": 15, "maxiter": 300, "de_runs": 1},
    "heavy": {"n_random": 96, "popsize": 40, "maxiter": 2000, "de_runs": 4},
}


# ====================================================================== view tracking
@kernel
def overlap_batch(Q, p_a, R_a, robot, tan_half, near, far, out):
    """OR between the da Vinci camera (p_a, R_a) and the continuum camera of each row of Q (n, 6).

    ``robot`` is ``ContinuumEndoscope.kernel_args()``; the frustum is (tan_half, near, far) in m.
    """
    p_cam = np.empty(3)
    R = np.empty((3, 3))
    p_ct = np.empty(3)
    J = np.empty((6, 6))
    ws = make_endoscope_workspace()
    work = make_overlap_work()
    for i in range(Q.shape[0]):
        endoscope_kinematics(Q[i], robot, ws, p_cam, R, p_ct, J, False)
        out[i] = overlap_ratio_in(p_a, R_a, p_cam, R, tan_half, near, far, work)


@kernel
def overlap_of_configuration(q, p_a, R_a, robot, tan_half, near, far):
    """OR between the da Vinci camera (p_a, R_a) and the continuum camera of configuration q (6,)."""
    p_cam = np.empty(3)
    R = np.empty((3, 3))
    p_ct = np.empty(3)
    J = np.empty((6, 6))
    endoscope_kinematics(q, robot, make_endoscope_workspace(), p_cam, R, p_ct, J, False)
    return overlap_ratio_nb(p_a, R_a, p_cam, R, tan_half, near, far)


def view_bounds(robot: ContinuumEndoscope, delta_span: float) -> tuple[np.ndarray, np.ndarray]:
    """Joint limits (6,) with the unlimited deltas bounded to [-delta_span, delta_span]."""
    lower, upper = robot.joint_limits
    lower[[3, 5]] = -delta_span
    upper[[3, 5]] = delta_span
    return lower, upper


def wrap_view(q: ArrayLike, lower: ArrayLike, upper: ArrayLike) -> np.ndarray:
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


def fit_pose(p_target: np.ndarray, R_target: np.ndarray, q0: ArrayLike, weight: float, robot: ContinuumEndoscope,
             lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    def residual(q):
        _, R, p_ct, _ = robot.fk_jacobian(q)
        e = rotation_vector(R_target @ R.T)
        return np.concatenate([p_ct - p_target, -weight * e])

    def jacobian(q):
        _, R, _, J = robot.fk_jacobian(q)
        e = rotation_vector(R_target @ R.T)
        return np.vstack([J[:3], weight * (_right_jacobian_inverse(e) @ J[3:])])

    start = np.clip(wrap_view(q0, lower, upper), lower, upper)
    result = least_squares(residual, start, jac=jacobian, bounds=(lower, upper), method="trf",
                           xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=200)
    return wrap_view(result.x, *robot.joint_limits)


def bounded_least_squares(target_p: ArrayLike, target_R: ArrayLike, q0: ArrayLike = CASE_STUDY_START,
                          orientation_weight: float = LSQ_ORIENTATION_WEIGHT,
                          robot: ContinuumEndoscope | None = None) -> np.ndarray:
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
    lower, upper = view_bounds(robot, 3.0 * math.pi)
    with single_threaded_blas():
        out = np.array([fit_pose(P[i], Rs[i], Q0[i], weight, robot, lower, upper) for i in range(P.shape[0])])
    return out.reshape(shape + (6,))


def _image_roll(R_a, R_b):
    """Angle (rad) of camera b's x axis in camera a's image plane (x_a, y_a)."""
    x_b = R_b[..., :, 0]
    return np.arctan2(np.sum(R_a[..., :, 1] * x_b, axis=-1), np.sum(R_a[..., :, 0] * x_b, axis=-1))


def _optimise_view_point(job):
    """Worker: the OR optimum for one target. ``job`` is a dict (picklable)."""
    robot = job["robot"]
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
        return -overlap_of_configuration(np.ascontiguousarray(q, dtype=float), p_a, R_a, robot, tan_half, near, far)

    def objective_population(X):
        X = np.ascontiguousarray(np.atleast_2d(X.T), dtype=float)
        out = np.empty(X.shape[0])
        overlap_batch(X, p_a, R_a, robot, tan_half, near, far, out)
        return -out

    candidates = []  # (or, q, source)

    def consider(q, source):
        q = wrap_view(q, lower, upper)
        candidates.append((-objective(q), q, source))

    def local(q0, source, method="L-BFGS-B"):
        start = np.clip(wrap_view(q0, lower, upper), local_lower, local_upper)
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
            "starts": {name: (q, -objective(wrap_view(q, lower, upper))) for name, q in job["starts"].items()}}


def view_tracking_optimum(q_davinci: ArrayLike, robot: ContinuumEndoscope | None = None,
                          davinci: DaVinciEndoscope | None = None, frustum: Frustum | None = None,
                          effort: str = "standard", seed: int = OPTIMUM_SEED, workers: int = 1, progress: bool = False,
                          baselines: bool = True) -> dict[str, Any]:
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
    workers = positive_int(workers, "workers")
    q_davinci = as_finite(q_davinci, (4,), "q_davinci")
    shape = q_davinci.shape[:-1]
    grid = q_davinci.reshape(-1, 4)
    n = grid.shape[0]
    p_a, R_a = davinci.forward_kinematics(grid)
    p_t, R_t = davinci.target_pose(grid)
    starts: dict[str, np.ndarray] = {}
    if baselines:
        start = np.broadcast_to(CASE_STUDY_START, (n, 6))
        starts["dimension_reduced"] = DimensionReduced(robot=robot).solve(start, (p_t, R_t))["q"]
        starts["resolved_rate"] = ResolvedRate(robot=robot).solve(start, (p_t, R_t))["q"]
    lower, upper = view_bounds(robot, math.pi)
    jobs: list[dict[str, Any]] = []
    for k in range(n):
        jobs.append({"index": k, "robot": robot.kernel_args(), "endoscope": robot, "p_a": np.ascontiguousarray(p_a[k]),
                     "R_a": np.ascontiguousarray(R_a[k]), "frustum": (frustum.tan_half, frustum.near, frustum.far),
                     "lower": lower, "upper": upper, "effort": effort, "seed": int(seed) + k,
                     "p_t": p_t[k], "R_t": R_t[k], "starts": {name: q[k] for name, q in starts.items()}})
    results = map_jobs(_view_job_with_lsq, jobs, workers, progress, f"view-tracking optimum ({effort})")
    q = np.array([r["q"] for r in results])
    p_c, R_c = robot.forward_kinematics(q)
    overlap = overlap_ratio(p_a, R_a, p_c, R_c, frustum)
    references: dict[str, dict[str, np.ndarray]] = {}
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
    robot = job["endoscope"]
    lower, upper = view_bounds(robot, 3.0 * math.pi)
    job = dict(job)
    job["starts"] = dict(job["starts"])
    job["starts"]["bounded_least_squares"] = fit_pose(job["p_t"], job["R_t"], CASE_STUDY_START,
                                                      LSQ_ORIENTATION_WEIGHT, robot, lower, upper)
    return _optimise_view_point(job)


def coverage_optimum(grid: int = COVERAGE_GRID, workers: int = 2, progress: bool = True,
                     global_check: int = GLOBAL_CHECK_SAMPLE, seed: int = OPTIMUM_SEED,
                     robot: ContinuumEndoscope | None = None, davinci: DaVinciEndoscope | None = None,
                     effort: str = "standard") -> dict[str, Any]:
    """Coverage of the paper's map (L_dV = 65 mm, roll 0, yaw/pitch in [-60, 60] deg, OR > 0.8).

    Returns a dict with the cache keys of ``coverage`` (percentages, mean OR, per-point OR maps of the
    optimum, bounded LSQ, DR and RMRC, yaw-major like ``coverage_grid``) and ``global_check``: the
    optimum against a heavy search (``effort="heavy"``) at ``global_check`` grid points, half of them
    those nearest the OR threshold (where a miss would change the coverage), half drawn at random.
    """
    grid = grid_size(grid)
    q_davinci = coverage_grid(grid)
    started = time.perf_counter()
    result = view_tracking_optimum(q_davinci, robot=robot, davinci=davinci, effort=effort, seed=seed, workers=workers,
                                   progress=progress)
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
        "optimum_or": rounded(optimum),
        "bounded_least_squares_or": rounded(refs["bounded_least_squares"]["overlap"]),
        "dimension_reduced_or": rounded(refs["dimension_reduced"]["overlap"]),
        "resolved_rate_or": rounded(refs["resolved_rate"]["overlap"]),
        "optimum_roll_error": rounded(result["roll_error"]),
        "optimum_at_L0_zero_percent": float(np.mean(result["q"][:, 0] <= 1e-9) * 100.0),
        "seed": int(seed),
        "wall_time_s": round(elapsed, 1),
        "workers": int(workers),
    }
    if global_check:
        indices = _global_check_sample(optimum, threshold, int(global_check), seed)
        started = time.perf_counter()
        heavy = view_tracking_optimum(q_davinci[indices], robot=robot, davinci=davinci, effort="heavy",
                                      seed=seed + 10_000, workers=workers, progress=progress)
        gap = heavy["overlap"] - optimum[indices]
        out["global_check"] = {
            "indices": indices.tolist(),
            "standard_or": rounded(optimum[indices]),
            "heavy_or": rounded(heavy["overlap"]),
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
def env_optimum(config: Any, *, episodes: int, grid: int, split: str, progress: bool, workers: int) -> dict:
    """The optimum cache of a ViewTracking variant (``EnvSpec.optimum``): its coverage grid's optimum."""
    return {"coverage": coverage_optimum(grid, workers=workers, progress=progress, global_check=0, robot=config.robot,
                                         davinci=config.davinci)}


