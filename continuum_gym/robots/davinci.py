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

import numpy as np

from .validation import angle_in_open_interval, as_configuration, positive

__all__ = ["DaVinciEndoscope", "ALPHA_CONVENTIONS"]

#: Valid values of ``DaVinciEndoscope(alpha_convention=...)``.
ALPHA_CONVENTIONS = ("eq2", "eq1")

_DOF = 4


def _stem_rotation(q):
    """``w_R_dV3 = Ry(yaw) Rx(pitch) Rz(roll)`` (..., 3, 3) of a validated q (..., 4).

    Written out elementwise (one contiguous cos/sin call, no matmul), so a batch equals looped
    single calls bit for bit.
    """
    angles = np.ascontiguousarray(q[..., 1:4])
    cos, sin = np.cos(angles), np.sin(angles)
    cy, cp, cr = cos[..., 0], cos[..., 1], cos[..., 2]
    sy, sp, sr = sin[..., 0], sin[..., 1], sin[..., 2]
    # Ry Rx = [c0 c1 c2] with c0 = [cy, 0, -sy], c1 = [sy sp, cp, cy sp], c2 = [sy cp, -sp, cy cp];
    # then (Ry Rx) Rz = [cr c0 + sr c1, -sr c0 + cr c1, c2]
    c1x, c1z = sy * sp, cy * sp
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = cr * cy + sr * c1x
    R[..., 1, 0] = sr * cp
    R[..., 2, 0] = sr * c1z - cr * sy
    R[..., 0, 1] = cr * c1x - sr * cy
    R[..., 1, 1] = cr * cp
    R[..., 2, 1] = sr * sy + cr * c1z
    R[..., 0, 2] = sy * cp
    R[..., 1, 2] = -sp
    R[..., 2, 2] = cy * cp
    return R


class DaVinciEndoscope:
    """4-DoF 30° da Vinci endoscope about the remote centre of motion (paper 001, Fig. 2a, Table II).

    Parameters:
        alpha: viewing angle (rad) between the stem axis and the optical axis, in (-pi/2, pi/2); default pi/6.
        Le: effective view distance from the camera to the visual target point (m, > 0); default 0.120.
        alpha_convention: ``"eq2"`` (default, paper-notes §2.3 item 1: R = R3 Rx(-alpha), eq 2 as printed) or
            ``"eq1"`` (eq 1 as printed with Rx(+alpha), sin(alpha) flipped in eq 2).

    ``q = [L_dV (m), yaw, pitch, roll (rad)]``; every method accepts shape (4,) or (..., 4).
    """

    dof = _DOF
    joint_names = ("L_dV", "yaw", "pitch", "roll")

    def __init__(self, alpha=np.pi / 6, Le=0.120, alpha_convention="eq2"):
        self._alpha = angle_in_open_interval(alpha, "alpha", -np.pi / 2, np.pi / 2, "(-pi/2, pi/2)")
        self._Le = positive(Le, "Le", "m")
        if not isinstance(alpha_convention, str) or alpha_convention not in ALPHA_CONVENTIONS:
            raise ValueError(
                f"alpha_convention must be one of {', '.join(repr(c) for c in ALPHA_CONVENTIONS)}; "
                f"got {alpha_convention!r}"
            )
        self._convention = alpha_convention
        # signed viewing angle: the camera frame is R3 Rx(-sign * alpha), the target direction
        # in {dV3} is [0, sign * sin(alpha), cos(alpha)]
        sign = 1.0 if alpha_convention == "eq2" else -1.0
        a = sign * self._alpha
        self._cos_a = float(np.cos(a))
        self._sin_a = float(np.sin(a))
        self._lower = np.array([0.0, -np.pi / 3, -np.pi / 3, -np.pi])
        self._upper = np.array([0.100, np.pi / 3, np.pi / 3, np.pi])

    alpha = property(lambda self: self._alpha, doc="Viewing angle alpha (rad).")
    Le = property(lambda self: self._Le, doc="View distance camera -> target point (m).")
    alpha_convention = property(lambda self: self._convention, doc='"eq2" (default) or "eq1".')

    @property
    def joint_limits(self):
        """``(lower, upper)``, each shape (4,) (Table II, fresh copies).

        L_dV in [0, 0.1] m, yaw and pitch in [-pi/3, pi/3], roll in [-pi, pi].
        """
        return self._lower.copy(), self._upper.copy()

    # -- named configurations -----------------------------------------------------------------
    @property
    def straight(self):
        """All zeros: stem along z_w, camera at the remote centre (L_dV = 0 m)."""
        return np.zeros(_DOF)

    @property
    def home(self):
        """Centre of the coverage map (paper-notes §2.6): L_dV = 0.065 m, yaw = pitch = roll = 0."""
        return np.array([0.065, 0.0, 0.0, 0.0])

    @property
    def case1(self):
        """Case study 1 (paper-notes §2.1): L_dV = 0.06088 m, yaw 0.5, pitch -0.4, roll 0."""
        return np.array([0.06088, 0.5, -0.4, 0.0])

    @property
    def case2(self):
        """Case study 2 (paper-notes §2.1): L_dV = 0.0625 m, yaw -0.9, pitch 0.7, roll 0."""
        return np.array([0.0625, -0.9, 0.7, 0.0])

    @property
    def named_configurations(self):
        """``{"straight", "home", "case1", "case2"}`` -> fresh arrays."""
        return {"straight": self.straight, "home": self.home, "case1": self.case1, "case2": self.case2}

    # -- kinematics ----------------------------------------------------------------------------
    def stem_rotation(self, q):
        """``w_R_dV3 = Ry(yaw) Rx(pitch) Rz(roll)`` (..., 3, 3) (eqs 1, 2: w_R_dV1 dV1_R_dV2 dV2_R_dV3)."""
        return _stem_rotation(as_configuration(q, _DOF))

    def _poses(self, q):
        q = as_configuration(q, _DOF)
        w_R_dV3 = _stem_rotation(q)
        r1, r2 = w_R_dV3[..., :, 1], w_R_dV3[..., :, 2]
        # camera at the stem tip: w_R_dV3 dV3_p_dVe with dV3_p_dVe = [0, 0, L_dV], dV3_R_dVe = I
        p_cam = q[..., 0:1] * r2
        # w_R_cam = w_R_dV3 Rx(-a): columns r0, c r1 - s r2, s r1 + c r2 (a = +-alpha by convention)
        c, s = self._cos_a, self._sin_a
        w_R_cam = w_R_dV3  # column 0 is shared; columns 1, 2 are overwritten below
        z_cam = s * r1 + c * r2
        w_R_cam[..., :, 1] = c * r1 - s * r2
        w_R_cam[..., :, 2] = z_cam
        # eq (2): p_dVt = cam + w_R_dV3 Le [0, sin a, cos a] = cam + Le z_cam
        p_t = p_cam + self._Le * z_cam
        return p_cam, w_R_cam, p_t

    def forward_kinematics(self, q):
        """Camera frame in {w}: ``(p (..., 3) in m, R (..., 3, 3))``.

        ``p = R3 [0, 0, L_dV]`` (the stem tip, eq 2 first term); ``R = R3 Rx(-alpha)`` (eq 1 corrected,
        paper-notes §2.3 item 1), whose z-axis is the optical axis pointing at the target point.
        """
        p_cam, w_R_cam, _ = self._poses(q)
        return p_cam, w_R_cam

    def target_pose(self, q):
        """Visual target frame the continuum endoscope must reach: ``(w_p_dVt (..., 3) in m, w_R_dVt)``.

        ``w_p_dVt = cam + R3 Le [0, sin alpha, cos alpha]`` (eq 2), ``w_R_dVt = R3 Rx(-alpha)`` (eq 1
        corrected, paper-notes §2.3 item 1); both with alpha's sign flipped under ``alpha_convention="eq1"``.
        """
        _, w_R_cam, p_t = self._poses(q)
        return p_t, w_R_cam

    def target_point(self, q):
        """Visual target point ``w_p_dVt`` (..., 3) in m (eq 2)."""
        return self._poses(q)[2]

    def __repr__(self):
        return (
            f"DaVinciEndoscope(alpha={self._alpha!r}, Le={self._Le!r}, "
            f"alpha_convention={self._convention!r})"
        )
