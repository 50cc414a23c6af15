"""Issue 38, Campaign 4: run ``hold_arc_plan``'s planned trajectories in the OcclusionAvoidance env itself.

The ``planned_trajectory`` reference row is computed in the kinematics alone (the tip held on the self-motion
arc, every rate within its limit). This script checks that the env's own step (1 ms substeps, the projected
gradient recomputed in each, the uniform rate scaling, the visibility guard) executes it: a scripted residual
makes base + residual equal the plan's rates, reading the state from the core and the base command from the
observation (``OBS.base_command``, the next substep's). The plans are made with visibility 0.69, the env's guard,
so the guard has nothing to cut. Validation hold ids 0-31 by default; prints the plan's and the env's mean VOI.

    PYTHONPATH=. python scripts/optimum/plan_in_env.py [--split validation] [--tasks 32]
"""

from __future__ import annotations

import argparse
import math

import numpy as np


def plan_action(core, obs: np.ndarray, q_next: np.ndarray, gamma_next: np.ndarray, scale: float) -> np.ndarray:
    """The residual action (N, 8) that makes base + residual move ``core`` to the plan's next joints and gamma
    in one control step: the base command is read from the observation (``OBS.base_command``)."""
    from continuum_gym.envs.columns import at
    from continuum_gym.envs.occlusion.outputs import OBS

    rates = np.asarray(core.rate_scale_vec, dtype=float)
    first = at(OBS.base_command, core.robot.n_segments)
    dq = q_next - core.q
    dq[:, 1:6:2] = _wrap(dq[:, 1:6:2])  # bending-plane angles are angles on the circle
    desired = np.concatenate([dq, _wrap(gamma_next - core.gamma)[:, None]], axis=1) / core.config.control_dt
    base = obs[:, first:first + rates.size] * rates
    return np.clip((desired - base) / (scale * rates), -1.0, 1.0)


def _wrap(x: np.ndarray) -> np.ndarray:
    return (x + math.pi) % (2 * math.pi) - math.pi


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--split", default="validation", choices=("validation", "test", "train"))
    parser.add_argument("--tasks", type=int, default=32)
    args = parser.parse_args(argv)
    from continuum_gym.envs.occlusion.tasks import hold_start_pool
    from continuum_gym.evaluation.optimum import hold_arc_plan
    from continuum_gym.evaluation.rollout import make_core, run_episodes

    scale, guard = 2.0, 0.69
    core = make_core("ContinuumGym/OcclusionAvoidance-v0", args.tasks, task="hold", task_split=args.split,
                     residual_scale=scale, visibility_guard=guard)
    lim = core.limits
    robot = core.robot
    starts = np.asarray(hold_start_pool(args.split, float(lim.max_bend), tuple(lim.insertion), robot, core.cone))
    plans = [hold_arc_plan(robot, q0, lim, visibility=guard, cone=core.cone) for q0 in starts[:args.tasks]]
    q_plan = np.stack([p["q_plan"] for p in plans], axis=1)  # (steps, N, 7)
    g_plan = np.stack([p["gamma_plan"] for p in plans], axis=1)
    step = {"k": 0}

    def scripted(obs: np.ndarray) -> np.ndarray:
        k = min(step["k"], len(q_plan) - 1)
        step["k"] += 1
        return plan_action(core, obs, q_plan[k], g_plan[k], scale)

    out = run_episodes(core, scripted, np.arange(args.tasks), record=True)
    planned = np.array([p["mean_voi_plan"] for p in plans])
    print(f"{args.split} hold ids 0-{args.tasks - 1}: planned {planned.mean():.4f}, executed in the env "
          f"{out['mean_voi'].mean():.4f} (largest per-task difference {np.abs(out['mean_voi'] - planned).max():.4f}), "
          f"tip in view {out['tip_in_view_fraction'].min():.3f} (min over episodes), tip error "
          f"{np.nanmax(out['trace_tip_error']) * 1e3:.3f} mm (max)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
