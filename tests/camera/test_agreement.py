"""The batched renderer agrees with the pybullet scenes (TinyRenderer) at 128 x 128, on 225 states per environment
drawn from the environments' task pools (``conftest.py``).

Measured (225 states each; the thresholds leave a margin):

- OcclusionAvoidance, robot masks: aggregate IoU 0.995; per state min 0.979 / 5th percentile 0.989 / mean 0.995
  (over the states where either mask is non-empty: all 225). Round tubes (``faceted=False``) instead of the
  meshes' prisms: aggregate 0.969, min 0.930;
- pixel occlusion vs ``OcclusionScene.pixel_occlusion``: max difference 0.11 percentage points (mean 0.035);
- depth within 0.5 mm: 99.86 % of all pixels (worst state 99.65 %), 98.8 % of the robot's pixels;
- ViewTracking: the continuum endoscope as the da Vinci camera sees it (both robots drawn; in view in 54 of the
  225 states): aggregate IoU 0.9996, min 0.995; depth within 0.5 mm on 100 % / 99.999 % of the pixels of the
  continuum endoscope's / the da Vinci's view.
"""

from __future__ import annotations

import numpy as np
import pytest

from continuum_gym.camera import Renderer, occlusion_fraction, occlusion_scene, view_tracking_scene
from continuum_gym.render import OcclusionScene, ViewTrackingScene

SIZE = 128
MIN_STATES = 200
IOU_AGGREGATE_MIN = 0.97
IOU_P5_MIN = 0.97
IOU_MIN = 0.95
OCCLUSION_MAX_DIFFERENCE = 0.01
DEPTH_TOLERANCE = 5e-4  # m
DEPTH_SHARE_MIN = 0.95


def _iou(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, float]:
    """Per-state IoU over the states where either mask is non-empty, and the aggregate (pooled) IoU."""
    inter = np.sum(a & b, axis=(1, 2))
    union = np.sum(a | b, axis=(1, 2))
    return inter[union > 0] / union[union > 0], float(inter.sum() / union.sum())


@pytest.fixture(scope="module")
def occlusion_pybullet(occlusion_states):
    """pybullet's robot masks, pixel occlusion and full-scene depth of every state."""
    core, q, gamma = occlusion_states
    masks, occlusion, depth = [], [], []
    with OcclusionScene(robot=core.robot, cone=core.cone, circular_fov=False, cache_background=False) as scene:
        for k in range(len(q)):
            scene.update(q[k], gamma[k])
            masks.append(scene.segmentation(SIZE, SIZE))
            occlusion.append(scene.pixel_occlusion(SIZE))
            scene.render("endoscope", SIZE, SIZE)
            depth.append(scene.last_depth())
    return np.array(masks), np.array(occlusion), np.array(depth)


def test_enough_states(occlusion_states, view_tracking_states):
    assert len(occlusion_states[1]) >= MIN_STATES and len(view_tracking_states[1]) >= MIN_STATES
    # the states differ: resets and random rollouts, not one pose repeated
    assert len(np.unique(occlusion_states[1].round(6), axis=0)) >= MIN_STATES
    assert len(np.unique(view_tracking_states[1].round(6), axis=0)) >= MIN_STATES


def test_occlusion_robot_masks_agree(occlusion_states, occlusion_pybullet):
    core, q, gamma = occlusion_states
    masks = occlusion_pybullet[0]
    scene = occlusion_scene(core.robot, core.cone, q, gamma, width=SIZE, tissue=False, circular_fov=False)
    seg = Renderer(threads=1).render(scene, modalities=("segmentation",)).segmentation[..., 0]
    mine = (seg >= 1) & (seg <= scene.n_segments)
    per_state, aggregate = _iou(mine, masks)
    assert len(per_state) >= MIN_STATES - 10  # the robot is in view in (nearly) every state
    assert aggregate >= IOU_AGGREGATE_MIN
    assert np.percentile(per_state, 5) >= IOU_P5_MIN
    assert per_state.min() >= IOU_MIN


def test_round_tubes_are_what_the_prisms_correct(occlusion_states, occlusion_pybullet):
    """Without the meshes' prism silhouettes the masks agree less: the faceting is what matches pybullet."""
    core, q, gamma = occlusion_states
    masks = occlusion_pybullet[0]
    seg = {}
    for faceted in (True, False):
        scene = occlusion_scene(core.robot, core.cone, q, gamma, width=SIZE, tissue=False, circular_fov=False,
                                faceted=faceted)
        seg[faceted] = Renderer(threads=1).render(scene, modalities=("segmentation",)).segmentation[..., 0]
    iou = {f: _iou((s >= 1) & (s <= 3), masks)[1] for f, s in seg.items()}
    assert iou[True] > iou[False] + 0.01


def test_pixel_occlusion_agrees(occlusion_states, occlusion_pybullet):
    core, q, gamma = occlusion_states
    scene = occlusion_scene(core.robot, core.cone, q, gamma, width=SIZE, tissue=False)
    frames = Renderer(threads=1).render(scene, modalities=("segmentation",))
    mine = occlusion_fraction(frames.segmentation, frames.cameras, core.cone.beta, scene.n_segments)
    pybullet = occlusion_pybullet[1]
    assert pybullet.max() > 0.05  # some states are well occluded
    assert np.max(np.abs(mine - pybullet)) <= OCCLUSION_MAX_DIFFERENCE


def test_occlusion_depth_agrees(occlusion_states, occlusion_pybullet):
    core, q, gamma = occlusion_states
    scene = occlusion_scene(core.robot, core.cone, q, gamma, width=SIZE, circular_fov=False)
    depth = Renderer(threads=1).render(scene, modalities=("depth",)).depth[..., 0]
    close = np.abs(depth - occlusion_pybullet[2]) <= DEPTH_TOLERANCE
    assert close.mean() >= DEPTH_SHARE_MIN
    assert close.mean(axis=(1, 2)).min() >= DEPTH_SHARE_MIN
    # the robot's own pixels too, not only the tissue at 65 mm
    robot = occlusion_pybullet[0]
    assert close[robot].mean() >= DEPTH_SHARE_MIN


def test_view_tracking_agrees(view_tracking_states):
    """Tissue depth in both views, and the continuum endoscope's mask as the da Vinci camera sees it."""
    core, q, q_dv = view_tracking_states
    scene = view_tracking_scene(core.robot, core.davinci, core.frustum, q, q_dv, width=SIZE, show_other=True)
    renderer = Renderer(threads=1)
    mine = {view: renderer.render(scene, view, modalities=("depth", "segmentation")) for view in scene.views}
    masks, depths = [], {"endoscope": [], "davinci": []}
    with ViewTrackingScene.from_core(core) as pybullet:
        groups = {"endoscope", "davinci", "tissue", "tissue_frame"}
        robot_ids = np.array(pybullet.body_ids["endoscope"])
        for k in range(len(q)):
            pybullet.update(q[k], q_dv[k])
            for view in depths:
                _, ids, depth = pybullet.camera_image(view, groups, SIZE, SIZE)
                depths[view].append(depth)
                if view == "davinci":
                    masks.append(np.isin(ids, robot_ids))
    for view, depth in depths.items():
        close = np.abs(mine[view].depth[..., 0] - np.array(depth)) <= DEPTH_TOLERANCE
        assert close.mean(axis=(1, 2)).min() >= DEPTH_SHARE_MIN, view
    seg = mine["davinci"].segmentation[..., 0]
    per_state, aggregate = _iou((seg == 1) | (seg == 2), np.array(masks))
    assert len(per_state) >= 20  # the continuum endoscope is in the da Vinci's view in some states
    assert aggregate >= IOU_AGGREGATE_MIN
    assert np.median(per_state) >= IOU_AGGREGATE_MIN


@pytest.mark.parametrize("lens_model", ["literal", "physical"])
def test_the_endoscope_cameras_are_the_pybullet_scenes(occlusion_states, lens_model):
    """Every row's camera pose is the pybullet scene's ``camera_pose``, for both lens models."""
    from continuum_gym.geometry.lens_cone import LensCone

    core, q, gamma = occlusion_states
    cone = LensCone(lens_model=lens_model)
    cameras = occlusion_scene(core.robot, cone, q[:20], gamma[:20], width=SIZE).views["endoscope"].cameras
    with OcclusionScene(robot=core.robot, cone=cone, tissue=None) as scene:
        for k in range(20):
            scene.update(q[k], gamma[k])
            p, R = scene.camera_pose("endoscope")
            np.testing.assert_allclose(cameras.positions[k], p, atol=1e-15)
            np.testing.assert_allclose(cameras.rotations[k], R, atol=1e-15)


def test_the_view_tracking_cameras_are_the_pybullet_scenes(view_tracking_states):
    core, q, q_dv = view_tracking_states
    views = view_tracking_scene(core.robot, core.davinci, core.frustum, q[:20], q_dv[:20], width=SIZE).views
    with ViewTrackingScene.from_core(core) as scene:
        for k in range(20):
            scene.update(q[k], q_dv[k])
            for view in ("endoscope", "davinci"):
                p, R = scene.camera_pose(view)
                np.testing.assert_allclose(views[view].cameras.positions[k], p, atol=1e-15)
                np.testing.assert_allclose(views[view].cameras.rotations[k], R, atol=1e-15)
