"""The S4 die file: the shipped, declared layout and the one-line refusals of impossible dies."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from softtip.systems.cilia.layout import SHIPPED_DIE, DieError, read_die

SHIPPED = SHIPPED_DIE.read_text(encoding="utf-8")


def test_the_shipped_die_matches_the_spec():
    die = read_die()
    assert np.allclose(die.size, [3e-3, 3e-3])
    assert len(die.pillars.positions) == 5
    # four corners of the active area and its centre
    corners = {tuple(p) for p in np.round(die.pillars.positions / 1e-3, 9)}
    half = die.active_area / 2 / 1e-3
    assert corners == {(-half[0], -half[1]), (half[0], -half[1]), (-half[0], half[1]), (half[0], half[1]), (0.0, 0.0)}
    rod = die.pillars.rod
    assert (rod.length, rod.tip_diameter, rod.base_diameter, rod.youngs_modulus) == pytest.approx(
        (1e-3, 200e-6, 320e-6, 1e6))
    assert die.pillars.moment == pytest.approx(2.8e-6)  # 2.8 memu per pillar, 1 emu = 1e-3 A·m²
    x, y = die.meander("X"), die.meander("Y")
    assert (len(x.strips), len(y.strips)) == (444, 416)
    assert (x.axis, y.axis) == (0, 1)
    assert x.readout.sensor.minimum_resistance == pytest.approx(183.25e3)
    assert y.readout.sensor.minimum_resistance == pytest.approx(168.75e3)
    assert x.readout.current == pytest.approx(100e-6)
    # strips inside the die, apart from each other, in the plane 10 µm below the bases
    for meander in die.meanders:
        for rectangles in (meander.strips, meander.elements):
            assert rectangles.z == pytest.approx(-10e-6)
            x0, x1 = rectangles.x.T
            y0, y1 = rectangles.y.T
            overlap = ((x0[:, None] < x1[None]) & (x0[None] < x1[:, None]) & (y0[:, None] < y1[None])
                       & (y0[None] < y1[:, None]))
            assert overlap.sum() == len(rectangles)  # each strip (each area element) overlaps itself only
            assert np.all(np.abs(rectangles.x) <= 1.5e-3) and np.all(np.abs(rectangles.y) <= 1.5e-3)
        # the area elements hold every strip's area once: their weights add up to the strips' area, and each
        # holds the strips' area inside it
        weights = np.array(meander.readout.sensor.area_weights)
        assert weights.sum() == pytest.approx(meander.strips.area.sum(), rel=1e-12)
        inside = [np.sum(np.clip(np.minimum(meander.strips.x[:, 1], ex1) - np.maximum(meander.strips.x[:, 0], ex0), 0, None)
                         * np.clip(np.minimum(meander.strips.y[:, 1], ey1) - np.maximum(meander.strips.y[:, 0], ey0), 0,
                                   None))
                  for (ex0, ex1), (ey0, ey1) in zip(meander.elements.x, meander.elements.y)]
        np.testing.assert_allclose(weights, inside, rtol=1e-9)


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "die.toml"
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize(("old", "new", "message"), [
    ("positions_mm = [[-1.0, -1.0],", "positions_mm = [[-1.4, -1.0],",
     r"pillars.positions_mm\[0\] = \[-1.4, -1.0\]: the pillar's base leaves the die"),
    ("[1.0, 1.0], [0.0, 0.0]]", "[1.0, 1.0], [0.9, 0.9]]",
     r"pillars.positions_mm\[3\] and \[4\]: the pillars' bases overlap"),
    ("tip_diameter_um = 200.0", "tip_diameter_um = -200.0", r"pillars.tip_diameter_um = -200.0: expected a positive number"),
    ("moment_memu = 2.8", "moment_memu = 0", r"pillars.moment_memu = 0: expected a positive number"),
    ('magnetisation = "up"', 'magnetisation = "sideways"', r"pillars.magnetisation = 'sideways': expected one of up, down"),
    ("elements = 444\n", "elements = 440\n", r"sensors.X.banks = .*: expected banks holding 440 elements in all"),
    ("element_width_um = 2.0\n# The X and Y", "element_width_um = 9.0\n# The X and Y",
     r"sensors.X.banks\[0\] = .*: 111 strips of 9.0 um do not fit"),
    ("linear_range_Oe = [-25.0, 37.5]\naxis = \"x\"", "linear_range_Oe = [37.5, -25.0]\naxis = \"x\"",
     r"sensors.X.linear_range_Oe = \[37.5, -25.0\]: expected \[low, high\] with low < high"),
    ("active_area_mm = [2.0, 2.0]", "active_area_mm = [4.0, 2.0]", r"die.active_area_mm = \[4.0, 2.0\]: expected an area within the die"),
    ("sensing_depth_um = 10.0", "sensing_depth_um = 10.0\ncolour = 1", r"die.colour: unknown key"),
    ("tip_diameter_um = 200.0", "tip_diameter_um = 400.0",
     r"pillars.tip_diameter_um = 400.0: a tip wider than its base \(320 um\)"),
    ("height_mm = 1.0", "height_mm = 0.3", r"pillars.base_diameter_um = 320.0: pillars wider than they are high \(300 um\)"),
    ("youngs_modulus_MPa = 1.0 ", "youngs_modulus_MPa = 1e300 ",
     r"pillars.youngs_modulus_MPa = 1e\+300: expected 0.001 <= E <= 100 MPa"),
    # a frustum of 1 mm, 200 and 320 um: pi h (a^2 + a b + b^2) / 12 = 5.404e-11 m^3, times 1.6 T / mu_0 = 68.8 memu
    ("moment_memu = 2.8", "moment_memu = 70", r"pillars.moment_memu = 70: more than a pillar of solid NdFeB holds \(68.8 memu"),
])
def test_an_impossible_die_is_refused_in_one_line(tmp_path, old, new, message):
    assert old in SHIPPED
    path = write(tmp_path, SHIPPED.replace(old, new, 1))
    with pytest.raises(DieError, match=message) as refused:
        read_die(path)
    assert "\n" not in str(refused.value)
    assert str(path) in str(refused.value)


def test_missing_or_broken_files_are_refused(tmp_path):
    with pytest.raises(DieError, match=re.escape(f"die file {tmp_path / 'none.toml'} does not exist")):
        read_die(tmp_path / "none.toml")
    with pytest.raises(DieError, match="not valid TOML"):
        read_die(write(tmp_path, "[die\n"))


def test_saturation_per_area_element_against_a_point_by_point_reference():
    """The meander read point by point (every 5 µm along each strip's centre line, each point saturating on
    its own: the free layer's local response; 10 µm spacing gives the same to 1e-5) is the reference, at 8 mN
    in paper mode; the die's ~25 µm area elements come within 0.5 % of its voltage change (measured 0.1 %;
    50 µm ones: 0.6 %), where saturating each strip's mean field, as a whole-strip element does, is 14.2 %
    over."""
    from dataclasses import replace

    from softtip.magnetics.dipoles import dipole_field
    from softtip.systems.cilia.model import CiliaModel, element_fields, pillar_dipoles

    die = read_die()
    model = CiliaModel(die)
    meander = die.meander("X")
    shapes = model.shapes(np.array([0.0, 8e-3]))
    dipoles = pillar_dipoles(die.pillars, shapes, model.chain_count)
    strips = meander.strips
    along = (np.arange(180) + 0.5) / 180
    ys = strips.y[:, :1] + (strips.y[:, 1:] - strips.y[:, :1]) * along[None, :]
    points = np.column_stack([np.repeat(strips.x.mean(axis=1), 180), ys.ravel(), np.full(ys.size, strips.z)])
    field = dipole_field(points, dipoles.positions, dipoles.moments)[..., 0]  # (loads, points)
    by_point = replace(meander.readout, sensor=replace(meander.readout.sensor, elements=points.shape[0],
                                                       area_weights=None))
    reference = np.diff(by_point.voltage(field))[0]
    modelled = np.diff(model.volts(element_fields(meander, dipoles), "X"))[0]
    whole = replace(meander.readout, sensor=replace(meander.readout.sensor, area_weights=None))
    strip_means = whole.voltage(element_fields(replace(meander, elements=strips), dipoles))
    assert modelled == pytest.approx(reference, rel=0.005)
    assert abs(np.diff(strip_means)[0] / reference - 1) > 0.1
