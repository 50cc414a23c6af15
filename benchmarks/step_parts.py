"""Where one robot-step goes: the compiled parts of each env's step, timed alone, beside the whole step.

    python benchmarks/step_parts.py [--json PATH] [--quick]

Each part is the package's own kernel called in a compiled loop over the 1024 rows of a native vector
env after a few steps (so the states are the env's), one thread, best of 3; the whole step is
``vector_env.step`` at the same N, zero actions. Microseconds per robot. OcclusionAvoidance: a step is
10 substeps, each one controller evaluation (tip pose and Jacobian, the 10-point potential gradient,
the damped 6 x 6 solve) and, with a residual, a null-space projection; then VOI on 126 backbone
samples and the next command. ViewTracking: the da Vinci target, dimension-reduced IK (FK and
Jacobian included) and the exact overlap ratio of the two frusta, once per step.

JSON keys: ``<env id>.<part>_us``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import best_seconds, finish, machine, print_table, vector_env_rate  # noqa: E402

from continuum_gym.baselines.occlusion_kernels import make_scratch, occlusion_rates_kernel  # noqa: E402
from continuum_gym.baselines.view_tracking import make_view_scratch, view_errors, view_rates_kernel  # noqa: E402
from continuum_gym.envs.common_kernels import desired_point  # noqa: E402
from continuum_gym.geometry.force_field import potential_gradient_framed  # noqa: E402
from continuum_gym.geometry.occlusion import VOI_SAMPLES_PER_SEGMENT, voi_of_configuration  # noqa: E402
from continuum_gym.geometry.overlap import make_overlap_work, overlap_ratio_in  # noqa: E402
from continuum_gym.robots.compiled import kernel  # noqa: E402
from continuum_gym.robots.davinci import davinci_pose  # noqa: E402
from continuum_gym.robots.mbcr_kernels import fill_frames, make_workspace, tip_kernel  # noqa: E402

OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"
UNITS = {"*_us": "us", "peak_rss_mib": "MiB", "machine.*": "info"}


# Borrowing, as the step's own row kernels are (``kernel(borrows=True)``): a loop with reference counts
# would time those as well. So the work arrays come from outside.
@kernel(borrows=True)
def occlusion_part(part, Q, G, P_des, robot, prm, ws, scratch, points, lens, dr, R_des, v_ff, qdot, reps):
    """0: tip pose + Jacobian; 1: frames + potential gradient; 2: one controller evaluation; 3: VOI."""
    total = 0.0
    for _ in range(reps):
        for i in range(Q.shape[0]):
            if part == 0:
                tip_kernel(Q[i], robot, ws, scratch.p, scratch.R, scratch.J)
                total += scratch.p[0]
            elif part == 1:
                fill_frames(Q[i], robot, ws)
                potential_gradient_framed(Q[i], robot, ws, prm.segments, prm.fractions, scratch.P, scratch.JV, G[i],
                                          prm.cone, prm.field, scratch.grad)
                total += scratch.grad[0]
            elif part == 2:
                gd, _, _ = occlusion_rates_kernel(Q[i], G[i], P_des[i], R_des, v_ff, 1e-3, robot, prm, ws, scratch,
                                                  qdot)
                total += qdot[0] + gd
            else:
                voi, _, _, _ = voi_of_configuration(Q[i], robot, ws, G[i], prm.cone, VOI_SAMPLES_PER_SEGMENT, points,
                                                    lens, dr)
                total += voi
    return total


@kernel(borrows=True)
def view_part(part, Q, steps, dt, tasks, robot, prm, dv, frustum, scratch, overlap, q_dv, dv_rate, p_dv, R_dv, p_tgt,
              qdot, reps):
    """0: the da Vinci target; 1: + FK and Jacobian; 2: + DR IK (FK included); 3: + FK + exact overlap ratio."""
    total = 0.0
    for _ in range(reps):
        for i in range(Q.shape[0]):
            desired_point(tasks, i, steps[i] * dt, q_dv, dv_rate)
            davinci_pose(q_dv, dv, True, p_dv, R_dv, p_tgt)
            total += p_tgt[0]
            if part == 1:
                total += view_errors(Q[i], p_tgt, R_dv, robot, scratch)[0]
            elif part == 2:
                total += view_rates_kernel(Q[i], p_tgt, R_dv, dt, robot, prm, scratch, qdot)[0]
            elif part == 3:
                view_errors(Q[i], p_tgt, R_dv, robot, scratch)
                total += overlap_ratio_in(p_dv, R_dv, scratch.p_cam, scratch.R_ct, frustum.tan_half, frustum.near,
                                          frustum.far, overlap)
    return total


def per_robot_us(fn, args: tuple, n: int, repeats: int) -> float:
    """Best microseconds per robot of ``fn(*args, reps=3)`` over ``repeats`` calls (after a compiling one)."""
    return best_seconds(lambda: fn(*args, 3), number=1, repeat=repeats) / (3 * n) * 1e6


def whole_step_us(venv, n: int, seconds: float) -> float:
    """Microseconds per robot of ``venv.step`` with zero actions."""
    return 1e6 / vector_env_rate(venv, np.zeros((1, n) + venv.single_action_space.shape, dtype=np.float32), seconds)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", help="write results to this JSON file")
    parser.add_argument("--quick", action="store_true", help="fewer rows and repeats (smoke test)")
    args = parser.parse_args(argv)
    n, repeats, seconds = (128, 1, 0.3) if args.quick else (1024, 3, 2.0)
    results = {"machine": machine(), "units": UNITS}
    rows = []

    venv = gym.make_vec(OCCLUSION, num_envs=n, vectorization_mode="vector_entry_point", num_threads=1)
    venv.reset(seed=0)
    for _ in range(5):
        venv.step(np.zeros((n,) + venv.single_action_space.shape, dtype=np.float32))
    core = venv.unwrapped.core
    robot, prm = core.kernel_model()
    p_des = np.array([core.desired(row, core.steps[row] * core.control_dt)[0] for row in range(n)])
    m = robot.n_insert + core.robot.n_segments * VOI_SAMPLES_PER_SEGMENT + 1
    state = (core.q.copy(), core.gamma.copy(), p_des, robot, prm, make_workspace(core.robot.n_segments),
             make_scratch(prm.segments.shape[0], core.dof), np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 2)),
             np.eye(3), np.zeros(3), np.empty(core.dof))
    parts = {"tip_pose_jacobian": 0, "potential_gradient": 1, "controller_evaluation": 2, "voi": 3}
    values = {name: per_robot_us(occlusion_part, (part, *state), n, repeats) for name, part in parts.items()}
    values["whole_step"] = whole_step_us(venv, n, seconds)
    for name, value in values.items():
        results[f"{OCCLUSION}.{name}_us"] = value
        rows.append((OCCLUSION, name, f"{value:.2f}"))
    rows.append((OCCLUSION, "10 evaluations + VOI", f"{10 * values['controller_evaluation'] + values['voi']:.2f}"))

    venv = gym.make_vec(VIEW, num_envs=n, vectorization_mode="vector_entry_point", num_threads=1)
    venv.reset(seed=0)
    for _ in range(5):
        venv.step(np.zeros((n,) + venv.single_action_space.shape, dtype=np.float32))
    core = venv.unwrapped.core
    robot, prm, dv, frustum = core.kernel_model()
    tasks = core.kernel_args(np.zeros((1, 6)), np.zeros(n, dtype=np.uint8))[3]  # the task bundle the step reads
    state = (core.q.copy(), core.steps.copy(), core.control_dt, tasks, robot, prm, dv, frustum, make_view_scratch(),
             make_overlap_work(), np.empty(4), np.empty(4), np.empty(3), np.empty((3, 3)), np.empty(3), np.empty(6))
    cumulative = {name: per_robot_us(view_part, (part, *state), n, repeats)
                  for name, part in (("target", 0), ("fk_jacobian", 1), ("dr_ik", 2), ("overlap", 3))}
    values = {"davinci_target": cumulative["target"],
              "fk_jacobian": cumulative["fk_jacobian"] - cumulative["target"],
              "dr_ik_with_fk": cumulative["dr_ik"] - cumulative["target"],
              "overlap_ratio": cumulative["overlap"] - cumulative["fk_jacobian"],
              "whole_step": whole_step_us(venv, n, seconds)}
    for name, value in values.items():
        results[f"{VIEW}.{name}_us"] = value
        rows.append((VIEW, name, f"{value:.2f}"))
    print_table(rows, ["environment", "part", "us per robot"])
    return finish(results, args.json)


if __name__ == "__main__":
    sys.exit(main())
