"""Plain-numpy implementations of the MBCR kinematics, force gradient and VOI (benchmark references).

Written the straightforward way (3x3 numpy operations per segment, per point), as a researcher would
first write them; the benchmark times the compiled kernels against these in the same run.
"""

from __future__ import annotations

import math

import numpy as np

HALF_PI = math.pi / 2


def _chi(phi):
    if abs(phi) < 2e-3:
        return (-0.5 + phi**2 / 8, -phi / 3 + phi**3 / 30, -phi / 2 + phi**3 / 24, 1 - phi**2 / 6)
    c, s = math.cos(phi), math.sin(phi)
    return ((1 - c - phi * s) / phi**2, (phi * c - s) / phi**2, (c - 1) / phi, s / phi)


def _rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _segment(phi, delta, length, sigma=1.0):
    chi1, chi2, chi3, sinc = _chi(sigma * phi)
    cd, sd = math.cos(delta), math.sin(delta)
    ls = sigma * length
    p = ls * np.array([cd * chi3, -sd * chi3, sinc])
    Q = _rz(-delta) @ _ry(-sigma * phi) @ _rz(delta)
    jv = np.array([[sigma * ls * cd * chi1, -ls * sd * chi3],
                   [-sigma * ls * sd * chi1, -ls * cd * chi3],
                   [sigma * ls * chi2, 0.0]])
    sp, cp = math.sin(sigma * phi), math.cos(sigma * phi)
    jw = np.array([[-sd * sigma, -cd * sp], [-cd * sigma, sd * sp], [0.0, cp - 1.0]])
    return p, Q, jv, jw


def _frames(q, lengths):
    Rs = [np.eye(3)]
    gs = [np.array([0.0, 0.0, q[6]])]
    for j in range(3):
        p, Q, _, _ = _segment(q[2 * j] - HALF_PI, q[2 * j + 1], lengths[j])
        gs.append(gs[-1] + Rs[-1] @ p)
        Rs.append(Rs[-1] @ Q)
    return Rs, gs


def fk_jacobian_numpy(q, lengths):
    """Tip (p, R) and 6x7 Jacobian of one configuration, eqs (2)-(8) with paper-notes §1.2."""
    Rs, gs = _frames(q, lengths)
    J = np.zeros((6, 7))
    for j in range(3):
        _, _, jv, jw = _segment(q[2 * j] - HALF_PI, q[2 * j + 1], lengths[j])
        S = np.block([[Rs[j], _skew(gs[j + 1] - gs[3]) @ Rs[j]], [np.zeros((3, 3)), Rs[j]]])
        J[:, 2 * j:2 * j + 2] = S @ np.vstack([jv, jw])
    J[2, 6] = 1.0
    return gs[3], Rs[3], J


def point_jacobian_numpy(q, lengths, segment, sigma):
    Rs, gs = _frames(q, lengths)
    p_local, _, jv, _ = _segment(q[2 * segment] - HALF_PI, q[2 * segment + 1], lengths[segment], sigma)
    point = gs[segment] + Rs[segment] @ p_local
    Jv = np.zeros((3, 7))
    for k in range(segment):
        _, _, jvk, jwk = _segment(q[2 * k] - HALF_PI, q[2 * k + 1], lengths[k])
        Jv[:, 2 * k:2 * k + 2] = Rs[k] @ jvk - _skew(point - gs[k + 1]) @ Rs[k] @ jwk
    Jv[:, 2 * segment:2 * segment + 2] = Rs[segment] @ jv
    Jv[2, 6] = 1.0
    return point, Jv


def _to_lens(p, gamma, d_o, alpha):
    return _ry(alpha) @ _rz(-gamma) @ p + np.array([0.0, -d_o, 0.0])


def force_numpy(p, gamma, d_o=4.47e-3, alpha=math.radians(30), beta=math.radians(27.5), d0=5e-3, r_star=0.06,
                f_star=5.0):
    x = _to_lens(p, gamma, d_o, alpha)
    rho = math.hypot(x[0], x[1])
    d = math.cos(beta) * rho - math.sin(beta) * x[2]
    r = math.sin(beta) * rho + math.cos(beta) * x[2]
    if d > d0 or r < 1e-9 or rho < 1e-12:
        return np.zeros(3)
    f_hat = np.array([x[0] * math.cos(beta) / rho, x[1] * math.cos(beta) / rho, -math.sin(beta)])
    return f_star * (r_star / r) ** 2 * (1 - d / d0) ** 2 * ((_ry(alpha) @ _rz(-gamma)).T @ f_hat)


def potential_gradient_numpy(q, lengths, stiffness, psps, gamma):
    grad = np.zeros(7)
    grad[0:6:2] = -stiffness * (HALF_PI - q[0:6:2])
    for segment, sigma in psps:
        point, Jv = point_jacobian_numpy(q, lengths, segment, sigma)
        grad -= Jv.T @ force_numpy(point, gamma)
    return grad


def voi_numpy(q, lengths, gamma, n_per_segment=40, n_insert=5, d_o=4.47e-3, alpha=math.radians(30),
              beta=math.radians(27.5)):
    Rs, gs = _frames(q, lengths)
    pts = [np.array([0.0, 0.0, q[6] * k / n_insert]) for k in range(n_insert)]
    for j in range(3):
        for k in range(0 if j == 0 else 1, n_per_segment + 1):
            p_local, _, _, _ = _segment(q[2 * j] - HALF_PI, q[2 * j + 1], lengths[j], k / n_per_segment)
            pts.append(gs[j] + Rs[j] @ p_local)
    lens = np.array([_to_lens(p, gamma, d_o, alpha) for p in pts])
    rho = np.hypot(lens[:, 0], lens[:, 1])
    d = math.cos(beta) * rho - math.sin(beta) * lens[:, 2]
    r = math.sin(beta) * rho + math.cos(beta) * lens[:, 2]
    inside = (d <= 0) & (r > 0)
    if not inside.any():
        return 0.0
    entry = int(np.argmax(inside))
    e = lens[entry]
    if entry > 0:
        t = d[entry - 1] / (d[entry - 1] - d[entry])
        e = lens[entry - 1] + t * (lens[entry] - lens[entry - 1])
    r_e = math.sin(beta) * math.hypot(e[0], e[1]) + math.cos(beta) * e[2]
    r_max = r[-1]
    if r_e >= r_max:
        return 0.0
    ok = inside & (r <= r_max)
    ok[:entry] = False
    if not ok.any():
        return 0.0
    v = lens[ok]
    nu = np.max(np.arctan2(np.linalg.norm(np.cross(e, v), axis=1), v @ e))
    nu = min(nu, 2 * beta)
    return (math.sin(nu) / (2 * math.sin(beta) * math.cos(nu - beta))) ** 2 * (1 - (r_e / r_max) ** 3)
