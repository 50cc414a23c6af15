"""Occlusion measured in pixels: the fraction of the endoscope's circular field of view covered by the robot.

``pixel_occlusion`` renders the robot alone (no tissue) from the lens with pybullet's TinyRenderer and counts
the segmentation-mask pixels of robot bodies among the pixels whose ray lies within the cone half-angle beta
of the view axis (the inscribed disk of the square image with vertical field of view 2 beta).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.geometry.lens_cone import LensCone, resolve_cone
from continuum_gym.validation import as_finite, integer

if TYPE_CHECKING:
    from continuum_gym.render.occlusion_scene import OcclusionScene
    from continuum_gym.robots import MultiBackboneRobot

__all__ = ["pixel_occlusion", "clear_scene_cache"]

_SCENES: dict = {}
_MAX_CACHED_SCENES = 2


def _cached_scene(robot, cone):
    from continuum_gym.render.occlusion_scene import OcclusionScene

    key = (robot, cone)
    scene = _SCENES.get(key)
    if scene is None or scene.closed:
        while len(_SCENES) >= _MAX_CACHED_SCENES:
            _SCENES.pop(next(iter(_SCENES))).close()
        scene = OcclusionScene(robot=robot, cone=cone, tissue=None)
        _SCENES[key] = scene
    return scene


def clear_scene_cache() -> None:
    """Close the scenes ``pixel_occlusion`` keeps between calls (one per (robot, cone), at most 2)."""
    while _SCENES:
        _SCENES.popitem()[1].close()


def pixel_occlusion(robot: MultiBackboneRobot, q: ArrayLike, gamma: ArrayLike, cone: LensCone | None = None,
                    resolution: int = 128, scene: OcclusionScene | None = None) -> float | np.ndarray:
    """Fraction of the endoscope image's circular field of view covered by the robot (segmentation mask).

    Args:
        robot: ``MultiBackboneRobot``.
        q: configuration(s) (..., 7).
        gamma: endoscope rotation(s) (rad), broadcasting with q.shape[:-1].
        cone: ``LensCone`` (None: the paper's).
        resolution: side of the square endoscope image (pixels); the circular field of view holds about
            pi/4 of its pixels, so the result is quantised to ~1.3 / resolution**2.
        scene: an ``OcclusionScene`` with the same robot and cone to render in (it is left at the last
            configuration). Without it a cached scene without tissue is used (built on the first call, ~0.2 s).

    Returns:
        float for a single configuration, else an array of the broadcast shape. Robot parts beyond the
        tissue count (the tissue is hidden for this render); the endoscope shaft never counts.
    """
    from continuum_gym.robots import MultiBackboneRobot

    if not isinstance(robot, MultiBackboneRobot):
        raise ValueError(f"robot must be a MultiBackboneRobot; got {type(robot).__name__}")
    cone = resolve_cone(cone)
    resolution = integer(resolution, "resolution (pixels)", low=4, high=4096)
    q = as_finite(q, (robot.dof,), "q")
    gamma = as_finite(gamma, (), "gamma")
    shape = np.broadcast_shapes(q.shape[:-1], gamma.shape)
    if scene is None:
        scene = _cached_scene(robot, cone)
    elif scene.robot != robot or scene.cone != cone:
        raise ValueError("scene was built for another robot or cone")
    Q = np.broadcast_to(q, shape + (robot.dof,)).reshape(-1, robot.dof)
    G = np.broadcast_to(gamma, shape).reshape(-1)
    out = np.empty(len(Q))
    for i in range(len(Q)):
        scene.update(Q[i], G[i])
        out[i] = scene.pixel_occlusion(int(resolution))
    if shape == ():
        return float(out[0])
    return out.reshape(shape)
