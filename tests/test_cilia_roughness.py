"""Brushing the die across rough surfaces: the profiles against their analytic statistics, the trace
against the balance curve, the meter's averaging against a sinusoid's, and the study's trends."""

from __future__ import annotations

import math

import numpy as np
import pytest

from softtip.mechanics.rod import PlateContact
from softtip.systems.cilia.layout import DieError, read_die
from softtip.systems.cilia.model import CiliaModel
from softtip.systems.cilia.roughness import (
    SPACING,
    SURFACES,
    Brush,
    Recording,
    ac_rms,
    analyse_roughness,
    brush_surfaces,
    read_brushing,
    surface_profile,
)

MODEL = CiliaModel(read_die())


@pytest.fixture(scope="module")
def brush() -> Brush:
    return Brush.of(MODEL, "X", PlateContact(0.5, math.radians(0.5)))


def test_a_profile_has_the_stated_rms_and_a_gaussian_autocorrelation():
    correlation, spacing = 20e-6, 2e-6
    heights = surface_profile(46.2e-6, correlation, 0.2, spacing, np.random.default_rng(1))
    assert heights.std() == pytest.approx(46.2e-6, rel=1e-12) and abs(heights.mean()) < 1e-18
    lag = round(correlation / spacing)
    acf = np.mean(heights[:-lag] * heights[lag:]) / heights.var()
    assert acf == pytest.approx(math.exp(-1), abs=0.03)  # exp(−(x/ℓ)²) at x = ℓ
    assert not surface_profile(0.0, 0.0, 1e-3, spacing, np.random.default_rng(1)).any()  # silicon is flat


def test_a_raised_surface_reads_as_the_balance_curve_a_step_further_down(brush):
    engagement, raised = brush.descent[10], brush.descent[14] - brush.descent[10]
    heights = np.full(2000, raised)
    trace = brush.trace(heights, SPACING, engagement)
    direct = MODEL.balance_curve(np.linspace(0.0, brush.descent[14], 15), PlateContact(0.5, math.radians(0.5)), "X")
    assert np.allclose(trace, direct.change[-1], rtol=1e-9)


def test_the_meter_averages_away_a_wavelength_it_integrates_over(brush):
    wavelength = 200e-6
    x = np.arange(0, 40e-3, SPACING)
    heights = 20e-6 * np.sin(2 * np.pi * x / wavelength)
    rng = np.random.default_rng(2)
    # a reading per 20 µm of travel follows the sinusoid; one per whole wavelength averages it to zero
    fine = ac_rms(read_brushing(brush, heights, SPACING, 150e-6, 1e-3, 50.0, rng))
    whole = ac_rms(read_brushing(brush, heights, SPACING, 150e-6, 5e-3, 25.0, rng))
    flat = ac_rms(read_brushing(brush, 0 * heights, SPACING, 150e-6, 5e-3, 25.0, rng))
    assert fine > 10 * whole and whole < 3 * flat


@pytest.mark.parametrize("call, message", [
    (lambda b: surface_profile(-1e-6, 1e-5, 1e-3, 1e-6, np.random.default_rng()), "rms = -1e-06"),
    (lambda b: surface_profile(1e-5, 1e-6, 1e-3, 1e-6, np.random.default_rng()), "correlation"),
    (lambda b: read_brushing(b, np.zeros(5000), SPACING, 150e-6, math.nan, 20.0, np.random.default_rng()), "speed"),
    (lambda b: read_brushing(b, np.zeros(5000), SPACING, 150e-6, 1e-3, -1.0, np.random.default_rng()), "rate"),
    (lambda b: b.trace(np.zeros(5000), SPACING, 2e-3), "engagement"),
])
def test_bad_input_is_refused(brush, call, message):
    with pytest.raises(DieError, match=message):
        call(brush)


def test_rougher_surfaces_read_larger_and_a_slow_rate_misses_roughness():
    brushings = brush_surfaces(MODEL, PlateContact(0.5, math.radians(0.5)), 150e-6, 10e-3, 1e-3, 50.0,
                               (0.5e-3, 2e-3), (2.0, 20.0, 100.0), 2, np.random.default_rng(3))
    # every strip at the nominal and both other speeds at 50/s, and the first strip at 1 mm/s at each rate
    assert len(brushings) == 4 * (2 * 3 + 3)
    force = brushings[-1].force  # P100: the vertical force rides the grains about the engagement's
    assert force.min() >= 0 and force.std() > 0
    study = analyse_roughness([b.recording for b in brushings], 1e-3, 50.0, seed=3)
    assert study.surfaces == ("silicon", "P1000", "P320", "P100")
    assert study.floor == study.total_rms[0] and np.all(np.diff(study.total_rms) > 0)
    assert study.slope > 0
    assert list(study.rates) == [2.0, 20.0, 50.0, 100.0]  # the nominal rate's recordings join the curve
    # the rate curve: 2 readings/s average the grains away (measured on 10 mm: 4 × below 100/s on P1000)
    assert np.all(study.rms_by_rate[1:3, 0] < 0.5 * study.rms_by_rate[1:3, -1])  # grains << 0.5 mm a reading
    # the speed curve at 50/s: the nominal speed's column is the level itself; faster, a reading crosses more
    # grains and reads less (measured: P1000 0.79 × at 2 mm/s of its 0.5 mm/s level)
    np.testing.assert_allclose(study.speeds, [0.5e-3, 1e-3, 2e-3])
    np.testing.assert_array_equal(study.rms_by_speed[:, 1], study.total_rms)
    assert np.all(np.diff(study.rms_by_speed[1:], axis=1) < 0)
    assert study.rms_by_speed[1, -1] < 0.85 * study.rms_by_speed[1, 0]
    classified = study.classification
    assert classified.confusion_by_recording.sum() == classified.windows
    assert classified.by_recording > 0.6  # chance: 0.25
    assert classified.held_speed == 2e-3 and classified.confusion_at_held_speed.sum() > 0


def test_the_analysis_refuses_recordings_without_a_flat_surface_or_a_nominal_run():
    rng = np.random.default_rng(0)
    rough = [Recording("P320", SURFACES["P320"], 0, 1e-3, 50.0, rng.normal(size=100))]
    with pytest.raises(DieError, match="expected a flat surface"):
        analyse_roughness(rough, 1e-3, 50.0, 0)
    flat = [Recording("silicon", 0.0, 0, 1e-3, 50.0, rng.normal(size=100))]
    with pytest.raises(DieError, match="no brushing of silicon at 2 mm/s"):
        analyse_roughness(flat + rough, 2e-3, 50.0, 0)
    with pytest.raises(DieError, match="found none"):
        analyse_roughness([], 1e-3, 50.0, 0)
