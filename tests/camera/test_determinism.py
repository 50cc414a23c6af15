"""Determinism: the same seed gives the same images; the number of threads changes no bit; the nominal
images draw nothing from the generator."""

from __future__ import annotations

import threading

import numpy as np
import pytest

import continuum_gym.camera.renderer as renderer_module
from continuum_gym.camera import Randomisation, Renderer, occlusion_scene, view_tracking_scene
from continuum_gym.geometry.frustum import Frustum
from continuum_gym.robots import ContinuumEndoscope, DaVinciEndoscope, MultiBackboneRobot

#: k1 down to -0.07: a 90 degree view (ViewTracking) stays invertible above -0.074 (``camera.model.k1_lower_bound``)
RANDOM = Randomisation(k1=(-0.07, 0.1), light=(0.6, 1.4), ambient_share=(0.3, 0.6), noise_std=6.0)


@pytest.fixture(scope="module")
def scenes():
    rng = np.random.default_rng(0)
    robot = MultiBackboneRobot()
    q = robot.home + rng.normal(0.0, 0.25, (37, robot.dof)) * np.r_[np.ones(robot.dof - 1), 0.01]
    occlusion = occlusion_scene(robot, None, q, rng.uniform(-np.pi, np.pi, 37), width=48)
    endoscope, davinci = ContinuumEndoscope(), DaVinciEndoscope()
    q = endoscope.home + rng.normal(0.0, 0.15, (37, 6)) * [0.01, 1, 1, 1, 1, 1]
    q_dv = davinci.home + rng.uniform(-0.3, 0.3, (37, 4)) * [0.02, 1, 1, 1]
    view = view_tracking_scene(endoscope, davinci, Frustum(), q, q_dv, width=48, show_other=True)
    return {"occlusion": (occlusion, "endoscope"), "davinci": (view, "davinci"), "continuum": (view, "endoscope")}


@pytest.mark.parametrize("case", ["occlusion", "davinci", "continuum"])
def test_threads_change_no_bit(scenes, case):
    scene, view = scenes[case]
    one = Renderer(threads=1).render(scene, view, randomisation=RANDOM, rng=np.random.default_rng(5))
    two = Renderer(threads=2, block=4).render(scene, view, randomisation=RANDOM, rng=np.random.default_rng(5))
    for modality in ("rgb", "depth", "segmentation"):
        np.testing.assert_array_equal(getattr(one, modality), getattr(two, modality))
    np.testing.assert_array_equal(one.cameras.k1, two.cameras.k1)


def test_rows_rendered_on_two_threads_at_once_are_the_same(scenes, monkeypatch):
    """The kernel on two threads at the same time (each half of the rows from its own thread, both started before
    either is joined) writes the bits one call writes: its scratch is per call, its inputs read-only."""
    scene, view = scenes["occlusion"]
    one = Renderer(threads=1).render(scene, view, randomisation=RANDOM, rng=np.random.default_rng(5))
    used = []
    # Both threads wait here until the other has started: they are alive at the same time, so their idents
    # differ (an ident is reused once its thread has exited) and the kernel really runs twice at once.
    both = threading.Barrier(2, timeout=60)

    def halves(entry, args, num_rows, threads, block):
        def run(start, stop):
            used.append(threading.get_ident())
            both.wait()
            entry(start, stop, *args)

        workers = [threading.Thread(target=run, args=(0, num_rows // 2)),
                   threading.Thread(target=run, args=(num_rows // 2, num_rows))]
        for worker in workers:
            worker.start()
        for worker in workers:
            worker.join()

    monkeypatch.setattr(renderer_module, "run_blocks", halves)
    two = Renderer(threads=2).render(scene, view, randomisation=RANDOM, rng=np.random.default_rng(5))
    assert len(set(used)) == 2
    for modality in ("rgb", "depth", "segmentation"):
        np.testing.assert_array_equal(getattr(one, modality), getattr(two, modality))


def test_the_same_seed_gives_the_same_images_and_another_seed_others(scenes):
    scene, view = scenes["occlusion"]
    renderer = Renderer(threads=2, block=8)
    a = renderer.render(scene, view, randomisation=RANDOM, rng=np.random.default_rng(11))
    b = renderer.render(scene, view, randomisation=RANDOM, rng=np.random.default_rng(11))
    c = renderer.render(scene, view, randomisation=RANDOM, rng=np.random.default_rng(12))
    np.testing.assert_array_equal(a.rgb, b.rgb)
    np.testing.assert_array_equal(a.depth, b.depth)
    assert not np.array_equal(a.rgb, c.rgb)
    assert np.all(a.cameras.k1 != 0) and not np.array_equal(a.cameras.k1, c.cameras.k1)


def test_the_nominal_images_draw_nothing(scenes):
    scene, view = scenes["occlusion"]
    rng = np.random.default_rng(3)
    state = rng.bit_generator.state
    plain = Renderer(threads=1).render(scene, view, rng=rng)
    assert rng.bit_generator.state == state
    again = Renderer(threads=1).render(scene, view, randomisation=Randomisation(), rng=None)
    np.testing.assert_array_equal(plain.rgb, again.rgb)
    assert np.all(plain.cameras.k1 == 0)
    with pytest.raises(ValueError, match="rng"):
        Renderer(threads=1).render(scene, view, randomisation=RANDOM)


def test_noise_has_the_asked_spread(scenes):
    scene, view = scenes["continuum"]
    plain = Renderer(threads=1).render(scene, view)
    noisy = Renderer(threads=1).render(scene, view, randomisation=Randomisation(noise_std=5.0),
                                       rng=np.random.default_rng(0))
    difference = noisy.rgb.astype(float) - plain.rgb
    unclipped = (plain.rgb > 30) & (plain.rgb < 225)
    assert abs(difference[unclipped].mean()) < 0.1
    assert difference[unclipped].std() == pytest.approx(5.0, rel=0.05)
    np.testing.assert_array_equal(noisy.depth, plain.depth)


def test_randomisation_ranges_are_checked():
    with pytest.raises(ValueError, match="light"):
        Randomisation(light=(1.2, 0.8))
    with pytest.raises(ValueError, match="ambient_share"):
        Randomisation(ambient_share=(0.2, 1.5))
    with pytest.raises(ValueError, match="noise_std"):
        Randomisation(noise_std=-1.0)
