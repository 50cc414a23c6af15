"""The computations behind ``continuum-gym reproduce``: each published result of both papers.

Parts (paper-notes §3 gives the bands a faithful implementation lands in): the hold task and its
random-start sweep, the circle, the two case studies and the coverage map (see
``continuum_gym.evaluation.reproduce`` for the command, table and figures).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.baselines import (
    DimensionReduced,
    MinimumNorm,
    ProjectedGradient,
    ResolvedRate,
)
from continuum_gym.baselines.scenarios import (
    CASE_STUDIES,
    CASE_STUDY_START,
    COVERAGE_THRESHOLD,
    HOLD_ITERATIONS,
    PAPER_DT,
    VIEW_DT,
    VIEW_MAX_STEPS,
    CircleTask,
    coverage_grid,
    sample_hold_starts,
)
from continuum_gym.geometry import overlap_ratio, visual_occlusion_index
from continuum_gym.robots import (
    ContinuumEndoscope,
    DaVinciEndoscope,
    MultiBackboneRobot,
)

SWEEP_SEED = 0
SWEEP_STARTS = 60



# ---------------------------------------------------------------------- parts
def hold_part(robot: MultiBackboneRobot, n_starts: int, seed: int) -> tuple[dict[str, Any], dict[str, Any]]:
    p0, R0 = robot.forward_kinematics(robot.psi_a)
    p_des = np.broadcast_to(p0, (HOLD_ITERATIONS, 3))
    R_des = np.broadcast_to(R0, (HOLD_ITERATIONS, 3, 3))
    controller = ProjectedGradient(rotate_endoscope=False)
    q, gamma = controller.rollout(robot.psi_a, 0.0, p_des, R_des, dt=PAPER_DT)
    voi = visual_occlusion_index(robot, q, gamma)
    tip, R_tip = robot.forward_kinematics(q)
    drift = np.linalg.norm(tip - p0, axis=-1)
    hold = {
        "voi": voi.tolist(),
        "max_tip_drift_m": float(drift.max()),
        "final_voi": float(voi[-1]),
        "voi_at": {str(k): float(voi[k]) for k in (100, 200, 300, 400, 800, 1500)},
        "elastic_energy": robot.elastic_energy(q).tolist(),
        "max_orientation_drift_rad": float(np.max(np.arccos(np.clip(
            (np.trace(R_tip @ R0.T, axis1=-2, axis2=-1) - 1) / 2, -1, 1)))),
    }
    starts = sample_hold_starts(robot, n_starts, np.random.default_rng(seed))
    p_s, R_s = robot.forward_kinematics(starts)
    q_s, g_s = controller.rollout(starts, np.zeros(len(starts)),
                                  np.broadcast_to(p_s[:, None], (len(starts), HOLD_ITERATIONS, 3)),
                                  np.broadcast_to(R_s[:, None], (len(starts), HOLD_ITERATIONS, 3, 3)), dt=PAPER_DT)
    final = visual_occlusion_index(robot, q_s[:, -1], 0.0)
    initial = visual_occlusion_index(robot, starts, 0.0)
    sweep = {
        "seed": seed,
        "n_starts": int(len(starts)),
        "initial_voi_median": float(np.median(initial)),
        "final_voi": final.tolist(),
        "final_voi_median": float(np.median(final)),
        "final_voi_p10": float(np.percentile(final, 10)),
        "final_voi_p25": float(np.percentile(final, 25)),
        "final_voi_p75": float(np.percentile(final, 75)),
        "final_voi_p90": float(np.percentile(final, 90)),
        "decreased_fraction": float(np.mean(final < initial)),
        "max_tip_drift_m": float(np.linalg.norm(robot.forward_kinematics(q_s)[0] - p_s[:, None], axis=-1).max()),
    }
    return hold, sweep


def circle_part(robot: MultiBackboneRobot) -> dict[str, Any]:
    task = CircleTask()
    q0 = task.start_configuration()
    _, R0 = robot.forward_kinematics(q0)
    t = np.arange(int(round(task.period / PAPER_DT))) * PAPER_DT
    p_des, v_des = task.trajectory(t)
    R_des = np.broadcast_to(R0, (t.size, 3, 3))
    result = {"period_s": task.period, "distance_m": task.distance, "radius_m": task.radius, "t": t[::10].tolist()}
    for controller in (MinimumNorm(), ProjectedGradient()):
        q, gamma = controller.rollout(q0, 0.0, p_des, R_des, v_des, dt=PAPER_DT)
        voi = visual_occlusion_index(robot, q[:-1], gamma[:-1])
        tip, _ = robot.forward_kinematics(q[1:])
        error = np.linalg.norm(tip - p_des, axis=-1)
        result[controller.name] = {
            "mean_voi": float(voi.mean()),
            "voi": voi[::10].tolist(),
            "gamma_deg": np.degrees(gamma[:-1:10]).tolist(),
            "gamma_min_deg": float(np.degrees(gamma.min())),
            "gamma_max_deg": float(np.degrees(gamma.max())),
            "final_gamma_deg": float(np.degrees(gamma[-1])),
            "mean_tip_error_m": float(error.mean()),
            "max_tip_error_m": float(error.max()),
            "max_bend_deg": float(np.degrees(np.abs(robot.bend_angles(q)).max())),
        }
    # gamma depends only on the tip (paper-notes §1.3 item 10): the paper reports one range.
    result["gamma_min_deg"] = result["projected_gradient"]["gamma_min_deg"]
    result["gamma_max_deg"] = result["projected_gradient"]["gamma_max_deg"]
    return result


def _overlap(endo: ContinuumEndoscope, davinci: DaVinciEndoscope, q: ArrayLike, q_davinci: ArrayLike) -> np.ndarray:
    p_c, R_c = endo.forward_kinematics(q)
    p_d, R_d = davinci.forward_kinematics(q_davinci)
    return overlap_ratio(p_d, R_d, p_c, R_c)


def case_part(endo: ContinuumEndoscope, davinci: DaVinciEndoscope) -> dict[str, Any]:
    out = {}
    for case, q_dv in CASE_STUDIES.items():
        target = davinci.target_pose(q_dv)
        out[case] = {"davinci_q": q_dv.tolist()}
        for controller in (ResolvedRate(), DimensionReduced()):
            solved = controller.solve(CASE_STUDY_START, target, dt=VIEW_DT, max_steps=VIEW_MAX_STEPS, record=True)
            history = solved["history"]
            _, info = controller.joint_rates_with_info(history, target, dt=VIEW_DT)
            ratio = _overlap(endo, davinci, history, q_dv)
            out[case][controller.name] = {
                "or": float(ratio[-1]),
                "final_q": solved["q"].tolist(),
                "steps": int(solved["steps"]),
                "status": ["max_steps", "converged", "stalled"][int(solved["status"])],
                "position_error_m": float(info["position_error_m"][-1]),
                "orientation_error_rad": float(info["orientation_error_rad"][-1]),
                "or_history": ratio[::5].tolist(),
                "position_error_history_m": info["position_error_m"][::5].tolist(),
                "orientation_error_history_rad": info["orientation_error_rad"][::5].tolist(),
                "q_history": history[::5].tolist(),
            }
    return out


def coverage_part(endo: ContinuumEndoscope, davinci: DaVinciEndoscope, grid: int) -> dict[str, Any]:
    targets = coverage_grid(grid)
    target_pose = davinci.target_pose(targets)
    start = np.broadcast_to(CASE_STUDY_START, (len(targets), 6))
    out: dict[str, Any] = {"grid": int(grid), "threshold": COVERAGE_THRESHOLD, "yaw_pitch_limit_rad": float(np.pi / 3)}
    for controller in (ResolvedRate(), DimensionReduced()):
        solved = controller.solve(start, target_pose, dt=VIEW_DT, max_steps=VIEW_MAX_STEPS)
        ratio = _overlap(endo, davinci, solved["q"], targets)
        out[f"{controller.name}_percent"] = float(np.mean(ratio > COVERAGE_THRESHOLD) * 100)
        out[f"{controller.name}_mean_or"] = float(ratio.mean())
        out[f"{controller.name}_or"] = ratio.reshape(grid, grid).tolist()
    return out


# ---------------------------------------------------------------------- report
def reproduce(quick: bool = False, grid: int | None = None, progress: bool = True) -> dict:
    """Run all parts; returns the nested results dict (SI units unless a key says otherwise)."""
    from tqdm.auto import tqdm

    robot, endo, davinci = MultiBackboneRobot(), ContinuumEndoscope(), DaVinciEndoscope()
    grid = grid or (11 if quick else 41)
    n_starts = 10 if quick else SWEEP_STARTS
    results: dict[str, Any] = {"quick": bool(quick), "seconds": {}}
    parts = [
        ("hold", lambda: hold_part(robot, n_starts, SWEEP_SEED)),
        ("circle", lambda: circle_part(robot)),
        ("case_studies", lambda: case_part(endo, davinci)),
        ("coverage", lambda: coverage_part(endo, davinci, grid)),
    ]
    for name, fn in tqdm(parts, desc="reproduce", disable=not progress):
        start = time.perf_counter()
        value = fn()
        results["seconds"][name] = time.perf_counter() - start
        if name == "hold":
            results["hold"], results["hold_sweep"] = value
        elif name == "case_studies":
            results.update(value)
        else:
            results[name] = value
    return results
def warm_up_occlusion() -> None:
    """The robot's and the baselines' batched Python API, as ``continuum-gym reproduce`` calls them
    (``warm_ups``: ``continuum-gym precompile`` compiles them)."""
    from continuum_gym.robots import MultiBackboneRobot

    robot = MultiBackboneRobot()
    hold_part(robot, 2, 0)
    circle_part(robot)


def warm_up_view() -> None:
    """As ``warm_up_occlusion``, for ViewTracking; and the overlap ratio's public entry points."""
    from continuum_gym.geometry import overlap_ratio
    from continuum_gym.robots import ContinuumEndoscope, DaVinciEndoscope

    endoscope, davinci = ContinuumEndoscope(), DaVinciEndoscope()
    coverage_part(endoscope, davinci, 3)
    case_part(endoscope, davinci)
    overlap_ratio(np.zeros(3), np.eye(3), np.zeros(3), np.eye(3))  # one pair, then a batch
    overlap_ratio(np.zeros((2, 3)), np.eye(3), np.zeros(3), np.eye(3))


def warm_ups(env_id: str) -> tuple:
    """The library calls ``continuum-gym reproduce`` makes for ``env_id``'s robots (none for another env), which
    ``continuum-gym precompile`` makes once so that their kernels are in the precompiled set."""
    from continuum_gym.envs.occlusion.spec import ENV_ID as OCCLUSION
    from continuum_gym.envs.view_tracking.spec import ENV_ID as VIEW

    return {OCCLUSION: (warm_up_occlusion,), VIEW: (warm_up_view,)}.get(env_id, ())

