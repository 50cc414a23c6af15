"""OcclusionAvoidance's visibility guard: the residual's endoscope rotation cut where it would carry the tip out.

At every substep the residual's share of the endoscope rate is scaled back (bisection, ``GUARD_BISECTIONS``
halvings) where it would carry the tip, at the joints that substep reaches, beyond ``visibility_guard`` of the
cone's half-angle, or beyond where the baseline's own rotation leaves it if that is further. The baseline's rate
is never changed. The env's docstring states what this guarantees and what it does not.
"""

from __future__ import annotations

import math

from continuum_gym.envs.common_kernels import clamp
from continuum_gym.geometry.lens_cone import to_lens
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.mbcr_kernels import tip_kernel

#: Halvings of the residual's share of the endoscope rate when the guard cuts it.
GUARD_BISECTIONS = 20


@kernel(inline="always")
def view_fraction_at(p, gamma, cone):
    """Angle of point p (m, {w}) from the lens axis at endoscope rotation gamma, in half-angles."""
    xl, yl, zl = to_lens(p[0], p[1], p[2], gamma, cone.d_o, cone.alpha, cone.model)
    return math.atan2(math.sqrt(xl * xl + yl * yl), zl) / cone.beta


@kernel(borrows=True)
def guard_gamma_rate(p, gamma, base_rate, residual_rate, dt, bound, cone):
    """Endoscope rate with the residual's share scaled back so the tip p stays within ``bound`` half-angles.

    The baseline's own rate is never changed: the residual is cut only where it would carry the tip
    beyond max(bound, where the baseline alone leaves it). Returns (rate, guarded).
    """
    limit = max(bound, view_fraction_at(p, gamma + base_rate * dt, cone))
    if view_fraction_at(p, gamma + (base_rate + residual_rate) * dt, cone) <= limit:
        return base_rate + residual_rate, False
    low, high = 0.0, 1.0  # share of the residual: low is feasible, high is not
    for _ in range(GUARD_BISECTIONS):
        mid = 0.5 * (low + high)
        if view_fraction_at(p, gamma + (base_rate + mid * residual_rate) * dt, cone) <= limit:
            low = mid
        else:
            high = mid
    return base_rate + low * residual_rate, True


@kernel(inline="always")
def guard_on(env, gamma_residual):
    """Whether the visibility guard checks this step's endoscope rate."""
    return env.visibility_guard > 0.0 and gamma_residual != 0.0


@kernel(inline="always")
def endoscope_rate(qg, gamma, gd, gamma_residual, dt, robot, prm, env, ws, tip_p, tip_R, tip_J):
    """The endoscope's rate: baseline + residual, guarded at the joints qg (where ``guard_on``), clipped to the
    rate limit. Returns (rate, guarded, clipped)."""
    if guard_on(env, gamma_residual):
        tip_kernel(qg, robot, ws, tip_p, tip_R, tip_J)
        g_rate, guarded = guard_gamma_rate(tip_p, gamma, gd, gamma_residual, dt, env.visibility_guard, prm.cone)
    else:
        g_rate, guarded = gd + gamma_residual, False
    g_rate, clipped = clamp(g_rate, -env.gamma_rate_limit, env.gamma_rate_limit)
    return g_rate, guarded, clipped


__all__ = ["GUARD_BISECTIONS", "view_fraction_at", "guard_gamma_rate", "guard_on", "endoscope_rate"]
