"""The composed S4 model: chains placed on the die, element fields against magpylib, the voltage curve's
behaviour in both regimes and in the balance test, and bad input."""

from __future__ import annotations

import math
from dataclasses import replace

import magpylib as magpy
import numpy as np
import pytest

from softtip.magnetics.dipoles import Rectangles, rectangle_average_in_plane
from softtip.mechanics.rod import PlateContact, lower_plate, touching_height
from softtip.systems.cilia.layout import DieError, read_die
from softtip.systems.cilia.model import BalancePlate, CiliaModel, element_fields, pillar_dipoles

DIE = read_die()
MODEL = CiliaModel(DIE)


def test_chains_stand_on_the_pillar_bases_and_follow_the_bent_centre_line():
    shapes = MODEL.shapes(np.array([0.0, 10e-3]))
    dipoles = pillar_dipoles(DIE.pillars, shapes, 10)
    assert dipoles.positions.shape == (2, 50, 3)
    per_pillar = dipoles.positions.reshape(2, 5, 10, 3)
    # at rest: straight up over each base at (k + 1/2) mm / 10, moment 2.8 memu / 10 each, along +z
    assert np.allclose(per_pillar[0, :, :, :2], DIE.pillars.positions[:, None, :])
    assert np.allclose(per_pillar[0, 0, :, 2], (np.arange(10) + 0.5) * 1e-4)
    assert np.allclose(dipoles.moments[0], [0.0, 0.0, 2.8e-7])
    # loaded: bent towards +x (the die's bend azimuth), every pillar alike, moments along the chords
    bent = per_pillar[1] - per_pillar[1, :, :1] * [1, 1, 0]
    assert np.allclose(bent, bent[0])
    assert np.all(np.diff(per_pillar[1, 0, :, 0]) > 0) and np.allclose(per_pillar[1, :, :, 1], per_pillar[0, :, :, 1])
    moments = dipoles.moments[1].reshape(5, 10, 3)
    assert np.allclose(np.linalg.norm(moments, axis=-1), 2.8e-7)
    assert moments[0, -1, 0] > moments[0, 0, 0] > 0  # the tip turns further than the root


def test_element_fields_match_magpylib_dipoles_integrated_over_the_strips():
    shapes = MODEL.shapes(np.array([8e-3]))
    dipoles = pillar_dipoles(DIE.pillars, shapes, 10)
    meander = DIE.meander("X")
    ours = element_fields(meander, dipoles)[0]
    sources = [magpy.misc.Dipole(moment=m, position=p) for p, m in zip(dipoles.positions[0], dipoles.moments[0])]
    # strips under a corner pillar's root, beside the centre pillar, and mid-bank
    chosen = [0, 10, 221, 222, 300, 443]
    g, w = np.polynomial.legendre.leggauss(6)
    for index in chosen:
        (x0, x1), (y0, y1) = meander.elements.x[index], meander.elements.y[index]
        # composite Gauss–Legendre: 400 panels along the strip (the field changes over tens of µm there)
        edges = np.linspace(y0, y1, 401)
        ys = ((edges[:-1, None] + edges[1:, None]) / 2 + (edges[1:, None] - edges[:-1, None]) / 2 * g).ravel()
        wy = np.tile(w, 400) * np.repeat(np.diff(edges) / 2, 6)
        xs = (x0 + x1) / 2 + (x1 - x0) / 2 * g
        grid_x, grid_y = np.meshgrid(xs, ys, indexing="ij")
        points = np.column_stack([grid_x.ravel(), grid_y.ravel(), np.full(grid_x.size, meander.elements.z)])
        field = magpy.getB(sources, points, sumup=True)[:, 0].reshape(grid_x.shape)
        average = (w[:, None] * wy[None, :] * field).sum() * (x1 - x0) / 2 / ((x1 - x0) * (y1 - y0))
        # measured: 5e-13 relative at worst (the quadrature's own error)
        assert ours[index] == pytest.approx(average, rel=1e-11)


def test_the_curve_is_linear_at_small_forces_and_saturates_as_the_pillars_turn_over():
    small = MODEL.curve(np.array([1e-5, 2e-5, 4e-5]), "X")
    ratio = small.change / small.force
    assert np.allclose(ratio, ratio[0], rtol=2e-3)  # measured 0.1 % across 10 .. 40 µN
    curve = MODEL.curve(np.linspace(0.0, 40e-3, 41), "X")
    slope = np.gradient(curve.change, curve.force)
    # the voltage follows the force less and less: measured slope at 40 mN 4.6 % of the one at rest
    assert abs(slope[-1]) < 0.06 * abs(slope[0])
    # monotonic for the declared die over the published range (measured: to 39 mN; from 39 to 40 mN the
    # change turns back by 8 µV as the bent pillars' tips near the meanders' far squares)
    assert np.all(np.diff(curve.change[curve.force <= 26e-3]) < 0)
    assert not curve.lying.any()  # a fixed perpendicular load never lays a pillar flat
    # the field the pillars make over a sensor is a few oersted, as published (≈ 3 Oe)
    meander = DIE.meander("X")
    oersted = abs(curve.change[-1]) / (meander.readout.current * 146.6)
    assert 1.0 < oersted < 5.0


def test_the_follower_reading_lays_the_pillars_on_their_side():
    curve = CiliaModel(DIE, mode="paper-follower").curve(np.linspace(0.0, 60e-3, 13), "X")
    assert curve.lying[-1] and not curve.lying[0]
    lying = np.flatnonzero(curve.lying)
    assert np.allclose(curve.change[lying], curve.change[lying[0]])  # the voltage stops with the shape


def test_the_balance_test_buckles_the_pillars_before_bending_them():
    rod = DIE.pillars.rod
    descent = np.linspace(0.0, 0.5 * rod.length, 12)
    curve = MODEL.balance_curve(descent, PlateContact(friction=0.5, imperfection=0.01), "X")
    assert curve.force[0] == 0.0 and curve.change[0] == 0.0  # touching: no push yet, the tare itself
    assert np.all(np.diff(curve.force[:3]) > 0)
    # straight compression hardly changes the field: the first micro-newtons change it by < 1 µV per µN
    noise = DIE.meander("X").readout.noise(18.7).total
    assert abs(curve.change[1]) < 1.0 * curve.force[1] + noise  # 1 V/N: 1 µV per µN
    assert np.any(np.abs(curve.shapes.tip_angle) > 0.3)


def test_bad_input_is_refused_in_one_line():
    with pytest.raises(DieError, match="forces: expected a non-empty 1-D array of finite forces >= 0 N"):
        MODEL.curve(np.array([-1e-3]))
    with pytest.raises(DieError, match="forces: expected"):
        MODEL.curve(np.array([np.nan]))
    with pytest.raises(DieError, match="no sensor 'Z'"):
        MODEL.curve(np.array([1e-3]), "Z")
    with pytest.raises(DieError, match="mode = 'tilted'"):
        CiliaModel(DIE, mode="tilted")
    with pytest.raises(DieError, match="chain_count = 0"):
        CiliaModel(DIE, chain_count=0)
    with pytest.raises(DieError, match="descent: expected a non-empty 1-D array of increasing distances"):
        MODEL.balance_curve(np.array([0.5e-3, 0.1e-3]))
    with pytest.raises(DieError, match="descent: expected"):
        MODEL.balance_curve(np.array([0.0, 2e-3]))


def test_a_chain_given_in_the_pillars_frame_is_turned_to_their_azimuth_and_set_on_each_base():
    from dataclasses import replace

    from softtip.systems.cilia.model import chain_dipoles

    die = read_die()
    pillars = replace(die.pillars, positions=np.array([[1e-3, -1e-3]]), bend_azimuth=np.pi / 2)
    # one dipole 0.1 mm along the bend, 0.5 mm up, pointing along the bend: at 90° the bend is +y
    dipoles = chain_dipoles(pillars, np.array([[[1e-4, 0.0, 5e-4]]]), np.array([[[1.0, 0.0, 0.0]]]))
    assert np.allclose(dipoles.positions, [[[1e-3, -1e-3 + 1e-4, 5e-4]]], atol=1e-15)
    assert np.allclose(dipoles.moments, [[[0.0, pillars.moment, 0.0]]], atol=1e-18)


def test_a_tilted_die_on_a_turning_plate_meets_each_pillar_at_its_own_height():
    """Each pillar's push is read off one rod's path at its own gap; checked against the rod solved at that
    gap directly, and the plate's turn against the moment balance k φ = −Σ F (a + u)."""
    tilt = math.radians(1.0)
    contact = PlateContact(friction=0.5, imperfection=0.01, tilt=tilt)
    plate = BalancePlate(rotation_stiffness=1e-4)
    descent = np.linspace(0.0, 60e-6, 4)
    curve = MODEL.balance_curve(descent, contact, "X", plate)
    lever = DIE.pillars.positions[:, 0]  # the bend is along +x
    rod = DIE.pillars.rod
    start = touching_height(rod, contact)
    turn = curve.rotation[-1]
    # the bases at +x sit nearer the plate by 2 mm sin(1°) = 35 µm; the turned plate moves each by −a φ
    expected = start - descent[-1] + (lever.max() - lever) * math.sin(tilt) - lever * turn
    assert np.allclose(curve.gaps[-1], expected, atol=1e-12)
    order = np.argsort(curve.gaps[-1])[::-1]
    direct = lower_plate(rod, curve.gaps[-1][order], contact)
    pushes = np.empty(lever.size)
    pushes[order] = direct.vertical_force
    tips = np.empty(lever.size)
    tips[order] = direct.shapes.x[:, -1]
    # measured: the table's interpolation within 0.3 % of the direct solve
    assert curve.force[-1] == pytest.approx(pushes.sum(), rel=5e-3)
    assert plate.rotation_stiffness * turn == pytest.approx(-(pushes @ (lever + tips)), rel=2e-2)
    assert turn < 0  # the pillars at +x touch first: the plate gives way there
    rigid = MODEL.balance_curve(descent, contact, "X")
    assert np.all(rigid.rotation == 0)
    assert np.allclose(rigid.gaps[-1], start - descent[-1] + (lever.max() - lever) * math.sin(tilt), atol=1e-12)


def test_every_pillar_alike_on_a_parallel_plate_is_one_rod_five_times():
    contact = PlateContact(friction=0.5, imperfection=0.01)
    descent = np.array([0.0, 30e-6, 300e-6, 550e-6])
    curve = MODEL.balance_curve(descent, contact, "X")
    rod = DIE.pillars.rod
    fine = np.linspace(0.0, 550e-6, 221)  # the path solved alone, in steps of its own
    direct = lower_plate(rod, touching_height(rod, contact) - fine, contact)
    rows = np.searchsorted(fine, descent - 1e-12)
    direct = replace(direct, vertical_force=direct.vertical_force[rows], shapes=direct.shapes.take(rows))
    assert curve.force == pytest.approx(5 * direct.vertical_force, rel=5e-3, abs=1e-6)
    assert np.array_equal(curve.lying, direct.lying)
    # the plate folds the lying pillars: the balance reads past the published 26 mN
    assert curve.lying[-1] and curve.force[-1] > 26e-3


def test_the_tip_load_curve_converges_in_the_chains_dipoles():
    """The tip-load curve moves within 2.5 % from 10 to 160 dipoles a pillar (measured 2.2 % at 5 mN and 2.1 %
    at 26 mN), while the balance test's needs 40."""
    forces = np.array([5e-3, 26e-3])
    coarse, fine = (CiliaModel(DIE, chain_count=count).curve(forces, "X").change for count in (10, 160))
    assert np.allclose(coarse, fine, rtol=0.025)


@pytest.mark.slow
def test_the_balance_tests_chain_converges_by_40_dipoles_not_at_the_published_10():
    """The balance test read with 10, 40 and 160 equal dipoles a pillar (20 steps of the shipped plan): 40 and
    160 agree, the published 10 do not (their points sit too far apart over the roots' area elements)."""
    from softtip.systems.cilia.study import CiliaSettings, balance_contact, balance_plate

    model = CiliaModel(read_die())
    settings = CiliaSettings()
    descent = np.linspace(0.0, 0.7 * model.die.pillars.rod.length, 20)
    change = {count: replace(model, chain_count=count).balance_curve(descent, balance_contact(settings), "X",
                                                                     balance_plate(settings)).change
              for count in (10, 40, 160)}
    scale = np.abs(change[160]).max()
    gaps = {count: np.abs(change[count] - change[160]).max() / scale for count in (10, 40)}
    # measured: 40 within 4.3 % of the curve's largest change, 10 off by 120 %
    assert gaps[40] < 0.05
    assert gaps[10] > 0.5


def test_the_curves_fields_summed_per_load_equal_each_element_taken_alone():
    # the shared-corner kernel sums its corners over a load's dipoles before the elements gather them; each
    # element alone takes the per-rectangle closed form, dipole by dipole (the kernel's other branch): every
    # seventh element, over the whole of both meanders
    forces = np.array([0.0, 2e-3, 14e-3, 26e-3])
    dipoles = pillar_dipoles(DIE.pillars, MODEL.shapes(forces), 10)
    for sensor in ("X", "Y"):
        meander = DIE.meander(sensor)
        summed = element_fields(meander, dipoles)
        cells = meander.elements
        alone = np.stack([rectangle_average_in_plane(Rectangles(cells.x[i:i + 1], cells.y[i:i + 1], cells.z),
                                                     dipoles.positions, dipoles.moments, (meander.axis,))[:, 0, 0]
                          for i in range(0, len(cells), 7)], axis=1)
        summed = summed[:, ::7]
        # measured: 1.2e-13 of the largest field at worst
        assert np.max(np.abs(summed - alone)) <= 1e-12 * np.max(np.abs(alone))
