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

from continuum_gym.render.occlusion import clear_scene_cache, pixel_occlusion
from continuum_gym.render.occlusion_scene import OcclusionScene
from continuum_gym.render.scene import CAMERAS_OCCLUSION, CAMERAS_VIEW_TRACKING
from continuum_gym.render.textures import tissue_texture
from continuum_gym.render.view_scene import ViewTrackingScene

__all__ = ["OcclusionScene", "ViewTrackingScene", "pixel_occlusion", "clear_scene_cache", "CAMERAS_OCCLUSION",
           "CAMERAS_VIEW_TRACKING", "tissue_texture"]
