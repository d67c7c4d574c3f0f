"""The sensitivity of the methods' ranking to what makes real fingers differ."""

from __future__ import annotations

import numpy as np
import pytest

from softtip.systems.haptics.fingertips import HUMAN_FINGERTIPS
from softtip.systems.haptics.sensitivity import FingerVariation, sensitivity_study
from softtip.systems.haptics.study import METHODS, StudySettings

SMALL = StudySettings(targets=30, fs_levels=9, user_levels=5)


def test_variation_changes_only_what_it_names():
    finger = HUMAN_FINGERTIPS[1]
    softer = FingerVariation(name="soft", stiffness_scale=0.5).apply(finger)
    assert softer.contact.youngs_modulus == pytest.approx(0.5 * finger.contact.youngs_modulus)
    assert (softer.shape, softer.mounting, softer.radius) == (finger.shape, finger.mounting, finger.radius)
    assert FingerVariation(name="nail", mounting="nail").apply(finger).mounting == "nail"
    with pytest.raises(ValueError, match="variation.shape = 'cube'"):
        FingerVariation(name="x", shape="cube")


def test_stiffness_the_geometric_method_ignores_costs_it_and_not_the_presses():
    published, softer = sensitivity_study(SMALL, seed=2, variations=(
        FingerVariation(name="as published"), FingerVariation(name="soft", stiffness_scale=0.5)))
    geometric, presses = METHODS.index("geometric (B)"), METHODS.index("geometric + presses (B+)")
    assert softer.median_error[geometric] > 2 * published.median_error[geometric]
    assert softer.median_error[presses] < softer.median_error[geometric]
    assert softer.ranking[-1] == "standard" and set(softer.ranking) == set(METHODS)
    assert np.all(np.isfinite(softer.median_error))


def test_a_variation_that_puts_a_finger_out_of_reach_is_reported_not_hidden():
    (nail,) = sensitivity_study(SMALL, seed=2, variations=(FingerVariation(name="nail", mounting="nail"),))
    assert nail.median_error is None and nail.pooled is None
    assert "human 1 (6.5 mm)" in nail.refused and "barely reaches" in nail.refused
