"""View cone, force field and VOI against the reference, finite differences and limiting cases."""

from __future__ import annotations

import math
from fractions import Fraction

import numba
import numpy as np
import pytest

from continuum_gym.geometry.force_field import (
    ForceField,
    exact_square,
    potential_gradient,
    pow_as_libm,
    repulsive_force,
)
from continuum_gym.geometry.lens_cone import (
    ConeKernelArgs,
    LensCone,
    centre_distance,
    cone_coordinates,
    lens_origin,
    lens_rotation,
    view_axis,
)
from continuum_gym.geometry.occlusion import (
    occlusion_details,
    visual_occlusion_index,
    voi_kernel,
)
from continuum_gym.robots.mbcr import MultiBackboneRobot
from tests.conftest import fd_gradient

ROBOT = MultiBackboneRobot()
CONE = LensCone()
PHYSICAL = LensCone(lens_model="physical")
HALF_PI = math.pi / 2


@pytest.mark.parametrize("index", range(8))
def test_reference_values(reference, index):
    entry = reference["mbcr"][index]
    q = np.array(entry["q"])
    details = occlusion_details(ROBOT, q, 0.0)
    assert details["voi"] == pytest.approx(entry["voi_gamma0_literal"], abs=1e-9)
    assert details["nu"] == pytest.approx(entry["voi_nu"], abs=1e-9)
    assert details["r_max"] == pytest.approx(entry["voi_r_max"], abs=1e-12)
    if entry["voi_r_e"] is None:
        assert np.isnan(details["r_e"]) or details["voi"] == 0.0
    else:
        assert details["r_e"] == pytest.approx(entry["voi_r_e"], abs=1e-12)
    np.testing.assert_allclose(potential_gradient(ROBOT, q, 0.0), entry["grad_potential_gamma0"],
                               rtol=1e-9, atol=1e-12)
    tip, _ = ROBOT.forward_kinematics(q)
    np.testing.assert_allclose(repulsive_force(tip, 0.0), entry["force_at_tip_gamma0"], rtol=1e-9, atol=1e-12)
    d_c, dd_c = centre_distance(tip, 0.3)
    assert d_c == pytest.approx(entry["d_c_tip_gamma0.3"], rel=1e-9)
    assert dd_c == pytest.approx(entry["dd_c_dgamma_tip_gamma0.3"], rel=1e-9, abs=1e-15)


def test_psi_a_voi_matches_errata_numbers():
    """paper-notes §1.3 item 13: VOI 0.2502, nu 0.4909 rad, r_e 23.73 mm, r_max 69.35 mm."""
    details = occlusion_details(ROBOT, ROBOT.psi_a, 0.0)
    assert details["voi"] == pytest.approx(0.2502, abs=1e-4)
    assert details["nu"] == pytest.approx(0.4909, abs=1e-4)
    assert details["r_e"] * 1e3 == pytest.approx(23.73, abs=0.01)
    assert details["r_max"] * 1e3 == pytest.approx(69.35, abs=0.01)


# ---------------------------------------------------------------- cone geometry
@pytest.mark.parametrize("cone", [CONE, PHYSICAL])
def test_cone_frame_is_consistent(cone):
    rng = np.random.default_rng(0)
    for gamma in rng.uniform(-math.pi, math.pi, 5):
        vertex = lens_origin(gamma, cone)
        axis = view_axis(gamma, cone)
        R = lens_rotation(gamma, cone)
        np.testing.assert_allclose(R[:, 2], axis, atol=1e-15)
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-15)
        # The vertex maps to the lens origin, and points along the axis at distance s have d < 0, r = s cos(beta).
        np.testing.assert_allclose(cone_coordinates(vertex, gamma, cone)["lens"], 0.0, atol=1e-15)
        s = 0.05
        coords = cone_coordinates(vertex + s * axis, gamma, cone)
        assert coords["d"] == pytest.approx(-s * math.sin(cone.beta))
        assert coords["r"] == pytest.approx(s * math.cos(cone.beta))
        # A point on the cone surface has d = 0 and r = its distance from the vertex.
        side = math.cos(cone.beta) * axis + math.sin(cone.beta) * R[:, 0]
        on_surface = cone_coordinates(vertex + 0.03 * side, gamma, cone)
        assert on_surface["d"] == pytest.approx(0.0, abs=1e-15)
        assert on_surface["r"] == pytest.approx(0.03)
        assert on_surface["angle"] == pytest.approx(cone.beta)


def test_lens_models_coincide_at_zero_and_differ_elsewhere():
    p = np.array([0.01, 0.02, 0.05])
    np.testing.assert_allclose(cone_coordinates(p, 0.0, CONE)["lens"], cone_coordinates(p, 0.0, PHYSICAL)["lens"])
    assert not np.allclose(cone_coordinates(p, 0.5, CONE)["lens"], cone_coordinates(p, 0.5, PHYSICAL)["lens"])
    np.testing.assert_allclose(lens_origin(0.7, PHYSICAL), [0, CONE.d_o, 0])
    np.testing.assert_allclose(view_axis(0.0), [-0.5, 0.0, math.sqrt(3) / 2], atol=1e-15)


@pytest.mark.parametrize("cone", [CONE, PHYSICAL])
def test_force_direction_is_gradient_of_distance(cone):
    """f_hat = grad d (eq 19 = outward normal, paper-notes §1.3 item 8), checked by FD of eq (16)."""
    rng = np.random.default_rng(1)
    checked = 0
    while checked < 50:
        p = rng.uniform([-0.04, -0.02, 0.0], [0.02, 0.04, 0.08])
        gamma = rng.uniform(-1, 1)
        force = repulsive_force(p, gamma, cone)
        lens = cone_coordinates(p, gamma, cone)["lens"]
        if not np.any(force) or math.hypot(lens[0], lens[1]) < 2e-3:  # FD error grows as h^2 / rho^2
            continue
        grad_d = fd_gradient(lambda x, gamma=gamma: cone_coordinates(x, gamma, cone)["d"], p)
        np.testing.assert_allclose(force / np.linalg.norm(force), grad_d, atol=1e-8)
        assert np.linalg.norm(grad_d) == pytest.approx(1.0, abs=1e-8)
        checked += 1


def test_force_magnitude_and_support():
    field = ForceField()
    vertex = lens_origin(0.0)
    axis = view_axis(0.0)
    side = math.cos(CONE.beta) * axis + math.sin(CONE.beta) * lens_rotation(0.0)[:, 0]
    # On the cone face at r = r*, the force is f* (Fig. 2-b normalisation).
    on_face = vertex + field.r_star * side
    assert np.linalg.norm(repulsive_force(on_face, 0.0)) == pytest.approx(field.f_star)
    # Beyond the distance of influence, on the axis and behind the vertex: zero.
    outward = lens_rotation(0.0)[:, 0] * math.cos(CONE.beta) - axis * math.sin(CONE.beta)
    assert not np.any(repulsive_force(on_face + 1.01 * field.d0 * outward, 0.0))
    assert not np.any(repulsive_force(vertex + 0.04 * axis, 0.0))
    assert not np.any(repulsive_force(vertex - 0.01 * axis, 0.0))
    assert not np.any(repulsive_force(vertex, 0.0))
    # Deeper inside, stronger; farther from the vertex, weaker (eq 18).
    mags = [np.linalg.norm(repulsive_force(on_face - k * 1e-3 * outward, 0.0)) for k in range(4)]
    assert np.all(np.diff(mags) > 0)
    far = np.linalg.norm(repulsive_force(vertex + 2 * field.r_star * side, 0.0))
    assert far == pytest.approx(field.f_star / 4)


@numba.njit
def _pow_as_libm_all(xs, y, y_is_two):
    out = np.empty_like(xs)
    for i in range(xs.shape[0]):
        out[i] = pow_as_libm(xs[i], y, y_is_two)
    return out


def _libm_pow(x: float, y: float) -> float:
    try:
        return math.pow(x, y)  # CPython calls the C library's pow
    except OverflowError:
        return math.inf


def test_exact_square_is_exact():
    rng = np.random.default_rng(5)
    xs = np.concatenate([rng.uniform(0.0, 2.0, 500), np.exp(rng.uniform(-300.0, 300.0, 500))])
    for x in xs:
        hi, lo = exact_square(x)
        assert hi == x * x
        assert Fraction(hi) + Fraction(lo) == Fraction(float(x)) ** 2


@pytest.mark.parametrize("y", [2.0, 1.0, 2.5, 3.0])
def test_pow_as_libm_is_libm_pow_to_the_bit(y):
    # The force's two powers take their base from (0, 1] (1 - d/d0) and from r*/r (~0.1 to 1e8).
    rng = np.random.default_rng(6)
    xs = np.concatenate([rng.uniform(0.0, 1.0, 400_000), rng.uniform(1.0, 100.0, 200_000),
                         np.exp(rng.uniform(-320.0, 320.0, 200_000)),
                         [0.0, 5e-324, 1e-140, 1e140, 1e160, 1.0, 2.0, 0.5, np.inf]])
    got = _pow_as_libm_all(xs, y, y == 2.0)
    expected = np.array([_libm_pow(x, y) for x in xs])
    mismatched = np.flatnonzero(got != expected)
    assert mismatched.size == 0, f"{mismatched.size} bases differ from libm's pow, e.g. {xs[mismatched[:3]]}"


@pytest.mark.parametrize("cone", [CONE, PHYSICAL])
def test_centre_distance_derivative_matches_finite_differences(cone):
    rng = np.random.default_rng(2)
    for _ in range(30):
        tip = rng.uniform([-0.03, -0.01, 0.03], [0.01, 0.04, 0.09])
        gamma = rng.uniform(-math.pi, math.pi)
        d_c, dd_c = centre_distance(tip, gamma, cone)
        h = 1e-6
        fd = (centre_distance(tip, gamma + h, cone)[0] - centre_distance(tip, gamma - h, cone)[0]) / (2 * h)
        assert dd_c == pytest.approx(fd, abs=1e-9)
        lens = cone_coordinates(tip, gamma, cone)["lens"]
        assert d_c == pytest.approx(math.hypot(lens[0], lens[1]))
        coords = cone_coordinates(tip, gamma, cone)
        if coords["r"] > 0:  # eq (25) as printed equals rho_ee when r > 0
            printed = np.linalg.norm(lens) * math.sin(cone.beta + math.atan(coords["d"] / coords["r"]))
            assert d_c == pytest.approx(printed, abs=1e-15)


def test_potential_gradient_is_elastic_minus_force_work():
    """grad Pi = grad E - sum Jv^T f (eq 12), assembled independently from the public pieces."""
    rng = np.random.default_rng(3)
    for _ in range(10):
        q = ROBOT.psi_a + rng.normal(0, 0.2, 7) * [1, 1, 1, 1, 1, 1, 0.01]
        gamma = rng.uniform(-0.5, 0.5)
        P, JV = ROBOT.points_jacobians(q)
        forces = repulsive_force(P, gamma)
        expected = ROBOT.elastic_energy_gradient(q) - np.einsum("mik,mi->k", JV, forces)
        # Rounding of a sum is bounded by a few eps times the sum of |terms| (forces of ~100 N cancel here).
        scale = np.abs(ROBOT.elastic_energy_gradient(q)) + np.einsum("mik,mi->k", np.abs(JV), np.abs(forces))
        assert np.all(np.abs(potential_gradient(ROBOT, q, gamma) - expected) <= 1e-13 * scale + 1e-15)


# ---------------------------------------------------------------- VOI
def _world_from_lens(lens_points, gamma=0.0):
    R = lens_rotation(gamma)
    return lens_points @ R.T + lens_origin(gamma)


def _voi_of_path(lens_points, beta=CONE.beta):
    world = _world_from_lens(np.asarray(lens_points, dtype=float))
    m = world.shape[0]
    cone = ConeKernelArgs(CONE.d_o, CONE.alpha, beta, 0)
    return voi_kernel(world, 0.0, cone, np.empty((m, 3)), np.empty((m, 2)))


def _lens_point(r_slant, angle_from_axis, azimuth=0.0):
    """A point at distance ``r_slant`` from the vertex, ``angle_from_axis`` off the axis, in {lens}."""
    return r_slant * np.array([math.sin(angle_from_axis) * math.cos(azimuth),
                               math.sin(angle_from_axis) * math.sin(azimuth), math.cos(angle_from_axis)])


def test_voi_formula_equals_printed_eq27():
    beta = CONE.beta
    for nu in np.linspace(0.01, 2 * beta - 0.01, 20):
        printed = ((1 + 1 / math.tan(beta) ** 2) ** 2 * math.tan(nu) ** 2
                   / (4 * (1 / math.tan(beta) + math.tan(nu)) ** 2))
        readable = (math.sin(nu) / (2 * math.sin(beta) * math.cos(nu - beta))) ** 2
        assert readable == pytest.approx(printed, rel=1e-12)


def test_voi_is_one_when_the_body_crosses_the_cone_at_the_vertex():
    """Paper 000: 'VOI = 1 when the first segment crosses the cone near the vertex'."""
    beta = CONE.beta
    # In the x-z plane of {lens}: enter at +beta right by the vertex, sweep across to -beta, then out to the tip.
    planar = [1e-6 * np.array([math.sin(s), 0.0, math.cos(s)]) for s in np.linspace(beta + 0.1, -beta + 1e-9, 41)]
    tip = _lens_point(0.07, 0.0)
    voi, nu, r_e, r_max = _voi_of_path(planar + [tip])
    assert nu == pytest.approx(2 * beta)
    assert voi == pytest.approx(1.0, abs=1e-8)
    # A robot whose first segment curls across the lens ~9 mm from the vertex (the highest VOI of a
    # seeded random search over 2e5 configurations) sweeps nearly the whole cone.
    q = np.array([0.08828894031532908, -2.537668328400316, 1.6728206261984617, 2.3899797214250373,
                  0.7196282763341717, 2.407002792066959, 0.0001497024726192664])
    details = occlusion_details(ROBOT, q, 0.0)
    assert details["nu"] > 0.99 * 2 * beta and details["r_e"] < 0.2 * details["r_max"]
    assert 0.99 < details["voi"] <= 1.0


def test_voi_zero_when_the_robot_stays_outside_the_cone():
    # Bent away from the lens (toward -y, the lens sits at +y), the body never enters the cone.
    q = np.array([HALF_PI - 0.6, HALF_PI, HALF_PI - 0.3, HALF_PI, HALF_PI, 0.0, 0.0])
    pts = ROBOT.backbone(q)
    assert np.all(cone_coordinates(pts, 0.0)["d"] > 0)
    assert visual_occlusion_index(ROBOT, q, 0.0) == 0.0
    assert visual_occlusion_index(ROBOT, ROBOT.straight, 0.0) == 0.0


def test_voi_monotone_in_subtended_angle_and_entry_height():
    beta = CONE.beta
    outside = _lens_point(0.01, beta + 0.2)
    tip = _lens_point(0.07, beta - 0.05)
    by_angle = [_voi_of_path([outside, _lens_point(0.02, beta - 1e-6), _lens_point(0.03, beta - a), tip])[0]
                for a in (0.1, 0.2, 0.3, 0.4)]
    assert np.all(np.diff(by_angle) > 0)
    by_entry = [_voi_of_path([_lens_point(r, beta + 0.2), _lens_point(r, beta - 1e-6), _lens_point(0.05, 0.0), tip])[0]
                for r in (0.01, 0.02, 0.04, 0.06)]
    assert np.all(np.diff(by_entry) < 0)
    assert 0.0 <= min(by_angle + by_entry) and max(by_angle + by_entry) <= 1.0


def _brute_force_nu(lens, dr):
    """nu of paper-notes §1.3 item 13 by the definition: atan2 of every qualifying sample, then the maximum."""
    m = len(dr)
    entry = next(i for i in range(m) if dr[i, 0] <= 0.0 and dr[i, 1] > 0.0)
    if entry > 0:
        t = dr[entry - 1, 0] / (dr[entry - 1, 0] - dr[entry, 0])
        e = [lens[entry - 1, a] + t * (lens[entry, a] - lens[entry - 1, a]) for a in range(3)]
    else:
        e = list(lens[0])
    angles = []
    for i in range(entry, m):
        if dr[i, 0] <= 0.0 and dr[i, 1] > 0.0 and dr[i, 1] <= dr[m - 1, 1]:
            px, py, pz = lens[i]
            cx, cy, cz = e[1] * pz - e[2] * py, e[2] * px - e[0] * pz, e[0] * py - e[1] * px
            angles.append(math.atan2(math.sqrt(cx * cx + cy * cy + cz * cz), e[0] * px + e[1] * py + e[2] * pz))
    return max(angles)


@pytest.mark.parametrize("gap", [0.0, 1e-15, 1e-12, 1e-10, 1e-9, 1e-8, 1e-3])
def test_voi_nu_is_the_exact_maximum_of_every_samples_angle(gap):
    """The kernel orders the samples' angles without atan2 and settles near ties (< 1e-9 rad) with it:
    nu must still be the very double that the maximum over every sample's atan2 gives."""
    rng = np.random.default_rng(int(gap * 1e15) % 1000)
    beta = CONE.beta
    for _ in range(40):
        entry_angle = beta - 1e-4
        top = rng.uniform(0.2, 1.9) * beta
        # Samples at angles around the largest, some of them apart by only `gap` (rad), in shuffled order.
        offsets = np.concatenate([[0.0, gap, -gap, 2 * gap], rng.uniform(-0.3, 0.0, 6)])
        rng.shuffle(offsets)
        path = [_lens_point(0.01, beta + 0.2), _lens_point(0.02, entry_angle)]
        for offset in offsets:
            # In the entry's plane, `top + offset` (rad) off its direction, kept 1 mrad inside the cone.
            angle = np.clip(entry_angle - (top + offset), -beta + 1e-3, beta - 1e-3)
            path.append(_lens_point(rng.uniform(0.025, 0.06), angle))
        path.append(_lens_point(0.07, 0.0))
        world = _world_from_lens(np.asarray(path, dtype=float))
        m = world.shape[0]
        lens, dr = np.empty((m, 3)), np.empty((m, 2))
        voi, nu, _, _ = voi_kernel(world, 0.0, ConeKernelArgs(CONE.d_o, CONE.alpha, beta, 0), lens, dr)
        assert nu == min(_brute_force_nu(lens, dr), 2.0 * beta)
        assert 0.0 < voi <= 1.0


def test_voi_is_zero_when_the_entry_is_beyond_the_tip():
    beta = CONE.beta
    path = [_lens_point(0.08, beta + 0.1), _lens_point(0.08, beta - 0.1), _lens_point(0.05, beta + 0.3)]
    voi, _, r_e, r_max = _voi_of_path(path)
    assert r_e >= r_max and voi == 0.0


def test_voi_broadcasts_and_batches_exactly():
    rng = np.random.default_rng(4)
    q = ROBOT.psi_a + rng.normal(0, 0.3, (3, 4, 7)) * [1, 1, 1, 1, 1, 1, 0.01]
    gammas = np.linspace(-0.5, 0.5, 4)
    batch = visual_occlusion_index(ROBOT, q, gammas)
    assert batch.shape == (3, 4)
    for i, j in np.ndindex(3, 4):
        assert batch[i, j] == visual_occlusion_index(ROBOT, q[i, j], gammas[j])
    single = visual_occlusion_index(ROBOT, ROBOT.psi_a, 0.0)
    assert isinstance(single, np.ndarray) and single.shape == ()
    grads = potential_gradient(ROBOT, q, gammas)
    for i, j in np.ndindex(3, 4):
        assert np.array_equal(grads[i, j], potential_gradient(ROBOT, q[i, j], gammas[j]))


def test_gamma_changes_voi_strongly():
    """paper-notes §5: rotating the angled endoscope alone takes psi_a from VOI 0.25 to near 0."""
    gammas = np.linspace(-math.pi, math.pi, 181)
    vois = visual_occlusion_index(ROBOT, ROBOT.psi_a, gammas)
    assert vois.min() < 0.05 and vois.max() >= 0.25


# ---------------------------------------------------------------- input checks
@pytest.mark.parametrize("kwargs, name", [
    ({"d_o": 0.0}, "d_o"), ({"d_o": -1e-3}, "d_o"), ({"alpha": 0.0}, "alpha"), ({"alpha": 2.0}, "alpha"),
    ({"beta": -0.1}, "beta"), ({"beta": math.pi / 2}, "beta"), ({"lens_model": "fisheye"}, "lens_model"),
    ({"alpha": float("nan")}, "alpha"),
])
def test_bad_cone_parameters_raise(kwargs, name):
    with pytest.raises(ValueError, match=name):
        LensCone(**kwargs)


@pytest.mark.parametrize("kwargs, name", [({"d0": 0.0}, "d0"), ({"r_star": -1.0}, "r_star"), ({"f_star": 0}, "f_star")])
def test_bad_field_parameters_raise(kwargs, name):
    with pytest.raises(ValueError, match=name):
        ForceField(**kwargs)


def test_bad_inputs_raise():
    with pytest.raises(ValueError, match="gamma"):
        visual_occlusion_index(ROBOT, ROBOT.psi_a, np.nan)
    with pytest.raises(ValueError, match="q"):
        visual_occlusion_index(ROBOT, ROBOT.psi_a[:6], 0.0)
    with pytest.raises(ValueError, match="finite"):
        visual_occlusion_index(ROBOT, np.full(7, np.inf), 0.0)
    with pytest.raises(ValueError, match="points"):
        cone_coordinates(np.zeros((4, 2)), 0.0)
    with pytest.raises(ValueError, match="cone"):
        visual_occlusion_index(ROBOT, ROBOT.psi_a, 0.0, cone="literal")
    with pytest.raises(ValueError, match="gamma"):
        visual_occlusion_index(ROBOT, np.tile(ROBOT.psi_a, (3, 1)), np.zeros(4))
