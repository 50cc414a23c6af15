"""The rasteriser against closed forms: a tube's silhouette and depth, a prism's, a plane's depth and texture,
clipping, the circular field of view, distortion, and the modalities and buffers of a render call."""

from __future__ import annotations

import math

import numpy as np
import pytest

from continuum_gym.camera import Randomisation, Renderer
from continuum_gym.camera.model import Cameras, intrinsics, pose_matrix
from continuum_gym.camera.primitives import FLAT, OPEN, ROUND
from continuum_gym.camera.scene import Scene, TexturedPlane, Tubes, View
from continuum_gym.camera.texture import MipPyramid, mip_pyramid
from continuum_gym.render.camera import fov_mask

W = H = 64
FOV = 1.0
NEAR, FAR = 1e-3, 0.5


def camera(n: int = 1, k1: float = 0.0, width: int = W, height: int = H) -> Cameras:
    """Cameras at the origin looking along +z_w (the world frame is the camera frame)."""
    T = np.broadcast_to(pose_matrix(np.zeros(3), np.eye(3)), (n, 4, 4))
    return Cameras(np.broadcast_to(intrinsics(width, height, FOV), (n, 3, 3)), T, width, height, NEAR, FAR, k1)


def tube_scene(a, b, radius, sides=0, caps=(OPEN, FLAT), u=(0.0, 1.0, 0.0), cameras=None, plane=None, fov=None):
    a, b = np.asarray(a, float).reshape(-1, 1, 3), np.asarray(b, float).reshape(-1, 1, 3)
    n = a.shape[0]
    tubes = Tubes(a, b, np.broadcast_to(np.asarray(u, float), (n, 1, 3)), [radius], [sides], [caps], [1],
                  [[0.5, 0.5, 0.5]], [0])
    cams = camera(n) if cameras is None else cameras
    return Scene(tubes, {"endoscope": View(cams, (0,), fov, plane)}, 1)


def rays(cams: Cameras) -> np.ndarray:
    return cams.pixel_rays()[0]


def test_a_round_tube_has_the_analytic_silhouette_and_depth():
    """A tube of radius r along x at depth D: rays (x, y, 1) meet it where |y| <= r / sqrt(D^2 - r^2), at depth
    t = (D - sqrt(D^2 - (1 + y^2)(D^2 - r^2))) / (1 + y^2)."""
    D, r = 0.1, 0.004
    scene = tube_scene([-0.5, 0.0, D], [0.5, 0.0, D], r)
    frames = Renderer(threads=1).render(scene)
    y = rays(scene.views["endoscope"].cameras)[:, 0, 1]
    limit = r / math.sqrt(D * D - r * r)
    inside = np.abs(y) <= limit
    assert inside.sum() >= 4  # about 2 f r / D = 5 pixels wide
    seg = frames.segmentation[0, :, :, 0]
    np.testing.assert_array_equal(seg == 1, np.broadcast_to(inside[:, None], seg.shape))
    t = (D - np.sqrt(np.maximum(D * D - (1.0 + y**2) * (D * D - r * r), 0.0))) / (1.0 + y**2)
    depth = frames.depth[0, :, :, 0]
    np.testing.assert_allclose(depth[inside], np.broadcast_to(t[:, None], depth.shape)[inside], rtol=1e-6)
    np.testing.assert_array_equal(depth[~inside], FAR)  # no plane: the far distance


def test_a_prism_has_the_polygons_silhouette_and_facet_depth():
    """An octagonal prism along x at depth D, a vertex toward u = (0, cos phi, sin phi): in the y-z plane the ray of
    slope y meets it exactly when the octagon reaches the ray's line; its depth is the nearest face's."""
    D, r, phi = 0.1, 0.004, 0.3
    u = (0.0, math.cos(phi), math.sin(phi))
    scene = tube_scene([-0.5, 0.0, D], [0.5, 0.0, D], r, sides=8, u=u)
    frames = Renderer(threads=1).render(scene)
    y = rays(scene.views["endoscope"].cameras)[:, 0, 1]
    angles = phi + np.arange(8) * math.pi / 4  # vertex angles in the (y, z) plane
    vy, vz = r * np.cos(angles), D + r * np.sin(angles)
    # the ray (y, 1) meets the polygon when the vertices are not all on one side of it
    side = vy[None, :] - y[:, None] * vz[None, :]
    inside = (side.min(axis=1) <= 0.0) & (side.max(axis=1) >= 0.0)
    seg = frames.segmentation[0, :, 0, 0]
    np.testing.assert_array_equal(seg == 1, inside)
    # depth: the largest entry across the faces (half-planes n . (p - c) <= apothem)
    normals = angles + math.pi / 8
    ny, nz = np.cos(normals), np.sin(normals)
    apothem = r * math.cos(math.pi / 8)
    t_face = (apothem + ny[None, :] * 0.0 + nz[None, :] * D) / (ny[None, :] * y[:, None] + nz[None, :])
    entering = (ny[None, :] * y[:, None] + nz[None, :]) < 0.0
    t = np.where(entering, t_face, -np.inf).max(axis=1)
    np.testing.assert_allclose(frames.depth[0, inside, 0, 0], t[inside], rtol=1e-6)


def test_flat_and_round_ends_seen_end_on():
    """Looking down a tube's axis: a flat end is a disk at its distance, a round end a sphere; an open end shows
    nothing (the inside is back faces)."""
    D, r, L = 0.1, 0.004, 0.02
    y = rays(camera())[:, W // 2, 1]
    centre = (H // 2 - 1, W // 2)  # the principal point's pixel
    for caps, depth in (((OPEN, FLAT), D), ((OPEN, ROUND), D - r)):
        scene = tube_scene([0.0, 0.0, D + L], [0.0, 0.0, D], r, caps=caps)  # a toward the back, b facing the camera
        frames = Renderer(threads=1).render(scene)
        assert frames.depth[0, centre[0], centre[1], 0] == pytest.approx(depth, rel=1e-6)
        covered = frames.segmentation[0, :, W // 2, 0] == 1
        assert covered.sum() >= 3
        assert np.all(np.abs(y[covered]) <= r / (D - (r if caps[1] == ROUND else 0.0)) + 1e-12)
    scene = tube_scene([0.0, 0.0, D + L], [0.0, 0.0, D], r, caps=(OPEN, OPEN))
    assert not np.any(Renderer(threads=1).render(scene).segmentation)


def test_a_plane_has_the_analytic_depth_and_texture():
    """A plane at distance d facing the camera: depth d everywhere (the ray's length d / cos(angle)); tilted by
    theta about x: depth d / (1 - y tan(theta)). Its texel at the image centre is the one its coordinates name."""
    d = 0.08
    checker = np.zeros((4, 4, 3), dtype=np.uint8)
    checker[::2, ::2] = checker[1::2, 1::2] = 200
    checker[..., 1] = np.arange(4)[None, :] * 60  # columns differ in green
    texture = MipPyramid(checker)
    for theta in (0.0, 0.4):
        normal = np.array([0.0, math.sin(theta), -math.cos(theta)])
        axis_y = np.array([0.0, math.cos(theta), math.sin(theta)])
        plane = TexturedPlane("world", [0.0, 0.0, d], [1.0, 0.0, 0.0], axis_y, normal, [1.0, 1.0], [1.0, 1.0],
                              texture)
        scene = tube_scene([0.0, 0.0, -1.0], [0.0, 0.0, -0.9], 0.001, plane=plane)  # the tube is behind
        frames = Renderer(threads=1).render(scene)
        r = rays(scene.views["endoscope"].cameras)
        expected = d / (1.0 - r[..., 1] * math.tan(theta))
        np.testing.assert_allclose(frames.depth[0, ..., 0], expected, rtol=1e-6)
        if theta == 0.0:
            length = frames.depth[0, ..., 0] * np.linalg.norm(r, axis=-1)
            np.testing.assert_allclose(length, d / np.cos(np.arctan(np.hypot(r[..., 0], r[..., 1]))), rtol=1e-6)
            # the principal point's ray hits (0, 0): texture coordinate (1, 1) tiles * 4 texels -> texel (4, 4) mod 4;
            # texture rows run against v: row (-1 - 4) mod 4 = 3, column 0; facing the camera, cos = 1
            i, j = H // 2 - 1, W // 2
            np.testing.assert_array_equal(frames.rgb[0, i, j], checker[3, 0])
    assert not np.any(frames.segmentation)
    # seen from behind, the plane is not drawn (pybullet culls back faces)
    back = TexturedPlane("world", [0.0, 0.0, d], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0],
                         [1.0, 1.0], texture)
    frames = Renderer(threads=1).render(tube_scene([0.0, 0.0, -1.0], [0.0, 0.0, -0.9], 0.001, plane=back))
    np.testing.assert_array_equal(frames.depth, FAR)


def test_near_and_far_clip():
    r = 0.002
    for depth in (0.5 * NEAR, 1.2 * FAR):
        scene = tube_scene([-0.1, 0.0, depth], [0.1, 0.0, depth], r * depth * 10)
        assert not np.any(Renderer(threads=1).render(scene).segmentation)
    # a tube through the camera plane is drawn where it is in front of near
    scene = tube_scene([0.0, 0.02, -0.05], [0.0, 0.02, 0.2], r, caps=(FLAT, FLAT))
    seg = Renderer(threads=1).render(scene).segmentation[0, ..., 0]
    assert np.any(seg)


def test_the_circular_field_of_view_is_pybullets_and_zero_outside():
    half = 0.4
    plane = TexturedPlane("camera", [0.0, 0.0, 0.05], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0],
                          [1.0, 1.0], [1.0, 1.0], mip_pyramid(64, 0, 1.0))
    scene = tube_scene([-0.1, 0.0, 0.05], [0.1, 0.0, 0.04], 0.003, plane=plane, fov=half)
    frames = Renderer(threads=1).render(scene)
    inside = fov_mask(W, H, FOV, half)
    assert 0.3 < inside.mean() < 0.9
    assert np.all(frames.rgb[0][~inside] == 0) and np.all(frames.depth[0][~inside] == 0)
    assert np.all(frames.segmentation[0][~inside] == 0)
    assert np.all(frames.depth[0][inside] > 0) and np.all(frames.rgb[0][inside].max(axis=-1) > 0)


def test_a_distorted_camera_draws_a_point_where_project_puts_it():
    """A small sphere (a round end on a very short tube) lands, under radial distortion, where ``project``
    puts its centre: its mask's centroid is there to a fraction of a pixel."""
    centre = np.array([0.025, -0.018, 0.06])
    for k1 in (-0.15, 0.0, 0.2):
        cams = camera(k1=k1, width=128, height=128)
        scene = tube_scene(centre - [0.0, 0.0, 1e-6], centre, 0.002, caps=(OPEN, ROUND), cameras=cams)
        seg = Renderer(threads=1).render(scene).segmentation[0, ..., 0]
        rows, columns = np.nonzero(seg)
        assert len(rows) > 20
        np.testing.assert_allclose([columns.mean(), rows.mean()], cams.project(centre)[0], atol=0.5)


def test_modalities_and_buffers():
    """Any subset of modalities gives the same pixels as all of them; ``out`` buffers are written in place."""
    scene = tube_scene([[-0.05, 0.0, 0.1], [0.0, -0.05, 0.1]], [[0.05, 0.01, 0.08], [0.01, 0.05, 0.12]], 0.005, sides=8,
                       caps=(OPEN, ROUND))
    renderer = Renderer(threads=1)
    full = renderer.render(scene)
    for modality in ("rgb", "depth", "segmentation"):
        alone = renderer.render(scene, modalities=(modality,))
        np.testing.assert_array_equal(getattr(alone, modality), getattr(full, modality))
        assert all(getattr(alone, m) is None for m in ("rgb", "depth", "segmentation") if m != modality)
    out = {"depth": np.full((2, H, W, 1), -1.0, dtype=np.float32)}
    frames = renderer.render(scene, modalities=("depth",), out=out)
    assert frames.depth is out["depth"]
    np.testing.assert_array_equal(out["depth"], full.depth)
    with pytest.raises(ValueError, match="out\\['depth'\\]"):
        renderer.render(scene, modalities=("depth",), out={"depth": np.zeros((2, H, W), dtype=np.float32)})
    with pytest.raises(ValueError, match="modalities"):
        renderer.render(scene, modalities=("colour",))
    with pytest.raises(ValueError, match="view"):
        renderer.render(scene, "davinci")


def test_light_scales_the_shading():
    scene = tube_scene([-0.05, 0.0, 0.1], [0.05, 0.0, 0.1], 0.01)
    dim = Renderer(threads=1).render(scene, randomisation=Randomisation(light=(0.5, 0.5)))
    nominal = Renderer(threads=1).render(scene)
    lit = nominal.segmentation[0, ..., 0] == 1
    ratio = dim.rgb[0][lit].astype(float) / np.maximum(nominal.rgb[0][lit], 1)
    assert np.all(np.abs(ratio[nominal.rgb[0][lit] > 40] - 0.5) < 0.02)
