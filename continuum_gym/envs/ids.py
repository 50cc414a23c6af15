"""The environment ids, for modules that must name one without importing its specification."""

OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"

__all__ = ["OCCLUSION", "VIEW"]
