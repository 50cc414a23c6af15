"""Rigid angled da Vinci endoscope pivoting about the remote centre.

Paper 001, §II.B, eqs (1) and (2), corrected per paper-notes §2.2 and §2.3 item 1.

Configuration ``q = [L_dV, yaw, pitch, roll]``: ``L_dV`` in m (insertion past the remote centre,
which is the origin of {w}), angles in rad. ``w_R_dV3 = Ry(yaw) Rx(pitch) Rz(roll)``; the camera
sits at ``w_R_dV3 [0, 0, L_dV]``. With the default ``alpha_convention="eq2"`` (paper-notes §2.3 item 1):

    camera frame / visual target frame   w_R_dVt = w_R_dV3 Rx(-alpha)          (eq 1 corrected)
    visual target point                  w_p_dVt = cam + w_R_dV3 Le [0, sin alpha, cos alpha]   (eq 2)

so the camera's z-axis (the optical axis) points at the target. ``"eq1"`` is the alternative the
paper notes allow as an option: keep eq (1) with Rx(+alpha) and flip sin(alpha) in eq (2).

All lengths in m. Vectorised numpy; any finite q is accepted (limits are only data).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.robots.compiled import kernel
from continuum_gym.validation import (
    angle_in_open_interval,
    as_configuration,
    choice,
    positive,
)

__all__ = ["DaVinciEndoscope", "DaVinciKernelArgs", "ALPHA_CONVENTIONS", "davinci_pose", "stem_rotation",
           "davinci_configuration"]

#: Valid values of ``DaVinciEndoscope(alpha_convention=...)``.
ALPHA_CONVENTIONS = ("eq2", "eq1")

DOF = 4
#: What the compiled kernels read of the da Vinci endoscope: the signed viewing angle (rad; the sign
#: encodes ``alpha_convention``), the view distance Le (m) and the joint ranges (4,) of Table II.
DaVinciKernelArgs = namedtuple("DaVinciKernelArgs", ["alpha", "Le", "lower", "upper"])


@kernel(inline="always")
def stem_rotation(yaw, pitch, roll, R):
    """``w_R_dV3 = Ry(yaw) Rx(pitch) Rz(roll)`` into R (eqs 1, 2: w_R_dV1 dV1_R_dV2 dV2_R_dV3)."""
    cy, sy = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    # Ry Rx = [c0 c1 c2] with c0 = [cy, 0, -sy], c1 = [sy sp, cp, cy sp], c2 = [sy cp, -sp, cy cp];
    # then (Ry Rx) Rz = [cr c0 + sr c1, -sr c0 + cr c1, c2]
    c1x = sy * sp
    c1z = cy * sp
    R[0, 0] = cr * cy + sr * c1x
    R[1, 0] = sr * cp
    R[2, 0] = sr * c1z - cr * sy
    R[0, 1] = cr * c1x - sr * cy
    R[1, 1] = cr * cp
    R[2, 1] = sr * sy + cr * c1z
    R[0, 2] = sy * cp
    R[1, 2] = -sp
    R[2, 2] = cy * cp


@kernel(inline="always")
def davinci_configuration(p_tgt, R_cam, alpha, le, out):
    """The configuration [L_dV, yaw, pitch, roll] (4,) whose ``davinci_pose`` is (R_cam, p_tgt), into ``out``.

    ``alpha`` is the signed viewing angle of ``DaVinciKernelArgs``, ``le`` the view distance (m). The exact
    inverse for yaw, pitch in (-pi/2, pi/2) and roll in (-pi, pi]: the stem's z-axis is R_cam's y and z columns
    turned back by alpha, L_dV the camera position's component along it.
    """
    ca, sa = math.cos(alpha), math.sin(alpha)
    zx = -sa * R_cam[0, 1] + ca * R_cam[0, 2]
    zy = -sa * R_cam[1, 1] + ca * R_cam[1, 2]
    zz = -sa * R_cam[2, 1] + ca * R_cam[2, 2]
    out[0] = (p_tgt[0] - le * R_cam[0, 2]) * zx + (p_tgt[1] - le * R_cam[1, 2]) * zy + \
        (p_tgt[2] - le * R_cam[2, 2]) * zz
    yaw = math.atan2(zx, zz)
    pitch = math.asin(min(max(-zy, -1.0), 1.0))
    cy, sy, cp, sp = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch)
    # the stem's x-axis (R_cam's first column) is cos(roll) [cy, 0, -sy] + sin(roll) [sy sp, cp, cy sp]
    out[1] = yaw
    out[2] = pitch
    out[3] = math.atan2(R_cam[0, 0] * sy * sp + R_cam[1, 0] * cp + R_cam[2, 0] * cy * sp,
                        R_cam[0, 0] * cy - R_cam[2, 0] * sy)


@kernel(borrows=True)
def davinci_pose(q_dv, dv, clip, p_cam, R_cam, p_tgt):
    """Camera (= visual target) frame and target point of one da Vinci configuration (paper-notes §2.2).

    ``dv`` is ``DaVinciEndoscope.kernel_args()``; with ``clip`` the configuration is first clipped to
    its ranges. ``p_cam = R3 [0, 0, L_dV]``, ``R_cam = R3 Rx(-alpha)`` (eq 1 corrected, paper-notes §2.3
    item 1), ``p_tgt = p_cam + Le z_cam`` (eq 2).
    """
    L = q_dv[0]
    yaw = q_dv[1]
    pitch = q_dv[2]
    roll = q_dv[3]
    if clip:
        L = min(max(L, dv.lower[0]), dv.upper[0])
        yaw = min(max(yaw, dv.lower[1]), dv.upper[1])
        pitch = min(max(pitch, dv.lower[2]), dv.upper[2])
        roll = min(max(roll, dv.lower[3]), dv.upper[3])
    stem_rotation(yaw, pitch, roll, R_cam)
    ca, sa = math.cos(dv.alpha), math.sin(dv.alpha)
    for a in range(3):
        r1 = R_cam[a, 1]
        r2 = R_cam[a, 2]
        p_cam[a] = L * r2
        R_cam[a, 1] = ca * r1 - sa * r2
        R_cam[a, 2] = sa * r1 + ca * r2
        p_tgt[a] = p_cam[a] + dv.Le * R_cam[a, 2]


@kernel
def _stem_batch(Q, out):
    for i in range(Q.shape[0]):
        stem_rotation(Q[i, 1], Q[i, 2], Q[i, 3], out[i])


@kernel
def _pose_batch(Q, dv, clip, p_cam, R_cam, p_tgt):
    for i in range(Q.shape[0]):
        davinci_pose(Q[i], dv, clip, p_cam[i], R_cam[i], p_tgt[i])


@kernel
def _configuration_batch(P, R, alpha, le, out):
    for i in range(P.shape[0]):
        davinci_configuration(P[i], R[i], alpha, le, out[i])


class DaVinciEndoscope:
    """4-DoF 30° da Vinci endoscope about the remote centre of motion (paper 001, Fig. 2a, Table II).

    Parameters:
        alpha: viewing angle (rad) between the stem axis and the optical axis, in (-pi/2, pi/2); default pi/6.
        Le: effective view distance from the camera to the visual target point (m, > 0); default 0.120.
        alpha_convention: ``"eq2"`` (default, paper-notes §2.3 item 1: R = R3 Rx(-alpha), eq 2 as printed) or
            ``"eq1"`` (eq 1 as printed with Rx(+alpha), sin(alpha) flipped in eq 2).

    ``q = [L_dV (m), yaw, pitch, roll (rad)]``; every method accepts shape (4,) or (..., 4).
    """

    dof = DOF
    joint_names = ("L_dV", "yaw", "pitch", "roll")

    def __init__(self, alpha: float = np.pi / 6, Le: float = 0.120, alpha_convention: str = "eq2") -> None:
        self._alpha = angle_in_open_interval(alpha, "alpha", -np.pi / 2, np.pi / 2, "(-pi/2, pi/2)")
        self._Le = positive(Le, "Le", "m")
        self._convention = choice(alpha_convention, ALPHA_CONVENTIONS, "alpha_convention")
        # signed viewing angle: the camera frame is R3 Rx(-sign * alpha), the target direction
        # in {dV3} is [0, sign * sin(alpha), cos(alpha)]
        sign = 1.0 if alpha_convention == "eq2" else -1.0
        self._lower = np.array([0.0, -np.pi / 3, -np.pi / 3, -np.pi])
        self._upper = np.array([0.100, np.pi / 3, np.pi / 3, np.pi])
        for array in (self._lower, self._upper):
            array.flags.writeable = False
        self._args = DaVinciKernelArgs(sign * self._alpha, self._Le, self._lower, self._upper)

    def kernel_args(self) -> DaVinciKernelArgs:
        """(signed alpha (rad), Le (m), lower (4,), upper (4,)): the bundle ``davinci_pose`` reads."""
        return self._args

    def __reduce__(self):
        # rebuilt through __init__, so that the kernel arrays are read-only again (the compiled kernels' types)
        return (type(self), (self._alpha, self._Le, self._convention))

    def to_dict(self) -> dict:
        """The constructor arguments as plain YAML/JSON values (rad, m)."""
        return {"alpha": self._alpha, "Le": self._Le, "alpha_convention": self._convention}

    alpha = property(lambda self: self._alpha, doc="Viewing angle alpha (rad).")
    Le = property(lambda self: self._Le, doc="View distance camera -> target point (m).")
    alpha_convention = property(lambda self: self._convention, doc='"eq2" (default) or "eq1".')

    @property
    def joint_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)``, each shape (4,) (Table II, fresh copies).

        L_dV in [0, 0.1] m, yaw and pitch in [-pi/3, pi/3], roll in [-pi, pi].
        """
        return self._lower.copy(), self._upper.copy()

    # -- named configurations -----------------------------------------------------------------
    @property
    def straight(self) -> np.ndarray:
        """All zeros: stem along z_w, camera at the remote centre (L_dV = 0 m)."""
        return np.zeros(DOF)

    @property
    def home(self) -> np.ndarray:
        """Centre of the coverage map (paper-notes §2.6): L_dV = 0.065 m, yaw = pitch = roll = 0."""
        return np.array([0.065, 0.0, 0.0, 0.0])

    @property
    def case1(self) -> np.ndarray:
        """Case study 1 (paper-notes §2.1): L_dV = 0.06088 m, yaw 0.5, pitch -0.4, roll 0."""
        return np.array([0.06088, 0.5, -0.4, 0.0])

    @property
    def case2(self) -> np.ndarray:
        """Case study 2 (paper-notes §2.1): L_dV = 0.0625 m, yaw -0.9, pitch 0.7, roll 0."""
        return np.array([0.0625, -0.9, 0.7, 0.0])

    @property
    def named_configurations(self) -> dict[str, np.ndarray]:
        """``{"straight", "home", "case1", "case2"}`` -> fresh arrays."""
        return {"straight": self.straight, "home": self.home, "case1": self.case1, "case2": self.case2}

    # -- kinematics ----------------------------------------------------------------------------
    def stem_rotation(self, q: ArrayLike) -> np.ndarray:
        """``w_R_dV3 = Ry(yaw) Rx(pitch) Rz(roll)`` (..., 3, 3) (eqs 1, 2: w_R_dV1 dV1_R_dV2 dV2_R_dV3)."""
        q = as_configuration(q, DOF)
        flat = np.ascontiguousarray(q.reshape(-1, DOF))
        out = np.empty((flat.shape[0], 3, 3))
        _stem_batch(flat, out)
        return out.reshape(q.shape[:-1] + (3, 3))

    def _poses(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        q = as_configuration(q, DOF)
        flat = np.ascontiguousarray(q.reshape(-1, DOF))
        n = flat.shape[0]
        p_cam, w_R_cam, p_t = np.empty((n, 3)), np.empty((n, 3, 3)), np.empty((n, 3))
        _pose_batch(flat, self._args, False, p_cam, w_R_cam, p_t)
        lead = q.shape[:-1]
        return p_cam.reshape(lead + (3,)), w_R_cam.reshape(lead + (3, 3)), p_t.reshape(lead + (3,))

    def forward_kinematics(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Camera frame in {w}: ``(p (..., 3) in m, R (..., 3, 3))``.

        ``p = R3 [0, 0, L_dV]`` (the stem tip, eq 2 first term); ``R = R3 Rx(-alpha)`` (eq 1 corrected,
        paper-notes §2.3 item 1), whose z-axis is the optical axis pointing at the target point.
        """
        p_cam, w_R_cam, _ = self._poses(q)
        return p_cam, w_R_cam

    def target_pose(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Visual target frame the continuum endoscope must reach: ``(w_p_dVt (..., 3) in m, w_R_dVt)``.

        ``w_p_dVt = cam + R3 Le [0, sin alpha, cos alpha]`` (eq 2), ``w_R_dVt = R3 Rx(-alpha)`` (eq 1
        corrected, paper-notes §2.3 item 1); both with alpha's sign flipped under ``alpha_convention="eq1"``.
        """
        _, w_R_cam, p_t = self._poses(q)
        return p_t, w_R_cam

    def configuration_of(self, p_target: ArrayLike, R_target: ArrayLike) -> np.ndarray:
        """The configuration (..., 4) whose ``target_pose`` is (p_target (..., 3) in m, R_target (..., 3, 3)).

        The inverse of ``target_pose`` for yaw and pitch in (-pi/2, pi/2) (the joint ranges are within) and
        roll in (-pi, pi]; a pose no configuration reaches gives the configuration of its nearest stem axis.
        """
        p = np.asarray(p_target, dtype=float)
        R = np.asarray(R_target, dtype=float)
        if p.shape[-1:] != (3,) or R.shape[-2:] != (3, 3) or p.shape[:-1] != R.shape[:-2]:
            raise ValueError(f"p_target must be (..., 3) and R_target (..., 3, 3) with the same leading shape; got "
                             f"{p.shape} and {R.shape}")
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(R))):
            raise ValueError("p_target and R_target must be finite")
        out = np.empty(p.shape[:-1] + (DOF,))
        _configuration_batch(np.ascontiguousarray(p.reshape(-1, 3)), np.ascontiguousarray(R.reshape(-1, 3, 3)),
                             self._args.alpha, self._Le, out.reshape(-1, DOF))
        return out

    def target_point(self, q: ArrayLike) -> np.ndarray:
        """Visual target point ``w_p_dVt`` (..., 3) in m (eq 2)."""
        return self._poses(q)[2]

    def __repr__(self):
        return (
            f"DaVinciEndoscope(alpha={self._alpha!r}, Le={self._Le!r}, "
            f"alpha_convention={self._convention!r})"
        )
