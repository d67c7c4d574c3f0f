"""Finite elements of a cap on a rigid core under a plate: the evidence for S3's contact law."""

from __future__ import annotations

import numpy as np
import pytest

from softtip.mechanics.cap_fe import FE_POISSON_RATIO, plate_on_cap_fe
from softtip.mechanics.plate_contact import bonded_layer_force
from softtip.systems.haptics.fingertips import (
    CALIBRATED_LAYERS,
    CALIBRATED_RADII,
    CORE_RADIUS,
    VYTAFLEX_30_MODULUS,
    cast,
    layer_thickness,
)


@pytest.mark.slow
def test_fs_cast_calibration_is_what_the_fe_gives_and_hertz_is_not():
    depths = np.array([0.1e-3, 0.25e-3, 0.5e-3, 0.75e-3, 1.0e-3])
    curve = plate_on_cap_fe(7.5e-3, 7.5e-3 - CORE_RADIUS, VYTAFLEX_30_MODULUS, depths, tip_size=0.5e-3)
    assert curve.converged
    assert curve.calibrated_thickness == pytest.approx(dict(CALIBRATED_LAYERS)[7.5e-3], rel=0.01)
    assert np.allclose(curve.calibrated_forces, curve.fe_forces, rtol=0.05)
    assert np.all(curve.hertz_forces < 0.8 * curve.fe_forces)  # the core stiffens the contact
    assert np.all(np.diff(curve.hertz_forces / curve.fe_forces) < 0)  # more so the deeper


@pytest.mark.slow
def test_shallow_contact_on_a_thick_cap_approaches_hertz():
    # a contact radius of 0.61 mm under 6.5 mm of rubber: near Hertz's half space (FE 3.4 % above it)
    curve = plate_on_cap_fe(7.5e-3, 6.5e-3, 1e6, [0.05e-3], tip_size=0.25e-3)
    assert curve.converged
    assert curve.fe_forces[0] == pytest.approx(curve.hertz_forces[0], rel=0.05)


def test_depths_beyond_the_layer_are_refused():
    with pytest.raises(ValueError, match="depths"):
        plate_on_cap_fe(7.5e-3, 3e-3, 1e6, [4e-3])


@pytest.mark.slow
def test_the_calibration_between_its_radii_is_what_the_fe_gives():
    # 9 mm is not in the calibration grid (8.5 and 10 mm are its neighbours): the FE at three of the
    # calibration's depths, its own best thickness, and the law with the interpolated one
    depths = np.array([0.1e-3, 0.5e-3, 1.0e-3])
    radius = 9.0e-3
    assert radius not in dict(CALIBRATED_LAYERS)
    curve = plate_on_cap_fe(radius, radius - CORE_RADIUS, VYTAFLEX_30_MODULUS, depths, tip_size=0.5e-3)
    assert curve.converged
    interpolated = layer_thickness(radius)
    assert interpolated == pytest.approx(curve.calibrated_thickness, rel=0.01)  # measured: 0.70 % below
    law = bonded_layer_force(depths, radius, VYTAFLEX_30_MODULUS / (1 - FE_POISSON_RATIO**2) * 0.75, interpolated)
    assert np.allclose(law, curve.fe_forces, rtol=0.03)  # measured: 98.5–102.4 % of the FE
    assert np.all(curve.hertz_forces < 0.9 * curve.fe_forces)  # measured: 60–88 %: the law is needed


def test_the_calibration_is_a_function_of_the_radius_over_its_range():
    radii, thicknesses = np.array(CALIBRATED_LAYERS).T
    assert [layer_thickness(r) for r in radii] == pytest.approx(thicknesses, rel=1e-12)  # the FE's, at its radii
    between = np.linspace(*CALIBRATED_RADII, 200)
    found = np.array([layer_thickness(r) for r in between])
    assert np.all(np.diff(found) > 0)  # more rubber, a thicker effective layer: no overshoot between the radii
    assert np.all(found > between - CORE_RADIUS)  # and thicker than the rubber itself, as at every FE radius
    assert cast("a 9 mm finger", 9.0e-3).contact.layer_thickness == pytest.approx(layer_thickness(9.0e-3))
    for radius in (6.0e-3, 11.5e-3, float("nan")):
        with pytest.raises(ValueError, match="expected a cast radius from 6.5 to 11 mm"):
            cast("outside", radius)
