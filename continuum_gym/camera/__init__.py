"""The batched renderer of the analytic scenes: images of N robots at nearly the cost of a state step.

Without pybullet: one compiled call renders every row's robot tubes, the other endoscope's shaft and the
textured tissue through each row's camera (``docs/rendering.md``). It sits below the environments
(they will produce image observations from it) and imports only ``robots``, ``geometry`` and ``validation``.

- ``Cameras``, ``intrinsics``, ``pose_matrix``: the public pinhole model (``project``, radial distortion).
- ``occlusion_scene``, ``view_tracking_scene``: the two environments' scenes as batched arrays.
- ``Renderer``: renders a view of a scene into rgb / depth / segmentation buffers on a pool of threads.
- ``Randomisation``: lens distortion, light and pixel noise per row, from the caller's generator.
- ``occlusion_fraction``, ``view_centre_error``: the pixel metrics.
- ``tissue_texture``: the procedural tissue both renderers draw.

Importing this package loads nothing compiled; each name is imported when first used.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "Cameras": "continuum_gym.camera.model",
    "intrinsics": "continuum_gym.camera.model",
    "pose_matrix": "continuum_gym.camera.model",
    "occlusion_scene": "continuum_gym.camera.occlusion",
    "view_tracking_scene": "continuum_gym.camera.view_tracking",
    "Renderer": "continuum_gym.camera.renderer",
    "Frames": "continuum_gym.camera.renderer",
    "MODALITIES": "continuum_gym.camera.renderer",
    "allocate_frames": "continuum_gym.camera.renderer",
    "Randomisation": "continuum_gym.camera.randomisation",
    "Scene": "continuum_gym.camera.scene",
    "occlusion_fraction": "continuum_gym.camera.metrics",
    "view_centre_error": "continuum_gym.camera.metrics",
    "tissue_texture": "continuum_gym.camera.texture",
}


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'continuum_gym.camera' has no attribute {name!r}")


__all__ = sorted(_EXPORTS)
