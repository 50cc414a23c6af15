"""Self-motion of a held tip pose (paper 000's MBCR): predictor-corrector continuation of the
one-dimensional set of configurations with the same tip pose (7 joints, 6-D pose)."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.baselines.occlusion import OcclusionLimits
from continuum_gym.robots import MultiBackboneRobot
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.linalg import damped_gram_solve
from continuum_gym.robots.mbcr_kernels import make_workspace, tip_kernel
from continuum_gym.robots.rotations import orientation_error
from continuum_gym.validation import as_finite, integer, positive

# Self-motion tracing: joint-space metric scales the insertion (m) by this length to compare with rad.
INSERTION_SCALE = 0.02

TRACE_STEP = 0.01

NEWTON_TOLERANCE = 1e-12

NEWTON_MAX_ITERATIONS = 12


# ====================================================================== self-motion (paper 000)
@kernel
def _newton_project(q, p0, R0, robot, scale, tolerance, max_iterations):
    """Newton on the 6-D tip pose error with the pseudo-inverse (scaled joints), in place.

    Returns (iterations or -1 if not converged, final max-abs error, total scaled correction length).
    """
    dof = q.shape[0]
    ws = make_workspace(robot.lengths.shape[0])
    p = np.empty(3)
    R = np.empty((3, 3))
    J = np.empty((6, dof))
    work = np.empty((3, 3))
    e_w = np.empty(3)
    e = np.empty(6)
    Js = np.empty((6, dof))
    G = np.empty((6, 6))
    y = np.empty((6, 1))
    ones = np.ones(dof)
    moved = 0.0
    err = math.inf
    for it in range(max_iterations + 1):
        tip_kernel(q, robot, ws, p, R, J)
        for a in range(3):
            e[a] = p0[a] - p[a]
        orientation_error(R0, R, work, e_w)
        for a in range(3):
            e[3 + a] = e_w[a]
        err = 0.0
        for a in range(6):
            err = max(err, abs(e[a]))
        if err < tolerance:
            return it, err, moved
        if it == max_iterations or not math.isfinite(err):
            break
        for a in range(6):
            for k in range(dof):
                Js[a, k] = J[a, k] * scale[k]
        # minimum-norm step dq = Js^T (Js Js^T)^-1 e (Cholesky; a tiny damping only if it is singular)
        damping = 0.0
        for _ in range(8):
            for a in range(6):
                y[a, 0] = e[a]
            if damped_gram_solve(Js, ones, damping, G, y):
                break
            damping = 1e-14 if damping == 0.0 else 100.0 * damping
        size = 0.0
        for k in range(dof):
            step = 0.0
            for a in range(6):
                step += Js[a, k] * y[a, 0]
            q[k] += step * scale[k]
            size += step * step
        moved += math.sqrt(size)
    return -1, err, moved


@kernel
def _null_direction(q, robot, scale, previous):
    """Unit null vector of the scaled 6x7 tip Jacobian, sign-continuous with ``previous`` (scaled space).

    Near a rank drop (two small singular values) the previous direction is projected onto the 2-D null space.
    Returns (direction, smallest / largest nonzero singular value ratio).
    """
    dof = q.shape[0]
    ws = make_workspace(robot.lengths.shape[0])
    p = np.empty(3)
    R = np.empty((3, 3))
    J = np.empty((6, dof))
    tip_kernel(q, robot, ws, p, R, J)
    Js = np.empty((6, dof))
    for a in range(6):
        for k in range(dof):
            Js[a, k] = J[a, k] * scale[k]
    _, s, vt = np.linalg.svd(Js)
    t = vt[6].copy()
    if s[5] < 1e-6 * s[0]:
        a = vt[5].copy()
        b = vt[6].copy()
        ca = 0.0
        cb = 0.0
        for k in range(7):
            ca += previous[k] * a[k]
            cb += previous[k] * b[k]
        norm = math.sqrt(ca * ca + cb * cb)
        if norm > 0.0:
            for k in range(7):
                t[k] = (ca * a[k] + cb * b[k]) / norm
    dot = 0.0
    for k in range(7):
        dot += t[k] * previous[k]
    if dot < 0.0:
        for k in range(7):
            t[k] = -t[k]
    return t, s[5] / s[0]


class SelfMotion(NamedTuple):
    """A traced self-motion arc: ``q`` (M, 7) ordered along the arc, ``q[start_index]`` is q0.

    ``closed``: the arc closed into a loop (then q[0] = q0 and the last point is next to it, deltas
    modulo 2 pi). ``ends``: why each end stopped ("limit:<joint>", "loop", "max_steps", "stuck"),
    (backward end, forward end).
    """

    q: np.ndarray
    start_index: int
    closed: bool
    ends: tuple


def limit_arrays(limits: OcclusionLimits | None, n_segments: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) position limits of an ``OcclusionLimits`` (None: unlimited)."""
    dof = 2 * n_segments + 1
    if limits is None:
        return np.full(dof, -np.inf), np.full(dof, np.inf)
    if not isinstance(limits, OcclusionLimits):
        raise ValueError(f"limits must be an OcclusionLimits or None; got {type(limits).__name__}")
    lower, upper, _ = limits.bounds(n_segments)
    return lower, upper

JOINT_NAMES = ("theta1", "delta1", "theta2", "delta2", "theta3", "delta3", "q_ins")


class SelfMotionTracer:
    """Predictor-corrector continuation on the self-motion set of the tip pose (p0, R0)."""

    def __init__(self, robot: MultiBackboneRobot, p0: ArrayLike, R0: ArrayLike, lower: np.ndarray, upper: np.ndarray,
                 step: float, tolerance: float) -> None:
        self.robot_args = robot.kernel_args()
        self.p0 = np.ascontiguousarray(p0, dtype=float)
        self.R0 = np.ascontiguousarray(R0, dtype=float)
        self.lower, self.upper = lower, upper
        self.step = step
        self.tolerance = tolerance
        self.scale = np.ones(7)
        self.scale[6] = INSERTION_SCALE

    def inside(self, q: np.ndarray) -> bool:
        return bool(np.all(q >= self.lower) and np.all(q <= self.upper))

    def violated(self, q: np.ndarray) -> str | None:
        bad = np.where((q < self.lower) | (q > self.upper))[0]
        return JOINT_NAMES[bad[0]] if len(bad) else None

    def project(self, q: ArrayLike) -> np.ndarray | None:
        """Newton projection of q onto the manifold (copy); None if it does not converge."""
        q = np.array(q, dtype=float)
        it, _, _ = _newton_project(q, self.p0, self.R0, self.robot_args, self.scale, self.tolerance,
                                   NEWTON_MAX_ITERATIONS)
        return q if it >= 0 else None

    def direction(self, q: np.ndarray, previous: np.ndarray) -> np.ndarray:
        return _null_direction(np.ascontiguousarray(q), self.robot_args, self.scale, previous)[0]

    def _corrected(self, q, t, h):
        qn = q + h * t * self.scale
        it, _, moved = _newton_project(qn, self.p0, self.R0, self.robot_args, self.scale, self.tolerance,
                                       NEWTON_MAX_ITERATIONS)
        return qn if it >= 0 and moved < 0.5 * h else None

    def walk(self, q: np.ndarray, t: np.ndarray, max_steps: int, origin: np.ndarray | None = None,
             step: float | None = None) -> tuple[list[np.ndarray], str]:
        """Points after q along direction t (scaled space); returns (points, reason)."""
        nominal = self.step if step is None else step
        h = nominal
        points: list[np.ndarray] = []
        far = False
        for _ in range(max_steps):
            while True:
                qn = self._corrected(q, t, h)
                if qn is not None:
                    tn = self.direction(qn, t)
                    if float(tn @ t) > 0.9:
                        break
                h *= 0.5
                if h < 1e-10 * nominal:
                    return points, "stuck"
            if not self.inside(qn):
                joint = self.violated(qn)
                a, b, qa = 0.0, h, None
                for _ in range(60):  # bisection onto the limit
                    m = 0.5 * (a + b)
                    qm = self._corrected(q, t, m)
                    if qm is not None and self.inside(qm):
                        a, qa = m, qm
                    else:
                        b = m
                    if b - a < 1e-12:
                        break
                if qa is not None:
                    points.append(qa)
                return points, f"limit:{joint}"
            q, t = qn, tn
            points.append(q)
            h = min(nominal, 2.0 * h)
            if origin is not None:
                d = self.distance(q, origin)
                if d > 3.0 * nominal:
                    far = True
                elif far and d < 0.75 * nominal:
                    return points, "loop"
        return points, "max_steps"

    def distance(self, a: np.ndarray, b: np.ndarray) -> float:
        d = (a - b) / self.scale
        d[[1, 3, 5]] = (d[[1, 3, 5]] + math.pi) % (2.0 * math.pi) - math.pi
        return float(np.linalg.norm(d))


def trace_self_motion(robot: MultiBackboneRobot, q0: ArrayLike, limits: OcclusionLimits | None,
                      step: float = TRACE_STEP, max_steps: int = 20_000,
                      tolerance: float = NEWTON_TOLERANCE) -> SelfMotion:
    """The self-motion arc of the tip pose of q0 by predictor-corrector continuation.

    7 joints and a 6-D tip pose leave a one-dimensional set of configurations with the same tip pose.
    From q0 it is traced in both directions: predictor = unit null vector of the 6x7 tip Jacobian
    (joints scaled so that ``INSERTION_SCALE`` = 0.02 m of insertion counts as 1 rad; sign continuous;
    near a rank drop the previous direction projected on the null space), step ``step`` in that metric;
    corrector = Newton on the 6-D pose error [p0 - p; log(R0 R^T)] with the pseudo-inverse, until the
    largest error component is below ``tolerance`` (m / rad). The step halves when Newton fails or the
    direction turns by more than ~25 degrees. A direction stops at the limits (bend |pi/2 - theta_j|
    <= max_bend, insertion range; the last point is bisected onto the limit) or when the arc closes
    into a loop (back within 0.75 step of q0, deltas modulo 2 pi).

    Args:
        robot: ``MultiBackboneRobot``.
        q0: start configuration (7,), within the limits.
        limits: ``OcclusionLimits`` or None (unlimited).
        step: nominal step (rad-equivalent) of the predictor.
        max_steps: per direction.
        tolerance: Newton tolerance on the pose error.

    Returns:
        ``SelfMotion`` (q (M, 7), start_index, closed, ends).
    """
    if not isinstance(robot, MultiBackboneRobot):
        raise ValueError(f"robot must be a MultiBackboneRobot; got {type(robot).__name__}")
    if robot.dof != 7:
        raise ValueError(f"self-motion continuation needs a 3-segment robot (7 joints, a one-dimensional self-motion "
                         f"set for a 6-D tip pose); got {robot.n_segments} segments")
    q0 = as_finite(q0, (7,), "q0")
    if q0.shape != (7,):
        raise ValueError(f"q0 must have shape (7,); got {q0.shape}")
    step = positive(step, "step", "rad")
    max_steps = integer(max_steps, "max_steps", low=1)
    tolerance = positive(tolerance, "tolerance", "m or rad")
    lower, upper = limit_arrays(limits)
    if np.any(q0 < lower) or np.any(q0 > upper):
        raise ValueError(f"q0 must be within the limits; got q0 = {q0.tolist()}")
    p0, R0 = robot.forward_kinematics(q0)
    tracer = SelfMotionTracer(robot, p0, R0, lower, upper, step, tolerance)
    t0 = tracer.direction(q0, np.full(7, 7 ** -0.5))
    forward, reason_f = tracer.walk(q0.copy(), t0, max_steps, origin=q0)
    if reason_f == "loop":
        return SelfMotion(np.array([q0] + forward), 0, True, ("loop", "loop"))
    backward, reason_b = tracer.walk(q0.copy(), -t0, max_steps, origin=q0)
    q = np.array(backward[::-1] + [q0] + forward)
    return SelfMotion(q, len(backward), False, (reason_b, reason_f))


def trace_self_motion_from(tracer: SelfMotionTracer, q0: np.ndarray, max_steps: int = 20_000) -> SelfMotion:
    """``trace_self_motion`` with an existing tracer (its pose and limits); q0 on the manifold."""
    t0 = tracer.direction(q0, np.full(7, 7 ** -0.5))
    forward, reason_f = tracer.walk(q0.copy(), t0, max_steps, origin=q0)
    if reason_f == "loop":
        return SelfMotion(np.array([q0] + forward), 0, True, ("loop", "loop"))
    backward, reason_b = tracer.walk(q0.copy(), -t0, max_steps, origin=q0)
    return SelfMotion(np.array(backward[::-1] + [q0] + forward), len(backward), False, (reason_b, reason_f))


def sample_self_motion(robot: MultiBackboneRobot, q0: ArrayLike, limits: OcclusionLimits | None, samples: int = 1500,
                       step: float = 0.05, seed: int = 0) -> SelfMotion:
    """Configurations with the tip pose of q0 within ``limits``, for a robot whose DoF is not 7.

    With fewer than 7 joints a 6-D tip pose is (generically) held by isolated configurations: the set
    is q0 alone. With 9 (4 segments) it is a 3-D manifold, sampled by a seeded random walk: a step of
    ``step`` (rad-equivalent, insertion scaled by ``INSERTION_SCALE``) along a random direction of the
    Jacobian's null space, corrected by Newton onto the manifold, kept if it converged within the
    limits. The minimum over the samples is a ceiling from above (the true optimum may be a little lower).
    """
    q0 = np.asarray(q0, dtype=float)
    if robot.dof < 7:
        return SelfMotion(q0[None].copy(), 0, False, ("isolated", "isolated"))
    lower, upper = limit_arrays(limits, robot.n_segments)
    p0, R0 = robot.forward_kinematics(q0)
    scale = np.ones(robot.dof)
    scale[-1] = INSERTION_SCALE
    args = robot.kernel_args()
    rng = np.random.default_rng(seed)
    points = [q0.copy()]
    q = q0.copy()
    for _ in range(int(samples) * 4):
        if len(points) >= samples:
            break
        _, _, J = robot.forward_kinematics_and_jacobian(q)
        _, _, vt = np.linalg.svd(J * scale)
        null = vt[6:]
        direction = rng.normal(size=null.shape[0]) @ null
        candidate = np.ascontiguousarray(q + step * direction / np.linalg.norm(direction) * scale)
        iterations, _, _ = _newton_project(candidate, p0, R0, args, scale, NEWTON_TOLERANCE, NEWTON_MAX_ITERATIONS)
        if iterations >= 0 and np.all(candidate >= lower) and np.all(candidate <= upper):
            q = candidate
            points.append(q.copy())
        elif rng.random() < 0.1:  # stuck at a limit: restart the walk from a sample already found
            q = points[int(rng.integers(len(points)))].copy()
    return SelfMotion(np.array(points), 0, False, ("sampled", "sampled"))
