"""Frustum geometry and the overlap ratio OR = vol(F_a ∩ F_b) / vol(F_a) (paper-notes §2.4, §2.8)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from numba import njit
from scipy.integrate import quad
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation

from continuum_gym.geometry.frustum import FACE_VERTICES, Frustum
from continuum_gym.geometry.overlap import make_overlap_work, overlap_ratio, overlap_ratio_in, overlap_ratio_nb
from continuum_gym.geometry.overlap_reference import (
    overlap_ratio_monte_carlo,
    overlap_ratio_reference,
)
from tests.conftest import load_reference

REFERENCE = load_reference()
OVERLAP_CASES = REFERENCE["overlap"]
TOL = 1e-9  # exact divergence-theorem volume vs the reference implementation


def _case(entry):
    return tuple(np.array(entry[key], dtype=float) for key in ("p_a", "R_a", "p_b", "R_b"))


def _rot(rotvec) -> np.ndarray:
    return Rotation.from_rotvec(rotvec).as_matrix()


def _random_pose(rng):
    return rng.uniform(-0.05, 0.05, 3), Rotation.random(random_state=rng).as_matrix()


def _perturbed_pair(rng, max_angle=1.0, max_shift=0.05):
    """Pose b = pose a moved by a random rotation (angle <= max_angle) and shift (|component| <= max_shift)."""
    p_a, R_a = _random_pose(rng)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    R_b = R_a @ _rot(rng.uniform(0.0, max_angle) * axis)
    p_b = p_a + rng.uniform(-max_shift, max_shift, 3)
    return p_a, R_a, p_b, R_b


def _fast(p_a, R_a, p_b, R_b, frustum=None) -> float:
    return float(overlap_ratio(p_a, R_a, p_b, R_b, frustum))


def _translated_closed_form(shift, frustum: Frustum) -> float:
    """OR for F_b = F_a translated by ``shift`` (camera frame of a), same orientation, by 1-D integration.

    At depth z (frame a) both cross-sections are axis-aligned squares: F_a's centred at 0 with
    half-width t z, F_b's centred at (dx, dy) with half-width t (z − dz); integrate the area of their
    intersection over the common depth range.
    """
    dx, dy, dz = shift
    t = frustum.tan_half

    def overlap_1d(centre, half_a, half_b):
        return max(0.0, min(half_a, centre + half_b) - max(-half_a, centre - half_b))

    def area(z):
        return overlap_1d(dx, t * z, t * (z - dz)) * overlap_1d(dy, t * z, t * (z - dz))

    low, high = max(frustum.near, frustum.near + dz), min(frustum.far, frustum.far + dz)
    if high <= low:
        return 0.0
    volume, _ = quad(area, low, high, epsabs=1e-16, epsrel=1e-13, limit=200)
    return volume / frustum.volume


# ----------------------------------------------------------------------------------------------
# Frustum
# ----------------------------------------------------------------------------------------------
def test_frustum_defaults_match_reference():
    frustum = Frustum()
    expected = REFERENCE["overlap_frustum"]
    assert frustum.full_angle == pytest.approx(expected["full_angle_rad"], abs=1e-15)
    assert frustum.near == expected["near_m"] and frustum.far == expected["far_m"]
    assert frustum.half_angle == pytest.approx(np.pi / 4, abs=1e-15)
    assert frustum.tan_half == pytest.approx(1.0, abs=1e-15)
    assert frustum.volume == pytest.approx(expected["volume_m3"], rel=1e-14)


@pytest.mark.parametrize("frustum", [Frustum(), Frustum(np.deg2rad(60.0), 0.01, 0.2)])
def test_frustum_vertices_halfspaces_volume(frustum):
    rng = np.random.default_rng(0)
    p, R = _random_pose(rng)
    vertices = frustum.vertices(p, R)
    halfspaces = frustum.halfspaces(p, R)
    assert vertices.shape == (8, 3) and halfspaces.shape == (6, 4)
    assert ConvexHull(vertices).volume == pytest.approx(frustum.volume, rel=1e-12)
    np.testing.assert_allclose(np.linalg.norm(halfspaces[:, :3], axis=1), 1.0, atol=1e-15)
    distances = vertices @ halfspaces[:, :3].T + halfspaces[:, 3]  # (8 vertices, 6 planes)
    assert np.all(distances <= 1e-15)
    for face, corners in enumerate(FACE_VERTICES):
        np.testing.assert_allclose(distances[corners, face], 0.0, atol=1e-15)
        # counter-clockwise about the outward normal
        v = vertices[corners]
        assert np.cross(v[1] - v[0], v[2] - v[0]) @ halfspaces[face, :3] > 0.0
    # apex at p, axis R[:, 2]: the centroid of the far face is p + far R[:, 2]
    np.testing.assert_allclose(vertices[4:].mean(axis=0), p + frustum.far * R[:, 2], atol=1e-15)
    # batched
    p_batch = rng.uniform(-0.05, 0.05, (2, 3, 3))
    assert frustum.vertices(p_batch, R).shape == (2, 3, 8, 3)
    assert frustum.halfspaces(p_batch, R).shape == (2, 3, 6, 4)
    np.testing.assert_allclose(frustum.halfspaces(p_batch, R)[1, 2], frustum.halfspaces(p_batch[1, 2], R))


def test_frustum_sample_uniform():
    frustum = Frustum()
    samples = frustum.sample_uniform(200_000, np.random.default_rng(0))
    assert samples.shape == (200_000, 3)
    planes = frustum.local_halfspaces()
    assert np.all(samples @ planes[:, :3].T + planes[:, 3] <= 1e-15)
    # uniform in volume: E[z] = 3 (far^4 - near^4) / (4 (far^3 - near^3))
    near, far = frustum.near, frustum.far
    mean_z = 3.0 * (far**4 - near**4) / (4.0 * (far**3 - near**3))
    assert samples[:, 2].mean() == pytest.approx(mean_z, abs=2e-4)
    assert abs(np.mean(samples[:, 0] / samples[:, 2])) < 5e-3
    np.testing.assert_array_equal(samples, frustum.sample_uniform(200_000, 0))  # seed == Generator(seed)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"full_angle": 0.0}, "full_angle"),
        ({"full_angle": np.pi}, "full_angle"),
        ({"full_angle": -0.5}, "full_angle"),
        ({"full_angle": np.nan}, "full_angle"),
        ({"full_angle": "wide"}, "full_angle"),
        ({"near": 0.0}, "near"),
        ({"near": -0.01}, "near"),
        ({"near": np.inf}, "near"),
        ({"far": 0.03}, "far"),
        ({"far": 0.01}, "far"),
        ({"far": np.nan}, "far"),
        ({"near": 0.2, "far": 0.1}, "far"),
    ],
)
def test_frustum_rejects_bad_parameters(kwargs, name):
    with pytest.raises(ValueError, match=name):
        Frustum(**kwargs)


def test_frustum_is_frozen_and_checks_sample_arguments():
    frustum = Frustum()
    with pytest.raises(AttributeError):
        frustum.near = 0.05
    with pytest.raises(ValueError, match="n must"):
        frustum.sample_uniform(0, 0)
    with pytest.raises(ValueError, match="p must"):
        frustum.vertices([0.0, 0.0], np.eye(3))
    with pytest.raises(ValueError, match="R must"):
        frustum.halfspaces(np.zeros(3), np.eye(2))


# ----------------------------------------------------------------------------------------------
# reference values, scipy reference, Monte Carlo
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("index", range(len(OVERLAP_CASES)))
def test_reference_values(index):
    entry = OVERLAP_CASES[index]
    pose = _case(entry)
    fast = overlap_ratio(*pose)
    assert isinstance(fast, np.ndarray) and fast.shape == ()
    assert float(fast) == pytest.approx(entry["overlap_ratio"], abs=TOL)
    assert overlap_ratio_reference(*pose) == pytest.approx(entry["overlap_ratio"], abs=TOL)


def test_fast_kernel_matches_scipy_reference_on_random_pairs():
    rng = np.random.default_rng(1234)
    fast, reference = [], []
    for k in range(300):
        # most pairs: moderate perturbations (OR across (0, 1)); one in six: large shifts (many
        # zeros); one in six: small perturbations (OR near 1)
        if k % 6 == 0:
            pair = _perturbed_pair(rng, max_angle=1.0, max_shift=0.2)
        elif k % 6 == 1:
            pair = _perturbed_pair(rng, max_angle=0.2, max_shift=0.01)
        else:
            pair = _perturbed_pair(rng, max_angle=1.0, max_shift=0.05)
        fast.append(_fast(*pair))
        reference.append(overlap_ratio_reference(*pair))
    fast, reference = np.array(fast), np.array(reference)
    np.testing.assert_allclose(fast, reference, rtol=0.0, atol=TOL)
    # the distribution exercises zeros and the whole open interval
    assert np.sum(reference == 0.0) >= 10
    counts, _ = np.histogram(reference[reference > 0.0], bins=5, range=(0.0, 1.0))
    assert np.all(counts >= 10), counts


def test_non_default_frustum_matches_scipy_reference():
    frustum = Frustum(np.deg2rad(70.0), 0.005, 0.08)
    rng = np.random.default_rng(7)
    for _ in range(40):
        pair = _perturbed_pair(rng, max_angle=1.0, max_shift=0.03)
        assert _fast(*pair, frustum) == pytest.approx(overlap_ratio_reference(*pair, frustum), abs=TOL)
    p, R = _random_pose(rng)
    assert _fast(p, R, p, R, frustum) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("index", [0, 1, 3])
def test_monte_carlo_agrees(index):
    """paper-notes §2.4: 4e5 samples agree with the exact value within 2e-3 (seeded, so deterministic)."""
    pose = _case(OVERLAP_CASES[index])
    estimate = overlap_ratio_monte_carlo(*pose, n_samples=400_000, rng=np.random.default_rng(0))
    assert estimate == pytest.approx(OVERLAP_CASES[index]["overlap_ratio"], abs=2e-3)
    assert estimate == pytest.approx(_fast(*pose), abs=2e-3)


def test_monte_carlo_random_pair():
    pair = _perturbed_pair(np.random.default_rng(99), max_angle=0.6, max_shift=0.03)
    estimate = overlap_ratio_monte_carlo(*pair, n_samples=400_000, rng=0)
    assert estimate == pytest.approx(_fast(*pair), abs=2e-3)


# ----------------------------------------------------------------------------------------------
# closed forms and degenerate configurations
# ----------------------------------------------------------------------------------------------
def test_identical_frustums_give_one():
    rng = np.random.default_rng(3)
    for _ in range(20):
        p, R = _random_pose(rng)
        assert _fast(p, R, p, R) == pytest.approx(1.0, abs=1e-12)
    p, R = _random_pose(rng)
    assert overlap_ratio_reference(p, R, p, R) == pytest.approx(1.0, abs=TOL)


@pytest.mark.parametrize("roll", [0.0, 0.1, np.pi / 4, 1.0, np.pi / 2, np.pi, 2.5, -np.pi / 2])
def test_roll_about_shared_axis(roll):
    """Same apex and axis, rolled by φ: every cross-section is two concentric squares,
    OR = 2 / (1 + sin φ' + cos φ')."""
    p, R = _random_pose(np.random.default_rng(4))
    R_b = R @ _rot([0.0, 0.0, roll])
    phi = roll % (np.pi / 2)
    expected = 2.0 / (1.0 + np.sin(phi) + np.cos(phi))
    assert _fast(p, R, p, R_b) == pytest.approx(expected, abs=1e-12)
    assert overlap_ratio_reference(p, R, p, R_b) == pytest.approx(expected, abs=TOL)


@pytest.mark.parametrize(
    "shift",
    [
        (0.0, 0.0, 0.01),
        (0.0, 0.0, -0.02),
        (0.0, 0.0, 0.05),
        (0.01, 0.0, 0.0),
        (0.01, -0.005, 0.02),
        (0.03, 0.02, -0.01),
        (-0.02, 0.015, 0.04),
    ],
)
def test_translation_matches_integrated_cross_sections(shift):
    frustum = Frustum()
    p, R = _random_pose(np.random.default_rng(5))
    p_b = p + R @ np.array(shift)
    expected = _translated_closed_form(shift, frustum)
    assert 0.0 < expected < 1.0
    assert _fast(p, R, p_b, R) == pytest.approx(expected, abs=1e-12)
    assert overlap_ratio_reference(p, R, p_b, R) == pytest.approx(expected, abs=TOL)


@pytest.mark.parametrize("axial_shift", [0.09, 0.1, 0.12, 0.3, -0.09, -0.2])
def test_axial_shift_beyond_depth_range_is_disjoint(axial_shift):
    # |shift| >= far - near: b's near plane is at or beyond a's far plane (touching at 0.09)
    p, R = _random_pose(np.random.default_rng(6))
    assert _fast(p, R, p + axial_shift * R[:, 2], R) == 0.0
    assert overlap_ratio_reference(p, R, p + axial_shift * R[:, 2], R) == 0.0


def test_disjoint_and_touching():
    p, R = _random_pose(np.random.default_rng(8))
    assert _fast(p, R, p + 1.0 * R[:, 0], R) == 0.0  # far apart sideways
    assert _fast(p, R, p, R @ _rot([np.pi, 0.0, 0.0])) == 0.0  # looking backwards from the same apex
    # b looks back at a from 2 far: the far planes coincide with opposite normals
    R_back = R @ _rot([np.pi, 0.0, 0.0])
    assert _fast(p, R, p + 2 * 0.12 * R[:, 2], R_back) == 0.0
    # ... a little closer: a thin slab of two opposite pyramids, exact = scipy
    p_b = p + 0.2399 * R[:, 2]
    value = _fast(p, R, p_b, R_back)
    assert 0.0 < value < 0.01
    assert value == pytest.approx(overlap_ratio_reference(p, R, p_b, R_back), abs=TOL)


@pytest.mark.parametrize("angle", [1e-12, 1e-10, 1e-8, 1e-6, 1e-4])
def test_nearly_coplanar_faces(angle):
    """Tiny tilts make faces of a and b almost coplanar; the volume must stay continuous (no double count)."""
    rng = np.random.default_rng(9)
    p, R = _random_pose(rng)
    for axis, shift in (([1.0, 0.0, 0.0], 0.0), ([0.3, 1.0, 0.0], 0.0), ([0.3, 1.0, 0.0], 0.003)):
        axis = np.array(axis) / np.linalg.norm(axis)
        p_b = p + shift * R[:, 0]
        R_b = R @ _rot(angle * axis)
        value = _fast(p, R, p_b, R_b)
        baseline = _translated_closed_form((shift, 0.0, 0.0), Frustum())
        # OR moves by O(angle) away from the untilted value
        assert abs(value - baseline) <= 5.0 * angle
        assert value == pytest.approx(overlap_ratio_reference(p, R, p_b, R_b), abs=TOL)
    # roll only: closed form 2 / (1 + sin + cos)
    assert _fast(p, R, p, R @ _rot([0.0, 0.0, angle])) == pytest.approx(
        2.0 / (1.0 + np.sin(angle) + np.cos(angle)), abs=1e-13
    )


def test_shared_apex_random_rotations():
    rng = np.random.default_rng(10)
    for _ in range(30):
        p, R = _random_pose(rng)
        R_b = R @ Rotation.random(random_state=rng).as_matrix()
        assert _fast(p, R, p, R_b) == pytest.approx(overlap_ratio_reference(p, R, p, R_b), abs=TOL)


def test_symmetry_for_equal_frustums():
    rng = np.random.default_rng(11)
    for _ in range(100):
        p_a, R_a, p_b, R_b = _perturbed_pair(rng)
        assert _fast(p_a, R_a, p_b, R_b) == pytest.approx(_fast(p_b, R_b, p_a, R_a), abs=1e-13)


# ----------------------------------------------------------------------------------------------
# batching and the numba entry point
# ----------------------------------------------------------------------------------------------
def test_batch_equals_looped_single_calls():
    rng = np.random.default_rng(12)
    pairs = [_perturbed_pair(rng) for _ in range(12)]
    p_a, R_a, p_b, R_b = (np.array([pair[k] for pair in pairs]).reshape((3, 4) + pairs[0][k].shape) for k in range(4))
    batch = overlap_ratio(p_a, R_a, p_b, R_b)
    assert batch.shape == (3, 4)
    looped = np.array([[float(overlap_ratio(p_a[i, j], R_a[i, j], p_b[i, j], R_b[i, j])) for j in range(4)]
                       for i in range(3)])
    np.testing.assert_array_equal(batch, looped)


def test_broadcasting_one_pose_against_many():
    rng = np.random.default_rng(13)
    p_a, R_a = _random_pose(rng)
    p_b = p_a + rng.uniform(-0.03, 0.03, (5, 3))
    R_b = np.array([R_a @ _rot(rng.normal(size=3) * 0.3) for _ in range(5)])
    many = overlap_ratio(p_a, R_a, p_b, R_b)
    assert many.shape == (5,)
    np.testing.assert_array_equal(many, [float(overlap_ratio(p_a, R_a, p_b[k], R_b[k])) for k in range(5)])
    # shared rotation, batch of positions on one side; (2, 1) x (3,) batch shapes broadcast to (2, 3)
    assert overlap_ratio(p_a, R_a, p_b, R_a).shape == (5,)
    grid = overlap_ratio(p_b[:2, None, :], R_a, p_b[2:5], R_b[2:5])
    assert grid.shape == (2, 3)
    assert grid[1, 2] == float(overlap_ratio(p_b[1], R_a, p_b[4], R_b[4]))
    # lists work too; empty batches give empty results
    assert float(overlap_ratio(p_a.tolist(), R_a.tolist(), p_a.tolist(), R_a.tolist())) == pytest.approx(1.0, abs=1e-12)
    assert overlap_ratio(np.zeros((0, 3)), R_a, p_a, R_a).shape == (0,)


def test_numba_entry_point_callable_from_compiled_code():
    @njit
    def twice(p_a, R_a, p_b, R_b):
        return (overlap_ratio_nb(p_a, R_a, p_b, R_b, 1.0, 0.03, 0.12)
                + overlap_ratio_nb(p_b, R_b, p_a, R_a, 1.0, 0.03, 0.12))

    pose = _case(OVERLAP_CASES[2])
    assert twice(*pose) == pytest.approx(2.0 * OVERLAP_CASES[2]["overlap_ratio"], abs=2 * TOL)


def test_reused_work_arrays_give_the_allocating_kernels_result_bit_for_bit():
    # One OverlapWork over pairs of every kind (disjoint, partial, identical, other frustums): nothing
    # left in it by one pair may change the next, so each result equals a fresh allocation's.
    rng = np.random.default_rng(23)
    work = make_overlap_work()
    pairs = [_perturbed_pair(rng, max_angle=angle, max_shift=shift) for angle, shift in
             [(0.0, 0.0), (0.3, 0.01), (1.0, 0.05), (3.0, 0.2)] * 10]
    frustums = [(1.0, 0.03, 0.12), (0.4, 0.01, 0.3)]
    values = []
    for k, pair in enumerate(pairs):
        tan_half, near, far = frustums[k % 2]
        fresh = overlap_ratio_nb(*pair, tan_half, near, far)
        assert overlap_ratio_in(*pair, tan_half, near, far, work) == fresh
        values.append(fresh)
    assert min(values) == 0.0 and max(values) == pytest.approx(1.0, abs=1e-12) and 0.05 < np.median(values) < 0.95


def test_numpy_clipping_reference_agrees():
    path = Path(__file__).resolve().parents[2] / "benchmarks" / "numpy_reference_overlap.py"
    spec = importlib.util.spec_from_file_location("numpy_reference_overlap", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    rng = np.random.default_rng(14)
    for _ in range(20):
        pair = _perturbed_pair(rng)
        assert module.overlap_ratio_numpy(*pair, Frustum()) == pytest.approx(_fast(*pair), abs=1e-12)
    pose = _case(OVERLAP_CASES[0])
    assert module.overlap_ratio_numpy(*pose, None) == pytest.approx(OVERLAP_CASES[0]["overlap_ratio"], abs=TOL)
    p, R = _random_pose(rng)
    assert module.overlap_ratio_numpy(p, R, p, R, None) == pytest.approx(1.0, abs=1e-12)


# ----------------------------------------------------------------------------------------------
# input validation
# ----------------------------------------------------------------------------------------------
def _bad_inputs():
    p, R = np.array([0.01, -0.02, 0.0]), _rot([0.1, 0.2, 0.3])
    nan_p = p.copy()
    nan_p[1] = np.nan
    inf_R = R.copy()
    inf_R[2, 0] = np.inf
    reflection = R @ np.diag([1.0, 1.0, -1.0])
    return [
        ((p[:2], R, p, R), "p_a"),
        ((p, R[:2], p, R), "R_a"),
        ((p, R, np.zeros((2, 4)), R), "p_b"),
        ((p, R, p, np.eye(2)), "R_b"),
        ((p, R, p, "identity"), "R_b"),
        ((nan_p, R, p, R), "p_a"),
        ((p, inf_R, p, R), "R_a"),
        ((p, R, nan_p, R), "p_b"),
        ((p, R, p, inf_R), "R_b"),
        ((p, 2.0 * R, p, R), "R_a"),
        ((p, R, p, reflection), "R_b"),
        ((np.zeros((2, 3)), R, np.zeros((3, 3)), R), "broadcast"),
        ((np.stack([p, nan_p]), R, p, R), "p_a"),
        ((p, R, p, np.stack([R, reflection])), "R_b"),
    ]


@pytest.mark.parametrize("args, name", _bad_inputs())
def test_overlap_ratio_rejects_bad_inputs(args, name):
    with pytest.raises(ValueError, match=name):
        overlap_ratio(*args)


@pytest.mark.parametrize("args, name", [case for case in _bad_inputs() if case[1] != "broadcast"])
def test_reference_and_monte_carlo_reject_bad_inputs(args, name):
    with pytest.raises(ValueError, match=name):
        overlap_ratio_reference(*args)
    with pytest.raises(ValueError, match=name):
        overlap_ratio_monte_carlo(*args, n_samples=10, rng=0)


def test_other_bad_arguments():
    p, R = np.zeros(3), np.eye(3)
    with pytest.raises(ValueError, match="frustum"):
        overlap_ratio(p, R, p, R, frustum=(np.pi / 2, 0.03, 0.12))
    with pytest.raises(ValueError, match="p_a"):
        overlap_ratio_reference(np.zeros((2, 3)), R, p, R)  # one pair only
    with pytest.raises(ValueError, match="n_samples"):
        overlap_ratio_monte_carlo(p, R, p, R, n_samples=0, rng=0)
    with pytest.raises(ValueError, match="n_samples"):
        overlap_ratio_monte_carlo(p, R, p, R, n_samples=10.5, rng=0)
