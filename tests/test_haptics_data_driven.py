"""Personalisation A's two variants compared on the same tables: their statistics against scipy, and
each variant's errors against the study run with that variant alone."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from matplotlib.figure import Figure
from scipy import stats

from softtip.systems.haptics.collection import CollectionSettings
from softtip.systems.haptics.data_driven import compare_data_driven
from softtip.systems.haptics.device import load_device
from softtip.systems.haptics.fingertips import TEST_FINGERTIPS
from softtip.systems.haptics.personalisation import DATA_DRIVEN_VARIANTS
from softtip.systems.haptics.study import StudySettings, collect_study, study_fingertip

DEVICE = load_device()
SETTINGS = StudySettings(targets=40, fs_levels=9, user_levels=6)
FINGERTIPS = (TEST_FINGERTIPS[1], TEST_FINGERTIPS[-1])  # the FS cast and the 10 mm human cast
# a sensor of nN noise (none at all would read configurations without contact as identical entries): the
# variants' errors then depend on their tables alone, whatever noise stream renders them
_SENSOR = CollectionSettings().sensor
EXACT = CollectionSettings(sensor=replace(
    _SENSOR, force=replace(_SENSOR.force, noise=(1e-9,) * 3, resolution=(1e-12,) * 3),
    torque=replace(_SENSOR.torque, noise=(1e-12,) * 3, resolution=(1e-15,) * 3)))


@pytest.fixture(scope="module")
def collected():
    return collect_study(DEVICE, FINGERTIPS, SETTINGS, EXACT, seed=2)


def test_each_variant_renders_as_the_study_does_with_it(collected):
    shared, user_data = collected
    comparison = compare_data_driven(DEVICE, FINGERTIPS, shared, user_data, SETTINGS, EXACT, seed=2)
    assert comparison.errors.shape == (2, len(DATA_DRIVEN_VARIANTS), 40)
    for v, variant in enumerate(DATA_DRIVEN_VARIANTS):
        for index, fingertip in enumerate(FINGERTIPS):
            outcome = study_fingertip(DEVICE, fingertip, shared, replace(SETTINGS, data_driven=variant), EXACT, 2,
                                      index, tests=7, user_data=user_data[index])
            # method A (row 1) of the study: the same errors, its sensor noiseless
            assert np.allclose(comparison.errors[index, v], outcome.errors[1], rtol=0, atol=1e-6)
    # the two variants do differ
    assert not np.allclose(comparison.errors[:, 0], comparison.errors[:, 1])
    # the published search with other torque lengths: as the study renders with that length
    lengths = [length for length, _, _ in comparison.length_sweep]
    assert lengths == pytest.approx([SETTINGS.torque_length * f for f in (0.25, 1.0, 4.0)], rel=1e-12)
    for length, median, mean in comparison.length_sweep:
        pooled = np.concatenate([
            study_fingertip(DEVICE, fingertip, shared, replace(SETTINGS, torque_length=length), EXACT, 2, index,
                            tests=7, user_data=user_data[index]).errors[1] for index, fingertip in enumerate(FINGERTIPS)])
        assert median == pytest.approx(np.median(pooled), abs=1e-6) and mean == pytest.approx(pooled.mean(), abs=1e-6)
    assert comparison.length_sweep[1][1] == comparison.rows()[-1][1]  # the stated length: the comparison's own


def test_comparison_statistics_are_scipys(collected):
    shared, user_data = collected
    comparison = compare_data_driven(DEVICE, FINGERTIPS, shared, user_data, SETTINGS, EXACT, seed=2)
    rows = comparison.rows()
    assert [row[0] for row in rows] == [f.name for f in FINGERTIPS] + ["all fingertips (pooled)"]
    pooled = comparison.errors.transpose(1, 0, 2).reshape(2, -1)
    for row, errors in zip(rows, (*comparison.errors, pooled), strict=True):
        assert row[1:5] == pytest.approx([*np.median(errors, axis=1), *errors.mean(axis=1)], rel=1e-12)
        # Bonferroni over the two fingertips and the pooled test
        assert row[5] == pytest.approx(min(1.0, 3 * stats.wilcoxon(errors[0], errors[1]).pvalue), rel=1e-9)
    table = comparison.table()
    assert table.rows[:3] == [row[0] for row in rows] and len(table.columns) == 5
    assert table.rows[3:] == [f"all fingertips (pooled), torques over {length * 1e3:g} mm"
                              for length, _, _ in comparison.length_sweep]
    assert isinstance(comparison.figure(), Figure)
    assert comparison.to_dict()["torque_length_m"] == SETTINGS.torque_length
    with pytest.raises(ValueError, match="user_data: expected one per fingertip, 2, got 1"):
        compare_data_driven(DEVICE, FINGERTIPS, shared, user_data[:1], SETTINGS, EXACT, seed=2)


def test_ablations_rerun_each_method_as_the_study_and_the_comparison_do(collected):
    from softtip.systems.haptics.ablation import (
        A_DEVICE_AXES,
        A_PUBLISHED,
        B,
        B_PLUS_COMPLIANT,
        B_PLUS_RIGID,
        ROWS,
        ablate,
    )

    shared, user_data = collected
    ablations = ablate(DEVICE, FINGERTIPS, shared, user_data, SETTINGS, EXACT, seed=2)
    assert ablations.errors.shape == (len(ROWS), 2, 40)
    comparison = compare_data_driven(DEVICE, FINGERTIPS, shared, user_data, SETTINGS, EXACT, seed=2)
    # its sensor noiseless, each row is the comparison's or the study's own rendering of that method
    assert np.allclose(ablations.errors[A_PUBLISHED], comparison.errors[:, 0], rtol=0, atol=1e-6)
    assert np.allclose(ablations.errors[A_DEVICE_AXES], comparison.errors[:, 1], rtol=0, atol=1e-6)
    for index, fingertip in enumerate(FINGERTIPS):
        outcome = study_fingertip(DEVICE, fingertip, shared, SETTINGS, EXACT, 2, index, tests=7,
                                  user_data=user_data[index])
        assert np.allclose(ablations.errors[B, index], outcome.errors[2], rtol=0, atol=1e-6)
        assert np.allclose(ablations.errors[B_PLUS_RIGID, index], outcome.errors[3], rtol=0, atol=1e-6)
    # the cables' give changes B+, and each row's test is scipy's against its group's first, Bonferroni over 9
    assert not np.allclose(ablations.errors[B_PLUS_COMPLIANT], ablations.errors[B_PLUS_RIGID])
    test = ablations.tests[B_PLUS_COMPLIANT]
    reference = stats.wilcoxon(ablations.errors[B_PLUS_COMPLIANT].ravel(), ablations.errors[B_PLUS_RIGID].ravel())
    assert test.p_bonferroni == pytest.approx(min(1.0, 9 * reference.pvalue), rel=1e-9)
    assert ablations.table().rows == list(ROWS) and len(ablations.to_dict()["findings"]) == 2
