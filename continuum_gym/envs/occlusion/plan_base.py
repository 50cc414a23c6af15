"""OcclusionAvoidance's base ``arc_plan``: on hold tasks the projected gradient tracks a planned trajectory.

On a row whose task holds a static tip pose (the ``hold`` family, or any task with a constant target equal to
its start's tip pose: a recorded ``TipTrajectory`` whose samples all sit at the start's tip, for one), the base
plans when the episode starts: :func:`~continuum_gym.baselines.arc_plan.hold_arc_plan` from the start
configuration and endoscope rotation (a trajectory along the self-motion arc of the held pose
towards a low-VOI point, every joint and the endoscope within its rate limit, the tip kept in view within the
env's visibility guard). At every control step the base command of that row is the rate that reaches the plan's
next point in one step; the projected gradient (recomputed at every substep) stays underneath it, so the
residual sent to the step kernel is ``(plan rate - projected-gradient rate) / (residual_scale * rate limits)``
plus the policy's own action, clipped to [-1, 1]. Every other row keeps the projected gradient alone.

What a policy sees and pays for is its own part: the observation's ``base_command`` block holds the plan's
command on planned rows, and the action penalty is computed on the policy's action, not on the sum.

Under a model error (``model_error`` not "none") the core makes no planner: the plans run along the visibility guard's
edge, which the true tip then crosses (measured on validation holds with a zero residual: the tip in view on
0.59 of the steps with the ``mild`` error and 0.51 with ``severe``, against 1.0 for the projected gradient), so
every row keeps the base.

A plan costs about a second of Python. Plans are cached per process by start (joints and rotation) and by
everything else they depend on (robot, cone, limits, control step, duration, visibility), so the finite hold
pools of the built-in tasks are planned once per process.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from continuum_gym.baselines.arc_plan import VISIBILITY, hold_arc_plan
from continuum_gym.envs.columns import at
from continuum_gym.envs.occlusion.kernel import OBS_LIMIT, REWARD_TERMS
from continuum_gym.envs.occlusion.outputs import OBS

#: Largest offset (m, per axis) between a static target and the start's tip for the row to count as a hold.
HOLD_TOLERANCE_M = 1e-9
#: Column of the action penalty among the built-in reward terms.
ACTION_TERM = REWARD_TERMS.index("action")
#: Plans kept per process (about 10 kB each).
CACHE_SIZE = 8192
_CACHE: dict[tuple, tuple[np.ndarray, np.ndarray] | None] = {}


def _wrap(x: np.ndarray) -> np.ndarray:
    return (x + math.pi) % (2 * math.pi) - math.pi


def static_target(tasks: Any, r: int) -> np.ndarray | None:
    """Row ``r``'s target position if its task holds one tip pose for the whole episode, else None.

    A sine task holds when no term moves (amplitude or frequency zero): its centre. A recorded trajectory
    (``TipTrajectory``, spline knots) holds when every knot is at the first one's position and orientation
    with zero slopes: its first knot.
    """
    n = int(tasks.n_knots[r])
    if n == 0:
        return None if np.any(tasks.amp[r] * tasks.omega[r][:, None] != 0.0) else tasks.centre[r]
    x, r_knots = tasks.knot_x[r, :n], tasks.knot_r[r, :n]
    still = (np.all(np.abs(x - x[0]) <= HOLD_TOLERANCE_M) and np.all(tasks.knot_m[r, :n] == 0.0)
             and np.all(r_knots == r_knots[0]) and np.all(tasks.knot_rm[r, :n] == 0.0))
    return x[0] if still else None


class ArcPlanBase:
    """The per-row plans of one ``OcclusionCore`` and the residual that makes its base follow them."""

    def __init__(self, core: Any) -> None:  # an OcclusionCore (not imported: the core imports this module)
        self.core = core
        n, dof = core.num_envs, core.dof
        self.on = np.zeros(n, dtype=bool)
        self.q_plan = np.zeros((n, 1, dof))
        self.g_plan = np.zeros((n, 1))
        guard = core.visibility_guard
        self.visibility = VISIBILITY if guard is None else float(guard)
        self._key = repr((core.robot, core.cone, core.limits, core.control_dt, self.visibility))
        self._first = at(OBS.base_command, core.robot.n_segments)

    # ------------------------------------------------------------------ reset
    def reset_rows(self, rows: np.ndarray) -> None:
        """Plan the rows just reset (static holds only) and show the plan's command in their observation."""
        core = self.core
        tasks = core.tasks
        self.on[rows] = False
        for r in rows:
            target = static_target(tasks, r)
            if target is None:
                continue
            q0 = self._joints()[r]
            tip, _ = core.robot.forward_kinematics(q0)
            if np.max(np.abs(tip - target)) > HOLD_TOLERANCE_M:
                continue
            plan = self._plan(q0, float(core.gamma[r]), int(tasks.duration[r]))
            if plan is None:
                continue
            q_plan, g_plan = plan
            if q_plan.shape[0] > self.q_plan.shape[1]:
                self._grow(q_plan.shape[0])
            self.q_plan[r, :len(q_plan)] = q_plan
            self.q_plan[r, len(q_plan):] = q_plan[-1]
            self.g_plan[r, :len(g_plan)] = g_plan
            self.g_plan[r, len(g_plan):] = g_plan[-1]
            self.on[r] = True
        self.show(rows)

    def _plan(self, q0: np.ndarray, gamma0: float, steps: int) -> tuple[np.ndarray, np.ndarray] | None:
        key = (self._key, q0.tobytes(), gamma0, steps)
        if key not in _CACHE:
            core = self.core
            plan = hold_arc_plan(core.robot, q0, core.limits, dt=core.control_dt, steps=max(steps, 1), gamma0=gamma0,
                                 visibility=self.visibility, cone=core.cone)
            finite = math.isfinite(plan["mean_voi_plan"])
            if len(_CACHE) >= CACHE_SIZE:
                _CACHE.pop(next(iter(_CACHE)))
            _CACHE[key] = (plan["q_plan"], plan["gamma_plan"]) if finite else None
        return _CACHE[key]

    def _grow(self, steps: int) -> None:
        n, old, dof = self.q_plan.shape
        q = np.repeat(self.q_plan[:, -1:], steps, axis=1)
        q[:, :old] = self.q_plan
        g = np.repeat(self.g_plan[:, -1:], steps, axis=1)
        g[:, :old] = self.g_plan
        self.q_plan, self.g_plan = q, g

    # ------------------------------------------------------------------ step
    def _joints(self) -> np.ndarray:
        """The joints the controllers see (the sensors' reading under a model error)."""
        return self.core.sensed_joints()

    def command(self, rows: np.ndarray) -> np.ndarray:
        """The plan's command (rows, dof + 1) in rad/s and m/s: its next point reached in one control step."""
        core = self.core
        k = np.minimum(core.steps[rows], self.q_plan.shape[1] - 1)
        dq = self.q_plan[rows, k] - self._joints()[rows]
        dq[:, 1:2 * core.robot.n_segments:2] = _wrap(dq[:, 1:2 * core.robot.n_segments:2])  # bending-plane angles
        dg = _wrap(self.g_plan[rows, k] - core.gamma[rows])
        return np.concatenate([dq, dg[:, None]], axis=1) / core.control_dt

    def show(self, rows: np.ndarray) -> None:
        """Write the plan's command into the observation's ``base_command`` block of the planned ``rows``."""
        rows = np.asarray(rows)[self.on[rows]]
        if rows.size:
            core = self.core
            width = core.rate_scale_vec.size
            core.obs[rows, self._first:self._first + width] = np.clip(
                self.command(rows) / core.rate_scale_vec, -OBS_LIMIT, OBS_LIMIT)

    def actions(self, actions: np.ndarray, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The actions the step kernel gets (the plan's residual added on planned rows) and those rows."""
        rows = np.flatnonzero(self.on & (active == 1))
        if rows.size == 0:
            return actions, rows
        core = self.core
        out = np.array(np.broadcast_to(actions, (core.num_envs, core.rate_scale_vec.size)), dtype=np.float64)
        scale = core.residual_scale * core.rate_scale_vec
        planned = (self.command(rows) - core.base_cmd[rows]) / scale
        out[rows] = np.clip(out[rows] + planned, -1.0, 1.0)
        return out, rows

    def after_step(self, actions: np.ndarray, rows: np.ndarray) -> None:
        """Charge the planned rows' action penalty on the policy's own action; show the next plan command."""
        if rows.size == 0:
            return
        core = self.core
        own = np.broadcast_to(actions, (core.num_envs, core.rate_scale_vec.size))[rows]
        term = -core.weights["action"] * np.sum(np.square(own, dtype=np.float64), axis=1) / own.shape[1]
        core.rewards[rows] += term - core.terms[rows, ACTION_TERM]
        core.terms[rows, ACTION_TERM] = term
        self.show(rows)
