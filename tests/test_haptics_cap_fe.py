"""Finite elements of a cap on a rigid core under a plate: the evidence for S3's contact law."""

from __future__ import annotations

import numpy as np
import pytest

from softtip.mechanics.cap_fe import plate_on_cap_fe
from softtip.systems.haptics.fingertips import CALIBRATED_LAYERS, CORE_RADIUS, VYTAFLEX_30_MODULUS


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
