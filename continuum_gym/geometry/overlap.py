"""Overlap ratio of two camera frustums, OR = vol(F_a ∩ F_b) / vol(F_a) (Deng–Xu, paper-notes §2.4).

Three implementations of the same number:

* :func:`overlap_ratio` — exact, batched, compiled (numba): the divergence theorem over the faces of
  both frustums, each clipped by the other's half-spaces (``overlap_clipping``, whose docstring says how
  coplanar and nearly coplanar faces stay exact).
* ``overlap_reference.overlap_ratio_reference`` — the polytope-library recipe of paper-notes §2.4 (scipy: Chebyshev
  centre by ``linprog``/HiGHS, ``HalfspaceIntersection``, ``ConvexHull``); one pair, slow; the
  test reference.
* ``overlap_reference.overlap_ratio_monte_carlo`` — fraction of uniform samples of F_a inside F_b.

The two references (scipy, slow) live in their own module, which builds on this one and loads only
when a test or a user asks for it (``continuum_gym.geometry`` exports all three).

:func:`overlap_ratio_nb` is the compiled per-pair kernel without input checks, callable from other
numba kernels (e.g. a whole environment step).
"""

from __future__ import annotations

import threading

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.geometry.frustum import Frustum
from continuum_gym.geometry.overlap_clipping import (  # noqa: F401  (used below; also importable from this module)
    COPLANAR_NORMAL_TOL,
    COPLANAR_OFFSET_TOL,
    OverlapWork,
    local_geometry,
    make_overlap_work,
    overlap_pair,
    overlap_ratio_in,
    overlap_ratio_nb,
)
from continuum_gym.robots.compiled import kernel

__all__ = [
    "overlap_ratio",
    "overlap_ratio_nb",
    "overlap_ratio_in",
    "make_overlap_work",
    "OverlapWork",
]

#: Rotation matrices must satisfy max |RᵀR − I| <= ROTATION_TOL and det R > 0.
ROTATION_TOL = 1e-6

_DEFAULT_FRUSTUM = Frustum()

# Error codes returned by the compiled checks (argument, problem).
_ERRORS = {
    1: ("p_a", "must be finite (no NaN or inf)"),
    2: ("R_a", "must be finite (no NaN or inf)"),
    3: ("R_a", f"must be a rotation matrix (max |R^T R - I| <= {ROTATION_TOL:g}, det R > 0)"),
    4: ("p_b", "must be finite (no NaN or inf)"),
    5: ("R_b", "must be finite (no NaN or inf)"),
    6: ("R_b", f"must be a rotation matrix (max |R^T R - I| <= {ROTATION_TOL:g}, det R > 0)"),
}


# ----------------------------------------------------------------------------------------------
# compiled input checks and the Python API's entry points
# ----------------------------------------------------------------------------------------------
@kernel
def _check_pose(p, R):
    """0 if p and R are finite and R is a proper rotation; 1 bad p; 2 non-finite R; 3 not a rotation."""
    for i in range(3):
        if not np.isfinite(p[i]):
            return 1
    for i in range(3):
        for j in range(3):
            if not np.isfinite(R[i, j]):
                return 2
    for i in range(3):
        for j in range(3):
            g = R[0, i] * R[0, j] + R[1, i] * R[1, j] + R[2, i] * R[2, j]
            if i == j:
                g -= 1.0
            if abs(g) > ROTATION_TOL:
                return 3
    det = (
        R[0, 0] * (R[1, 1] * R[2, 2] - R[1, 2] * R[2, 1])
        - R[0, 1] * (R[1, 0] * R[2, 2] - R[1, 2] * R[2, 0])
        + R[0, 2] * (R[1, 0] * R[2, 1] - R[1, 1] * R[2, 0])
    )
    if det <= 0.0:
        return 3
    return 0


_SINGLE_SIGNATURE = "float64(float64[::1], float64[:, ::1], float64[::1], float64[:, ::1], float64, float64, float64)"
_BATCH_SIGNATURE = (
    "Tuple((int64, int64))(float64[:, ::1], float64[:, :, ::1], float64[:, ::1], float64[:, :, ::1], "
    "float64, float64, float64, float64[::1])"
)


def _compiled(dispatcher, signature: str):
    """``dispatcher`` compiled for ``signature`` (C-contiguous writable float64 arrays) and closed to any other.

    So unusual inputs (views, read-only arrays) never trigger new compilations. On first use, not at
    import (as a signature in the decorator would): an OcclusionAvoidance user never pays its ~4.6 s of
    compiling on an empty cache. The callers keep the result in a module global (a function call per
    pair would be ~5 % of a single pair's ~2 us).
    """
    with _COMPILE_LOCK:  # two threads' first calls: one compiles, the other finds it compiled
        if not dispatcher.signatures:
            dispatcher.compile(signature)
            dispatcher.disable_compile()
    return dispatcher


_COMPILE_LOCK = threading.Lock()
_single_kernel = None
_batch_kernel = None


@kernel
def _overlap_single(p_a, R_a, p_b, R_b, tan_half, near, far):
    """OR of one pair, or −(error code) if an input is invalid."""
    code = _check_pose(p_a, R_a)
    if code != 0:
        return -float(code)
    code = _check_pose(p_b, R_b)
    if code != 0:
        return -float(code + 3)
    return overlap_ratio_nb(p_a, R_a, p_b, R_b, tan_half, near, far)


@kernel
def _overlap_batch(p_a, R_a, p_b, R_b, tan_half, near, far, out):
    """OR of N pairs (p: (N, 3), R: (N, 3, 3)) into out (N,); returns (error code, index) or (0, -1)."""
    n = out.shape[0]
    for k in range(n):
        code = _check_pose(p_a[k], R_a[k])
        if code != 0:
            return code, k
        code = _check_pose(p_b[k], R_b[k])
        if code != 0:
            return code + 3, k
    # The work's arrays as locals: a bundle's array read inside the loop costs an atomic reference count
    # per read (~7 % of this loop if they are read there).
    lv, lh, vb, hb, cut, poly, dist = make_overlap_work()
    local_geometry(tan_half, near, far, lv, lh)  # once: the frustum is the same for every pair
    for k in range(n):
        out[k] = overlap_pair(p_a[k], R_a[k], p_b[k], R_b[k], tan_half, near, far, lv, lh, vb, hb, cut, poly, dist)
    return 0, -1


# ----------------------------------------------------------------------------------------------
# Python API
# ----------------------------------------------------------------------------------------------
def resolve_frustum(frustum: Frustum | None) -> Frustum:
    """``frustum``, or the paper's frustum for None (ValueError for anything else)."""
    if frustum is None:
        return _DEFAULT_FRUSTUM
    if not isinstance(frustum, Frustum):
        raise ValueError(f"frustum must be a Frustum or None; got {type(frustum).__name__}")
    return frustum


def _float_array(x, name: str) -> np.ndarray:
    if type(x) is np.ndarray and x.dtype == np.float64:
        return x
    try:
        return np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name} must be a numeric array; got {x!r}") from error


def _raise(code: int, index=None) -> None:
    name, problem = _ERRORS[int(code)]
    where = "" if index is None else f" (at flattened batch index {index})"
    raise ValueError(f"{name} {problem}{where}")


def overlap_ratio(p_a: ArrayLike, R_a: ArrayLike, p_b: ArrayLike, R_b: ArrayLike,
                  frustum: Frustum | None = None) -> np.ndarray:
    """Exact overlap ratio OR = vol(F_a ∩ F_b) / vol(F_a) of two camera frustums (paper-notes §2.4).

    Args:
        p_a, p_b: camera positions in {w} (m), shape (..., 3).
        R_a, R_b: camera rotations ^wR_cam, shape (..., 3, 3); z is the viewing axis.
        frustum: shared frustum shape; ``None`` means ``Frustum()`` (90°, 30 mm, 120 mm).

    Returns:
        float64 array with the batch shapes of the four inputs broadcast together (a 0-d array for
        one pair), values in [0, 1].

    Raises:
        ValueError: naming the argument, for wrong shapes, NaN/inf, non-rotations or
        non-broadcastable batch shapes.
    """
    global _single_kernel, _batch_kernel
    frustum = resolve_frustum(frustum)
    p_a = _float_array(p_a, "p_a")
    R_a = _float_array(R_a, "R_a")
    p_b = _float_array(p_b, "p_b")
    R_b = _float_array(R_b, "R_b")
    if p_a.shape == (3,) and p_b.shape == (3,) and R_a.shape == (3, 3) and R_b.shape == (3, 3):
        single = _single_kernel
        if single is None:
            single = _single_kernel = _compiled(_overlap_single, _SINGLE_SIGNATURE)
        try:
            value = single(p_a, R_a, p_b, R_b, frustum.tan_half, frustum.near, frustum.far)
        except TypeError:  # views or read-only arrays: the kernel takes C-contiguous writable arrays
            value = single(
                np.array(p_a, order="C"), np.array(R_a, order="C"), np.array(p_b, order="C"),
                np.array(R_b, order="C"), frustum.tan_half, frustum.near, frustum.far,
            )
        if value < 0.0:
            _raise(-value)
        return np.array(value)
    for name, array in (("p_a", p_a), ("p_b", p_b)):
        if array.ndim < 1 or array.shape[-1] != 3:
            raise ValueError(f"{name} must have shape (..., 3); got shape {array.shape}")
    for name, array in (("R_a", R_a), ("R_b", R_b)):
        if array.ndim < 2 or array.shape[-2:] != (3, 3):
            raise ValueError(f"{name} must have shape (..., 3, 3); got shape {array.shape}")
    try:
        batch = np.broadcast_shapes(p_a.shape[:-1], R_a.shape[:-2], p_b.shape[:-1], R_b.shape[:-2])
    except ValueError as error:
        raise ValueError(
            "batch shapes of p_a, R_a, p_b, R_b do not broadcast: "
            f"{p_a.shape[:-1]}, {R_a.shape[:-2]}, {p_b.shape[:-1]}, {R_b.shape[:-2]}"
        ) from error
    n = int(np.prod(batch))

    def flat(array, tail):  # a fresh C-contiguous writable (n, *tail) copy
        return np.array(np.broadcast_to(array, batch + tail), order="C").reshape((n,) + tail)

    out = np.empty(n)
    batch_kernel = _batch_kernel
    if batch_kernel is None:
        batch_kernel = _batch_kernel = _compiled(_overlap_batch, _BATCH_SIGNATURE)
    code, index = batch_kernel(
        flat(p_a, (3,)), flat(R_a, (3, 3)), flat(p_b, (3,)), flat(R_b, (3, 3)),
        frustum.tan_half, frustum.near, frustum.far, out,
    )
    if code != 0:
        _raise(code, index)
    return out.reshape(batch)

