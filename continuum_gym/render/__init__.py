"""Headless pybullet rendering: endoscope and external camera images, and occlusion measured in pixels.

- ``OcclusionScene``: the MBCR beside the rotating angled-lens endoscope (paper 000); cameras
  ``"external"`` and ``"endoscope"``; ``pixel_occlusion()`` of the current state.
- ``ViewTrackingScene``: the continuum endoscope and the da Vinci endoscope (paper 001); cameras
  ``"external"``, ``"endoscope"`` and ``"davinci"``.
- ``pixel_occlusion(robot, q, gamma, cone=None, resolution=128, scene=None)``: the fraction of the
  endoscope's circular field of view the robot covers.
- ``meshes`` and ``textures`` are numpy only; importing this package does not import pybullet: the
  scenes import it when they are built.
"""

from __future__ import annotations

import importlib
from typing import Any

# Lazy, so that ``continuum-gym render --help`` does not load the compiled geometry.
_EXPORTS = {
    "OcclusionScene": "continuum_gym.render.occlusion_scene",
    "ViewTrackingScene": "continuum_gym.render.view_scene",
    "pixel_occlusion": "continuum_gym.render.occlusion",
    "clear_scene_cache": "continuum_gym.render.occlusion",
    "CAMERAS_OCCLUSION": "continuum_gym.render.scene",
    "CAMERAS_VIEW_TRACKING": "continuum_gym.render.scene",
    "tissue_texture": "continuum_gym.render.textures",
}


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'continuum_gym.render' has no attribute {name!r}")


__all__ = sorted(_EXPORTS)
