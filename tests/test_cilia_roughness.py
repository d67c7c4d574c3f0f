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
    Brush,
    ac_rms,
    read_brushing,
    roughness_study,
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
    study = roughness_study(MODEL, PlateContact(0.5, math.radians(0.5)), 150e-6, 1e-3, 50.0, 10e-3,
                            (0.5e-3, 2e-3), (2.0, 20.0, 100.0), 2, seed=3)
    assert study.surfaces == ("silicon", "P1000", "P320", "P100")
    assert study.floor == study.total_rms[0] and np.all(np.diff(study.total_rms) > 0)
    assert study.slope > 0
    # the rate curve: 2 readings/s average the grains away (measured on 20 mm: 7 × below 100/s on P1000)
    assert np.all(study.rms_by_rate[1:3, 0] < 0.5 * study.rms_by_rate[1:3, -1])  # grains << 0.5 mm a reading
    classified = study.classification
    assert classified.confusion_by_recording.sum() == classified.windows
    assert classified.by_recording > 0.6  # chance: 0.25
