"""Repulsive force field of the view cone and the gradient of the potential Pi (paper 000, eqs 12, 18-19).

f = f* (r*/r)^q (1 - d/d_0)^(2p) f_hat for d <= d_0 and r >= 0, else 0 (eq 18 with p = 1, q = 2 from
Fig. 2-b, paper-notes §1.3 item 8); f_hat = grad d, the outward normal (eq 19). The formula is singular at
the vertex (r -> 0) and directionless on the axis (rho = 0): both return zero force.
grad Pi = grad E - sum_i Jv_i^T f_i (eq 12, paper-notes §1.3 item 5).
"""

from __future__ import annotations

import math
from collections import namedtuple
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.geometry.lens_cone import (
    LensCone,
    cone_distance_slant_cs,
    lens_to_world_direction_cs,
    points_and_gamma,
    resolve_cone,
    to_lens_cs,
)
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.mbcr import PAPER_PSPS, MultiBackboneRobot
from continuum_gym.robots.mbcr_kernels import all_finite, fill_frames, make_workspace, points_kernel_framed
from continuum_gym.validation import as_finite, positive

#: What the force kernels read: d0 (m), r_star (m), f_star (N), the exponents p, q of eq (18), and whether q
#: and 2p are 2 (flags of their own, see ``pow_as_libm``).
FieldKernelArgs = namedtuple("FieldKernelArgs", ["d0", "r_star", "f_star", "p", "q", "q_is_two", "two_p_is_two"])

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

    def __post_init__(self) -> None:
        positive(self.d0, "d0", "m")
        positive(self.r_star, "r_star", "m")
        positive(self.f_star, "f_star", "N")
        positive(self.p, "p", "-")
        positive(self.q, "q", "-")
        p, q = float(self.p), float(self.q)
        # The flags are the kernel's own exponents (q and 2p) compared with 2, in the same double arithmetic.
        object.__setattr__(self, "_kernel_args", FieldKernelArgs(float(self.d0), float(self.r_star),
                                                                 float(self.f_star), p, q, q == 2.0, 2.0 * p == 2.0))

    def kernel_args(self) -> FieldKernelArgs:
        """(d0, r_star, f_star, p, q, q == 2, 2p == 2): the bundle the force kernels read."""
        return self._kernel_args  # type: ignore[attr-defined]  # set in __post_init__ (not a dataclass field)


DEFAULT_FIELD = ForceField()


def resolve_field(field: ForceField | None) -> ForceField:
    if field is None:
        return DEFAULT_FIELD
    if not isinstance(field, ForceField):
        raise ValueError(f"field must be a ForceField or None; got {type(field).__name__}")
    return field


@kernel
def force_kernel(px, py, pz, gamma, cone, field):
    """World force (N) on one point (m): eq (18)-(19) with paper-notes §1.3 item 8. Returns (fx, fy, fz).

    ``cone`` and ``field`` are the ``kernel_args()`` of a ``LensCone`` and a ``ForceField``.
    """
    return force_kernel_cs(px, py, pz, math.cos(gamma), math.sin(gamma), math.cos(cone.alpha), math.sin(cone.alpha),
                           math.cos(cone.beta), math.sin(cone.beta), cone, field)


# Veltkamp's splitting constant, 2^27 + 1: x = xh + xl with halves whose products are exact.
SPLIT = 134217729.0
# The square is returned without calling pow when its exact value lies within this share of half an ulp of
# the rounded product. glibc's pow (>= 2.28; its source gives 0.54 ulp as the worst case over all x, y) can
# then round only to that same product, which needs a share under 0.92 (measured here: no difference up
# to 0.98 in 4e7 samples, 2,531 differences at 0.995).
SQUARE_SAFE_SHARE = 0.9


@kernel(inline="always")
def exact_square(x):
    """(hi, lo): hi = x * x rounded, and hi + lo = x² exactly (Dekker's product; for 1e-140 < |x| < 1e140)."""
    hi = x * x
    c = SPLIT * x
    xh = c - (c - x)
    xl = x - xh
    return hi, ((xh * xh - hi) + 2.0 * xh * xl) + xl * xl


@kernel(inline="always")
def pow_as_libm(x, y, y_is_two):
    """``x ** y`` (x >= 0) to the bit as libm's pow returns it, nine calls in ten spared for y = 2.

    The paper's field has q = 2 and 2p = 2, and pow, called twice per point subject to potential at every
    substep, is a large share of an OcclusionAvoidance step. A correctly
    rounded x * x differs from pow(x, 2.0) in about 1 case in 1,200 (glibc's pow is not correctly rounded),
    and every last-bit change grows along a closed-loop trajectory, so x * x alone would change results.
    Here the exact square hi + lo (Dekker's product: exact for 1e-140 < x < 1e140) decides: when lo is
    under 0.45 ulp of hi, a pow within 0.54 ulp of x² must return hi too; otherwise pow itself is called.
    With a C library whose pow errs by more, the fast path still returns the correctly rounded square,
    which that pow might not (this platform's golden files and tests pin glibc's behaviour).

    ``y_is_two`` must be ``y == 2.0``, computed by the caller outside the compiled code: tested here, the
    compiler would know y == 2 wherever pow is called for y = 2, turn pow(x, 2.0) into x * x, and change the
    bits (LLVM does so after unswitching a loop on the test).
    """
    if y_is_two and 1e-140 < x < 1e140:
        hi, lo = exact_square(x)
        # hi + t rounds back to hi exactly when |t| is under half an ulp of hi (a quarter below a power of
        # two, which only makes the test stricter): so this holds when |lo| < 0.45 ulp.
        if hi + lo * (1.0 / SQUARE_SAFE_SHARE) == hi:
            return hi
    return x ** y


@kernel(inline="always")
def force_kernel_cs(px, py, pz, cg, sg, ca, sa, cb, sb, cone, field):
    """``force_kernel`` with cos/sin of gamma, alpha and beta precomputed: the same for every point of a robot."""
    xl, yl, zl = to_lens_cs(px, py, pz, cg, sg, ca, sa, cone.d_o, cone.model)
    d, r, rho = cone_distance_slant_cs(xl, yl, zl, cb, sb)
    if d > field.d0 or r < VERTEX_EPS or rho < AXIS_EPS:
        return 0.0, 0.0, 0.0
    magnitude = (field.f_star * pow_as_libm(field.r_star / r, field.q, field.q_is_two)
                 * pow_as_libm(1.0 - d / field.d0, 2.0 * field.p, field.two_p_is_two))
    fx, fy, fz = lens_to_world_direction_cs(xl * cb / rho, yl * cb / rho, -sb, cg, sg, ca, sa)
    return magnitude * fx, magnitude * fy, magnitude * fz


@kernel
def potential_gradient_kernel(q, robot, ws, segments, fractions, P, JV, gamma, cone, field, grad):
    """grad Pi (eq 12) for one q into ``grad`` (dof,); P, JV are (m, 3), (m, 3, dof) scratch."""
    fill_frames(q, robot, ws)
    potential_gradient_framed(q, robot, ws, segments, fractions, P, JV, gamma, cone, field, grad)


@kernel(inline="always")
def potential_gradient_framed(q, robot, ws, segments, fractions, P, JV, gamma, cone, field, grad):
    """``potential_gradient_kernel`` with the ``frames`` of q already in ws (``tip_kernel`` leaves it)."""
    points_kernel_framed(q, robot, ws, segments, fractions, P, JV)
    dof = q.shape[0]
    for k in range(dof):
        grad[k] = 0.0
    for j in range(robot.lengths.shape[0]):
        grad[2 * j] = -robot.stiffness[j] * (0.5 * math.pi - q[2 * j])
    cg, sg = math.cos(gamma), math.sin(gamma)
    ca, sa = math.cos(cone.alpha), math.sin(cone.alpha)
    cb, sb = math.cos(cone.beta), math.sin(cone.beta)
    for i in range(segments.shape[0]):
        fx, fy, fz = force_kernel_cs(P[i, 0], P[i, 1], P[i, 2], cg, sg, ca, sa, cb, sb, cone, field)
        if fx == 0.0 and fy == 0.0 and fz == 0.0:
            continue
        for k in range(dof):
            grad[k] -= JV[i, 0, k] * fx + JV[i, 1, k] * fy + JV[i, 2, k] * fz


@kernel
def _potential_gradient_batch(qs, G, robot, segments, fractions, cone, field, out):
    if not all_finite(qs):
        return False
    ws = make_workspace(robot.lengths.shape[0])
    m = segments.shape[0]
    P = np.empty((m, 3))
    JV = np.empty((m, 3, qs.shape[1]))
    for i in range(qs.shape[0]):
        potential_gradient_kernel(qs[i], robot, ws, segments, fractions, P, JV, G[i], cone, field, out[i])
    return True


@kernel
def _force_batch(P, G, cone, field, out):
    for i in range(P.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = force_kernel(P[i, 0], P[i, 1], P[i, 2], G[i], cone, field)


def repulsive_force(points: ArrayLike, gamma: ArrayLike, cone: LensCone | None = None,
                    field: ForceField | None = None) -> np.ndarray:
    """Force (N) of eq (18) on world points (..., 3) in m, in {w}; gamma (rad) broadcasts."""
    cone = resolve_cone(cone)
    field = resolve_field(field)
    P, G, shape = points_and_gamma(points, gamma)
    out = np.empty((P.shape[0], 3))
    _force_batch(P, G, cone.kernel_args(), field.kernel_args(), out)
    return out.reshape(shape + (3,))


def potential_gradient(robot: MultiBackboneRobot, q: ArrayLike, gamma: ArrayLike, cone: LensCone | None = None,
                       field: ForceField | None = None,
                       psps: Sequence[tuple[int, float]] = PAPER_PSPS) -> np.ndarray:
    """grad Pi = grad E - sum_i Jv_i^T f_i (eq 12) over the points subject to potential, shape (..., dof).

    Args:
        robot: a ``MultiBackboneRobot``.
        q: configuration(s) (..., dof): rad, and m for q_ins.
        gamma: endoscope rotation (rad), broadcasts with q[..., 0].
        cone, field: ``LensCone`` and ``ForceField`` (None: the paper's).
        psps: (segment, arc fraction) pairs; default the paper's 10 (paper-notes §1.5).
    """
    if not isinstance(robot, MultiBackboneRobot):
        raise ValueError(f"robot must be a MultiBackboneRobot; got {type(robot).__name__}")
    cone = resolve_cone(cone)
    field = resolve_field(field)
    q = robot.as_configuration(q)
    gamma = as_finite(gamma, (), "gamma")
    try:
        shape = np.broadcast_shapes(q.shape[:-1], gamma.shape)
    except ValueError:
        raise ValueError(f"gamma of shape {gamma.shape} does not broadcast with q of shape {q.shape}") from None
    dof = robot.dof
    Q = np.ascontiguousarray(np.broadcast_to(q, shape + (dof,)).reshape(-1, dof))
    G = np.ascontiguousarray(np.broadcast_to(gamma, shape).reshape(-1))
    segments, fractions = robot.point_spec(psps)
    out = np.empty((Q.shape[0], dof))
    if not _potential_gradient_batch(Q, G, robot.kernel_args(), segments, fractions, cone.kernel_args(),
                                     field.kernel_args(), out):
        raise ValueError(f"q must be finite (no NaN or inf); got {q}")
    return out.reshape(shape + (dof,))
