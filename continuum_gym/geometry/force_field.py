"""Repulsive force field of the view cone and the gradient of the potential Pi (paper 000, eqs 12, 18-19).

f = f* (r*/r)^q (1 - d/d_0)^(2p) f_hat for d <= d_0 and r >= 0, else 0 (eq 18 with p = 1, q = 2 from
Fig. 2-b, paper-notes §1.3 item 8); f_hat = grad d, the outward normal (eq 19). The formula is singular at
the vertex (r -> 0) and directionless on the axis (rho = 0): both return zero force.
grad Pi = grad E - sum_i Jv_i^T f_i (eq 12, paper-notes §1.3 item 5).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from continuum_gym.geometry.lens_cone import (
    _points_and_gamma,
    cone_distance_slant,
    lens_to_world_direction,
    resolve_cone,
    to_lens,
)
from continuum_gym.robots.mbcr import DOF, PAPER_PSPS, _as_q, all_finite, make_workspace, points_kernel
from continuum_gym.robots.validation import positive

# Below these the force is singular (vertex) or has no direction (axis): paper-notes §1.3 item 8.
VERTEX_EPS = 1e-9
AXIS_EPS = 1e-12


@dataclass(frozen=True)
class ForceField:
    """Parameters of the repulsive field (Table I of paper 000, SI; p, q from Fig. 2-b).

    Args:
        d0: distance of influence outside the cone (m), 5 mm.
        r_star: nominal slant height (m), 60 mm.
        f_star: nominal force on the cone face at r = r_star (N), 5 N.
        p: exponent of the distance term (1).
        q: exponent of the slant-height term (2).
    """

    d0: float = 5e-3
    r_star: float = 60e-3
    f_star: float = 5.0
    p: float = 1.0
    q: float = 2.0

    def __post_init__(self):
        positive(self.d0, "d0", "m")
        positive(self.r_star, "r_star", "m")
        positive(self.f_star, "f_star", "N")
        positive(self.p, "p", "-")
        positive(self.q, "q", "-")

    @property
    def kernel_args(self) -> tuple:
        return (self.d0, self.r_star, self.f_star, self.p, self.q)


DEFAULT_FIELD = ForceField()


def resolve_field(field) -> ForceField:
    if field is None:
        return DEFAULT_FIELD
    if not isinstance(field, ForceField):
        raise ValueError(f"field must be a ForceField or None; got {type(field).__name__}")
    return field


@njit(cache=True)
def force_kernel(px, py, pz, gamma, d_o, alpha, beta, model, d0, r_star, f_star, p_exp, q_exp):
    """World force (N) on one point (m): eq (18)-(19) with paper-notes §1.3 item 8. Returns (fx, fy, fz)."""
    xl, yl, zl = to_lens(px, py, pz, gamma, d_o, alpha, model)
    d, r, rho = cone_distance_slant(xl, yl, zl, beta)
    if d > d0 or r < VERTEX_EPS or rho < AXIS_EPS:
        return 0.0, 0.0, 0.0
    magnitude = f_star * (r_star / r) ** q_exp * (1.0 - d / d0) ** (2.0 * p_exp)
    cb = math.cos(beta)
    sb = math.sin(beta)
    fx, fy, fz = lens_to_world_direction(xl * cb / rho, yl * cb / rho, -sb, gamma, alpha)
    return magnitude * fx, magnitude * fy, magnitude * fz


@njit(cache=True)
def potential_gradient_kernel(q, lengths, stiffness, ws, segments, fractions, P, JV, gamma,
                              d_o, alpha, beta, model, d0, r_star, f_star, p_exp, q_exp, grad):
    """grad Pi (eq 12) for one q into ``grad`` (7,); P, JV are (m, 3), (m, 3, 7) scratch."""
    points_kernel(q, lengths, ws, segments, fractions, P, JV)
    for k in range(7):
        grad[k] = 0.0
    for j in range(3):
        grad[2 * j] = -stiffness[j] * (0.5 * math.pi - q[2 * j])
    for i in range(segments.shape[0]):
        fx, fy, fz = force_kernel(P[i, 0], P[i, 1], P[i, 2], gamma, d_o, alpha, beta, model,
                                  d0, r_star, f_star, p_exp, q_exp)
        if fx == 0.0 and fy == 0.0 and fz == 0.0:
            continue
        for k in range(7):
            grad[k] -= JV[i, 0, k] * fx + JV[i, 1, k] * fy + JV[i, 2, k] * fz


@njit(cache=True)
def _potential_gradient_batch(qs, G, lengths, stiffness, segments, fractions,
                              d_o, alpha, beta, model, d0, r_star, f_star, p_exp, q_exp, out):
    if not all_finite(qs):
        return False
    ws = make_workspace()
    m = segments.shape[0]
    P = np.empty((m, 3))
    JV = np.empty((m, 3, 7))
    for i in range(qs.shape[0]):
        potential_gradient_kernel(qs[i], lengths, stiffness, ws, segments, fractions, P, JV, G[i],
                                  d_o, alpha, beta, model, d0, r_star, f_star, p_exp, q_exp, out[i])
    return True


@njit(cache=True)
def _force_batch(P, G, d_o, alpha, beta, model, d0, r_star, f_star, p_exp, q_exp, out):
    for i in range(P.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = force_kernel(P[i, 0], P[i, 1], P[i, 2], G[i], d_o, alpha, beta,
                                                       model, d0, r_star, f_star, p_exp, q_exp)


def repulsive_force(points, gamma, cone=None, field=None):
    """Force (N) of eq (18) on world points (..., 3) in m, in {w}; gamma (rad) broadcasts."""
    cone = resolve_cone(cone)
    field = resolve_field(field)
    P, G, shape = _points_and_gamma(points, gamma)
    out = np.empty((P.shape[0], 3))
    _force_batch(P, G, cone.d_o, cone.alpha, cone.beta, cone.model_code, *field.kernel_args, out)
    return out.reshape(shape + (3,))


def potential_gradient(robot, q, gamma, cone=None, field=None, psps=PAPER_PSPS):
    """grad Pi = grad E - sum_i Jv_i^T f_i (eq 12) over the points subject to potential, shape (..., 7).

    Args:
        robot: a ``MultiBackboneRobot``.
        q: configuration(s) (..., 7).
        gamma: endoscope rotation (rad), broadcasts with q[..., 0].
        cone, field: ``LensCone`` and ``ForceField`` (None: the paper's).
        psps: (segment, arc fraction) pairs; default the paper's 10 (paper-notes §1.5).
    """
    cone = resolve_cone(cone)
    field = resolve_field(field)
    q = _as_q(q)
    gamma = np.asarray(gamma, dtype=np.float64)
    if not np.all(np.isfinite(gamma)):
        raise ValueError(f"gamma must be finite (rad); got {gamma}")
    shape = np.broadcast_shapes(q.shape[:-1], gamma.shape)
    Q = np.ascontiguousarray(np.broadcast_to(q, shape + (DOF,)).reshape(-1, DOF))
    G = np.ascontiguousarray(np.broadcast_to(gamma, shape).reshape(-1))
    segments, fractions = robot._point_spec(psps)
    out = np.empty((Q.shape[0], DOF))
    if not _potential_gradient_batch(Q, G, robot._lengths_array, robot.stiffness, segments, fractions,
                                     *cone.kernel_args, *field.kernel_args, out):
        raise ValueError(f"q must be finite (no NaN or inf); got {q}")
    return out.reshape(shape + (DOF,))
