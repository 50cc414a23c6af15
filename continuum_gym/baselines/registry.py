"""Controller registry: ``make_controller("projected_gradient", **kwargs)``."""

from __future__ import annotations

from continuum_gym.baselines.occlusion import MinimumNorm, ProjectedGradient
from continuum_gym.baselines.view_tracking import DimensionReduced, ResolvedRate

CONTROLLERS = {
    MinimumNorm.name: MinimumNorm,
    ProjectedGradient.name: ProjectedGradient,
    ResolvedRate.name: ResolvedRate,
    DimensionReduced.name: DimensionReduced,
}
OCCLUSION_CONTROLLERS = (MinimumNorm.name, ProjectedGradient.name)
VIEW_TRACKING_CONTROLLERS = (ResolvedRate.name, DimensionReduced.name)


def make_controller(name: str, **kwargs):
    """Build a registered analytic controller by name; unknown names list the valid ones."""
    try:
        cls = CONTROLLERS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown controller {name!r}; valid names: {sorted(CONTROLLERS)}") from None
    return cls(**kwargs)
