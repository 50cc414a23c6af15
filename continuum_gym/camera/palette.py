"""Colours of the scenes' bodies (RGBA in [0, 1]), shared by the pybullet scenes and the batched renderer."""

from __future__ import annotations

from typing import Any

__all__ = ["COLORS", "CAVITY"]

#: colour (uint8 RGB) of rays that hit nothing in an endoscope image (an unlit cavity)
CAVITY = (14, 8, 8)

#: RGBA of each body (a tuple of RGBA for the robots' segments)
COLORS: dict[str, Any] = {
    "straight": (0.55, 0.57, 0.62, 1.0),
    "segments": ((0.80, 0.80, 0.84, 1.0), (0.62, 0.78, 0.90, 1.0), (0.90, 0.82, 0.55, 1.0)),
    "disk": (0.25, 0.27, 0.30, 1.0),
    "shaft": (0.12, 0.12, 0.14, 1.0),
    "lens": (0.20, 0.45, 0.85, 1.0),
    "cone": (1.0, 0.85, 0.10, 1.0),
    "endoscope": ((0.35, 0.75, 0.45, 1.0), (0.25, 0.45, 0.30, 1.0), (0.30, 0.65, 0.80, 1.0)),
    "camera_head": (0.10, 0.10, 0.12, 1.0),
    "davinci": (0.55, 0.58, 0.66, 1.0),
    "frustum_endoscope": (0.20, 0.95, 0.35, 1.0),
    "frustum_davinci": (0.25, 0.55, 1.00, 1.0),
}
