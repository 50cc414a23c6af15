"""How much of the view-tracking optimum a joint-rate residual of a given scale can reach and hold.

The residual env commands ``base + residual_scale * ACTION_SCALE * a`` with |a| <= 1. Dimension-reduced
IK keeps pulling towards its own pose fit, so a configuration q can be held only if the baseline's rate
there fits inside the residual's reach: its *hold effort* max_k |base_k(q)| / (residual_scale *
ACTION_SCALE_k) must be <= 1. :func:`reach_ceiling` moves every optimum the residual cannot hold to the
best-OR configuration it can hold, which is the coverage a perfect residual policy of that scale gets.

It chose ViewTracking's ``residual_scale`` in the packaged ``ppo.yml`` (a perfect residual covers 86.2 / 88.4 / 88.9 %
of the grid at scale 1 / 2 / 3; the optimum 89.3 %), and the campaign's label scripts use its hold effort:

    PYTHONPATH=.:experiments/optimum python -c "import residual_reach; print(residual_reach.reach_ceiling([1, 2, 3]))"

It was ``continuum_gym.evaluation.residual_reach`` until 0.3.0 (issue 55).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import minimize

from continuum_gym.baselines import make_controller
from continuum_gym.baselines.scenarios import COVERAGE_THRESHOLD, coverage_grid
from continuum_gym.baselines.view_tracking import ViewTrackingController, make_view_scratch, view_rates_kernel
from continuum_gym.evaluation.optimum.view import (
    overlap_of_configuration,
    view_tracking_optimum,
)
from continuum_gym.geometry.frustum import Frustum
from continuum_gym.robots import DaVinciEndoscope
from continuum_gym.validation import positive

#: The residual env's control step (s): the baseline's rate depends on it through its capped twist.
CONTROL_DT = 0.01
# Nelder-Mead on -OR + PENALTY * max(0, effort - HOLD_MARGIN): the margin keeps the result strictly holdable.
HOLD_MARGIN = 0.9
PENALTY = 5.0


def hold_effort(q: ArrayLike, q_davinci: ArrayLike, residual_scale: float,
                controller: ViewTrackingController | None = None, control_dt: float = CONTROL_DT) -> np.ndarray:
    """Hold effort of each configuration (n,): the largest |action| that cancels the baseline's rate at q.

    Args:
        q: configurations (n, 6) [L0 (m), phi, theta1, delta1, theta2, delta2 (rad)].
        q_davinci: the da Vinci configurations (n, 4) [L_dV (m), yaw, pitch, roll] defining each target.
        residual_scale: the env's ``residual_scale`` (> 0).
        controller: the base controller (default dimension-reduced IK).
        control_dt: control step (s).
    """
    residual_scale = positive(residual_scale, "residual_scale", "fraction of the action scale")
    controller = make_controller("dimension_reduced") if controller is None else controller
    q = np.ascontiguousarray(np.atleast_2d(q), dtype=float)
    p_t, R_t = DaVinciEndoscope().target_pose(np.atleast_2d(q_davinci))
    effort = HoldEffort(controller, residual_scale, control_dt)
    return np.array([effort(q[k], p_t[k], R_t[k]) for k in range(len(q))])


class HoldEffort:
    """The hold effort of one configuration towards one target pose, with its work arrays allocated once.

    ``HoldEffort(controller, residual_scale)(q, p_target, R_target)`` is :func:`hold_effort` for one row, for an
    optimiser that calls it many times (``holdable_optimum``); ``residual_scale`` is not validated here.
    """

    def __init__(self, controller: ViewTrackingController, residual_scale: float,
                 control_dt: float = CONTROL_DT) -> None:
        from continuum_gym.envs.view_tracking import ACTION_SCALE

        self.robot, self.params = controller.robot.kernel_args(), controller.params
        self.reach = residual_scale * ACTION_SCALE
        self.control_dt = control_dt
        self.scratch, self.rates = make_view_scratch(), np.empty(6)

    def __call__(self, q: ArrayLike, p_target: np.ndarray, R_target: np.ndarray) -> float:
        view_rates_kernel(np.ascontiguousarray(q, dtype=float), p_target, R_target, self.control_dt, self.robot,
                          self.params, self.scratch, self.rates)
        return float(np.max(np.abs(self.rates) / self.reach))


def holdable_optimum(q_star: ArrayLike, q_davinci: ArrayLike, residual_scale: float,
                     controller: ViewTrackingController | None = None, restarts: int = 3, seed: int = 0
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Replace each configuration the residual cannot hold by the best-OR one it can hold nearby.

    Nelder-Mead from q* (and ``restarts - 1`` starts jittered by 0.05) within the joint limits; a result
    replaces q* only if it is holdable. Returns (q (n, 6), OR (n,), hold effort (n,)).
    """
    controller = make_controller("dimension_reduced") if controller is None else controller
    q_davinci = np.atleast_2d(q_davinci)
    frustum, davinci = Frustum(), DaVinciEndoscope()
    p_a, R_a = davinci.forward_kinematics(q_davinci)
    p_t, R_t = davinci.target_pose(q_davinci)
    robot = controller.robot.kernel_args()
    lower, upper = controller.robot.joint_limits
    rng = np.random.default_rng(seed)
    q_out = np.array(q_star, dtype=float)

    def overlap(q, k):
        return overlap_of_configuration(np.ascontiguousarray(q, dtype=float), p_a[k], R_a[k], robot, frustum.tan_half,
                                        frustum.near, frustum.far)

    effort_kernel = HoldEffort(controller, positive(residual_scale, "residual_scale", "fraction of the action scale"))

    def effort(q, k):
        return effort_kernel(q, p_t[k], R_t[k])

    efforts = np.array([effort(q_out[k], k) for k in range(len(q_out))])
    for k in np.flatnonzero(efforts > 1.0):
        def objective(q, k=k):
            q = np.clip(q, lower, upper)
            return -overlap(q, k) + PENALTY * max(0.0, effort(q, k) - HOLD_MARGIN)

        starts = [q_out[k]] + [q_out[k] + rng.normal(0.0, 0.05, 6) for _ in range(restarts - 1)]
        best = min((minimize(objective, x0, method="Nelder-Mead",
                             options={"maxfev": 1500, "xatol": 1e-6, "fatol": 1e-8}) for x0 in starts),
                   key=lambda result: result.fun)
        candidate = np.clip(best.x, lower, upper)
        if effort(candidate, k) <= 1.0:
            q_out[k] = candidate
            efforts[k] = effort(candidate, k)
    overlaps = np.array([overlap(q_out[k], k) for k in range(len(q_out))])
    return q_out, overlaps, efforts


def reach_ceiling(residual_scales: Iterable[float], grid: int = 21, effort: str = "quick", workers: int = 2,
                  progress: bool = True) -> dict[str, Any]:
    """Coverage (%) of the paper's grid that a perfect joint-rate residual of each scale reaches and holds.

    Returns {"optimum_percent": ..., "ceiling_percent": {scale: ...}}: a point counts if its holdable
    optimum has OR > 0.8 and hold effort <= 1.
    """
    q_davinci = coverage_grid(grid)
    optimum = view_tracking_optimum(q_davinci, effort=effort, workers=workers, progress=progress)
    result: dict[str, Any] = {"optimum_percent": float(np.mean(optimum["overlap"] > COVERAGE_THRESHOLD) * 100),
                              "ceiling_percent": {}}
    for scale in residual_scales:
        _, overlaps, efforts = holdable_optimum(optimum["q"], q_davinci, scale)
        held = (overlaps > COVERAGE_THRESHOLD) & (efforts <= 1.0)
        result["ceiling_percent"][float(scale)] = float(np.mean(held) * 100)
    return result
