"""Field-of-view cone of the rotating angled-lens endoscope of Sarli & Simaan (paper 000).

The lens frame is {lens} with ^{lens}R_w = Ry(alpha) Rz(-gamma) (eq 15). Two readings of the lens
origin (paper-notes §1.3 item 7), equal at gamma = 0:

- ``"literal"`` (default, as printed): x_l = ^{lens}R_w p + [0, -d_o, 0]; the view orbits z_w with gamma.
- ``"physical"``: the endoscope spins about its own shaft through [0, d_o, 0]:
  x_l = ^{lens}R_w (p - [0, d_o, 0]).

Canonical distance d (< 0 inside) and slant height r of a point are eqs (16)-(17); the centre
distance d_c of the tip and its gamma-derivative are eq (25) as paper-notes §1.3 item 10 reads it.
"""

from __future__ import annotations

import math
from collections import namedtuple
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.robots.compiled import kernel
from continuum_gym.validation import (
    angle_in_open_interval,
    as_finite,
    as_vectors,
    choice,
    positive,
)

LENS_MODELS = ("literal", "physical")
#: What the cone kernels read: channel offset d_o (m), lens tilt alpha and half-angle beta (rad), and the
#: lens model code (0 literal, 1 physical).
ConeKernelArgs = namedtuple("ConeKernelArgs", ["d_o", "alpha", "beta", "model"])


@dataclass(frozen=True)
class LensCone:
    """Parameters of the endoscope's view cone (Table I of paper 000, SI).

    Args:
        d_o: centre distance between robot and endoscope channels (m), 4.47 mm.
        alpha: lens inclination angle (rad), 30 degrees; in (0, pi/2).
        beta: cone half-angle (rad), 27.5 degrees; in (0, pi/2).
        lens_model: ``"literal"`` or ``"physical"`` (paper-notes §1.3 item 7).
    """

    d_o: float = 4.47e-3
    alpha: float = math.radians(30.0)
    beta: float = math.radians(27.5)
    lens_model: str = "literal"

    def __post_init__(self) -> None:
        object.__setattr__(self, "d_o", positive(self.d_o, "d_o", "m"))
        object.__setattr__(self, "alpha", angle_in_open_interval(self.alpha, "alpha", 0.0, math.pi / 2, "(0, pi/2)"))
        object.__setattr__(self, "beta", angle_in_open_interval(self.beta, "beta", 0.0, math.pi / 2, "(0, pi/2)"))
        choice(self.lens_model, LENS_MODELS, "lens_model")
        object.__setattr__(self, "_kernel_args", ConeKernelArgs(self.d_o, self.alpha, self.beta, self.model_code))

    @property
    def model_code(self) -> int:
        """0 for literal, 1 for physical (what the compiled kernels take)."""
        return LENS_MODELS.index(self.lens_model)

    def kernel_args(self) -> ConeKernelArgs:
        """(d_o, alpha, beta, model): the bundle every cone kernel reads."""
        return self._kernel_args  # type: ignore[attr-defined]  # set in __post_init__ (not a dataclass field)

    def to_dict(self) -> dict:
        """The constructor arguments as plain YAML/JSON values (m, rad)."""
        return {"d_o": self.d_o, "alpha": self.alpha, "beta": self.beta, "lens_model": self.lens_model}


DEFAULT_CONE = LensCone()


def resolve_cone(cone: LensCone | None) -> LensCone:
    """``None`` means the paper's cone; anything else must be a ``LensCone``."""
    if cone is None:
        return DEFAULT_CONE
    if not isinstance(cone, LensCone):
        raise ValueError(f"cone must be a LensCone or None; got {type(cone).__name__}")
    return cone


# ---------------------------------------------------------------------- compiled kernels
@kernel(inline="always")
def to_lens_cs(px, py, pz, cg, sg, ca, sa, d_o, model):
    """``to_lens`` with cos/sin of gamma and alpha precomputed (for loops over many points)."""
    if model == 1:
        py = py - d_o
    # Rz(-gamma) then Ry(alpha)
    ux = cg * px + sg * py
    uy = -sg * px + cg * py
    xl = ca * ux + sa * pz
    yl = uy
    zl = -sa * ux + ca * pz
    if model == 0:
        yl -= d_o
    return xl, yl, zl


@kernel(inline="always")
def to_lens(px, py, pz, gamma, d_o, alpha, model):
    """Point (m) from {w} to {lens}: eq (15), both lens models. Returns (x_l, y_l, z_l)."""
    return to_lens_cs(px, py, pz, math.cos(gamma), math.sin(gamma), math.cos(alpha), math.sin(alpha), d_o, model)


@kernel(inline="always")
def lens_to_world_direction(vx, vy, vz, gamma, alpha):
    """Direction from {lens} to {w}: (^{lens}R_w)^T v = Rz(gamma) Ry(-alpha) v."""
    return lens_to_world_direction_cs(vx, vy, vz, math.cos(gamma), math.sin(gamma), math.cos(alpha),
                                      math.sin(alpha))


@kernel(inline="always")
def lens_to_world_direction_cs(vx, vy, vz, cg, sg, ca, sa):
    """``lens_to_world_direction`` with cos/sin of gamma and alpha precomputed."""
    ux = ca * vx - sa * vz
    uz = sa * vx + ca * vz
    return cg * ux - sg * vy, sg * ux + cg * vy, uz


@kernel(inline="always")
def cone_distance_slant(xl, yl, zl, beta):
    """(d, r, rho) of a point in {lens}: eqs (16)-(17); rho = sqrt(x_l^2 + y_l^2)."""
    return cone_distance_slant_cs(xl, yl, zl, math.cos(beta), math.sin(beta))


@kernel(inline="always")
def cone_distance_slant_cs(xl, yl, zl, cb, sb):
    """``cone_distance_slant`` with cos/sin of the half-angle beta precomputed (loops over many points)."""
    rho = math.sqrt(xl * xl + yl * yl)
    return cb * rho - sb * zl, sb * rho + cb * zl, rho


@kernel(inline="always")
def centre_distance_kernel(p, gamma, d_o, alpha, model):
    """(d_c, dd_c/dgamma) of the tip p (m): paper-notes §1.3 item 10 (d_c = rho_ee).

    dx_l/dgamma = -^{lens}R_w (e3 x (p - c)), c = 0 (literal) or [0, d_o, 0] (physical).
    """
    xl, yl, zl = to_lens(p[0], p[1], p[2], gamma, d_o, alpha, model)
    rho = math.sqrt(xl * xl + yl * yl)
    cx = p[0]
    cy = p[1] - d_o if model == 1 else p[1]
    # e3 x (p - c) = (-cy, cx, 0), rotated into {lens} (no offset: it is a direction)
    dx, dy, dz = to_lens(-cy, cx, 0.0, gamma, 0.0, alpha, 0)
    if rho < 1e-15:
        return rho, 0.0
    return rho, -(xl * dx + yl * dy) / rho


@kernel
def _centre_distance_batch(P, G, d_o, alpha, model, dc, grad):
    for i in range(P.shape[0]):
        dc[i], grad[i] = centre_distance_kernel(P[i], G[i], d_o, alpha, model)


@kernel
def _cone_coordinates_batch(P, G, d_o, alpha, beta, model, out):
    for i in range(P.shape[0]):
        xl, yl, zl = to_lens(P[i, 0], P[i, 1], P[i, 2], G[i], d_o, alpha, model)
        d, r, rho = cone_distance_slant(xl, yl, zl, beta)
        out[i, 0] = d
        out[i, 1] = r
        out[i, 2] = math.atan2(rho, zl)
        out[i, 3] = xl
        out[i, 4] = yl
        out[i, 5] = zl


# ---------------------------------------------------------------------- public functions
def points_and_gamma(points: ArrayLike, gamma: ArrayLike) -> tuple[np.ndarray, np.ndarray, tuple]:
    """Validated world points (..., 3) in m and endoscope rotations gamma (rad), broadcast together and
    flattened: (P (n, 3), G (n,), batch shape)."""
    points = as_vectors(points, 3, "points")
    gamma = as_finite(gamma, (), "gamma")
    try:
        shape = np.broadcast_shapes(points.shape[:-1], gamma.shape)
    except ValueError as error:
        raise ValueError(
            f"gamma of shape {gamma.shape} does not broadcast with points of shape {points.shape}") from error
    P = np.ascontiguousarray(np.broadcast_to(points, shape + (3,)).reshape(-1, 3))
    G = np.ascontiguousarray(np.broadcast_to(gamma, shape).reshape(-1))
    return P, G, shape


def cone_coordinates(points: ArrayLike, gamma: ArrayLike, cone: LensCone | None = None) -> dict[str, np.ndarray]:
    """Cone coordinates of world points (m) for endoscope rotation ``gamma`` (rad).

    Returns a dict of arrays of the broadcast shape: ``d`` (m, eq 16, < 0 inside), ``r`` (m, eq 17),
    ``angle`` (rad, angle from the view axis as seen from the cone vertex) and ``lens`` (..., 3),
    the point in {lens} (eq 15).
    """
    cone = resolve_cone(cone)
    P, G, shape = points_and_gamma(points, gamma)
    out = np.empty((P.shape[0], 6))
    _cone_coordinates_batch(P, G, cone.d_o, cone.alpha, cone.beta, cone.model_code, out)
    return {
        "d": out[:, 0].reshape(shape),
        "r": out[:, 1].reshape(shape),
        "angle": out[:, 2].reshape(shape),
        "lens": out[:, 3:6].reshape(shape + (3,)),
    }


def centre_distance(tip: ArrayLike, gamma: ArrayLike, cone: LensCone | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Tip-to-view-axis distance d_c (m, eq 25 read as rho_ee) and dd_c/dgamma (m/rad, paper-notes §1.3 item 10).

    Returns (d_c, dd_c_dgamma), each of the broadcast shape of tip[..., 0] and gamma.
    """
    cone = resolve_cone(cone)
    P, G, shape = points_and_gamma(tip, gamma)
    dc = np.empty(P.shape[0])
    grad = np.empty(P.shape[0])
    _centre_distance_batch(P, G, cone.d_o, cone.alpha, cone.model_code, dc, grad)
    return dc.reshape(shape), grad.reshape(shape)


def view_axis(gamma: ArrayLike, cone: LensCone | None = None) -> np.ndarray:
    """Unit direction (..., 3) of the cone axis in {w}: Rz(gamma) (-sin alpha, 0, cos alpha)."""
    cone = resolve_cone(cone)
    gamma = np.asarray(gamma, dtype=np.float64)
    a = np.array([-math.sin(cone.alpha), 0.0, math.cos(cone.alpha)])
    c, s = np.cos(gamma), np.sin(gamma)
    return np.stack([c * a[0], s * a[0], np.full_like(c, a[2])], axis=-1)


def lens_origin(gamma: ArrayLike, cone: LensCone | None = None) -> np.ndarray:
    """World position (m) of the cone vertex: Rz(gamma)[0, d_o, 0] (literal) or [0, d_o, 0] (physical)."""
    cone = resolve_cone(cone)
    gamma = np.asarray(gamma, dtype=np.float64)
    if cone.lens_model == "physical":
        return np.broadcast_to(np.array([0.0, cone.d_o, 0.0]), gamma.shape + (3,)).copy()
    return np.stack([-np.sin(gamma) * cone.d_o, np.cos(gamma) * cone.d_o, np.zeros_like(gamma)], axis=-1)


def lens_rotation(gamma: ArrayLike, cone: LensCone | None = None) -> np.ndarray:
    """^wR_lens = (Ry(alpha) Rz(-gamma))^T, shape gamma.shape + (3, 3); its z column is ``view_axis``."""
    cone = resolve_cone(cone)
    gamma = np.asarray(gamma, dtype=np.float64)
    c, s = np.cos(gamma), np.sin(gamma)
    ca, sa = math.cos(cone.alpha), math.sin(cone.alpha)
    Rz = np.zeros(gamma.shape + (3, 3))
    Rz[..., 0, 0] = c
    Rz[..., 0, 1] = -s
    Rz[..., 1, 0] = s
    Rz[..., 1, 1] = c
    Rz[..., 2, 2] = 1.0
    Ry_minus = np.array([[ca, 0.0, -sa], [0.0, 1.0, 0.0], [sa, 0.0, ca]])
    return Rz @ Ry_minus
