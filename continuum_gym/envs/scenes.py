"""What a core asks of its pybullet scene (``EnvSpec.scene``) to render a row: typing protocols only."""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np


class RowScene(Protocol):
    """What a core asks of its pybullet scene (``spec.scene``, e.g. ``render.OcclusionScene``) to render a row."""

    def show_row(self, core: Any, row: int) -> None: ...

    def render(self, camera: str = ..., width: int = ..., height: int = ...) -> np.ndarray: ...

    def close(self) -> None: ...


class OcclusionRowScene(RowScene, Protocol):
    """A scene that also measures the pixel occlusion of the endoscope image (``render.OcclusionScene``)."""

    def pixel_occlusion(self, resolution: int = ...) -> float: ...


__all__ = ["RowScene", "OcclusionRowScene"]
