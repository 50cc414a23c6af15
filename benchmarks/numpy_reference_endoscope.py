"""Plain-numpy forward kinematics + Jacobian of the continuum endoscope (benchmark reference).

One configuration at a time, written literally after paper 001 with paper-notes §2.2 / §2.3:
eqs (3), (4) corrected, (5), (6), (7), (8) and (9) with T0, T1, T2 built from 3x3 numpy products.
It is deliberately straightforward (no numba, no batching) and serves as the speed baseline for
``continuum_gym.robots.endoscope`` and as an independent cross-check in the tests. Lengths in m.
"""

from __future__ import annotations

import numpy as np

_SERIES = 2e-3  # paper-notes §2.2: series below |theta| < 2e-3


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _segment(theta, delta, length):
    """tb_p_te (eq 3), tb_R_te (eq 4 corrected), J_tv (eq 5), J_tw (eq 6) of one segment."""
    c, s = np.cos(theta), np.sin(theta)
    cd, sd = np.cos(delta), np.sin(delta)
    if abs(theta) < _SERIES:
        t2 = theta * theta
        a = theta / 2 - theta**3 / 24 + theta**5 / 720
        b = 1 - t2 / 6 + t2 * t2 / 120
        da = 0.5 - t2 / 8 + t2 * t2 / 144
        db = -theta / 3 + theta**3 / 30 - theta**5 / 840
    else:
        a = (1 - c) / theta
        b = s / theta
        da = (c - 1) / theta**2 + s / theta
        db = -s / theta**2 + c / theta
    p = length * np.array([cd * a, -sd * a, b])
    A = _rz(-delta) @ _rz(-np.pi / 2) @ _ry(-np.pi / 2)  # paper-notes §2.3 item 2
    R = A @ _rz(theta) @ A.T
    Jv = length * np.array([[cd * da, -sd * a], [-sd * da, -cd * a], [db, 0.0]])
    Jw = np.array([[sd, cd * s], [cd, -sd * s], [0.0, c - 1]])
    return p, R, Jv, Jw


def endoscope_fk_jacobian_numpy(q, robot):
    """``(p_cam, w_R_ct, p_ct, J)`` of one configuration q (6,) of ``robot`` (a ContinuumEndoscope).

    Same outputs and units as ``ContinuumEndoscope.fk_jacobian``: positions in m, J (6, 6) the twist
    [v; w] of the target point ct in {w} per joint rate (eq 9 with paper-notes §2.2 / §2.3 item 3).
    """
    L0, phi, th1, de1, th2, de2 = np.asarray(q, dtype=np.float64)
    L1, Lm, L2, Lc, Le = robot.L1, robot.Lm, robot.L2, robot.Lc, robot.Le
    e3 = np.array([0.0, 0.0, 1.0])

    p1, R1, J1v, J1w = _segment(th1, de1, L1)
    p2, R2, J2v, J2w = _segment(th2, de2, L2)
    w_R_1b = _rz(phi)
    w_p_1b = L0 * e3
    e1_p_2b = Lm * e3
    e1_R_2b = np.eye(3)
    e2_p_ct = (Lc + Le) * e3
    e2_p_cam = Lc * e3

    # eqs (7), (8)
    w_R_ct = w_R_1b @ R1 @ e1_R_2b @ R2
    b2_p_ct = p2 + R2 @ e2_p_ct
    e1_p_ct = e1_p_2b + e1_R_2b @ b2_p_ct
    b1_p_ct = p1 + R1 @ e1_p_ct
    p_ct = w_p_1b + w_R_1b @ b1_p_ct
    p_cam = w_p_1b + w_R_1b @ (p1 + R1 @ (e1_p_2b + e1_R_2b @ (p2 + R2 @ e2_p_cam)))

    # eq (9)
    J0v = np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0]])
    J0w = np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 1.0]])
    T0 = J0v - _skew(w_R_1b @ b1_p_ct) @ J0w
    T1 = J1v - _skew(R1 @ e1_p_ct) @ J1w
    T2 = J2v - _skew(R2 @ e2_p_ct) @ J2w
    w_R_2b = w_R_1b @ R1 @ e1_R_2b
    J = np.block(
        [
            [T0, w_R_1b @ T1, w_R_2b @ T2],
            [J0w, w_R_1b @ J1w, w_R_2b @ J2w],
        ]
    )
    return p_cam, w_R_ct, p_ct, J


def _benchmark():
    """Print per-call timings: compiled kernel (single, batch of 4096) against this numpy reference."""
    import timeit

    from continuum_gym.robots.endoscope import ContinuumEndoscope

    robot = ContinuumEndoscope()
    lower, upper = robot.joint_limits
    low = np.where(np.isfinite(lower), lower, -np.pi)
    high = np.where(np.isfinite(upper), upper, np.pi)
    Q = np.random.default_rng(0).uniform(low, high, (4096, 6))
    q = Q[0]
    for got, want in zip(robot.fk_jacobian(q), endoscope_fk_jacobian_numpy(q, robot)):
        assert np.allclose(got, want, rtol=0, atol=1e-14)

    def best(f, number, repeat=7):
        f()
        return min(timeit.repeat(f, number=number, repeat=repeat)) / number

    def separate():
        return robot.forward_kinematics(q), robot.jacobian(q)

    def numpy_loop():
        return [endoscope_fk_jacobian_numpy(x, robot) for x in Q]

    rows = [
        ("numba fk_jacobian(q), single", best(lambda: robot.fk_jacobian(q), 20000), 1),
        ("numba forward_kinematics(q) + jacobian(q)", best(separate, 20000), 1),
        ("numba fk_jacobian(Q), N=4096", best(lambda: robot.fk_jacobian(Q), 50), len(Q)),
        ("numpy reference, single", best(lambda: endoscope_fk_jacobian_numpy(q, robot), 500), 1),
        ("numpy reference, looped N=4096", best(numpy_loop, 1, 3), len(Q)),
    ]
    for name, seconds, n in rows:
        print(
            f"{name:45s} {seconds * 1e6:10.2f} us/call  {seconds / n * 1e6:8.3f} us/config"
            f"  {n / seconds / 1e6:8.3f} M config/s"
        )


if __name__ == "__main__":
    _benchmark()
