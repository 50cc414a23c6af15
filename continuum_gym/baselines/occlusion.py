"""Occlusion-avoidance baselines of Sarli & Simaan (paper 000): minimum-norm and projected gradient.

Both track a desired tip pose with the saturated proportional law of paper-notes §1.3 item 11 and
rotate the endoscope with eq (24) (gamma_dot = -eta2 dd_c/dgamma, paper-notes §1.3 item 10).

- ``MinimumNorm``: q_dot = J^+ xi_dot with the damped inverse of eq (23) (first term of eq 22).
- ``ProjectedGradient``: eq (22), q_dot = J^+ xi_dot - eta1 (I - J^+ J) grad Pi, with grad Pi of eq (12).

The damped projector leaks into the task (paper-notes §1.3 item 12); that is the paper's epsilon
trade-off and is kept.

Limits (the paper has none; ``OcclusionLimits``): a two-sided bend limit |pi/2 - theta_j| <= max_bend,
an insertion range, joint-rate limits and a gamma-rate limit. They are respected by
1. a quadratic barrier added to grad Pi inside a margin of each position limit (projected gradient),
2. rate saturation: the whole q_dot is scaled down uniformly, which keeps its direction and so the
   tracking direction,
3. saturation handling: a joint whose next step would cross its position limit is frozen (its column
   removed from J, its entry from the null-space step) and the step recomputed, as the
   dimension-reduced IK of paper 001 does.
``info`` of ``step`` reports frozen joints, the rate scale and any clamping.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TypeAlias

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.baselines.base import Controller, as_rotation_field, broadcast_rows
from continuum_gym.baselines.occlusion_kernels import (
    OcclusionParams,
    rates_batch,
    rollout_batch,
    twist_rates_batch,
    wrap_angle,
)
from continuum_gym.geometry.force_field import ForceField, resolve_field
from continuum_gym.geometry.lens_cone import LensCone, resolve_cone
from continuum_gym.robots.mbcr import MultiBackboneRobot, default_psps
from continuum_gym.validation import as_finite, interval, non_negative, number, positive

HALF_PI = 0.5 * math.pi
#: Physical ranges of the limits (generous: no continuum robot beside an endoscope comes near them).
MAX_INSERTION = 0.2  # m
MAX_ANGULAR_RATE = 100.0  # rad/s
MAX_INSERTION_RATE = 1.0  # m/s

#: What the controllers track: ``(p_des (..., 3) m, R_des (..., 3, 3)[, v_des (..., 3) m/s or None])`` or a
#: dict with those keys.
OcclusionTarget: TypeAlias = Sequence[ArrayLike | None] | Mapping[str, ArrayLike | None]

__all__ = ["OcclusionLimits", "OcclusionController", "MinimumNorm", "ProjectedGradient", "wrap_angle"]


@dataclass(frozen=True)
class OcclusionLimits:
    """Joint limits the paper lacks (the environments impose them; paper-notes §5), SI.

    Args:
        max_bend: per-segment bend limit |pi/2 - theta_j| <= max_bend (rad), two-sided, in (0, pi];
            default 90 degrees.
        insertion: (min, max) of q_ins (m), 0 <= min < max <= 0.2; default (0, 0.04).
        bend_rate: |theta_dot| limit (rad/s), in (0, 100].
        plane_rate: |delta_dot| limit (rad/s), in (0, 100].
        insertion_rate: |q_ins_dot| limit (m/s), in (0, 1].
        gamma_rate: |gamma_dot| limit (rad/s), in (0, 100].
        barrier_margin: width (rad, and the same fraction of the insertion range) inside each position
            limit where the projected gradient's barrier acts, in [0, 1].
        barrier_gain: stiffness of that barrier (N·m/rad²; per m² for insertion, scaled by range), in [0, 1e4].
    """

    max_bend: float = math.pi / 2
    insertion: tuple = (0.0, 0.04)
    bend_rate: float = 3.0
    plane_rate: float = 6.0
    insertion_rate: float = 0.02
    gamma_rate: float = 3.0
    barrier_margin: float = 0.1
    barrier_gain: float = 10.0

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "max_bend", number(self.max_bend, "max_bend", low=0.0, high=math.pi, low_open=True, unit="rad"))
        set_(self, "insertion", interval(self.insertion, "insertion", low=0.0, high=MAX_INSERTION, unit="m"))
        for name, high, unit in (("bend_rate", MAX_ANGULAR_RATE, "rad/s"), ("plane_rate", MAX_ANGULAR_RATE, "rad/s"),
                                 ("insertion_rate", MAX_INSERTION_RATE, "m/s"),
                                 ("gamma_rate", MAX_ANGULAR_RATE, "rad/s")):
            set_(self, name, number(getattr(self, name), name, low=0.0, high=high, low_open=True, unit=unit))
        set_(self, "barrier_margin", number(self.barrier_margin, "barrier_margin", low=0.0, high=1.0, unit="rad"))
        set_(self, "barrier_gain", number(self.barrier_gain, "barrier_gain", low=0.0, high=1e4, unit="N·m/rad²"))

    def bounds(self, n_segments: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(lower, upper, rate) arrays (2 n + 1,) for a robot of ``n_segments``.

        theta_j within pi/2 -+ max_bend, delta unlimited, q_ins within ``insertion`` (m); rates in rad/s
        for the angles and m/s for the insertion.
        """
        b = self.max_bend
        lower = np.tile([HALF_PI - b, -np.inf], n_segments)
        upper = np.tile([HALF_PI + b, np.inf], n_segments)
        rate = np.tile([self.bend_rate, self.plane_rate], n_segments)
        return (np.append(lower, self.insertion[0]), np.append(upper, self.insertion[1]),
                np.append(rate, self.insertion_rate))

    @property
    def lower(self) -> np.ndarray:
        """Lower position limits of the paper's 3-segment q (7,): ``bounds(3)[0]``."""
        return self.bounds(3)[0]

    @property
    def upper(self) -> np.ndarray:
        """Upper position limits of the paper's 3-segment q (7,): ``bounds(3)[1]``."""
        return self.bounds(3)[1]

    @property
    def rate_limit(self) -> np.ndarray:
        """|q_dot| limits (7,) of the paper's 3-segment robot: rad/s for angles, m/s for insertion."""
        return self.bounds(3)[2]


# ---------------------------------------------------------------------- public controllers
class OcclusionController(Controller):
    """Common part of the two paper-000 controllers (use ``MinimumNorm`` or ``ProjectedGradient``).

    Args:
        robot: ``MultiBackboneRobot`` (default geometry of Table I).
        cone: ``LensCone`` (None: Table I, literal lens).
        field: ``ForceField`` (None: Table I with p = 1, q = 2).
        psps: points subject to potential, (segment, arc fraction) pairs (paper-notes §1.5).
        eta1: null-space gradient gain (Table I: 30).
        eta2: endoscope rotation gain (Table I: 30).
        epsilon: damping of eq (23) (Table I: 1e-6, SI).
        k_track: proportional gain of the tip law (1/s), paper-notes §1.3 item 11: 100.
        v_max: tip speed cap (m/s): 0.05.
        w_max: tip angular-speed cap (rad/s): 1.
        rotate_endoscope: apply eq (24) to gamma (task (a) of the paper holds gamma fixed).
        limits: ``OcclusionLimits`` or None (the paper: unlimited).
    """

    name = "occlusion"
    use_gradient = False

    def __init__(self, robot: MultiBackboneRobot | None = None, cone: LensCone | None = None,
                 field: ForceField | None = None, psps: Sequence[tuple[int, float]] | None = None, eta1: float = 30.0,
                 eta2: float = 30.0, epsilon: float = 1e-6, k_track: float = 100.0, v_max: float = 0.05,
                 w_max: float = 1.0, rotate_endoscope: bool = True, limits: OcclusionLimits | None = None) -> None:
        self.robot = robot if robot is not None else MultiBackboneRobot()
        if not isinstance(self.robot, MultiBackboneRobot):
            raise ValueError(f"robot must be a MultiBackboneRobot; got {type(self.robot).__name__}")
        self.cone = resolve_cone(cone)
        self.field = resolve_field(field)
        self.psps = default_psps(self.robot.n_segments) if psps is None else tuple(psps)
        self.segments, self.fractions = self.robot.point_spec(self.psps)
        if limits is not None and not isinstance(limits, OcclusionLimits):
            raise ValueError(f"limits must be an OcclusionLimits or None; got {type(limits).__name__}")
        self.limits = limits
        self.eta1 = non_negative(eta1, "eta1", "1/s")
        self.eta2 = non_negative(eta2, "eta2", "1/s")
        self.epsilon = positive(epsilon, "epsilon", "m²")
        self.k_track = positive(k_track, "k_track", "1/s")
        self.v_max = positive(v_max, "v_max", "m/s")
        self.w_max = positive(w_max, "w_max", "rad/s")
        self.rotate_endoscope = bool(rotate_endoscope)
        dof = self.robot.dof
        unlimited = np.full(dof, np.inf)
        lower, upper, rate = limits.bounds(self.robot.n_segments) if limits else (-unlimited, unlimited, unlimited)
        self.params = OcclusionParams(
            eta1=self.eta1, eta2=self.eta2, epsilon=self.epsilon, k_track=self.k_track, v_max=self.v_max,
            w_max=self.w_max, use_gradient=self.use_gradient, rotate=self.rotate_endoscope,
            cone=self.cone.kernel_args(), field=self.field.kernel_args(), segments=self.segments,
            fractions=self.fractions, lower=lower, upper=upper, rate_limit=rate,
            gamma_rate_limit=limits.gamma_rate if limits else np.inf,
            barrier_gain=limits.barrier_gain if limits else 0.0,
            barrier_margin=limits.barrier_margin if limits else 0.0,
        )

    @property
    def action_dim(self) -> int:
        """Length of the command: the robot's joint rates and the endoscope rotation rate."""
        return self.robot.dof + 1

    # -------------------------------------------------------------- input handling
    def _inputs(self, q, gamma, target):
        dof = self.robot.dof
        q = as_finite(q, (dof,), "q")
        if isinstance(target, dict):
            target = (target["p_des"], target["R_des"], target.get("v_des"))
        if not isinstance(target, (tuple, list)) or len(target) not in (2, 3):
            raise ValueError("target must be (p_des (...,3) m, R_des (...,3,3)[, v_des (...,3) m/s])")
        p_des = as_finite(target[0], (3,), "target position p_des")
        R_des = as_finite(target[1], (3, 3), "target rotation R_des")
        v_des = np.zeros(3) if len(target) < 3 or target[2] is None else as_finite(target[2], (3,), "v_des")
        gamma = as_finite(gamma, (), "gamma")
        try:
            shape = np.broadcast_shapes(q.shape[:-1], gamma.shape, p_des.shape[:-1], R_des.shape[:-2],
                                        v_des.shape[:-1])
        except ValueError as error:
            raise ValueError(f"q, gamma and target batch shapes do not broadcast: {error}") from error
        return (*broadcast_rows(shape, (q, (dof,)), (gamma, ()), (p_des, (3,)), (R_des, (3, 3)), (v_des, (3,))),
                shape)

    def joint_rates(self, q: ArrayLike, target: OcclusionTarget, gamma: ArrayLike = 0.0, dt: float = 1e-3
                    ) -> np.ndarray:
        """Commanded rates [q_dot (dof), gamma_dot] of shape (..., dof + 1) (rad/s; m/s for q_ins).

        Args:
            q: configuration(s) (..., dof).
            target: (p_des (..., 3) m, R_des (..., 3, 3)[, v_des (..., 3) m/s feed-forward]) or a dict
                with those keys.
            gamma: endoscope rotation (rad).
            dt: step (s) used to predict position-limit crossings (saturation handling).
        """
        rates, _ = self.joint_rates_with_info(q, target, gamma, dt)
        return rates

    def joint_rates_with_info(self, q: ArrayLike, target: OcclusionTarget, gamma: ArrayLike = 0.0, dt: float = 1e-3
                              ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """As ``joint_rates``, plus info: ``frozen`` (..., dof) bool, ``rate_scale`` (...)."""
        Q, G, P, R, V, shape = self._inputs(q, gamma, target)
        dt = positive(dt, "dt", "s")
        dof = self.robot.dof
        n = Q.shape[0]
        qdot = np.empty((n, dof))
        gamma_dot = np.empty(n)
        frozen = np.empty(n, dtype=np.int64)
        scale = np.empty(n)
        rates_batch(Q, G, P, R, V, dt, self.robot.kernel_args(), self.params, qdot, gamma_dot, frozen, scale)
        rates = np.concatenate([qdot, gamma_dot[:, None]], axis=1).reshape(shape + (dof + 1,))
        frozen_mask = ((frozen[:, None] >> np.arange(dof)) & 1).astype(bool).reshape(shape + (dof,))
        return rates, {"frozen": frozen_mask, "rate_scale": scale.reshape(shape)}

    def rates_for_twist(self, q: ArrayLike, xi_dot: ArrayLike, gamma: ArrayLike = 0.0, dt: float = 1e-3
                        ) -> np.ndarray:
        """Rates [q_dot (dof), gamma_dot] (..., dof + 1) for a desired tip twist xi_dot = [v; w] (..., 6) in
        m/s and rad/s, eq (22)."""
        dof = self.robot.dof
        q = as_finite(q, (dof,), "q")
        gamma = as_finite(gamma, (), "gamma")
        xi_dot = as_finite(xi_dot, (6,), "xi_dot")
        try:
            shape = np.broadcast_shapes(q.shape[:-1], gamma.shape, xi_dot.shape[:-1])
        except ValueError as error:
            raise ValueError(f"q, gamma and xi_dot batch shapes do not broadcast: {error}") from None
        Q, G, XI = broadcast_rows(shape, (q, (dof,)), (gamma, ()), (xi_dot, (6,)))
        qdot = np.empty((Q.shape[0], dof))
        gamma_dot = np.empty(Q.shape[0])
        twist_rates_batch(Q, G, XI, positive(dt, "dt", "s"), self.robot.kernel_args(), self.params, qdot, gamma_dot)
        return np.concatenate([qdot, gamma_dot[:, None]], axis=1).reshape(shape + (dof + 1,))

    def rollout(self, q0: ArrayLike, gamma0: ArrayLike, p_des: ArrayLike, R_des: ArrayLike,
                v_des: ArrayLike | None = None, dt: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
        """Closed-loop explicit-Euler run (paper-notes §1.3 item 6) from q0 over per-step targets.

        Args:
            q0: (N, dof) or (dof,) start configurations.
            gamma0: (N,) or scalar start rotation (rad).
            p_des: (T, 3) or (N, T, 3) desired tip positions (m), one per step.
            R_des: (T, 3, 3) or (N, T, 3, 3).
            v_des: feed-forward velocities like p_des (m/s), default 0.
            dt: step (s), the paper's 1 ms.

        Returns:
            (q, gamma): (N, T+1, dof) and (N, T+1), iteration 0 first (squeezed to T+1 for a single q0).
        """
        dof = self.robot.dof
        single = np.ndim(q0) == 1
        q0 = np.atleast_2d(as_finite(q0, (dof,), "q0"))
        n = q0.shape[0]
        p_des = as_finite(p_des, (3,), "p_des")
        R_des = as_finite(R_des, (3, 3), "R_des")
        steps = p_des.shape[-2]
        v_des = np.zeros_like(p_des) if v_des is None else as_finite(v_des, (3,), "v_des")
        P = np.ascontiguousarray(np.broadcast_to(p_des, (n, steps, 3)))
        R = np.ascontiguousarray(np.broadcast_to(R_des, (n, steps, 3, 3)))
        V = np.ascontiguousarray(np.broadcast_to(v_des, (n, steps, 3)))
        G = np.ascontiguousarray(np.broadcast_to(as_finite(gamma0, (), "gamma0"), (n,)))
        q_traj = np.empty((n, steps + 1, dof))
        gamma_traj = np.empty((n, steps + 1))
        rollout_batch(np.ascontiguousarray(q0), G, P, R, V, positive(dt, "dt", "s"), self.robot.kernel_args(),
                      self.params, q_traj, gamma_traj)
        if single:
            return q_traj[0], gamma_traj[0]
        return q_traj, gamma_traj

    def predict(self, observation: np.ndarray | dict[str, np.ndarray], state: tuple[np.ndarray, ...] | None = None,
                episode_start: np.ndarray | None = None, deterministic: bool = False
                ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """SB3 ``predict``: observation dict with ``q``, ``gamma``, ``p_des``, ``R_des`` (and ``v_des``).

        Returns (rates (..., dof + 1), None): the same command as ``joint_rates``.
        """
        obs = self._observation_dict(observation, ("q", "gamma", "p_des", "R_des"))
        target = (obs["p_des"], as_rotation_field(obs["R_des"]), obs.get("v_des"))
        gamma = np.asarray(obs["gamma"], dtype=float)
        if gamma.ndim and gamma.shape[-1] == 1:
            gamma = gamma[..., 0]
        return self.joint_rates(obs["q"], target, gamma, dt=float(obs.get("dt", 1e-3))), state


class MinimumNorm(OcclusionController):
    """Minimum-norm rates J^+ xi_dot with the damped inverse of eq (23) (first term of eq 22), paper 000."""

    name = "minimum_norm"
    use_gradient = False


class ProjectedGradient(OcclusionController):
    """Projected gradient of eqs (21)-(23) on grad Pi of eq (12), with gamma by eq (24), paper 000."""

    name = "projected_gradient"
    use_gradient = True
