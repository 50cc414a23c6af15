"""Analytic controllers of the two papers, with SB3's ``predict`` and a plain ``joint_rates`` call."""

from continuum_gym.baselines.occlusion import (
    MinimumNorm,
    OcclusionLimits,
    ProjectedGradient,
)
from continuum_gym.baselines.registry import (
    CONTROLLERS,
    OCCLUSION_CONTROLLERS,
    VIEW_TRACKING_CONTROLLERS,
    make_controller,
)
from continuum_gym.baselines.view_tracking import DimensionReduced, ResolvedRate

__all__ = [
    "MinimumNorm", "ProjectedGradient", "OcclusionLimits", "ResolvedRate", "DimensionReduced",
    "make_controller", "CONTROLLERS", "OCCLUSION_CONTROLLERS", "VIEW_TRACKING_CONTROLLERS",
]
