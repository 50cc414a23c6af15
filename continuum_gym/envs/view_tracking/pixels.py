"""ViewTracking's image observations (issue 56): the continuum endoscope's view and the view asked for.

Two views of ``camera.view_tracking_scene``, the same modalities each: the continuum endoscope's camera
(``rgb``, ``depth``, ``segmentation``) and the da Vinci's, the view the surgeon asked for (``goal_rgb``,
``goal_depth``, ``goal_segmentation``). The task is then visual servoing: make the first image look like the
second. Both cameras have the frustum's full angle as vertical field of view; the tissue is the plane at the
height of the da Vinci home view's target. Segmentation ids: 1 the stem, segment 1 and the rigid cylinder,
2 segment 2 and the camera head, 3 the da Vinci (each view draws its own robot only, as the pybullet scene).

``state``: what the real system measures, [joints as the sensors read them (6: m, rad), the base
controller's command (6: m/s, rad/s)]. The target's pose is not in it: the goal images show it.

Pixel metric, in ``info`` of every image mode: ``view_centre_error_pct``, where the da Vinci view's centre
(its target point) appears in the continuum endoscope's image, as its distance from the principal point in %
of the image width (LapGym's SearchForPoint metric; ``camera.view_centre_error``), capped at 100 % (a target
behind the camera has no image), and ``view_centre_in_image`` (bool).

Under a model error the image shows the true endoscope (segment lengths scaled, the camera turned by its
mounting error at the tip): rows of one true endoscope share one compiled scene call.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from continuum_gym.envs.pixels import PixelSpec, mismatch_groups, with_rows
from continuum_gym.envs.spec import EpisodeMetric, Metric

#: Links per continuum segment of the drawn endoscope (``camera.view_tracking_scene``'s default).
N_PER_SEGMENT = 6
#: Both cameras' far clip (m).
FAR = 1.5
#: The view-centre error is capped at one image width (%): a target at or behind the camera plane has no image
#: (``camera.view_centre_error`` gives inf), and an episode's mean must stay a number; any error above ~71 % is
#: outside the image anyway (``view_centre_in_image`` says which).
MAX_CENTRE_ERROR_PCT = 100.0


def state(core: Any) -> np.ndarray:
    """[sensed joints, base command] (N, 12)."""
    return np.concatenate([core.sensed_joints(), core.base_cmd], axis=1)


def _frustum(core: Any) -> Any:
    from continuum_gym.geometry.frustum import Frustum

    frustum = getattr(core, "frustum", None)
    return frustum if isinstance(frustum, Frustum) else Frustum()


def davinci_configurations(core: Any, rows: np.ndarray) -> np.ndarray:
    """The da Vinci configuration of each row's target at its current time (len(rows), 4)."""
    return np.stack([core.davinci_configuration(int(row)) for row in rows])


def scene(core: Any, rows: np.ndarray, height: int, width: int) -> Any:
    """Both views' scene of ``rows`` at the core's true state and the targets' current configurations."""
    from scipy.spatial.transform import Rotation

    from continuum_gym.camera import view_tracking_scene
    from continuum_gym.camera.view_tracking import view_tracking_tubes

    robot, davinci = core.config.robot, core.config.davinci
    q, q_dv = np.ascontiguousarray(core.q[rows]), davinci_configurations(core, rows)
    out = view_tracking_scene(robot, davinci, _frustum(core), q, q_dv, width=width, height=height,
                              n_per_segment=N_PER_SEGMENT, far=FAR)
    for members, error in mismatch_groups(core, rows):
        if error is None:
            continue
        scale, calib = error
        true_robot = type(robot)(L1=robot.L1 * scale[0], Lm=robot.Lm, L2=robot.L2 * scale[1], Lc=robot.Lc,
                                 Le=robot.Le)
        m, count = len(members), out.tubes.count
        A, B, U = np.empty((m, count, 3)), np.empty((m, count, 3)), np.empty((m, count, 3))
        p_cam, R_cam, p_dv, R_dv = np.empty((m, 3)), np.empty((m, 3, 3)), np.empty((m, 3)), np.empty((m, 3, 3))
        view_tracking_tubes(np.ascontiguousarray(q[members]), np.ascontiguousarray(q_dv[members]),
                            true_robot.kernel_args(), davinci.kernel_args(), N_PER_SEGMENT, A, B, U, p_cam, R_cam,
                            p_dv, R_dv)
        mount = Rotation.from_rotvec(calib).as_matrix()  # the camera's true mounting at the tip (camera frame)
        out = with_rows(out, members, A, B, U, {"endoscope": (p_cam, R_cam @ mount)})
    return out


def metrics(core: Any, rows: np.ndarray, scene: Any, frames: dict) -> dict[str, np.ndarray]:
    """``view_centre_error_pct`` and ``view_centre_in_image`` of the rows' continuum endoscope images."""
    from continuum_gym.camera import view_centre_error

    poses = scene.view("davinci").cameras.poses  # the target point is Le along the da Vinci camera's axis (eq 2)
    points = poses[:, :3, 3] + core.config.davinci.Le * poses[:, :3, 2]
    error, in_image = view_centre_error(frames["endoscope"].cameras, points)
    return {"view_centre_error_pct": np.minimum(error, MAX_CENTRE_ERROR_PCT), "view_centre_in_image": in_image}


def make_spec() -> PixelSpec:
    """The ViewTracking ``PixelSpec``."""
    from continuum_gym.envs.view_tracking.config import ViewTrackingConfig

    return PixelSpec(
        env_id=ViewTrackingConfig.env_id, views=(("endoscope", ""), ("davinci", "goal_")), max_id=lambda core: 3,
        far=FAR, state_names=("sensed joints (6; m, rad)", "base command (6; m/s, rad/s)"),
        state=state, scene=scene, metrics=metrics,
        table_metrics=(Metric("mean_view_centre_error_pct", "mean view-centre error (% of the image width)", "%",
                              False),),
        episode_metrics=(EpisodeMetric("mean_view_centre_error_pct", "view_centre_error_pct"),))


PIXELS = make_spec()

__all__ = ["PIXELS", "state", "scene", "metrics", "davinci_configurations"]
