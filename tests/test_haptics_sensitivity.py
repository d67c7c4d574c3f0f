"""The sensitivity of the methods' ranking to what makes real fingers differ."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from softtip.systems.haptics.fingertips import HUMAN_FINGERTIPS, TEST_FINGERTIPS
from softtip.systems.haptics.sensitivity import Baseline, FingerVariation, sensitivity_study
from softtip.systems.haptics.study import METHODS, StudySettings, run_study

SMALL = StudySettings(targets=20, fs_levels=7, user_levels=7)


@pytest.fixture(scope="module")
def small_baseline():
    return Baseline.run(SMALL, seed=2)


def test_variation_changes_only_what_it_names():
    finger = HUMAN_FINGERTIPS[1]
    softer = FingerVariation(name="soft", stiffness_scale=0.5).apply(finger)
    assert softer.contact.youngs_modulus == pytest.approx(0.5 * finger.contact.youngs_modulus)
    assert (softer.shape, softer.mounting, softer.radius) == (finger.shape, finger.mounting, finger.radius)
    assert FingerVariation(name="nail", mounting="nail").apply(finger).mounting == "nail"
    moved = FingerVariation(name="core", core_offset=(0.0, 0.0, 1e-3)).apply(finger)
    assert moved.core_offset == (0.0, 0.0, 1e-3) and moved.contact == finger.contact
    with pytest.raises(ValueError, match="variation.shape = 'cube'"):
        FingerVariation(name="x", shape="cube")


def test_the_baseline_is_the_study_itself(small_baseline):
    study = run_study(SMALL, seed=2)
    for rerun, outcome in zip(small_baseline.outcomes, study.fingertips, strict=True):
        assert np.array_equal(rerun.errors, outcome.errors)  # the same noise streams, draw for draw


def test_stiffness_the_geometric_method_ignores_costs_it():
    finer = Baseline.run(replace(SMALL, fs_levels=11), seed=2)  # the FS table's own floor below the effect
    published, softer = sensitivity_study(finer, variations=(
        FingerVariation(name="as published"), FingerVariation(name="soft", stiffness_scale=0.5)))
    geometric = METHODS.index("geometric (B)")
    # the same indentation presses a softer pad less; the cables' give in series (the fitted device's)
    # takes up most of the difference, so the cost is small (measured: 0.291 -> 0.315 N)
    assert softer.median_error[geometric] > 1.05 * published.median_error[geometric]
    assert softer.ranking[-1] == "standard" and set(softer.ranking) == set(METHODS)
    assert np.all(np.isfinite(softer.median_error))


def test_the_core_position_moves_no_force(small_baseline):
    (moved,) = sensitivity_study(small_baseline, variations=(
        FingerVariation(name="core", core_offset=(0.0, 0.0, 1.5e-3)),))
    human = [o for o in small_baseline.outcomes if o.fingertip in HUMAN_FINGERTIPS]
    # the contact force does not depend on where the sensor's origin sits, and every method renders forces
    assert np.array_equal(moved.median_error, np.median(np.hstack([o.errors for o in human]), axis=1))


def test_a_variation_that_puts_a_finger_out_of_reach_is_reported_not_hidden(small_baseline):
    (nail,) = sensitivity_study(small_baseline, variations=(FingerVariation(name="nail", mounting="nail"),))
    # resting on the nail, the smallest finger's pad sits above the platform's reach: no press touches it
    assert nail.left_out[0] == "human 1 (6.5 mm)"
    assert nail.refused.startswith("fingertip 'human 1 (6.5 mm)': presses: none of the 5 presses touched")
    assert "human 2 (8 mm)" not in nail.left_out and np.all(np.isfinite(nail.median_error))
    # every human fingertip refused: no figures at all, and why
    only_small = Baseline.run(SMALL, seed=2, fingertips=(TEST_FINGERTIPS[1], HUMAN_FINGERTIPS[0]))
    (refused,) = sensitivity_study(only_small, variations=(FingerVariation(name="nail", mounting="nail"),))
    assert refused.median_error is None and refused.pooled is None and refused.left_out == ("human 1 (6.5 mm)",)
    with pytest.raises(ValueError, match="expected at least one of human 1"):
        sensitivity_study(Baseline.run(SMALL, seed=2, fingertips=TEST_FINGERTIPS[:1]))


def test_error_curves_vary_one_setting_at_a_time(small_baseline):
    from matplotlib.figure import Figure

    from softtip.systems.haptics.sensitivity import curves_figure, error_curves

    points = error_curves(small_baseline, curves=(("n_neighbours", (1, 8)), ("fs_levels", (5, 11))))
    assert [(p.setting, p.value) for p in points] == [("n_neighbours", 1), ("n_neighbours", 8), ("fs_levels", 5),
                                                      ("fs_levels", 11)]
    every = np.hstack([o.errors for o in small_baseline.outcomes])
    assert np.array_equal(points[1].median_error, np.median(every, axis=1))  # the study's own n: the baseline
    geometric = METHODS.index("geometric (B)")
    # the geometric method sits near the table's own floor: a coarser FS table renders worse
    assert points[2].median_error[geometric] > 1.1 * points[3].median_error[geometric]  # measured: 1.16 times
    assert isinstance(curves_figure(points), Figure)
    with pytest.raises(ValueError, match="'radius' is not a setting the curves vary"):
        error_curves(small_baseline, curves=(("radius", (1.0,)),))


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
