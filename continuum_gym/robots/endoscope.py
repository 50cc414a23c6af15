"""Two-segment continuum endoscope of Deng, Xu et al. (paper 001), corrected per paper-notes §2.

Configuration ``q = [L0, phi, theta1, delta1, theta2, delta2]`` in SI units: ``L0`` in m (stem
insertion), every angle in rad. ``theta = 0`` is a straight segment (Xu's convention, paper-notes §2.1);
the bending direction of segment t in {tb} is ``(cos delta, -sin delta, 0)``.

Frames (paper Fig. 2c): {w} at the incision; {1b} = {w} translated by ``[0, 0, L0]`` and rotated
``Rz(phi)``; segment 1 from {1b} to {1e}; a rigid multi-lumen cylinder of length ``Lm`` from {1e}
to {2b}; segment 2 from {2b} to {2e}. The camera sits ``Lc`` along ``z_2e`` from {2e} with
``w_R_cam = w_R_2e`` (its z-axis is the viewing axis); the visual target point ct sits
``Lc + Le`` along ``z_2e`` and ``w_R_ct = w_R_2e`` as well.

All lengths are in metres. The kinematics accept any finite ``q``; joint limits are only data.

The hot path (forward kinematics + Jacobian) is one numba kernel (``endoscope_kernels``) that loops
over a flattened batch, so a batched result equals the looped single results bit for bit. Both segments use the
segment terms of ``continuum_gym.robots.segment``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.robots.endoscope_kernels import (  # noqa: F401  (the kernels' names are importable from here too)
    DOF,
    UNUSED_JACOBIAN,
    EndoscopeKernelArgs,
    EndoscopeWorkspace,
    backbone_batch,
    endoscope_kinematics,
    kinematics_batch,
    kinematics_single,
    make_endoscope_workspace,
)
from continuum_gym.robots.segment import (  # noqa: F401  (the segment functions are public here too)
    SERIES_SWITCH,
    bend_rotation,
    bend_terms,
    endoscope_segment_jacobian,
    endoscope_segment_pose,
)
from continuum_gym.validation import (
    as_array,
    as_configuration,
    integer,
    number,
    positive,
)

__all__ = [
    "ContinuumEndoscope",
    "EndoscopeKernelArgs",
    "EndoscopeWorkspace",
    "SERIES_THRESHOLD",
    "endoscope_kinematics",
    "endoscope_segment_pose",
    "endoscope_segment_jacobian",
    "make_endoscope_workspace",
]

#: |theta| below which the series of paper-notes §2.2 replace the closed forms of eqs (3), (5).
SERIES_THRESHOLD = SERIES_SWITCH

# ----------------------------------------------------------------------------------------------
# Robot class
# ----------------------------------------------------------------------------------------------
#: Table II / paper-notes §2.1 joint limits: L0 in [0, 0.1] m, phi in [-pi, pi] (hard), theta1 in
#: [0, pi/4], theta2 in [0, pi/2]; the deltas are unlimited (wrapped by the controllers).
PAPER_LOWER = (0.0, -math.pi, 0.0, -math.inf, 0.0, -math.inf)
PAPER_UPPER = (0.100, math.pi, math.pi / 4, math.inf, math.pi / 2, math.inf)
#: Physical ranges a user's limits must stay in: insertion 0-0.5 m, |phi| <= pi, bends 0-pi.
_LIMIT_RANGES = ((0.0, 0.5, "m"), (-math.pi, math.pi, "rad"), (0.0, math.pi, "rad"), (-math.inf, math.inf, "rad"),
                 (0.0, math.pi, "rad"), (-math.inf, math.inf, "rad"))


def _read_only(values) -> np.ndarray:
    array = np.array(values, dtype=float)
    array.flags.writeable = False
    return array


class ContinuumEndoscope:
    """6-DoF two-segment continuum endoscope (paper 001, Fig. 2c, Table II; paper-notes §2).

    Parameters (all lengths in m, each must be finite and > 0):
        L1: length of segment 1 (default 0.020).
        Lm: length of the rigid multi-lumen cylinder between the segments (default 0.006).
        L2: length of segment 2 (default 0.030).
        Lc: camera offset along z_2e from the end of segment 2 (default 0.020).
        Le: effective view distance, camera to target point ct (default 0.120).
        joint_limits: ``(lower, upper)``, each 6 values [L0 (m), phi, theta1, delta1, theta2, delta2 (rad)];
            ``None`` is Table II's. L0 within [0, 0.5] m, phi within [-pi, pi], bends within [0, pi];
            the deltas may be +-inf (unlimited, wrapped).

    ``q = [L0 (m), phi, theta1, delta1, theta2, delta2 (rad)]``; every method accepts shape (6,)
    or (..., 6) and returns matching leading dimensions.
    """

    dof = DOF
    joint_names = ("L0", "phi", "theta1", "delta1", "theta2", "delta2")

    def __init__(self, L1: float = 0.020, Lm: float = 0.006, L2: float = 0.030, Lc: float = 0.020,
                 Le: float = 0.120, joint_limits: Sequence[ArrayLike] | None = None) -> None:
        self._args = EndoscopeKernelArgs(positive(L1, "L1", "m"), positive(Lm, "Lm", "m"), positive(L2, "L2", "m"),
                                         positive(Lc, "Lc", "m"), positive(Le, "Le", "m"))
        self._geom = _read_only(self._args)
        lower: tuple[float, ...] | np.ndarray
        upper: tuple[float, ...] | np.ndarray
        if joint_limits is None:
            lower, upper = PAPER_LOWER, PAPER_UPPER
        else:
            try:
                given_lower, given_upper = joint_limits
            except (TypeError, ValueError):
                raise ValueError("joint_limits must be (lower, upper), each 6 values [L0 (m), phi, theta1, delta1, "
                                 f"theta2, delta2 (rad)]; got {joint_limits!r}") from None
            lower = as_array(given_lower, "joint_limits lower", (6,)).reshape(6)
            upper = as_array(given_upper, "joint_limits upper", (6,)).reshape(6)
            for k, (lo, hi, unit) in enumerate(_LIMIT_RANGES):
                name = self.joint_names[k]
                for side, value in (("lower", lower[k]), ("upper", upper[k])):
                    if math.isfinite(lo) or math.isfinite(value):  # only the deltas may be unlimited (+-inf)
                        number(value, f"joint_limits {side} {name}", low=lo, high=hi, unit=unit)
                if math.isnan(lower[k]) or math.isnan(upper[k]) or not lower[k] < upper[k]:
                    raise ValueError(f"joint_limits: lower {name} must be < upper {name}; got {lower[k]} and "
                                     f"{upper[k]}")
        self._lower = _read_only(lower)
        self._upper = _read_only(upper)

    # -- parameters ---------------------------------------------------------------------------
    L1 = property(lambda self: self._args.L1, doc="Segment 1 length (m).")
    Lm = property(lambda self: self._args.Lm, doc="Rigid cylinder length (m).")
    L2 = property(lambda self: self._args.L2, doc="Segment 2 length (m).")
    Lc = property(lambda self: self._args.Lc, doc="Camera offset from the end of segment 2 (m).")
    Le = property(lambda self: self._args.Le, doc="View distance camera -> target point (m).")

    def kernel_args(self) -> EndoscopeKernelArgs:
        """(L1, Lm, L2, Lc, Le) in m: the bundle ``endoscope_kinematics`` and the controllers' kernels read."""
        return self._args

    @property
    def geometry(self) -> np.ndarray:
        """Read-only float64 array ``[L1, Lm, L2, Lc, Le]`` (m)."""
        return self._geom

    @property
    def joint_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)``, each shape (6,): L0 in m, angles in rad; deltas may be +-inf. Fresh copies."""
        return self._lower.copy(), self._upper.copy()

    # -- named configurations -----------------------------------------------------------------
    @property
    def straight(self) -> np.ndarray:
        """All zeros: stem not inserted (L0 = 0 m), both segments straight."""
        return np.zeros(DOF)

    @property
    def case_study_start(self) -> np.ndarray:
        """Psi0 of the case studies (paper-notes §2.1): [0.008 m, 0, 0.3857, -1.57, 0.7828, 1.57]."""
        return np.array([0.008, 0.0, 0.3857, -1.57, 0.7828, 1.57])

    home = case_study_start

    @property
    def named_configurations(self) -> dict:
        """``{"straight": ..., "home": ..., "case_study_start": ...}`` (fresh arrays)."""
        return {"straight": self.straight, "home": self.home, "case_study_start": self.case_study_start}

    # -- kinematics ----------------------------------------------------------------------------
    def _run(self, q: ArrayLike, with_jacobian):
        """reshape -> kernel -> reshape: ``(p_cam, w_R_cam, p_ct, J or None)`` with q's leading shape."""
        if type(q) is np.ndarray and q.shape == (DOF,) and q.dtype == np.float64 and q.flags.c_contiguous:
            # one configuration, already in the kernel's layout: the controllers' per-step call
            p_cam, w_R_cam, p_ct = np.empty(3), np.empty((3, 3)), np.empty(3)
            J = np.empty((6, 6)) if with_jacobian else UNUSED_JACOBIAN[0]
            try:
                kinematics_single(q, *self._args, p_cam, w_R_cam, p_ct, J, with_jacobian)
            except ValueError:
                as_configuration(q, DOF)  # raises "q must be finite ..."
                raise
            return p_cam, w_R_cam, p_ct, (J if with_jacobian else None)
        array = np.ascontiguousarray(as_array(q, "q", (DOF,)))
        if array.ndim == 0:
            raise ValueError(f"q must have shape (..., {DOF}); got a scalar")
        lead = array.shape[:-1]
        n = math.prod(lead)  # np.prod of an empty shape costs 4 us
        p_cam = np.empty((n, 3))
        w_R_cam = np.empty((n, 3, 3))
        p_ct = np.empty((n, 3))
        J = np.empty((n, 6, 6)) if with_jacobian else UNUSED_JACOBIAN
        try:
            kinematics_batch(array.reshape(-1, DOF), self._args, p_cam, w_R_cam, p_ct, J, with_jacobian)
        except ValueError:
            as_configuration(array, DOF)  # raises "q must be finite ..."
            raise
        return (p_cam.reshape(lead + (3,)), w_R_cam.reshape(lead + (3, 3)), p_ct.reshape(lead + (3,)),
                J.reshape(lead + (6, 6)) if with_jacobian else None)

    def forward_kinematics(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Camera frame in {w}: ``(p (..., 3) in m, R (..., 3, 3))``.

        Eqs (3), (4), (7), (8) with paper-notes §2.2 and §2.3 item 2. The camera sits ``Lc`` along z_2e
        from the end of segment 2; ``R = w_R_ct = w_R_2e``, its z-axis is the viewing axis.
        """
        p_cam, w_R_cam, _, _ = self._run(q, False)
        return p_cam, w_R_cam

    def target_point(self, q: ArrayLike) -> np.ndarray:
        """Visual target point ct, ``Lc + Le`` along z_2e from the end of segment 2: (..., 3) in m (eq 8)."""
        return self._run(q, False)[2]

    def target_pose(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """``(w_p_ct (..., 3) in m, w_R_ct (..., 3, 3))`` (eqs 7 and 8 with paper-notes §2.2 / §2.3 item 2)."""
        _, w_R_ct, p_ct, _ = self._run(q, False)
        return p_ct, w_R_ct

    def jacobian(self, q: ArrayLike) -> np.ndarray:
        """Twist Jacobian of the target point ct in {w}: (..., 6, 6).

        Eq (9) corrected per paper-notes §2.2 and §2.3 item 3.

        Rows ``[v (m/s); w (rad/s)]``; columns per rate of L0 (m/s), phi, theta1, delta1, theta2,
        delta2 (rad/s). J0v = [e3, 0], J0w = [0, e3]; T_t = J_tv - (lever from segment t's end to ct)^ J_tw,
        with J_tv, J_tw of eqs (5), (6) (series of paper-notes §2.2 near straight).
        """
        return self._run(q, True)[3]

    def fk_jacobian(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Everything in one kernel call: ``(p_cam (m), R, p_ct (m), J)`` as in the methods above."""
        return self._run(q, True)

    def backbone(self, q: ArrayLike, n_per_segment: int = 20) -> np.ndarray:
        """Sampled centre line for drawing: (..., 2 * n_per_segment + 4, 3) in m.

        Points: base origin (0, 0, 0); {1b} at [0, 0, L0]; ``n_per_segment`` points along segment 1
        (ending at {1e}); {2b} after the rigid Lm cylinder; ``n_per_segment`` points along segment 2
        (ending at {2e}); the camera, Lc further along z_2e. Arcs follow eq (3) at fractions of the segment.
        """
        m = integer(n_per_segment, "n_per_segment", low=1)
        array = np.ascontiguousarray(as_array(q, "q", (DOF,)))
        try:
            pts = backbone_batch(array.reshape(-1, DOF), self._args, m)
        except ValueError:
            as_configuration(array, DOF)  # raises "q must be finite ..."
            raise
        return pts.reshape(array.shape[:-1] + (2 * m + 4, 3))

    def to_dict(self) -> dict:
        """The constructor arguments as plain YAML/JSON values (m, rad; unlimited as None)."""
        def plain(values):
            return [None if not math.isfinite(v) else float(v) for v in values]

        return {"L1": self.L1, "Lm": self.Lm, "L2": self.L2, "Lc": self.Lc, "Le": self.Le,
                "joint_limits": [plain(self._lower), plain(self._upper)]}

    def __repr__(self) -> str:
        L1, Lm, L2, Lc, Le = self._args
        return f"ContinuumEndoscope(L1={L1}, Lm={Lm}, L2={L2}, Lc={Lc}, Le={Le})"
