"""The papers' experiments as named, fixed scenarios (SI), shared by ``reproduce`` and the environments.

Paper 000 (paper-notes §1.5): task (a) holds the tip pose of psi_a at gamma = 0 for 1500 iterations at
1 ms; task (b) tracks a 10 mm circle centred on the view axis. Paper 001 (paper-notes §2.1, §2.6): two
case-study targets from Psi0, and the coverage grid (L_dV = 65 mm, roll 0, yaw/pitch over [-pi/3, pi/3]).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.geometry.lens_cone import lens_origin, view_axis
from continuum_gym.geometry.occlusion import occlusion_details
from continuum_gym.robots.mbcr import PAPER_PSPS, MultiBackboneRobot

HOLD_ITERATIONS = 1500
PAPER_DT = 1e-3


@dataclass(frozen=True)
class CircleTask:
    """Task (b) of paper 000 with the paper-notes §1.5 assumptions.

    Args:
        radius: circle radius (m), 10 mm (paper).
        distance: centre distance from the lens along the view axis at gamma = 0 (m), 65 mm (assumed).
        period: time for one turn (s), 10 s (assumed).
    """

    radius: float = 0.010
    distance: float = 0.065
    period: float = 10.0

    def frame(self, alpha: float = math.radians(30.0), d_o: float = 4.47e-3
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(centre, n_hat, x_hat, y_hat) of the circle plane in {w}."""
        normal = np.array([-math.sin(alpha), 0.0, math.cos(alpha)])
        centre = np.array([0.0, d_o, 0.0]) + self.distance * normal
        x_hat = np.array([math.cos(alpha), 0.0, math.sin(alpha)])
        y_hat = np.array([0.0, 1.0, 0.0])
        return centre, normal, x_hat, y_hat

    def trajectory(self, t: ArrayLike, alpha: float = math.radians(30.0), d_o: float = 4.47e-3
                   ) -> tuple[np.ndarray, np.ndarray]:
        """Desired positions (..., 3) in m and feed-forward velocities (..., 3) in m/s at times t (s)."""
        t = np.asarray(t, dtype=float)[..., None]
        centre, _, x_hat, y_hat = self.frame(alpha, d_o)
        omega = 2.0 * math.pi / self.period
        p = centre + self.radius * (x_hat * np.cos(omega * t) + y_hat * np.sin(omega * t))
        v = self.radius * omega * (-x_hat * np.sin(omega * t) + y_hat * np.cos(omega * t))
        return p, v

    @staticmethod
    def start_configuration() -> np.ndarray:
        """psi_b of paper-notes §1.5 (bounded IK, most relaxed exact solution); the orientation to hold."""
        return MultiBackboneRobot.psi_b.copy()


def sample_hold_starts(robot: MultiBackboneRobot, n: int, rng: np.random.Generator, voi_target: float = 0.25,
                       voi_tolerance: float = 0.01, min_psps_inside: float = 0.6, max_bend: float = 1.2,
                       max_insertion: float = 0.02, batch: int = 4096, max_draws: int = 2_000_000) -> np.ndarray:
    """Paper-like hold starts (paper-notes §1.5 search): random bends, VOI in target ± tolerance at gamma = 0.

    Draws theta_i = pi/2 - U(0.05, max_bend), delta_i ~ U(-pi, pi), q_ins ~ U(0, max_insertion) (m),
    and accepts a draw whose VOI is within tolerance, whose tip is inside the cone and with at least
    ``min_psps_inside`` of the paper's psps inside. All draws come from ``rng``.

    Returns (n, 7) configurations.
    """
    accepted: list[np.ndarray] = []
    drawn = 0
    while sum(len(a) for a in accepted) < n:
        if drawn >= max_draws:
            raise RuntimeError(f"only {sum(len(a) for a in accepted)} of {n} hold starts after {drawn} draws")
        q = np.empty((batch, 7))
        q[:, 0:6:2] = math.pi / 2 - rng.uniform(0.05, max_bend, (batch, 3))
        q[:, 1:6:2] = rng.uniform(-math.pi, math.pi, (batch, 3))
        q[:, 6] = rng.uniform(0.0, max_insertion, batch)
        drawn += batch
        voi = occlusion_details(robot, q, 0.0)["voi"]
        candidates = np.abs(voi - voi_target) <= voi_tolerance
        if not np.any(candidates):
            continue
        q = q[candidates]
        inside = _inside_cone_fraction(robot, q)
        keep = (inside["tip"]) & (inside["psps"] >= min_psps_inside)
        accepted.append(q[keep])
    return np.concatenate(accepted)[:n]


def _inside_cone_fraction(robot: MultiBackboneRobot, q: np.ndarray) -> dict[str, np.ndarray]:
    from continuum_gym.geometry.lens_cone import cone_coordinates

    tip, _ = robot.forward_kinematics(q)
    P, _ = robot.points_jacobians(q, PAPER_PSPS)
    tip_c = cone_coordinates(tip, 0.0)
    psp_c = cone_coordinates(P, 0.0)
    return {
        "tip": (tip_c["d"] <= 0) & (tip_c["r"] > 0),
        "psps": np.mean((psp_c["d"] <= 0) & (psp_c["r"] > 0), axis=-1),
    }


# ---------------------------------------------------------------------- paper 001
#: Case-study start configuration Psi0 (paper-notes §2.1), SI: [L0 (m), phi, theta1, delta1, theta2, delta2].
CASE_STUDY_START = np.array([0.008, 0.0, 0.3857, -1.57, 0.7828, 1.57])
#: da Vinci targets of the two case studies, [L_dV (m), yaw, pitch, roll] (paper-notes §2.1).
CASE_STUDIES = {
    "case1": np.array([0.06088, 0.5, -0.4, 0.0]),
    "case2": np.array([0.0625, -0.9, 0.7, 0.0]),
}
VIEW_DT = 0.01
VIEW_MAX_STEPS = 1000
COVERAGE_INSERTION = 0.065
COVERAGE_THRESHOLD = 0.8


def coverage_grid(n: int, insertion: float = COVERAGE_INSERTION, limit: float = math.pi / 3) -> np.ndarray:
    """da Vinci configurations (n*n, 4) of the coverage map: yaw-major grid over [-limit, limit], roll 0."""
    if int(n) != n or n < 2:
        raise ValueError(f"grid must be an integer >= 2 points per axis; got {n!r}")
    axis = np.linspace(-limit, limit, int(n))
    yaw, pitch = np.meshgrid(axis, axis, indexing="ij")
    return np.stack([np.full(yaw.size, insertion), yaw.ravel(), pitch.ravel(), np.zeros(yaw.size)], axis=1)


__all__ = [
    "CircleTask", "sample_hold_starts", "HOLD_ITERATIONS", "PAPER_DT", "CASE_STUDY_START", "CASE_STUDIES",
    "VIEW_DT", "VIEW_MAX_STEPS", "COVERAGE_INSERTION", "COVERAGE_THRESHOLD", "coverage_grid",
    "lens_origin", "view_axis",
]
