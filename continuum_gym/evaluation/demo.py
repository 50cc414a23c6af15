"""``continuum-gym demo``: both papers' robots with their view cone / frustums, drawn like the papers' figures."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

if TYPE_CHECKING:
    from mpl_toolkits.mplot3d import Axes3D

    from continuum_gym.robots import MultiBackboneRobot


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="results/demo", help="output directory for demo.png (default: %(default)s)")


def _pose_line(name: str, p: np.ndarray, R: np.ndarray) -> str:
    from continuum_gym.robots import rotation_vector

    rotvec = rotation_vector(R)
    return (f"  {name:<38s} p = [{p[0] * 1e3:8.3f} {p[1] * 1e3:8.3f} {p[2] * 1e3:8.3f}] mm   "
            f"log R = [{rotvec[0]:7.4f} {rotvec[1]:7.4f} {rotvec[2]:7.4f}] rad")


def occlusion_snapshots() -> tuple[MultiBackboneRobot, np.ndarray, np.ndarray,
                                 dict[str, tuple[np.ndarray, np.ndarray]]]:
    """Configurations of paper 000 to draw: task (a) start/end, circle snapshots (min-norm vs min-potential)."""
    from continuum_gym.baselines import MinimumNorm, ProjectedGradient
    from continuum_gym.baselines.scenarios import HOLD_ITERATIONS, CircleTask
    from continuum_gym.robots import MultiBackboneRobot

    robot = MultiBackboneRobot()
    p0, R0 = robot.forward_kinematics(robot.psi_a)
    q_hold, _ = ProjectedGradient(rotate_endoscope=False).rollout(
        robot.psi_a, 0.0, np.broadcast_to(p0, (HOLD_ITERATIONS, 3)), np.broadcast_to(R0, (HOLD_ITERATIONS, 3, 3)))
    task = CircleTask()
    q_start = task.start_configuration()
    _, R_hold = robot.forward_kinematics(q_start)
    t = np.arange(int(task.period / 1e-3)) * 1e-3
    p_des, v_des = task.trajectory(t)
    R_des = np.broadcast_to(R_hold, (t.size, 3, 3))
    circle = {}
    for controller in (MinimumNorm(), ProjectedGradient()):
        q, gamma = controller.rollout(q_start, 0.0, p_des, R_des, v_des)
        circle[controller.name] = (q, gamma)
    return robot, q_hold, p_des, circle


def run(args: argparse.Namespace) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # Imported here, not at module level, so that `continuum-gym demo --help` answers at once.
    from continuum_gym.baselines import DimensionReduced, ResolvedRate
    from continuum_gym.baselines.scenarios import CASE_STUDIES, CASE_STUDY_START
    from continuum_gym.evaluation.drawing import (
        draw_backbone,
        draw_cone,
        draw_endoscope_shaft,
        draw_frame,
        draw_frustum,
        set_equal_3d,
    )
    from continuum_gym.geometry import overlap_ratio, visual_occlusion_index
    from continuum_gym.robots import ContinuumEndoscope, DaVinciEndoscope

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    robot, q_hold, circle_path, circle = occlusion_snapshots()
    endo, davinci = ContinuumEndoscope(), DaVinciEndoscope()

    fig = plt.figure(figsize=(15, 11))
    lines = ["Tip poses in demo.png, world frame (origin: the channel exit for the MBCR, the incision for paper 001): "
             "position p in mm, orientation log R as a rotation vector in rad"]

    # (a) hold the pose: start and end of the projected gradient.
    ax = cast("Axes3D", fig.add_subplot(2, 2, 1, projection="3d"))
    draw_cone(ax, 0.0)
    draw_endoscope_shaft(ax, 0.0)
    for q, color, label in ((robot.psi_a, "tab:red", "start psi_a"), (q_hold[-1], "tab:blue", "after 1500 it")):
        voi = float(visual_occlusion_index(robot, q, 0.0))
        draw_backbone(ax, robot.backbone(q), color, f"{label}: VOI {voi:.3f}")
        p, R = robot.forward_kinematics(q)
        draw_frame(ax, p, R)
        lines.append(_pose_line(f"MBCR {label}", p, R))
    set_equal_3d(ax, np.concatenate([robot.backbone(robot.psi_a), robot.backbone(q_hold[-1])]) * 1e3, margin=15)
    ax.view_init(elev=18, azim=-60)
    ax.set_title("Paper 000, task (a): hold the tip pose, projected gradient (gamma = 0)")
    ax.legend(loc="upper left", fontsize=8)

    # (b) the circle: min-norm vs min-potential at the same instant, each with its endoscope rotation.
    ax = cast("Axes3D", fig.add_subplot(2, 2, 2, projection="3d"))
    k = 2500
    ax.plot(*(circle_path * 1e3).T, color="0.5", linewidth=0.8, label="desired circle (r = 10 mm)")
    everything = [circle_path * 1e3]
    for name, color in (("minimum_norm", "tab:red"), ("projected_gradient", "tab:blue")):
        q, gamma = circle[name]
        voi = float(visual_occlusion_index(robot, q[k], gamma[k]))
        draw_cone(ax, gamma[k], color=color, alpha=0.05)
        draw_backbone(ax, robot.backbone(q[k]), color, f"{name}: VOI {voi:.2f}, gamma {np.degrees(gamma[k]):.1f} deg")
        everything.append(robot.backbone(q[k]) * 1e3)
        p, R = robot.forward_kinematics(q[k])
        lines.append(_pose_line(f"MBCR circle t=2.5 s {name}", p, R))
    set_equal_3d(ax, np.concatenate(everything), margin=15)
    ax.view_init(elev=18, azim=-60)
    ax.set_title("Paper 000, task (b): circle at t = 2.5 s, min-norm vs min-potential")
    ax.legend(loc="upper left", fontsize=8)

    # (c, d) the case studies of paper 001.
    for panel, (case, q_dv) in enumerate(CASE_STUDIES.items(), start=3):
        ax = cast("Axes3D", fig.add_subplot(2, 2, panel, projection="3d"))
        target = davinci.target_pose(q_dv)
        p_dv, R_dv = davinci.forward_kinematics(q_dv)
        ax.plot(*zip([0, 0, 0], p_dv * 1e3), color="k", linewidth=4, label="da Vinci stem (RCM at origin)")
        draw_frustum(ax, p_dv, R_dv, "tab:red", label="da Vinci frustum")
        lines.append(_pose_line(f"da Vinci {case} camera", p_dv, R_dv))
        pts = [p_dv[None] * 1e3, davinci.target_point(q_dv)[None] * 1e3]
        for controller, color in ((ResolvedRate(), "tab:blue"), (DimensionReduced(), "tab:green")):
            q = controller.solve(CASE_STUDY_START, target)["q"]
            p_cam, R_cam = endo.forward_kinematics(q)
            ratio = float(overlap_ratio(p_dv, R_dv, p_cam, R_cam))
            draw_backbone(ax, endo.backbone(q), color, f"{controller.name}: OR {ratio:.2f}")
            draw_frustum(ax, p_cam, R_cam, color)
            lines.append(_pose_line(f"endoscope {case} {controller.name}", p_cam, R_cam))
            pts.append(endo.backbone(q) * 1e3)
        draw_backbone(ax, endo.backbone(CASE_STUDY_START), "0.6", "start Psi0", linewidth=1.5)
        pts.append(davinci.forward_kinematics(q_dv)[0][None] * 1e3)
        set_equal_3d(ax, np.concatenate(pts + [np.zeros((1, 3))]), margin=10)
        ax.view_init(elev=15, azim=-50)
        ax.set_title(f"Paper 001, {case}: continuum endoscope vs da Vinci 30 deg view")
        ax.legend(loc="upper left", fontsize=8)

    fig.tight_layout()
    path = out / "demo.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print("\n".join(lines))
    print(f"wrote {path}")
    return 0
