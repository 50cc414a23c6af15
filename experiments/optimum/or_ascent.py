"""A residual policy plus an ascent step on the overlap ratio (issue 38, Campaign 7: ViewTracking precision).

The shipped ViewTracking residuals settle 0.01-0.02 below the optimum's OR on most of the targets they miss
(Campaign 6). This wraps a policy (SB3 model) so that each action gets an extra term along the gradient of
the overlap ratio with respect to the action: from the observation alone, the configuration q (its
normalised joints), the target pose (the target point error and the orientation error against the
forward kinematics of q) and so the da Vinci camera; the OR's gradient in q by central differences; in
action units through the joint-space residual's map (``residual_scale * ACTION_SCALE * control_dt``).

    a = clip(policy(obs) + gain * dOR/da, -1, 1)

It needs the same information as the base controller (robot model, target pose), nothing the env hides.
The lookahead that Campaign 7 kept is now the env option ``overlap_polish`` (``envs/view_tracking/polish.py``);
this script keeps the wrappers its screen measured.

    PYTHONPATH=.:experiments/optimum python experiments/optimum/or_ascent.py RUN --gain 30 --selection
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from continuum_gym.envs.view_tracking.env import ACTION_SCALE
from continuum_gym.envs.view_tracking.outputs import OBS
from continuum_gym.envs.view_tracking.polish import observed_camera
from continuum_gym.geometry.overlap_clipping import make_overlap_work, overlap_ratio_in
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.endoscope import endoscope_kinematics, make_endoscope_workspace

VIEW = "ContinuumGym/ViewTracking-v0"


@kernel
def make_scratch():
    """Work arrays of one observed camera and one OR (see ``observed_camera``)."""
    return (np.empty(3), np.empty((3, 3)), np.empty(3), np.empty((6, 6)), make_endoscope_workspace(),
            make_overlap_work(), np.empty(6), np.empty(3), np.empty((3, 3)), np.empty((3, 3)), np.empty(3))


@kernel
def overlap_gradient(obs, lower, upper, robot, le_dv, tan_half, near, far, h, grad, ratio):
    """Per row of obs (n, 22+): the OR at the observed configuration (ratio) and dOR/dq (grad, central)."""
    p_cam, R, p_ct, J, ws, work, q, w, turn, R_dv, p_dv = make_scratch()
    for i in range(obs.shape[0]):
        observed_camera(obs[i], lower, upper, robot, le_dv, ws, q, p_cam, R, p_ct, J, w, turn, R_dv, p_dv)
        ratio[i] = overlap_ratio_in(p_dv, R_dv, p_cam, R, tan_half, near, far, work)
        for k in range(6):
            keep = q[k]
            q[k] = keep + h
            endoscope_kinematics(q, robot, ws, p_cam, R, p_ct, J, False)
            up = overlap_ratio_in(p_dv, R_dv, p_cam, R, tan_half, near, far, work)
            q[k] = keep - h
            endoscope_kinematics(q, robot, ws, p_cam, R, p_ct, J, False)
            down = overlap_ratio_in(p_dv, R_dv, p_cam, R, tan_half, near, far, work)
            q[k] = keep
            grad[i, k] = (up - down) / (2.0 * h)


@kernel
def overlap_at(obs, Q, lower, upper, robot, le_dv, tan_half, near, far, out):
    """OR of configuration Q[i] (n, 6) against row i's observed target (the da Vinci camera of obs[i])."""
    p_cam, R, p_ct, J, ws, work, q, w, turn, R_dv, p_dv = make_scratch()
    for i in range(obs.shape[0]):
        observed_camera(obs[i], lower, upper, robot, le_dv, ws, q, p_cam, R, p_ct, J, w, turn, R_dv, p_dv)
        endoscope_kinematics(Q[i], robot, ws, p_cam, R, p_ct, J, False)
        out[i] = overlap_ratio_in(p_dv, R_dv, p_cam, R, tan_half, near, far, work)


def observed_q(obs: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """The configurations (n, 6) of observation rows (the inverse of the observation's joint normalisation)."""
    q = np.empty((obs.shape[0], 6))
    for k, column in ((0, OBS.l0), (2, OBS.theta1), (4, OBS.theta2)):
        q[:, k] = lower[k] + (obs[:, column] + 1.0) * 0.5 * (upper[k] - lower[k])
    q[:, 1] = obs[:, OBS.phi] * math.pi
    q[:, 3] = np.arctan2(obs[:, OBS.delta1], obs[:, OBS.delta1 + 1])
    q[:, 5] = np.arctan2(obs[:, OBS.delta2], obs[:, OBS.delta2 + 1])
    return q


class OverlapLookahead:
    """``policy`` plus the step along the OR's gradient (at the policy's next configuration) that maximises the
    OR predicted for the next configuration, among ``steps`` (action units; 0 keeps the policy's action).
    ``coordinates``: the steps along each action axis (both signs) are candidates too, for OR maxima at a kink,
    where the gradient's direction need not ascend (Campaign 10)."""

    def __init__(self, policy, config: dict, steps=(0.02, 0.05, 0.1, 0.2, 0.4), min_ratio: float = 0.0,
                 h: float = 1e-4, coordinates: bool = False) -> None:
        self.inner = OverlapAscent(policy, config, 0.0, h=h)
        self.steps, self.min_ratio = tuple(float(s) for s in steps), float(min_ratio)
        self.coordinates = bool(coordinates)
        env_config = config["env_config"]
        self.dt = float(env_config["control_dt"])
        self.rate = float(env_config["residual_scale"]) * ACTION_SCALE

    def next_q(self, rows, q, action):
        base = rows[:, OBS.base_command:OBS.base_command + 6] * ACTION_SCALE
        q_next = q + self.dt * (base + action * self.rate)
        return np.clip(q_next, self.inner.lower, self.inner.upper)

    def predicted(self, rows, Q):
        out = np.empty(rows.shape[0])
        a = self.inner
        overlap_at(rows, np.ascontiguousarray(Q), a.lower, a.upper, a.robot, a.le_dv, *a.frustum, out)
        return out

    def predict(self, obs, state=None, episode_start=None, deterministic: bool = True):
        a = self.inner
        action, state = a.policy.predict(obs, state=state, episode_start=episode_start, deterministic=True)
        shape = np.shape(action)
        rows = np.ascontiguousarray(np.atleast_2d(obs), dtype=np.float64)
        action = np.clip(np.asarray(action, dtype=np.float64).reshape(rows.shape[0], 6), -1.0, 1.0)
        q = observed_q(rows, a.lower, a.upper)
        q_pol = self.next_q(rows, q, action)
        best = self.predicted(rows, q_pol)
        ratio_now = rows[:, OBS.overlap]
        # the gradient at the policy's next configuration, against the observed target
        grad = np.empty((rows.shape[0], 6))
        for k in range(6):
            up, down = q_pol.copy(), q_pol.copy()
            up[:, k] += a.h
            down[:, k] -= a.h
            grad[:, k] = (self.predicted(rows, up) - self.predicted(rows, down)) / (2.0 * a.h)
        direction = grad * self.rate * self.dt
        norm = np.linalg.norm(direction, axis=1, keepdims=True)
        direction = np.divide(direction, norm, out=np.zeros_like(direction), where=norm > 0)
        chosen = action.copy()
        axes = [sign * axis for axis in np.eye(6) for sign in (-1.0, 1.0)] if self.coordinates else []
        for d in [direction, *axes]:
            for step in self.steps:
                candidate = np.clip(action + step * d, -1.0, 1.0)
                value = self.predicted(rows, self.next_q(rows, q, candidate))
                better = (value > best) & (ratio_now >= self.min_ratio)
                chosen[better] = candidate[better]
                best = np.where(better, value, best)
        return chosen.reshape(shape), state


class OverlapAscent:
    """``policy`` (SB3 model) plus ``gain`` times the OR's gradient in action units (see the module doc)."""

    def __init__(self, policy, config: dict, gain: float, h: float = 1e-4, min_ratio: float = 0.0) -> None:
        from continuum_gym.geometry import Frustum
        from continuum_gym.robots import ContinuumEndoscope, DaVinciEndoscope

        env_config = config["env_config"]
        if env_config.get("residual_space", "joint") != "joint":
            raise ValueError("OverlapAscent: a joint-space residual only")
        robot = ContinuumEndoscope()
        self.policy, self.gain, self.h, self.min_ratio = policy, float(gain), float(h), float(min_ratio)
        self.lower, self.upper = robot.joint_limits
        self.robot = robot.kernel_args()
        self.le_dv = DaVinciEndoscope().Le
        frustum = Frustum()
        self.frustum = (frustum.tan_half, frustum.near, frustum.far)
        self.map = float(env_config["residual_scale"]) * ACTION_SCALE * float(env_config["control_dt"])

    def predict(self, obs, state=None, episode_start=None, deterministic: bool = True):
        action, state = self.policy.predict(obs, state=state, episode_start=episode_start, deterministic=True)
        rows = np.ascontiguousarray(np.atleast_2d(obs), dtype=np.float64)
        grad = np.empty((rows.shape[0], 6))
        ratio = np.empty(rows.shape[0])
        overlap_gradient(rows, self.lower, self.upper, self.robot, self.le_dv, *self.frustum, self.h, grad, ratio)
        extra = self.gain * grad * self.map
        extra[ratio < self.min_ratio] = 0.0
        return np.clip(action.reshape(extra.shape) + extra, -1.0, 1.0).reshape(np.shape(action)), state


def main(argv: list[str] | None = None) -> int:
    import val_eval

    from continuum_gym.envs.spec import get_spec
    from continuum_gym.evaluation.methods import load_policy, policy_env_kwargs

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--gain", type=float, nargs="+", required=True)
    parser.add_argument("--min-ratio", type=float, default=0.0)
    parser.add_argument("--lookahead", type=float, nargs="*", default=None,
                        help="OverlapLookahead with these step sizes (action units); --gain is then ignored")
    parser.add_argument("--coordinates", action="store_true",
                        help="the lookahead also tries its steps along each action axis (Campaign 10)")
    parser.add_argument("--selection", action="store_true", help="pan_tilt ids 4096-5119 only")
    parser.add_argument("--model-error", default="none", help="the env's model_error (none, mild, severe): the "
                        "robot differs from the nominal model the base controller and the lookahead use")
    parser.add_argument("--out", type=Path, default=val_eval.ROOT / "results" / "val_view_ascent.jsonl")
    args = parser.parse_args(argv)
    model, config = load_policy(args.run)
    kwargs = dict(policy_env_kwargs(get_spec(VIEW), config), model_error=args.model_error)
    kwargs.pop("overlap_polish", None)  # a run shipped with the env's polish is scored with this script's instead
    for gain in args.gain:
        if args.lookahead:
            policy = OverlapLookahead(model, config, args.lookahead, min_ratio=args.min_ratio,
                                      coordinates=args.coordinates)
        else:
            policy = OverlapAscent(model, config, gain, min_ratio=args.min_ratio) if gain else model
        summary, _ = val_eval.measure(VIEW, policy, kwargs, selection=args.selection)
        row = dict(run=str(args.run), gain=gain, lookahead=args.lookahead, coordinates=args.coordinates,
                   model_error=args.model_error, min_ratio=args.min_ratio, selection=args.selection, **summary)
        print(json.dumps(row), flush=True)
        with args.out.open("a") as f:
            f.write(json.dumps(row) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
