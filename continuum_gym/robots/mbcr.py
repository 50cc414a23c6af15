"""The 3-segment multi-backbone continuum robot (MBCR) with insertion of Sarli & Simaan (paper 000).

Configuration q = [theta1, delta1, theta2, delta2, theta3, delta3, q_ins] (rad, rad, ..., m), with
Simaan's convention theta = pi/2 straight (paper-notes §1.1). World frame {w}: centred on the robot-channel
exit, z along the sheath; the base of segment 1 is at [0, 0, q_ins].

Kinematics follows paper-notes §1.2 (eqs 2-8 corrected): eq (4) uses (g_j - g_3)^ R_{j-1} (paper-notes §1.3 item 1),
eq (5) is the ordered product (paper-notes §1.3 item 2), eq (7) includes the insertion (paper-notes §1.3 item 3). Near straight the
chi functions switch to the series of paper-notes §1.4.

The compiled kernels (``_frames``, ``_tip_kernel``, ``_points_kernel``, ``_backbone_kernel``) are
public to the package so that baselines and environments can call them inside their own kernels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from continuum_gym.robots.segment import segment_jacobian, segment_position, segment_rotation
from continuum_gym.robots.validation import as_configuration, positive

HALF_PI = 0.5 * math.pi
DOF = 7

# Points subject to potential (paper-notes §1.5, paper 000 section V): (segment, arc fraction).
PAPER_PSPS = (
    (0, 0.5), (0, 0.75), (0, 1.0),
    (1, 0.25), (1, 0.5), (1, 0.75), (1, 1.0),
    (2, 0.25), (2, 0.5), (2, 0.75),
)


@njit(cache=True)
def make_workspace():
    """Scratch arrays for one robot: (R_base, g_base, p_local, Q, jv, jw, Jv, Jw).

    Allocated once per batch call so that the per-robot kernels never allocate.
    """
    return (np.empty((4, 3, 3)), np.empty((4, 3)), np.empty(3), np.empty((3, 3)),
            np.empty((3, 2)), np.empty((3, 2)), np.empty((3, 7)), np.empty((3, 7)))


@njit(cache=True)
def all_finite(x):
    for v in x.ravel():
        if not math.isfinite(v):
            return False
    return True


@njit(cache=True)
def frames(q, lengths, ws):
    """Fill ws[0][j] = ^wR_j and ws[1][j] = ^wg_j for j = 0..3 (eqs 5, 7 corrected)."""
    R_base, g_base, p_local, Q = ws[0], ws[1], ws[2], ws[3]
    for a in range(3):
        for b in range(3):
            R_base[0, a, b] = 1.0 if a == b else 0.0
    g_base[0, 0] = 0.0
    g_base[0, 1] = 0.0
    g_base[0, 2] = q[6]
    for j in range(3):
        phi = q[2 * j] - HALF_PI
        delta = q[2 * j + 1]
        segment_position(phi, delta, lengths[j], p_local)
        segment_rotation(phi, delta, Q)
        for a in range(3):
            acc = g_base[j, a]
            for b in range(3):
                acc += R_base[j, a, b] * p_local[b]
            g_base[j + 1, a] = acc
            for b in range(3):
                acc2 = 0.0
                for c in range(3):
                    acc2 += R_base[j, a, c] * Q[c, b]
                R_base[j + 1, a, b] = acc2


@njit(cache=True)
def point_columns(q, lengths, ws, segment, sigma, point, Jv, Jw, with_angular):
    """Columns of the twist of a body point (segment, sigma) at world position ``point``.

    Needs ``frames`` filled in ``ws``. Proximal segments k < segment: R_{k-1} J_{k,v} +
    (g_k - point)^ R_{k-1} J_{k,w} (eq 4 corrected, paper-notes §1.2); own segment evaluated at sigma;
    distal columns 0; insertion column e3. ``Jw`` is filled only when ``with_angular``.
    """
    R_base, g_base, jv, jw = ws[0], ws[1], ws[4], ws[5]
    for col in range(7):
        for a in range(3):
            Jv[a, col] = 0.0
            if with_angular:
                Jw[a, col] = 0.0
    Jv[2, 6] = 1.0
    for k in range(segment + 1):
        phi = q[2 * k] - HALF_PI
        delta = q[2 * k + 1]
        s = sigma if k == segment else 1.0
        segment_jacobian(phi, delta, lengths[k], s, jv, jw)
        # Lever arm from the point back to the end of this (whole) proximal segment.
        if k == segment:
            arm0 = 0.0
            arm1 = 0.0
            arm2 = 0.0
        else:
            arm0 = g_base[k + 1, 0] - point[0]
            arm1 = g_base[k + 1, 1] - point[1]
            arm2 = g_base[k + 1, 2] - point[2]
        for c in range(2):
            v0 = 0.0
            v1 = 0.0
            v2 = 0.0
            w0 = 0.0
            w1 = 0.0
            w2 = 0.0
            for b in range(3):
                v0 += R_base[k, 0, b] * jv[b, c]
                v1 += R_base[k, 1, b] * jv[b, c]
                v2 += R_base[k, 2, b] * jv[b, c]
                w0 += R_base[k, 0, b] * jw[b, c]
                w1 += R_base[k, 1, b] * jw[b, c]
                w2 += R_base[k, 2, b] * jw[b, c]
            col = 2 * k + c
            Jv[0, col] = v0 + arm1 * w2 - arm2 * w1
            Jv[1, col] = v1 + arm2 * w0 - arm0 * w2
            Jv[2, col] = v2 + arm0 * w1 - arm1 * w0
            if with_angular:
                Jw[0, col] = w0
                Jw[1, col] = w1
                Jw[2, col] = w2


@njit(cache=True)
def body_point(q, lengths, ws, segment, sigma, out):
    """World position (m) of the backbone point at arc fraction ``sigma`` of ``segment`` (frames in ws)."""
    R_base, g_base, p_local = ws[0], ws[1], ws[2]
    phi = q[2 * segment] - HALF_PI
    segment_position(sigma * phi, q[2 * segment + 1], sigma * lengths[segment], p_local)
    for a in range(3):
        acc = g_base[segment, a]
        for b in range(3):
            acc += R_base[segment, a, b] * p_local[b]
        out[a] = acc


@njit(cache=True)
def tip_kernel(q, lengths, ws, p, R, J):
    """Tip position, rotation and 6x7 Jacobian [v; w] in {w} (eq 2 with paper-notes §1.2) for one q."""
    frames(q, lengths, ws)
    R_base, g_base, Jv, Jw = ws[0], ws[1], ws[6], ws[7]
    for a in range(3):
        p[a] = g_base[3, a]
        for b in range(3):
            R[a, b] = R_base[3, a, b]
    point_columns(q, lengths, ws, 2, 1.0, p, Jv, Jw, True)
    for a in range(3):
        for col in range(7):
            J[a, col] = Jv[a, col]
            J[3 + a, col] = Jw[a, col]


@njit(cache=True)
def _tip_single(q, lengths, p, R, J):
    if not all_finite(q):
        return False
    tip_kernel(q, lengths, make_workspace(), p, R, J)
    return True


@njit(cache=True)
def _tip_batch(qs, lengths, p, R, J):
    if not all_finite(qs):
        return False
    ws = make_workspace()
    for i in range(qs.shape[0]):
        tip_kernel(qs[i], lengths, ws, p[i], R[i], J[i])
    return True


@njit(cache=True)
def points_kernel(q, lengths, ws, segments, fractions, P, JV):
    """Positions (m, 3) and translational Jacobians (m, 3, 7) of body points, for one q."""
    frames(q, lengths, ws)
    dummy = ws[7]
    for i in range(segments.shape[0]):
        body_point(q, lengths, ws, segments[i], fractions[i], P[i])
        point_columns(q, lengths, ws, segments[i], fractions[i], P[i], JV[i], dummy, False)


@njit(cache=True)
def _points_batch(qs, lengths, segments, fractions, P, JV):
    if not all_finite(qs):
        return False
    ws = make_workspace()
    for i in range(qs.shape[0]):
        points_kernel(qs[i], lengths, ws, segments, fractions, P[i], JV[i])
    return True


@njit(cache=True)
def backbone_kernel(q, lengths, ws, n_insert, n_per_segment, out):
    """Backbone samples from the channel exit (paper-notes §1.3 item 13).

    ``n_insert`` samples from the origin toward [0, 0, q_ins] (the first at the origin, the last one
    step before the base of segment 1), then arc fractions k/n for k = 0..n on segment 1 and k = 1..n
    on segments 2 and 3. With q_ins = 0 the inserted samples coincide with the origin, which is
    outside every cone, so the count stays fixed and batches keep one shape.
    """
    frames(q, lengths, ws)
    idx = 0
    for k in range(n_insert):
        out[idx, 0] = 0.0
        out[idx, 1] = 0.0
        out[idx, 2] = q[6] * k / n_insert
        idx += 1
    for j in range(3):
        start = 0 if j == 0 else 1
        for k in range(start, n_per_segment + 1):
            body_point(q, lengths, ws, j, k / n_per_segment, out[idx])
            idx += 1


@njit(cache=True)
def _backbone_batch(qs, lengths, n_insert, n_per_segment, out):
    if not all_finite(qs):
        return False
    ws = make_workspace()
    for i in range(qs.shape[0]):
        backbone_kernel(qs[i], lengths, ws, n_insert, n_per_segment, out[i])
    return True


def _as_q(q):
    """Float64, C-contiguous (..., 7) view of q; finiteness is checked inside the kernels."""
    try:
        q = np.asarray(q, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"q must be a numeric array of shape (..., {DOF}); got {q!r}") from error
    if q.ndim == 0 or q.shape[-1] != DOF:
        raise ValueError(f"q must have shape (..., {DOF}); got shape {q.shape}")
    return np.ascontiguousarray(q)


def _raise_not_finite(q):
    raise ValueError(f"q must be finite (no NaN or inf); got {q}")


def tip_pose_jacobian(q, lengths):
    """(p, R, J) of the tip for q of shape (..., 7) with segment ``lengths`` (m) as a float64 array."""
    q = _as_q(q)
    if q.ndim == 1:
        p = np.empty(3)
        R = np.empty((3, 3))
        J = np.empty((6, 7))
        if not _tip_single(q, lengths, p, R, J):
            _raise_not_finite(q)
        return p, R, J
    batch = q.shape[:-1]
    flat = q.reshape(-1, DOF)
    n = flat.shape[0]
    p = np.empty((n, 3))
    R = np.empty((n, 3, 3))
    J = np.empty((n, 6, 7))
    if not _tip_batch(flat, lengths, p, R, J):
        _raise_not_finite(q)
    return p.reshape(batch + (3,)), R.reshape(batch + (3, 3)), J.reshape(batch + (6, 7))


def backbone_sample_count(n_per_segment: int, n_insert: int = 5) -> int:
    """Number of samples ``MultiBackboneRobot.backbone`` returns."""
    return n_insert + 3 * n_per_segment + 1


@dataclass(frozen=True)
class MultiBackboneRobot:
    """Three-segment multi-backbone continuum robot with insertion (Sarli & Simaan, paper 000).

    Args:
        lengths: segment arc lengths (m), Table I: (26, 20, 19) mm.
        youngs_modulus: backbone Young's modulus (Pa); NiTi 60 GPa (paper-notes §1.5 assumption).
        primary_diameter: primary backbone diameter (m), 0.6 mm (paper-notes §1.5).
        secondary_diameter: secondary backbone diameter (m), 0.4 mm (paper-notes §1.5).
        n_secondary: secondary backbones per segment (3).
        n_insert_samples: samples of the straight inserted part used by ``backbone`` (paper-notes §1.3 item 13: 5).
    """

    lengths: tuple = (0.026, 0.020, 0.019)
    youngs_modulus: float = 60e9
    primary_diameter: float = 0.6e-3
    secondary_diameter: float = 0.4e-3
    n_secondary: int = 3
    n_insert_samples: int = 5
    _lengths_array: np.ndarray = field(init=False, repr=False, compare=False)

    dof = DOF
    #: All segments straight, no insertion.
    straight = np.array([HALF_PI, 0.0, HALF_PI, 0.0, HALF_PI, 0.0, 0.0])
    #: Task (a) start configuration psi_a of paper-notes §1.5 (VOI 0.25 at gamma = 0).
    psi_a = np.array([0.981411417978988, -2.1391814000492557, 1.4343256703283846,
                      -0.484339338133009, 1.1014459391296132, -2.285467909847507,
                      0.009283887491045915])
    #: Task (b) (circle) start configuration psi_b of paper-notes §1.5.
    psi_b = np.array([1.1571463096352517, -2.7733740222436865, 1.3778194554049983, 2.704865019865162,
                      1.5026076079767348, 1.031851192490949, 0.002099818575749484])
    home = psi_a

    def __post_init__(self):
        lengths = tuple(float(x) for x in np.asarray(self.lengths, dtype=float).reshape(-1))
        if len(lengths) != 3:
            raise ValueError(f"lengths must hold 3 segment lengths (m); got {self.lengths!r}")
        for i, value in enumerate(lengths):
            positive(value, f"lengths[{i}]", "m")
        positive(self.youngs_modulus, "youngs_modulus", "Pa")
        positive(self.primary_diameter, "primary_diameter", "m")
        positive(self.secondary_diameter, "secondary_diameter", "m")
        if int(self.n_secondary) != self.n_secondary or self.n_secondary < 0:
            raise ValueError(f"n_secondary must be an integer >= 0; got {self.n_secondary!r}")
        if int(self.n_insert_samples) != self.n_insert_samples or self.n_insert_samples < 1:
            raise ValueError(f"n_insert_samples must be an integer >= 1; got {self.n_insert_samples!r}")
        object.__setattr__(self, "lengths", lengths)
        object.__setattr__(self, "_lengths_array", np.array(lengths))

    # ------------------------------------------------------------------ kinematics
    def forward_kinematics(self, q):
        """Tip pose in {w}: eqs (5)-(8) corrected (paper-notes §1.2, paper-notes §1.3 items 2-3).

        Args:
            q: configuration(s), shape (..., 7): rad for angles, m for q_ins.

        Returns:
            (p, R): tip position (..., 3) in m and rotation (..., 3, 3).
        """
        p, R, _ = tip_pose_jacobian(q, self._lengths_array)
        return p, R

    def jacobian(self, q):
        """6x7 Jacobian of the tip twist [v; w] in {w} (eq 2, eq 4 corrected per paper-notes §1.3 item 1).

        v is the velocity of the tip point g_3 (m/s per rad/s, and per m/s for q_ins).
        Returns shape (..., 6, 7).
        """
        return tip_pose_jacobian(q, self._lengths_array)[2]

    def forward_kinematics_and_jacobian(self, q):
        """(p, R, J) from one kernel call; shapes (..., 3) in m, (..., 3, 3), (..., 6, 7)."""
        return tip_pose_jacobian(q, self._lengths_array)

    def point_jacobian(self, q, segment, fraction):
        """Position and translational Jacobian of a backbone point (eq 11; paper-notes §1.2).

        Args:
            q: configuration(s), shape (..., 7).
            segment: 0-based segment index (0, 1 or 2).
            fraction: arc fraction in [0, 1] of that segment.

        Returns:
            (p, Jv): (..., 3) in m and (..., 3, 7).
        """
        P, JV = self.points_jacobians(q, [(segment, fraction)])
        return P[..., 0, :], JV[..., 0, :, :]

    def points_jacobians(self, q, points=PAPER_PSPS):
        """Positions (..., m, 3) in m and Jacobians (..., m, 3, 7) of body points (segment, fraction)."""
        segments, fractions = self._point_spec(points)
        q = _as_q(q)
        batch = q.shape[:-1]
        flat = q.reshape(-1, DOF)
        m = segments.shape[0]
        P = np.empty((flat.shape[0], m, 3))
        JV = np.empty((flat.shape[0], m, 3, 7))
        if not _points_batch(flat, self._lengths_array, segments, fractions, P, JV):
            _raise_not_finite(q)
        return P.reshape(batch + (m, 3)), JV.reshape(batch + (m, 3, 7))

    def backbone(self, q, n_per_segment: int = 40):
        """Sampled backbone from the channel exit, as paper-notes §1.3 item 13 samples it for VOI.

        The straight inserted part from the origin toward [0, 0, q_ins] (``n_insert_samples`` samples),
        then arc fractions k/n_per_segment on each segment (segment 1 from k = 0). Returns
        (..., n_insert_samples + 3 n_per_segment + 1, 3) in m; the last sample is the tip.
        """
        if int(n_per_segment) != n_per_segment or n_per_segment < 1:
            raise ValueError(f"n_per_segment must be an integer >= 1; got {n_per_segment!r}")
        q = _as_q(q)
        batch = q.shape[:-1]
        flat = q.reshape(-1, DOF)
        m = backbone_sample_count(int(n_per_segment), int(self.n_insert_samples))
        out = np.empty((flat.shape[0], m, 3))
        if not _backbone_batch(flat, self._lengths_array, int(self.n_insert_samples), int(n_per_segment), out):
            _raise_not_finite(q)
        return out.reshape(batch + (m, 3))

    # ------------------------------------------------------------------ elastic energy
    @property
    def stiffness(self) -> np.ndarray:
        """Bending stiffness K_i = (E_p I_p + n_s E_s I_s)/l_i per segment (N·m/rad²), paper-notes §1.3 item 9."""
        inertia_primary = math.pi * self.primary_diameter**4 / 64.0
        inertia_secondary = math.pi * self.secondary_diameter**4 / 64.0
        flexural = self.youngs_modulus * (inertia_primary + self.n_secondary * inertia_secondary)
        return flexural / self._lengths_array

    def elastic_energy(self, q):
        """Elastic energy E = sum K_i/2 (pi/2 - theta_i)^2 (eq 10 with l_ij = l_i), in J; shape q.shape[:-1]."""
        q = as_configuration(q, DOF)
        bend = HALF_PI - q[..., 0:6:2]
        return 0.5 * np.sum(self.stiffness * bend**2, axis=-1)

    def elastic_energy_gradient(self, q):
        """dE/dq, shape (..., 7): theta entries -K_i (pi/2 - theta_i), others 0 (paper-notes §1.3 item 9)."""
        q = as_configuration(q, DOF)
        grad = np.zeros_like(q)
        grad[..., 0:6:2] = -self.stiffness * (HALF_PI - q[..., 0:6:2])
        return grad

    # ------------------------------------------------------------------ helpers
    @staticmethod
    def bend_angles(q):
        """Bend angles pi/2 - theta_j (rad) of the three segments, shape (..., 3); 0 is straight."""
        q = as_configuration(q, DOF)
        return HALF_PI - q[..., 0:6:2]

    @staticmethod
    def _point_spec(points):
        points = list(points)
        if not points:
            raise ValueError("points must hold at least one (segment, fraction) pair")
        segments = np.empty(len(points), dtype=np.int64)
        fractions = np.empty(len(points))
        for i, (segment, fraction) in enumerate(points):
            if segment not in (0, 1, 2):
                raise ValueError(f"segment must be 0, 1 or 2 (0-based); got {segment!r}")
            fraction = float(fraction)
            if not (0.0 <= fraction <= 1.0):
                raise ValueError(f"fraction must be in [0, 1]; got {fraction!r}")
            segments[i] = segment
            fractions[i] = fraction
        return segments, fractions
