"""Analytic controllers of the two papers, with SB3's ``predict`` and a plain ``joint_rates`` call.

Every analytic controller is known by its name (``make_controller("projected_gradient", **kwargs)``); which ones
an environment offers as the residual's base is part of its config (``baselines``).
"""

from __future__ import annotations

from typing import Any, Literal, overload

from continuum_gym.baselines.base import Controller
from continuum_gym.baselines.occlusion import (
    MinimumNorm,
    OcclusionController,
    OcclusionLimits,
    ProjectedGradient,
)
from continuum_gym.baselines.view_tracking import (
    DimensionReduced,
    ResolvedRate,
    ViewTrackingController,
)
from continuum_gym.validation import closest

CONTROLLERS = {cls.name: cls for cls in (MinimumNorm, ProjectedGradient, ResolvedRate, DimensionReduced)}
#: Names of the controllers of each paper (derived from their base classes).
OCCLUSION_CONTROLLERS = tuple(name for name, cls in CONTROLLERS.items() if issubclass(cls, OcclusionController))
VIEW_TRACKING_CONTROLLERS = tuple(name for name, cls in CONTROLLERS.items() if issubclass(cls, ViewTrackingController))


@overload
def make_controller(name: Literal["minimum_norm"], **kwargs: Any) -> MinimumNorm: ...
@overload
def make_controller(name: Literal["projected_gradient"], **kwargs: Any) -> ProjectedGradient: ...
@overload
def make_controller(name: Literal["resolved_rate"], **kwargs: Any) -> ResolvedRate: ...
@overload
def make_controller(name: Literal["dimension_reduced"], **kwargs: Any) -> DimensionReduced: ...
@overload
def make_controller(name: str, **kwargs: Any) -> Controller: ...
def make_controller(name: str, **kwargs: Any) -> Controller:
    """Build a registered analytic controller by name; unknown names list the valid ones."""
    try:
        cls = CONTROLLERS[name]
    except (KeyError, TypeError):
        hint = closest(name, CONTROLLERS) if isinstance(name, str) else ""
        raise ValueError(f"unknown controller {name!r}{hint}; valid names: {sorted(CONTROLLERS)}") from None
    return cls(**kwargs)
__all__ = [
    "MinimumNorm", "ProjectedGradient", "OcclusionLimits", "ResolvedRate", "DimensionReduced",
    "make_controller", "CONTROLLERS", "OCCLUSION_CONTROLLERS", "VIEW_TRACKING_CONTROLLERS",
]
