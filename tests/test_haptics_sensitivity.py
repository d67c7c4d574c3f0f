"""The sensitivity of the methods' ranking to what makes real fingers differ."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from softtip.systems.haptics.fingertips import HUMAN_FINGERTIPS
from softtip.systems.haptics.sensitivity import FingerVariation, sensitivity_study
from softtip.systems.haptics.study import METHODS, StudySettings

SMALL = StudySettings(targets=20, fs_levels=7, user_levels=7)


def test_variation_changes_only_what_it_names():
    finger = HUMAN_FINGERTIPS[1]
    softer = FingerVariation(name="soft", stiffness_scale=0.5).apply(finger)
    assert softer.contact.youngs_modulus == pytest.approx(0.5 * finger.contact.youngs_modulus)
    assert (softer.shape, softer.mounting, softer.radius) == (finger.shape, finger.mounting, finger.radius)
    assert FingerVariation(name="nail", mounting="nail").apply(finger).mounting == "nail"
    with pytest.raises(ValueError, match="variation.shape = 'cube'"):
        FingerVariation(name="x", shape="cube")


@pytest.mark.slow
def test_stiffness_the_geometric_method_ignores_costs_it_and_not_the_presses():
    finer = replace(SMALL, fs_levels=11)  # the FS table's own floor below the effect of stiffness
    published, softer = sensitivity_study(finer, seed=2, variations=(
        FingerVariation(name="as published"), FingerVariation(name="soft", stiffness_scale=0.5)))
    geometric, presses = METHODS.index("geometric (B)"), METHODS.index("geometric + presses (B+)")
    assert softer.median_error[geometric] > 2 * published.median_error[geometric]
    assert softer.median_error[presses] < softer.median_error[geometric]
    assert softer.ranking[-1] == "standard" and set(softer.ranking) == set(METHODS)
    assert np.all(np.isfinite(softer.median_error))


def test_a_variation_that_puts_a_finger_out_of_reach_is_reported_not_hidden():
    (nail,) = sensitivity_study(SMALL, seed=2, variations=(FingerVariation(name="nail", mounting="nail"),))
    assert nail.median_error is None and nail.pooled is None
    # resting on the nail, the smallest finger's pad sits above the platform's reach: no press touches it
    assert nail.refused.startswith("fingertip 'human 1 (6.5 mm)': presses: none of the 5 presses touched")


@pytest.mark.slow
def test_error_curves_vary_one_setting_at_a_time():
    from matplotlib.figure import Figure

    from softtip.systems.haptics.sensitivity import curves_figure, error_curves

    points = error_curves(SMALL, seed=2, curves=(("n_neighbours", (1,)), ("fs_levels", (5, 11))))
    assert [(p.setting, p.value) for p in points] == [("n_neighbours", 1), ("fs_levels", 5), ("fs_levels", 11)]
    geometric = METHODS.index("geometric (B)")
    # the geometric method sits near the table's own floor: a coarser FS table renders worse
    assert points[1].median_error[geometric] > 1.2 * points[2].median_error[geometric]  # measured: 1.34 times
    assert isinstance(curves_figure(points), Figure)
    with pytest.raises(ValueError, match="'radius' is not a study setting"):
        error_curves(SMALL, curves=(("radius", (1.0,)),))


def test_weighting_power_zero_is_the_plain_average_and_two_the_inverse_square():
    from softtip.systems.haptics.rendering import NearestNeighbourRenderer

    rng = np.random.default_rng(5)
    forces, motor = rng.normal(size=(300, 3)), rng.uniform(size=(300, 3))
    wanted = rng.normal(size=(10, 3))
    for power in (0.0, 2.0):
        renderer = NearestNeighbourRenderer(weighting_power=power).fit(forces, motor)
        for row in wanted:
            distance = np.linalg.norm(forces - row, axis=1)
            nearest = np.argsort(distance)[:8]
            weights = distance[nearest] ** -power
            expected = weights @ motor[nearest] / weights.sum()
            assert np.allclose(renderer.predict(row), expected) and np.allclose(renderer.render_one(row)[0], expected)
