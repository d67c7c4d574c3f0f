"""The finger pad under a 3-axis fingertip force (S2's wearable twin) against independent references.

References: the cited exponential force-depth law evaluated by hand at its cited points; the last joint's
cited turn under its cited moment, and the nail's displacement from it by hand; the Winkler
pressure integrated numerically over the pad's contact on a grid; the overlap of pad and object
integrated on a grid; the thin layer's potential (the strip's Green's function, from the complex
logarithm) differentiated numerically at the free tip; finite differences; a source moved by hand;
the Prony creep function derived by hand; the ring's tangent stiffness from the exponential law.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from softtip._core.config import ConfigError
from softtip._core.units import MM
from softtip.systems.wearable.fingerpad import (DIP_LATERAL_STIFFNESS, SIDES, ChipMount, FingerPad, chip_forces,
                                                contact_points, exponential_force, indentation_volume,
                                                lateral_outflow, pad_response, shape_radii, side_outflow,
                                                winkler_pressure)
from softtip.mechanics.viscoelastic import PronySeries
ELASTIC = PronySeries((), ())  # no relaxation: the instantaneous laws alone
PAD = FingerPad()


def grid(half_width: float, n: int = 1601):
    axis = np.linspace(-half_width, half_width, n)
    x, y = np.meshgrid(axis, axis, indexing="ij")
    return x, y, (axis[1] - axis[0]) ** 2


def gap(x, y, radii):
    return x ** 2 / (2 * radii[0]) + y ** 2 / (2 * radii[1])


# ---------------------------------------------------------------------------------------------- the pad


def test_force_depth_is_the_cited_exponential_law_at_the_cited_points():
    # F = (b/m)(e^{mδ} − 1), b = 0.33 N/mm, m = 1.7 /mm: δ = ln(1 + mF/b)/m, stiffness b + mF
    for force, depth_mm, stiffness_N_per_mm in ((1.0, 1.0686, 2.03), (4.0, 1.8076, 7.13)):
        assert math.log(1 + 1.7 * force / 0.33) / 1.7 == pytest.approx(depth_mm, abs=5e-5)
        assert PAD.depth(force) / MM == pytest.approx(depth_mm, abs=5e-5)
        step = 1e-7
        slope = (PAD.force(PAD.depth(force) + step) - PAD.force(PAD.depth(force) - step)) / (2 * step)
        assert slope * MM == pytest.approx(stiffness_N_per_mm, rel=1e-6)


@pytest.mark.parametrize("shape", ["flat", "curved", "edge", "point"])
def test_the_winkler_pressure_over_the_contact_integrates_to_the_law(shape):
    # the distributed pressure summed over the pad-object overlap on a grid, against (R̄'/R̄) F_flat(δ)
    object_ = shape_radii(shape, 20 * MM, 1 * MM, 1 * MM)
    radii = PAD.contact_radii(np.array(object_))
    depth = PAD.depth(1.0, object_) if shape == "point" else PAD.depth(4.0, object_)
    x, y, cell = grid(math.sqrt(2 * max(radii) * depth) * 1.05)
    pressure = winkler_pressure(depth - gap(x, y, radii), PAD.stiffness, PAD.stiffening, PAD.mean_radius)
    assert pressure.sum() * cell == pytest.approx(1.0 if shape == "point" else 4.0, rel=2e-3)
    share = math.sqrt(radii[0] * radii[1]) / PAD.mean_radius
    assert float(PAD.force(depth, object_)) == pytest.approx(share * exponential_force(depth, 330.0, 1700.0))


@pytest.mark.parametrize("shape", ["flat", "curved", "edge", "point"])
def test_indentation_volume_is_the_overlap_of_pad_and_object(shape):
    radii = PAD.contact_radii(np.array(shape_radii(shape, 20 * MM, 1 * MM, 1 * MM)))
    depth = 1.5 * MM
    x, y, cell = grid(math.sqrt(2 * max(radii) * depth) * 1.05)
    overlap = np.maximum(depth - gap(x, y, radii), 0.0).sum() * cell
    assert indentation_volume(depth, *radii) == pytest.approx(overlap, rel=2e-3)


def test_a_point_pushes_in_less_volume_than_a_flat_plate_for_the_same_force():
    volumes = {}
    for shape in ("flat", "point"):
        object_ = shape_radii(shape, 20 * MM, 1 * MM, 1 * MM)
        radii = PAD.contact_radii(np.array(object_))
        volumes[shape] = indentation_volume(PAD.depth(3.0, object_), *radii)
    assert volumes["point"] < 0.5 * volumes["flat"]


# ---------------------------------------------------------------------------------------------- the bulge


def strip_potential(x, y, source, width, tip_y):
    """The thin layer's pressure for a unit source, zero on the free sides and tip: the half-plane
    Green's function mapped by w = exp(π (y + i X)/W), X = x + W/2, minus the tip's image."""
    def green(centre_y):
        w = np.exp(np.pi * (y + 1j * (x + width / 2)) / width)
        w0 = np.exp(np.pi * (centre_y + 1j * (source[0] + width / 2)) / width)
        return np.log(np.abs((w - np.conj(w0)) / (w - w0))) / (2 * np.pi)
    return green(source[1]) - green(2 * tip_y - source[1])


def tip_outflow(source, width, tip_y):
    step = 1e-9
    flux = lambda x: -(strip_potential(x, tip_y + step, source, width, tip_y)  # noqa: E731
                       - strip_potential(x, tip_y - step, source, width, tip_y)) / (2 * step)
    return quad(flux, -width / 2, width / 2, limit=200)[0]


def side_total(source, width, tip_y):
    return sum(quad(lambda y: side_outflow(source[0], source[1], y, side, width, tip_y)[0], -np.inf, tip_y,
                    limit=200)[0] for side in (1.0, -1.0))


@pytest.mark.parametrize("source_mm", [(0.0, 0.0), (3.0, 1.0), (-5.0, -4.0), (1.0, 6.0)])
def test_a_unit_volume_leaves_through_the_free_sides_and_tip(source_mm):
    source = np.array(source_mm) * MM
    assert side_total(source, PAD.width, PAD.tip_y) + tip_outflow(source, PAD.width, PAD.tip_y) == pytest.approx(
        1.0, abs=1e-7)


def test_the_bulge_volume_equals_the_indentation_volume():
    # incompressibility: a flat press's whole outflow (both sides, along the finger, and the tip)
    depth = 1.5 * MM
    volume = math.pi * math.sqrt(PAD.radius_x * PAD.radius_y) * depth ** 2  # analytic overlap
    centre, semi = np.array([0.5 * MM, -0.5 * MM]), np.sqrt(2 * np.array([PAD.radius_x, PAD.radius_y]) * depth)
    # along the finger the outflow decays as e^{-π|y|/W}: nothing is left 0.3 m (20 breadths) away
    sides = sum(quad(lambda y: lateral_outflow(volume, np.zeros(2), centre, semi, y, side, PAD.width, PAD.tip_y),
                     -0.3, PAD.tip_y, points=[-10 * MM, 0.0], limit=500, epsabs=0, epsrel=1e-11)[0]
                for side in (1.0, -1.0))
    points, compression, _ = contact_points(centre, semi)
    points = np.column_stack([points[:, 0], np.minimum(points[:, 1], 0.95 * PAD.tip_y)])
    tip = volume * sum(w * tip_outflow(p, PAD.width, PAD.tip_y) for p, w in zip(points, compression))
    assert sides + tip == pytest.approx(volume, rel=1e-8)


def test_the_contact_quadrature_weighs_by_compression_and_by_area():
    # on the unit ellipse the compression δ(1 − r²) gives E[r²] = 1/3 and the area E[r²] = 1/2
    points, compression, area = contact_points(np.zeros(2), np.array([2.0, 3.0]))
    r2 = (points[:, 0] / 2) ** 2 + (points[:, 1] / 3) ** 2
    assert compression @ r2 == pytest.approx(1 / 3) and area @ r2 == pytest.approx(1 / 2)
    assert compression.sum() == pytest.approx(1.0) and area.sum() == pytest.approx(1.0)


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_the_outflow_gradient_is_its_finite_difference(side):
    source, y, step = np.array([2.0, 1.0]) * MM, -3 * MM, 1e-8
    _, d_x, d_y = side_outflow(source[0], source[1], y, side, PAD.width, PAD.tip_y)
    for k, derivative in enumerate((d_x, d_y)):
        shift = np.eye(2)[k] * step
        up = side_outflow(*(source + shift), y, side, PAD.width, PAD.tip_y)[0]
        down = side_outflow(*(source - shift), y, side, PAD.width, PAD.tip_y)[0]
        assert derivative == pytest.approx((up - down) / (2 * step), rel=1e-6)


def test_a_sheared_column_bulges_like_its_volume_moved_against_the_force():
    # the dipole of a small volume moment M equals moving the volume V by M/V, to first order
    volume, centre, semi = 60e-9, np.zeros(2), np.full(2, 1e-6)
    moment = np.array([-4e-13, 3e-13])
    dipole = lateral_outflow(volume, moment, centre, semi, -3 * MM, 1.0, PAD.width, PAD.tip_y)
    moved = lateral_outflow(volume, np.zeros(2), centre + moment / volume, semi, -3 * MM, 1.0, PAD.width,
                            PAD.tip_y)
    assert dipole == pytest.approx(moved, rel=1e-5)


def held(force, seconds=4.0, rate=100.0):
    times = np.arange(0, seconds * rate + 1) / rate
    return times, np.broadcast_to(np.asarray(force, dtype=float), (len(times), 3)).copy()


@pytest.mark.parametrize("side", ["radial", "ulnar"])
def test_tangential_load_bulges_less_on_the_side_the_force_points_to(side):
    pad = FingerPad(prony=ELASTIC, lateral_drag=False, joint_stiffness=None)  # the bulge alone
    mount = ChipMount(side=side)
    bulge = {}
    for fx in (-1.0, 0.0, 1.0):
        times, force = held([fx, 0.0, 2.0])
        bulge[fx] = pad_response(times, force, pad, mount).skin[-1, 2]
    towards, away = (1.0, -1.0) if side == "radial" else (-1.0, 1.0)
    assert bulge[towards] < bulge[0.0] < bulge[away]


@pytest.mark.parametrize("side", ["radial", "ulnar"])
def test_the_lateral_drag_moves_the_skin_under_the_chip_by_the_transmitted_bone_displacement(side):
    # by hand: held Fx = 1 N on Fz = 2 N, no creep; u_x = Fx / (2/3 (b + m Fz)) = 1 / (2/3 x 3730 N/m) = 0.402 mm,
    # of which 10 % reaches the skin under the chip, away from a chip on the side the force points to
    times, force = held([1.0, 0.0, 2.0])
    mount = ChipMount(side=side)
    skin = {drag: pad_response(times, force, FingerPad(prony=ELASTIC, lateral_drag=drag), mount).skin[-1]
            for drag in (False, True)}
    expected = -SIDES[side] * 0.1 * 1.0 / (2 / 3 * (330.0 + 1700.0 * 2.0))
    assert expected == pytest.approx(-SIDES[side] * 40.21e-6, rel=1e-3)
    assert skin[True][2] - skin[False][2] == pytest.approx(expected, rel=1e-9)
    np.testing.assert_array_equal(skin[True][:2], skin[False][:2])  # the distal and dorsal drag as before


def test_the_joints_stiffness_is_the_cited_turn_under_the_cited_moment():
    # Minamikawa et al. (1993): 30 N·cm of lateral stress turned the middle joint by 5° on average
    assert math.degrees(0.3 / DIP_LATERAL_STIFFNESS) == pytest.approx(5.0, abs=0.01)


@pytest.mark.parametrize("side", ["radial", "ulnar"])
def test_the_last_joint_turns_the_nail_against_the_chip_by_the_moment_over_its_stiffness(side):
    # by hand: Fx = 1 N at the contact 12 mm distal of the joint turns it by 0.012 N·m / 3.44 N·m/rad = 3.49 mrad;
    # the nail 9 mm distal of the joint (the chip 3 mm behind the contact) moves 31.4 µm ulnarly, the tip pushed back
    times, force = held([1.0, 0.0, 2.0])
    mount = ChipMount(side=side)
    skin = {stiffness: pad_response(times, force, FingerPad(prony=ELASTIC, joint_stiffness=stiffness), mount).skin[-1]
            for stiffness in (None, 3.44)}
    assert skin[3.44][2] - skin[None][2] == pytest.approx(SIDES[side] * -31.395e-6, rel=1e-4)
    np.testing.assert_array_equal(skin[3.44][:2], skin[None][:2])  # the distal and dorsal skin as before


def test_placed_off_centre_the_finger_turns_its_last_joint_under_a_distal_force_too():
    # by hand: placed 1 mm radially, Fy = 0.8 N has the moment −0.001 x 0.8 N·m about the joint: the nail moves
    # 0.0008 / 3.44 x 9 mm = 2.09 µm radially, towards a radial chip
    times, force = held([0.0, 0.8, 2.0])
    skin = {stiffness: pad_response(times, force, FingerPad(prony=ELASTIC, joint_stiffness=stiffness), ChipMount(),
                                    rest_centre=(1 * MM, 0.0)).skin[-1, 2] for stiffness in (None, 3.44)}
    assert skin[3.44] - skin[None] == pytest.approx(2.093e-6, rel=1e-3)


def test_a_chip_behind_the_last_joint_is_not_moved_by_it():
    times, force = held([1.0, 0.5, 2.0])
    mount = ChipMount(position_y=-13 * MM)  # on the middle phalanx, 1 mm proximal of the joint
    skin = {stiffness: pad_response(times, force, FingerPad(prony=ELASTIC, joint_stiffness=stiffness), mount).skin
            for stiffness in (None, 3.44)}
    np.testing.assert_array_equal(skin[3.44], skin[None])


def test_a_radial_step_through_the_last_joint_relaxes_at_the_chip_by_the_nail_folds_function():
    # a press held, then Fx stepped on: the joint moves the nail at once (no creep of its ligaments), the chip's
    # tissue, displaced, relaxes by Fung's G(t) = g_inf + g e^{-t/τ} of the exponential law's step, by hand
    g, tau = 0.6, 0.2
    ramp = 1e-5
    times = np.concatenate([np.linspace(0.0, 1.0, 101), 1.0 + ramp + np.linspace(0, 2.0, 201)])
    force = np.zeros((len(times), 3))
    force[:, 2] = 2.0
    force[101:, 0] = 1.0
    mount = ChipMount(preload=0.5, tissue_prony=PronySeries((g,), (tau,)))
    pressure, skin = {}, {}
    for stiffness in (None, 3.44):
        pad = FingerPad(prony=ELASTIC, lateral_drag=False, joint_stiffness=stiffness)
        skin[stiffness] = pad_response(times, force, pad, mount).skin[:, 2]
        pressure[stiffness] = chip_forces(times, pad_response(times, force, pad, mount).skin, pad, mount)[:, 2]
    face = mount.face_area * PAD.edge_pressure * PAD.stiffening
    seated = np.log1p(PAD.stiffening * 0.5 / (1 - g) / face) / PAD.stiffening

    def elastic(indentation):
        return face / PAD.stiffening * np.expm1(PAD.stiffening * (seated + indentation))

    step = elastic(skin[3.44][-1]) - elastic(skin[None][-1])  # the bulge is held: only the joint's part steps
    assert skin[3.44][-1] - skin[None][-1] == pytest.approx(-31.395e-6, rel=1e-4)
    since = times[101:] - times[101]
    np.testing.assert_allclose(pressure[3.44][101:] - pressure[None][101:],
                               step * ((1 - g) + g * np.exp(-since / tau)), rtol=1e-4)
    np.testing.assert_allclose(pressure[3.44][:101], pressure[None][:101])


# ---------------------------------------------------------------------------------------------- slip, creep, ring


def test_beyond_the_friction_limit_the_shear_and_the_chip_stop_following_fx():
    pad, mount = FingerPad(prony=ELASTIC), ChipMount()
    times = np.linspace(0, 3, 301)
    intended = np.column_stack([np.linspace(0, 3.0, 301), np.zeros(301), np.full(301, 2.0)])
    response = pad_response(times, intended, pad, mount)
    chip = chip_forces(times, response.skin, pad, mount)
    limit = pad.friction * 2.0
    sliding = intended[:, 0] > limit
    assert np.array_equal(response.sliding, sliding) and 0 < sliding.sum() < len(times)
    np.testing.assert_allclose(response.force[:, 0], np.minimum(intended[:, 0], limit))
    # sticking, every reading follows Fx; sliding, none does while the intended force keeps rising
    assert np.all(np.diff(chip[~sliding, 2]) < 0)
    np.testing.assert_allclose(chip[sliding], chip[sliding][:1].repeat(sliding.sum(), axis=0), rtol=1e-12)
    np.testing.assert_allclose(response.shear[sliding], response.shear[sliding][:1].repeat(sliding.sum(), axis=0))


def test_a_held_press_creeps_by_the_law_through_the_prony_creep():
    g, tau = 0.6, 1.4
    pad = FingerPad(prony=PronySeries((g,), (tau,)))
    times, force = held([0.0, 0.0, 2.0], seconds=8.0, rate=1000.0)
    depth = pad_response(times, force, pad, ChipMount()).depth
    g_inf = 1 - g
    creeping = 2.0 / g_inf * (1 - g * np.exp(-g_inf * times / tau))  # the elastic force the depth carries
    expected = np.log1p(pad.stiffening * creeping / pad.stiffness) / pad.stiffening
    np.testing.assert_allclose(depth, expected, rtol=1e-6)
    assert depth[-1] > 1.2 * depth[0]


def test_a_held_tangential_force_creeps_by_its_own_relaxation_function():
    g, tau = 0.5, 11.8  # Pataky et al.'s time scale, one term: Fung's creep function by hand
    pad = FingerPad(prony=ELASTIC, shear_prony=PronySeries((g,), (tau,)))
    times, force = held([0.6, -0.3, 2.0], seconds=30.0, rate=100.0)
    shear = pad_response(times, force, pad, ChipMount()).shear
    g_inf = 1 - g
    creeping = force[:, :2] / g_inf * (1 - g * np.exp(-g_inf * times / tau))[:, None]
    tangent = 2 / 3 * (pad.stiffness + pad.stiffening * 2.0)  # Mindlin's 2/3 of b + m Fz, the pressed pad elastic
    np.testing.assert_allclose(shear, creeping / tangent, rtol=1e-8)  # the recursion accumulates 3.5e-9 in 30 s
    assert shear[-1, 0] > 1.7 * shear[0, 0]  # 1/g_inf = 2 once crept: most of it in 30 s


def test_the_tissue_under_the_chip_relaxes_by_its_own_function_around_the_preload():
    g, tau = 0.6, 0.2
    pad, mount = FingerPad(prony=ELASTIC), ChipMount(preload=0.5, tissue_prony=PronySeries((g,), (tau,)))
    ramp = 1e-5  # s: a step of the skin, linear over this time (the response's own interpolation)
    times = np.concatenate([[0.0, 1.0], 1.0 + ramp + np.linspace(0, 2.0, 201)])
    skin = np.zeros((len(times), 3))
    skin[2:, 2] = 50e-6
    pressure = chip_forces(times, skin, pad, mount)[:, 2]
    face = mount.face_area * pad.edge_pressure * pad.stiffening
    relaxed = 0.5 / (1 - g)  # the seated elastic force that has relaxed to the preload
    seated = np.log1p(pad.stiffening * relaxed / face) / pad.stiffening
    step = face / pad.stiffening * np.expm1(pad.stiffening * (seated + 50e-6)) - relaxed
    since = times[2:] - times[2]
    expected = 0.5 + step * ((1 - g) + g * np.exp(-since / tau))
    assert pressure[:2] == pytest.approx([0.5, 0.5])
    np.testing.assert_allclose(pressure[2:], expected, rtol=1e-4)


def test_with_one_relaxation_function_the_chip_follows_a_tangential_force_without_lag():
    # pressed and held, then a distal force stepped on: with one function for the pad sheared and the
    # tissue under the chip, the creep of the first and the relaxation of the second cancel
    times, force = held([0.0, 0.0, 2.0], seconds=40.0, rate=100.0)
    force[2000:, 1] = 0.8
    readings = {}
    for name, shear_prony in (("one function", None), ("tangential creep", PronySeries((0.5,), (11.8,)))):
        pad = FingerPad(shear_prony=shear_prony)
        response = pad_response(times, force, pad, ChipMount())
        readings[name] = chip_forces(times, response.skin, pad, ChipMount())[:, 0]
    # the largest departure of the chip's distal shear from its first value after the step, as a share of it
    drift = {name: np.abs(chip[2001:] - chip[2001]).max() / np.abs(chip[2001] - chip[1999])
             for name, chip in readings.items()}
    assert drift["one function"] < 0.04  # 3.3 %: only the laws' curvature (the bulge stiffens the chip's tissue)
    assert drift["tangential creep"] > 0.25  # 28 %: the chip's tissue relaxes in 1 s, the pad creeps for 12


def test_the_ring_preload_is_an_offset_and_sets_the_chip_sensitivity():
    pad = FingerPad(prony=ELASTIC)
    times = np.array([0.0, 1.0, 1.0 + 1e-3])
    step = 1e-6
    skin = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, step]])
    sensitivity = {}
    for preload in (0.3, 1.0):
        chip = chip_forces(times, skin, pad, ChipMount(preload=preload))
        assert chip[0, 2] == pytest.approx(preload) and np.all(chip[:2, :2] == 0)
        sensitivity[preload] = (chip[2, 2] - chip[1, 2]) / step
    # the side tissue's law A_f p_edge (e^{md} − 1) has the tangent stiffness A_f p_edge m + m F
    face = 7e-6 * pad.stiffness / (2 * np.pi * math.sqrt(7.5e-3 * 12e-3)) * pad.stiffening
    for preload, measured in sensitivity.items():
        assert measured == pytest.approx(face + pad.stiffening * preload, rel=1e-3)
    assert sensitivity[1.0] > 2 * sensitivity[0.3]


def test_the_chip_loses_contact_rather_than_pulling():
    pad = FingerPad(prony=ELASTIC)
    times = np.array([0.0, 1.0])
    chip = chip_forces(times, np.array([[0.0, 0.0, 0.0], [1e-4, 1e-4, -5e-3]]), pad, ChipMount(preload=0.2))
    assert chip[1, 2] == 0 and np.all(chip[1, :2] == 0)


def test_the_centre_of_force_rolls_with_the_lean_and_is_absent_off_the_object():
    pad = FingerPad(prony=ELASTIC)
    times, force = held([1.0, -0.5, 2.0])
    force[:10] = 0.0
    response = pad_response(times, force, pad, ChipMount(), rest_centre=(1 * MM, -1 * MM), lean=0.5)
    expected = np.array([1, -1]) * MM + 0.5 * np.array([pad.radius_x, pad.radius_y]) * response.shear[-1] / (
        0.4 * pad.width)
    np.testing.assert_allclose(response.centre[-1], expected)
    assert np.isnan(response.centre[:10]).all() and not np.isnan(response.centre[10:]).any()


def test_mistakes_in_the_finger_and_ring_are_one_line_errors():
    with pytest.raises(ConfigError, match=r"^finger.width = -0.01: expected a positive number$"):
        FingerPad(width=-0.01)
    with pytest.raises(ConfigError, match=r"^finger.transmission = 1.5: expected a number from 0 to 1$"):
        FingerPad(transmission=1.5)
    with pytest.raises(ConfigError, match=r"^ring.side = 'left': expected one of radial, ulnar$"):
        ChipMount(side="left")
    with pytest.raises(ValueError, match="contact shape 'cone'"):
        shape_radii("cone", 1.0, 1.0, 1.0)
    assert set(SIDES) == {"radial", "ulnar"}
