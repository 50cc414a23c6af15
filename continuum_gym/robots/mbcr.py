"""The multi-backbone continuum robot (MBCR) with insertion of Sarli & Simaan (paper 000), 1 to 4 segments.

Configuration q = [theta1, delta1, ..., thetan, deltan, q_ins] (rad, rad, ..., m), with Simaan's
convention theta = pi/2 straight (paper-notes §1.1); the paper's robot has n = 3 segments (7 DoF).
World frame {w}: centred on the robot-channel exit, z along the sheath; the base of segment 1 is at
[0, 0, q_ins].

Kinematics follows paper-notes §1.2 (eqs 2-8 corrected): eq (4) uses (g_j - g_n)^ R_{j-1}
(paper-notes §1.3 item 1), eq (5) is the ordered product (item 2), eq (7) includes the insertion
(item 3). Near straight the chi functions switch to the series of paper-notes §1.4.

The compiled kernels take the robot's ``kernel_args()`` bundle (``MBCRKernelArgs``) and a
``MBCRWorkspace`` of scratch arrays, so baselines and environments call them inside their own kernels.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.robots.mbcr_kernels import (  # noqa: F401  (the kernels' names are importable from here too)
    MBCRKernelArgs,
    MBCRWorkspace,
    all_finite,
    backbone_batch,
    backbone_kernel,
    body_point,
    frames,
    make_workspace,
    point_columns,
    points_batch,
    points_kernel,
    positions_batch,
    tip_batch,
    tip_kernel,
    tip_single,
)
from continuum_gym.validation import (
    as_array,
    as_configuration,
    fraction,
    integer,
    positive,
)

HALF_PI = 0.5 * math.pi
#: Segment counts a ``MultiBackboneRobot`` supports.
MIN_SEGMENTS, MAX_SEGMENTS = 1, 4



def default_psps(n_segments: int) -> tuple:
    """Points subject to potential, (segment, arc fraction), following the paper's pattern for any n.

    Paper 000 section V (paper-notes §1.5) uses, for its three segments, {0.5, 0.75, 1}, {0.25, 0.5, 0.75, 1}
    and {0.25, 0.5, 0.75}: quarter points from 0.5 on the first segment and from 0.25 on the others, the
    end disk of every segment but the last (the tip is tracked, not repelled).
    """
    points = []
    for j in range(n_segments):
        fractions = [0.5, 0.75] if j == 0 else [0.25, 0.5, 0.75]
        if j < n_segments - 1:
            fractions.append(1.0)
        points += [(j, f) for f in fractions]
    return tuple(points)


#: The paper's 10 points subject to potential (paper-notes §1.5): ``default_psps(3)``.
PAPER_PSPS = default_psps(3)

def backbone_sample_count(n_per_segment: int, n_insert: int = 5, n_segments: int = 3) -> int:
    """Number of samples ``MultiBackboneRobot.backbone`` returns."""
    return n_insert + n_segments * n_per_segment + 1


def _raise_not_finite(q) -> None:
    raise ValueError(f"q must be finite (no NaN or inf); got {q}")


def _three_segment_constant(values) -> np.ndarray:
    array = np.array(values)
    array.flags.writeable = False
    return array


def _point_spec(n_segments: int, points) -> tuple[np.ndarray, np.ndarray]:
    points = list(points)
    if not points:
        raise ValueError("points must hold at least one (segment, fraction) pair")
    segments = np.empty(len(points), dtype=np.int64)
    fractions = np.empty(len(points))
    for i, pair in enumerate(points):
        try:
            segment, value = pair
        except (TypeError, ValueError):
            raise ValueError(f"points[{i}] must be a (segment, fraction) pair; got {pair!r}") from None
        segments[i] = integer(segment, f"points[{i}] segment (0-based)", low=0, high=n_segments - 1)
        fractions[i] = fraction(value, f"points[{i}] fraction", allow_zero=True)
    return segments, fractions


@functools.lru_cache(maxsize=64)
def _cached_point_spec(n_segments: int, points: tuple) -> tuple[np.ndarray, np.ndarray]:
    # Shared arrays, left writeable: a read-only flag is part of a numba array type and would compile
    # a second specialisation of every kernel they reach. No kernel writes to them.
    return _point_spec(n_segments, points)


@dataclass(frozen=True)
class MultiBackboneRobot:
    """Multi-backbone continuum robot with insertion (Sarli & Simaan, paper 000): 1 to 4 segments.

    Args:
        lengths: segment arc lengths (m), one per segment; 1 to 4 segments. Default: the paper's
            three, Table I: (26, 20, 19) mm.
        youngs_modulus: backbone Young's modulus (Pa); NiTi 60 GPa (paper-notes §1.5 assumption).
        primary_diameter: primary backbone diameter (m), 0.6 mm (paper-notes §1.5).
        secondary_diameter: secondary backbone diameter (m), 0.4 mm (paper-notes §1.5).
        n_secondary: secondary backbones per segment (3).
        n_insert_samples: samples of the straight inserted part used by ``backbone`` (paper-notes §1.3
            item 13: 5).
        backbone_stiffness: bending stiffness per segment (N·m/rad²), overriding the value computed from
            the backbones (``None``: K_i = (E_p I_p + n_s E_s I_s) / l_i, paper-notes §1.3 item 9).

    ``q = [theta1, delta1, ..., thetan, deltan, q_ins]``; ``dof == 2 n + 1``.
    """

    lengths: tuple = (0.026, 0.020, 0.019)
    youngs_modulus: float = 60e9
    primary_diameter: float = 0.6e-3
    secondary_diameter: float = 0.4e-3
    n_secondary: int = 3
    n_insert_samples: int = 5
    backbone_stiffness: tuple | None = None
    _arrays: tuple = field(init=False, repr=False, compare=False)

    #: Task (a) start configuration psi_a of paper-notes §1.5 (3 segments; VOI 0.25 at gamma = 0).
    psi_a = _three_segment_constant([0.981411417978988, -2.1391814000492557, 1.4343256703283846,
                                     -0.484339338133009, 1.1014459391296132, -2.285467909847507,
                                     0.009283887491045915])
    #: Task (b) (circle) start configuration psi_b of paper-notes §1.5 (3 segments).
    psi_b = _three_segment_constant([1.1571463096352517, -2.7733740222436865, 1.3778194554049983,
                                     2.704865019865162, 1.5026076079767348, 1.031851192490949,
                                     0.002099818575749484])

    def __post_init__(self) -> None:
        values = np.asarray(self.lengths, dtype=float).reshape(-1) if not isinstance(self.lengths, str) else None
        if values is None or not (MIN_SEGMENTS <= values.size <= MAX_SEGMENTS):
            raise ValueError(f"lengths must hold {MIN_SEGMENTS} to {MAX_SEGMENTS} segment lengths (m); "
                             f"got {self.lengths!r}")
        lengths = tuple(positive(value, f"lengths[{i}]", "m") for i, value in enumerate(values))
        positive(self.youngs_modulus, "youngs_modulus", "Pa")
        positive(self.primary_diameter, "primary_diameter", "m")
        positive(self.secondary_diameter, "secondary_diameter", "m")
        integer(self.n_secondary, "n_secondary", low=0)
        integer(self.n_insert_samples, "n_insert_samples", low=1)
        object.__setattr__(self, "lengths", lengths)
        lengths_array = np.array(lengths)
        if self.backbone_stiffness is None:
            inertia_primary = math.pi * self.primary_diameter**4 / 64.0
            inertia_secondary = math.pi * self.secondary_diameter**4 / 64.0
            flexural = self.youngs_modulus * (inertia_primary + self.n_secondary * inertia_secondary)
            stiffness = flexural / lengths_array
        else:
            given = as_array(self.backbone_stiffness, "backbone_stiffness").reshape(-1)
            if given.size != len(lengths):
                raise ValueError(f"backbone_stiffness must hold one value per segment ({len(lengths)}; N·m/rad²); "
                                 f"got {self.backbone_stiffness!r}")
            stiffness = np.array([positive(k, f"backbone_stiffness[{i}]", "N·m/rad²") for i, k in enumerate(given)])
            object.__setattr__(self, "stiffness_override", tuple(float(k) for k in stiffness))
        for array in (lengths_array, stiffness):
            array.flags.writeable = False
        object.__setattr__(self, "_arrays", (lengths_array, stiffness))

    # ------------------------------------------------------------------ structure
    @property
    def n_segments(self) -> int:
        """Number of bending segments n."""
        return len(self.lengths)

    @property
    def dof(self) -> int:
        """Degrees of freedom, 2 n + 1."""
        return 2 * len(self.lengths) + 1

    @property
    def joint_names(self) -> tuple:
        """("theta1", "delta1", ..., "thetan", "deltan", "q_ins")."""
        names = []
        for j in range(1, self.n_segments + 1):
            names += [f"theta{j}", f"delta{j}"]
        return (*names, "q_ins")

    @property
    def straight(self) -> np.ndarray:
        """All segments straight, no insertion (a fresh array)."""
        q = np.zeros(self.dof)
        q[0:-1:2] = HALF_PI
        return q

    @property
    def home(self) -> np.ndarray:
        """psi_a for the paper's three segments; otherwise every segment bent by 0.3 rad, 5 mm inserted."""
        if self.n_segments == 3:
            return self.psi_a.copy()
        q = self.straight
        q[0:-1:2] -= 0.3
        q[-1] = 0.005
        return q

    def kernel_args(self) -> MBCRKernelArgs:
        """The bundle the compiled kernels read: lengths (m), stiffness (N·m/rad²), inserted samples."""
        lengths, stiffness = self._arrays
        return MBCRKernelArgs(lengths, stiffness, int(self.n_insert_samples))

    def as_configuration(self, q: ArrayLike, name: str = "q") -> np.ndarray:
        """``q`` as a float64, C-contiguous (..., dof) array (finiteness is checked in the kernels)."""
        return np.ascontiguousarray(as_array(q, name, (self.dof,)))

    def point_spec(self, points: Sequence[tuple[int, float]]) -> tuple[np.ndarray, np.ndarray]:
        """(segments (m,) int, fractions (m,)) of (segment, arc fraction) pairs; both validated.

        A tuple of pairs (such as ``PAPER_PSPS``) is validated once and its arrays are shared by later
        calls (the controllers ask for the same points at every step): do not write to them.
        """
        if isinstance(points, tuple):
            try:
                return _cached_point_spec(self.n_segments, points)
            except TypeError:  # unhashable entries: validate them below, with the error naming the entry
                pass
        return _point_spec(self.n_segments, points)

    # ------------------------------------------------------------------ kinematics
    def _flat(self, q: ArrayLike):
        q = self.as_configuration(q)
        if q.ndim == 0:
            raise ValueError(f"q must have shape (..., {self.dof}); got a scalar")
        return q, q.shape[:-1], q.reshape(-1, self.dof)

    def forward_kinematics_and_jacobian(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(p, R, J) from one kernel call; shapes (..., 3) in m, (..., 3, 3), (..., 6, dof)."""
        if type(q) is np.ndarray and q.shape == (self.dof,) and q.dtype == np.float64 and q.flags.c_contiguous:
            # one configuration, already in the kernel's layout: the controllers' per-step call
            p, R, J = np.empty(3), np.empty((3, 3)), np.empty((6, self.dof))
            lengths, stiffness = self._arrays
            if not tip_single(q, lengths, stiffness, self.n_insert_samples, p, R, J):
                _raise_not_finite(q)
            return p, R, J
        q, batch, flat = self._flat(q)
        n = flat.shape[0]
        p = np.empty((n, 3))
        R = np.empty((n, 3, 3))
        J = np.empty((n, 6, self.dof))
        if not tip_batch(flat, self.kernel_args(), p, R, J):
            _raise_not_finite(q)
        return p.reshape(batch + (3,)), R.reshape(batch + (3, 3)), J.reshape(batch + (6, self.dof))

    def forward_kinematics(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Tip pose in {w}: eqs (5)-(8) corrected (paper-notes §1.2, §1.3 items 2-3).

        Args:
            q: configuration(s), shape (..., dof): rad for angles, m for q_ins.

        Returns:
            (p, R): tip position (..., 3) in m and rotation (..., 3, 3).
        """
        p, R, _ = self.forward_kinematics_and_jacobian(q)
        return p, R

    def jacobian(self, q: ArrayLike) -> np.ndarray:
        """6 x dof Jacobian of the tip twist [v; w] in {w} (eq 2, eq 4 corrected per paper-notes §1.3 item 1).

        v is the velocity of the tip point (m/s per rad/s, and per m/s for q_ins). Shape (..., 6, dof).
        """
        return self.forward_kinematics_and_jacobian(q)[2]

    def point_jacobian(self, q: ArrayLike, segment: int, fraction: float) -> tuple[np.ndarray, np.ndarray]:
        """Position (..., 3) in m and translational Jacobian (..., 3, dof) of one backbone point (eq 11).

        Args:
            q: configuration(s), shape (..., dof).
            segment: 0-based segment index.
            fraction: arc fraction in [0, 1] of that segment.
        """
        P, JV = self.points_jacobians(q, [(segment, fraction)])
        return P[..., 0, :], JV[..., 0, :, :]

    def points_jacobians(self, q: ArrayLike, points: Sequence[tuple[int, float]] = PAPER_PSPS
                         ) -> tuple[np.ndarray, np.ndarray]:
        """Positions (..., m, 3) in m and Jacobians (..., m, 3, dof) of body points (segment, fraction)."""
        segments, fractions = self.point_spec(points)
        q, batch, flat = self._flat(q)
        m = segments.shape[0]
        P = np.empty((flat.shape[0], m, 3))
        JV = np.empty((flat.shape[0], m, 3, self.dof))
        if not points_batch(flat, self.kernel_args(), segments, fractions, P, JV):
            _raise_not_finite(q)
        return P.reshape(batch + (m, 3)), JV.reshape(batch + (m, 3, self.dof))

    def points(self, q: ArrayLike, points: Sequence[tuple[int, float]] = PAPER_PSPS) -> np.ndarray:
        """Positions (..., m, 3) in m of body points (segment, fraction): those of ``points_jacobians``,
        bit for bit, without computing the Jacobians."""
        segments, fractions = self.point_spec(points)
        q, batch, flat = self._flat(q)
        m = segments.shape[0]
        P = np.empty((flat.shape[0], m, 3))
        if not positions_batch(flat, self.kernel_args(), segments, fractions, P):
            _raise_not_finite(q)
        return P.reshape(batch + (m, 3))

    def backbone(self, q: ArrayLike, n_per_segment: int = 40) -> np.ndarray:
        """Sampled backbone from the channel exit, as paper-notes §1.3 item 13 samples it for VOI.

        The straight inserted part from the origin toward [0, 0, q_ins] (``n_insert_samples`` samples),
        then arc fractions k/n_per_segment on each segment (segment 1 from k = 0). Returns
        (..., n_insert_samples + n n_per_segment + 1, 3) in m; the last sample is the tip.
        """
        n_per_segment = integer(n_per_segment, "n_per_segment", low=1)
        q, batch, flat = self._flat(q)
        m = backbone_sample_count(n_per_segment, int(self.n_insert_samples), self.n_segments)
        out = np.empty((flat.shape[0], m, 3))
        if not backbone_batch(flat, self.kernel_args(), n_per_segment, out):
            _raise_not_finite(q)
        return out.reshape(batch + (m, 3))

    # ------------------------------------------------------------------ elastic energy
    @property
    def stiffness(self) -> np.ndarray:
        """Bending stiffness K_i per segment (N·m/rad²): (E_p I_p + n_s E_s I_s)/l_i (paper-notes §1.3 item 9)
        unless given."""
        return self._arrays[1]

    def elastic_energy(self, q: ArrayLike) -> np.ndarray:
        """Elastic energy E = sum K_i/2 (pi/2 - theta_i)^2 (eq 10 with l_ij = l_i), in J; shape q.shape[:-1]."""
        bend = self.bend_angles(q)
        return 0.5 * np.sum(self.stiffness * bend**2, axis=-1)

    def elastic_energy_gradient(self, q: ArrayLike) -> np.ndarray:
        """dE/dq, shape (..., dof): theta entries -K_i (pi/2 - theta_i), others 0 (paper-notes §1.3 item 9)."""
        q = as_configuration(q, self.dof)
        grad = np.zeros_like(q)
        grad[..., 0:-1:2] = -self.stiffness * (HALF_PI - q[..., 0:-1:2])
        return grad

    def bend_angles(self, q: ArrayLike) -> np.ndarray:
        """Bend angles pi/2 - theta_j (rad) of the segments, shape (..., n); 0 is straight."""
        q = as_configuration(q, self.dof)
        return HALF_PI - q[..., 0:-1:2]

    def __reduce__(self):
        # rebuilt through __init__, so that the kernel arrays are read-only again (the compiled kernels' types)
        return (type(self), (self.lengths, self.youngs_modulus, self.primary_diameter, self.secondary_diameter,
                             self.n_secondary, self.n_insert_samples, self.backbone_stiffness))

    def to_dict(self) -> dict:
        """The constructor arguments as plain YAML/JSON values."""
        out = {"lengths": list(self.lengths), "youngs_modulus": self.youngs_modulus,
               "primary_diameter": self.primary_diameter, "secondary_diameter": self.secondary_diameter,
               "n_secondary": int(self.n_secondary), "n_insert_samples": int(self.n_insert_samples)}
        if self.backbone_stiffness is not None:
            out["backbone_stiffness"] = list(self.backbone_stiffness)
        return out

