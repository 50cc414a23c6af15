"""OcclusionAvoidance's image observations (issue 56): the angled endoscope's view of the true robot.

The image is what the endoscope sees, framed as the pybullet scene frames it (``camera.occlusion_scene``): a
square image with vertical field of view 2 beta and the circular field of view inscribed in it, the tissue
65 mm along the view axis. Segmentation ids: 1..n the robot's segments from base to tip (the inserted
straight part counts with segment 1), n + 1 the endoscope's shaft (never in its own view).

``state``: what the real system measures, [joints as the sensors read them (dof: rad, m for the insertion),
gamma (rad), the base controller's command (dof + 1: rad/s, m/s)]. Not the tip pose, the cone distances or
the VOI: the image shows them.

Pixel metric, in ``info`` of every image mode: ``image_occlusion``, the fraction of the circular field of view
the robot covers in the observed image (``camera.occlusion_fraction``; tissue drawn, so parts beyond it are
hidden; pybullet's ``pixel_occlusion=True`` renders without tissue).

Under a model error the image shows the true robot (segment lengths scaled) through the true lens (channel
offset and lens tilt off by the calibration error): rows of one true robot share one compiled scene call.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from continuum_gym.envs.pixels import PixelSpec, mismatch_groups, with_rows
from continuum_gym.envs.spec import EpisodeMetric, Metric

#: Links per segment of the drawn robot (``camera.occlusion_scene``'s default, the pybullet scene's).
N_PER_SEGMENT = 8
#: The scene's far clip (m): the depth of a ray that meets nothing.
FAR = 0.3


def state(core: Any) -> np.ndarray:
    """[sensed joints, gamma, base command] (N, 2 dof + 2)."""
    return np.concatenate([core.sensed_joints(), core.gamma[:, None], core.base_cmd], axis=1)


def max_id(core: Any) -> int:
    """n + 1, the shaft's id (n segments; never in the endoscope's own view)."""
    return int(core.config.robot.n_segments) + 1


def scene(core: Any, rows: np.ndarray, height: int, width: int) -> Any:
    """The endoscope's scene of ``rows`` at the core's true state."""
    from continuum_gym.camera import occlusion_scene
    from continuum_gym.camera.occlusion import occlusion_tubes
    from continuum_gym.geometry.lens_cone import LensCone

    robot, cone = core.config.robot, core.config.cone
    q, gamma = np.ascontiguousarray(core.q[rows]), np.ascontiguousarray(core.gamma[rows])
    out = occlusion_scene(robot, cone, q, gamma, width=width, height=height, n_per_segment=N_PER_SEGMENT, far=FAR)
    for members, error in mismatch_groups(core, rows):
        if error is None:
            continue
        scale, calib = error
        true_robot = dataclasses.replace(robot, lengths=tuple(np.asarray(robot.lengths) * scale))
        true_cone = LensCone(cone.d_o + calib[0], cone.alpha + calib[1], cone.beta, cone.lens_model)
        m, count = len(members), out.tubes.count
        A, B, U = np.empty((m, count, 3)), np.empty((m, count, 3)), np.empty((m, count, 3))
        p_cam, R_cam = np.empty((m, 3)), np.empty((m, 3, 3))
        occlusion_tubes(np.ascontiguousarray(q[members]), np.ascontiguousarray(gamma[members]),
                        true_robot.kernel_args(), true_cone.d_o, true_cone.alpha, true_cone.model_code, N_PER_SEGMENT,
                        A, B, U, p_cam, R_cam)
        out = with_rows(out, members, A, B, U, {"endoscope": (p_cam, R_cam)})
    return out


def metrics(core: Any, rows: np.ndarray, scene: Any, frames: dict) -> dict[str, np.ndarray]:
    """``image_occlusion``: the fraction of the circular field of view the robot covers."""
    from continuum_gym.camera import occlusion_fraction

    view = frames["endoscope"]
    return {"image_occlusion": occlusion_fraction(view.segmentation, view.cameras, core.config.cone.beta,
                                                  scene.n_segments)}


def make_spec() -> PixelSpec:
    """The OcclusionAvoidance ``PixelSpec``."""
    from continuum_gym.envs.occlusion.config import OcclusionConfig

    return PixelSpec(
        env_id=OcclusionConfig.env_id, views=(("endoscope", ""),), max_id=max_id, far=FAR,
        state_names=("sensed joints (dof; rad, m)", "gamma (rad)", "base command (dof + 1; rad/s, m/s)"),
        state=state, scene=scene, metrics=metrics, metric_modalities=("segmentation",),
        table_metrics=(Metric("mean_image_occlusion", "mean pixel occlusion of the endoscope image", "", False),),
        episode_metrics=(EpisodeMetric("mean_image_occlusion", "image_occlusion"),))


PIXELS = make_spec()

__all__ = ["PIXELS", "state", "scene", "metrics"]
