"""Independent references for the overlap ratio (paper-notes §2.4): the polytope-library recipe (scipy's
LP + half-space intersection + convex hull) and Monte Carlo. Slow; the tests compare the compiled
``overlap_ratio`` against both."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.geometry.frustum import Frustum
from continuum_gym.geometry.overlap import ROTATION_TOL, resolve_frustum
from continuum_gym.validation import as_rotations, as_vectors

#: Chebyshev radius (m) below which the reference treats the intersection as empty (paper-notes §2.4).
REFERENCE_MIN_RADIUS = 1e-10


def _pose(p, R, name_p: str, name_R: str) -> tuple[np.ndarray, np.ndarray]:
    """One camera pose: p (3,), R (3, 3) finite proper rotation, else ValueError naming the argument."""
    p = as_vectors(p, 3, name_p)
    R = as_rotations(R, name_R)
    if p.shape != (3,):
        raise ValueError(f"{name_p} must have shape (3,) (one pose); got shape {p.shape}")
    if R.shape != (3, 3):
        raise ValueError(f"{name_R} must have shape (3, 3) (one pose); got shape {R.shape}")
    if np.max(np.abs(R.T @ R - np.eye(3))) > ROTATION_TOL or np.linalg.det(R) <= 0.0:
        raise ValueError(
            f"{name_R} must be a rotation matrix (max |R^T R - I| <= {ROTATION_TOL:g}, det R > 0)"
        )
    return p, R


def overlap_ratio_reference(p_a: ArrayLike, R_a: ArrayLike, p_b: ArrayLike, R_b: ArrayLike,
                            frustum: Frustum | None = None) -> float:
    """OR of one pair by the polytope-library recipe of paper-notes §2.4 (slow; the test reference).

    Stacks the 12 world half-spaces A x + b <= 0, finds the Chebyshev centre with
    ``scipy.optimize.linprog`` (HiGHS): maximise s s.t. a_iᵀx + s‖a_i‖ <= −b_i, s >= 0. OR = 0 if
    the LP is infeasible or s < 1e-10 m; otherwise ``HalfspaceIntersection`` from that centre and
    ``ConvexHull(intersections).volume / frustum.volume``.
    """
    from scipy.optimize import linprog
    from scipy.spatial import ConvexHull, HalfspaceIntersection

    frustum = resolve_frustum(frustum)
    p_a, R_a = _pose(p_a, R_a, "p_a", "R_a")
    p_b, R_b = _pose(p_b, R_b, "p_b", "R_b")
    halfspaces = np.concatenate([frustum.halfspaces(p_a, R_a), frustum.halfspaces(p_b, R_b)])
    A, b = halfspaces[:, :3], halfspaces[:, 3]
    norms = np.linalg.norm(A, axis=1)
    result = linprog(
        c=[0.0, 0.0, 0.0, -1.0],
        A_ub=np.column_stack([A, norms]),
        b_ub=-b,
        bounds=[(None, None)] * 3 + [(0.0, None)],
        method="highs",
    )
    if result.status != 0 or result.x[3] < REFERENCE_MIN_RADIUS:
        return 0.0
    intersection = HalfspaceIntersection(halfspaces, result.x[:3])
    return float(ConvexHull(intersection.intersections).volume / frustum.volume)


def overlap_ratio_monte_carlo(p_a: ArrayLike, R_a: ArrayLike, p_b: ArrayLike, R_b: ArrayLike, n_samples: int,
                              rng: np.random.Generator | int | None, frustum: Frustum | None = None) -> float:
    """Monte-Carlo OR: the fraction of ``n_samples`` uniform samples of F_a that lie inside F_b.

    ``rng`` is a ``numpy.random.Generator`` or a seed. Standard error ≈ sqrt(OR (1 − OR) / n_samples).
    """
    frustum = resolve_frustum(frustum)
    p_a, R_a = _pose(p_a, R_a, "p_a", "R_a")
    p_b, R_b = _pose(p_b, R_b, "p_b", "R_b")
    if isinstance(n_samples, (bool, np.bool_)) or not isinstance(n_samples, (int, np.integer)) or n_samples < 1:
        raise ValueError(f"n_samples must be an integer >= 1; got {n_samples!r}")
    samples_a = frustum.sample_uniform(int(n_samples), rng)
    w_x = p_a + samples_a @ R_a.T
    halfspaces_b = frustum.halfspaces(p_b, R_b)
    inside = np.all(w_x @ halfspaces_b[:, :3].T + halfspaces_b[:, 3] <= 0.0, axis=1)
    return float(np.mean(inside))
