"""Brushing the die across rough surfaces: the profiles against their analytic statistics, the trace
against the balance curve, the meter's averaging against a sinusoid's, the published readout's floor against
the HP 34401A's datasheet, the slopes' fits against scipy, and the study's trends."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal, stats

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
    fit_line,
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
    # at 5 readings/s the meter integrates 10 cycles (0.2 s): at 0.05 mm/s a reading spans 10 µm of travel and
    # follows the sinusoid, at 1 mm/s it spans one whole wavelength and averages it to zero (through a bridge,
    # whose floor at 10 cycles is far below the signal)
    fine = ac_rms(read_brushing(brush, heights, SPACING, 150e-6, 0.05e-3, 5.0, rng, bridge=True))
    whole = ac_rms(read_brushing(brush, heights, SPACING, 150e-6, 1e-3, 5.0, rng, bridge=True))
    flat = ac_rms(read_brushing(brush, 0 * heights, SPACING, 150e-6, 1e-3, 5.0, rng, bridge=True))
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
    # through a bridge, at 5 readings/s (10 cycles: no added noise), where the trends stand clear of the floor
    brushings = brush_surfaces(MODEL, PlateContact(0.5, math.radians(0.5)), 150e-6, 10e-3, 1e-3, 5.0,
                               (0.5e-3, 2e-3), (2.0, 20.0, 100.0), 2, np.random.default_rng(3), bridge=True)
    # every strip at the nominal and both other speeds at 5/s, and the first strip at 1 mm/s at each rate
    assert len(brushings) == 4 * (2 * 3 + 3)
    force = brushings[-1].force  # P100: the vertical force rides the grains about the engagement's
    assert force.min() >= 0 and force.std() > 0
    study = analyse_roughness([b.recording for b in brushings], 1e-3, 5.0, seed=3)
    assert study.surfaces == ("silicon", "P1000", "P320", "P100")
    assert study.floor == study.total_rms[0] and np.all(np.diff(study.total_rms) > 0)
    assert study.origin_fit.slope > 0 and study.published_fit.slope > 0
    assert list(study.rates) == [2.0, 5.0, 20.0, 100.0]  # the nominal rate's recordings join the curve
    # the rate curve: at 2 readings/s a reading integrates 0.2 s (10 cycles), 200 µm of travel, where 100/s
    # integrate 4 ms (0.2 cycles), 4 µm: the grains are averaged away, the finer the more (measured: 0.17 × on
    # P1000, 18 µm grains, and 0.61 × on P320, 46 µm)
    ratio = study.rms_by_rate[1:3, 0] / study.rms_by_rate[1:3, -1]
    assert ratio[0] < 0.25 and ratio[1] < 0.75 and ratio[0] < ratio[1]
    # the speed curve at 5/s: the nominal speed's column is the level itself; faster, a reading crosses more
    # grains and reads less (measured: P1000 0.45 × at 2 mm/s of its 0.5 mm/s level)
    np.testing.assert_allclose(study.speeds, [0.5e-3, 1e-3, 2e-3])
    np.testing.assert_array_equal(study.rms_by_speed[:, 1], study.total_rms)
    assert np.all(np.diff(study.rms_by_speed[1:], axis=1) < 0)
    assert study.rms_by_speed[1, -1] < 0.6 * study.rms_by_speed[1, 0]
    classified = study.classification
    assert classified.confusion_by_strip.sum() == classified.windows
    assert classified.by_strip > 0.6  # chance: 0.25
    assert classified.held_speed == 2e-3 and classified.confusion_at_held_speed.sum() > 0


def test_as_published_the_meter_on_its_100_v_range_buries_every_surface_under_its_datasheet_floor(brush):
    # 50 readings/s: the 34401A at 1 cycle on the 100 V range, 300 µV steps, 0.001 % of range + 20 µV noise
    rng = np.random.default_rng(4)
    heights = surface_profile(SURFACES["P100"], SURFACES["P100"], 40e-3, SPACING, rng)
    flat = read_brushing(brush, 0 * heights, SPACING, 150e-6, 1e-3, 50.0, rng)
    rough = read_brushing(brush, heights, SPACING, 150e-6, 1e-3, 50.0, rng)
    bridged = read_brushing(brush, heights, SPACING, 150e-6, 1e-3, 50.0, rng, bridge=True)
    datasheet = math.sqrt((1e-5 * 100.0) ** 2 + 20e-6**2 + (3e-6 * 100.0) ** 2 / 12)  # the sensor's own: < 1 µV
    steps = (flat + brush.rest) / 300e-6  # the meter's reading of the whole voltage, in its steps
    assert flat.size == 1900 and np.allclose(steps, np.round(steps), rtol=0, atol=1e-6)
    assert ac_rms(flat) == pytest.approx(datasheet, rel=3 / math.sqrt(2 * flat.size))  # 3 standard errors
    # P100's signal, plain through a bridge (its floor there: 20 µV), adds in quadrature to a 1 mV floor:
    # under its scatter
    signal = ac_rms(bridged)
    assert signal > 3 * 20e-6
    assert abs(ac_rms(rough) - ac_rms(flat)) < 3 * datasheet / math.sqrt(2 * flat.size) + datasheet * (
        math.hypot(1, signal / datasheet) - 1)


def test_the_ac_rms_takes_a_drift_out():
    # a measured trace drifts (the spin valves warm): a ramp of 2 mV over the record under 50 µV of roughness
    rng = np.random.default_rng(5)
    roughness = rng.normal(0.0, 50e-6, 4000)
    drifting = roughness + np.linspace(0.0, 2e-3, 4000)
    # scipy's linear detrend of the noise alone is the reference: the ramp leaves no trace in it
    assert ac_rms(drifting) == pytest.approx(float(np.std(signal.detrend(roughness))), rel=1e-9)
    assert ac_rms(drifting) == pytest.approx(50e-6, rel=0.05)


def test_both_slopes_and_their_intervals_equal_scipys_and_a_hand_computed_fit():
    roughness = np.array([0.0, 18.3, 46.2, 162.0]) * 1e-6
    rms = np.array([20.0, 31.0, 58.0, 150.0]) * 1e-6
    line = fit_line(roughness, rms)
    reference = stats.linregress(roughness, rms)
    t2 = stats.t.ppf(0.975, 2)  # four points, two parameters
    assert line.slope == pytest.approx(reference.slope, rel=1e-12) and line.dof == 2
    assert line.intercept == pytest.approx(reference.intercept, rel=1e-12)
    assert line.slope_interval == pytest.approx((reference.slope - t2 * reference.stderr,
                                                 reference.slope + t2 * reference.stderr), rel=1e-10)
    assert line.intercept_interval == pytest.approx((reference.intercept - t2 * reference.intercept_stderr,
                                                     reference.intercept + t2 * reference.intercept_stderr), rel=1e-10)
    # through the origin, by hand: slope Σxy/Σx², s² = RSS/(n − 1), se = s/√Σx², t with n − 1 = 2
    x, y = roughness[1:], rms[1:]
    slope = (x @ y) / (x @ x)
    se = math.sqrt(((y - slope * x) @ (y - slope * x)) / 2 / (x @ x))
    origin = fit_line(x, y, through_origin=True)
    assert origin.slope == pytest.approx(slope, rel=1e-12) and origin.intercept == 0.0 and origin.dof == 2
    assert origin.slope_interval == pytest.approx((slope - t2 * se, slope + t2 * se), rel=1e-10)
    with pytest.raises(DieError, match="expected at least 3 points"):
        fit_line(x[:2], y[:2])


def test_one_speed_and_one_strip_is_studied_and_says_it_cannot_classify():
    # what the publication recorded: each surface once, at one speed and one rate (the first strip of two)
    two = [b.recording for b in brush_surfaces(MODEL, PlateContact(0.5, math.radians(0.5)), 150e-6, 6e-3, 1e-3, 5.0,
                                               (), (), 2, np.random.default_rng(6), bridge=True)]
    study = analyse_roughness([r for r in two if r.strip == 0], 1e-3, 5.0, seed=0)
    assert list(study.speeds) == [1e-3] and list(study.rates) == [5.0] and study.published_fit is not None
    assert study.classification is None and "one strip only" in study.unclassified
    assert "one speed only" in study.unclassified
    # both strips at one speed: validated by strip, not at a held-out speed, and it says which
    classified = analyse_roughness(two, 1e-3, 5.0, seed=0).classification
    assert classified.by_strip is not None and classified.at_held_speed is None
    assert classified.missing and "one speed only" in classified.missing[0]


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


def test_the_command_reads_a_csv_at_one_speed_as_the_publication_recorded(tmp_path):
    import json

    import typer
    from typer.testing import CliRunner

    from softtip.cli.common import user_errors
    from softtip.systems.cilia.commands import roughness_cilia

    brushings = brush_surfaces(MODEL, PlateContact(0.5, math.radians(0.5)), 150e-6, 6e-3, 1e-3, 5.0, (), (), 2,
                               np.random.default_rng(8), bridge=True)
    recordings = [b.recording for b in brushings]
    # one row per reading, a recording a run of rows
    rows = ["surface,roughness_um,speed_mm_s,rate_hz,strip,volts"]
    for r in recordings:
        rows += [f"{r.surface},{r.roughness / 1e-6:.6g},{r.speed / 1e-3:g},{r.rate:g},{r.strip},{v:.15g}" for v in r.readings]
    table = tmp_path / "brushings.csv"
    table.write_text("\n".join(rows) + "\n")
    app = typer.Typer()
    app.command()(user_errors(roughness_cilia))
    ran = CliRunner().invoke(app, [str(table), "--channel", "volts", "--seed", "0", "--json"])
    assert ran.exit_code == 0, ran.output
    report = json.loads(ran.stdout)
    study = analyse_roughness(recordings, 1e-3, 5.0, seed=0)
    assert report["speed_mm_s"] == 1.0 and report["rate_hz"] == 5.0 and report["recordings"] == 8
    np.testing.assert_allclose(report["ac_rms_uV"], study.total_rms * 1e6, rtol=1e-9)
    # 1 V/m is 1 µV/µm
    assert report["slope_as_published_uV_per_um"]["slope"] == pytest.approx(study.published_fit.slope, rel=1e-9)
    # one speed: validated by strip only, and the report says why not at a held-out speed
    assert report["classification"]["accuracy_at_held_speed"] is None and report["classification"]["not_validated"]
    missing = tmp_path / "no-rate.csv"
    missing.write_text("surface,roughness_um,speed_mm_s,volts\nsilicon,0,1,0.0\n")
    refused = CliRunner().invoke(app, [str(missing), "--channel", "volts"])
    assert refused.exit_code == 2 and "no-rate.csv: no column 'rate_hz'" in refused.output
