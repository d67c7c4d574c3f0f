"""Fitting moment and diameter to force–voltage curves of known truth; uncertainties, identifiability,
the resolution figures and bad curves."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from softtip.systems.cilia.fit import (
    CHI2_95,
    CurveError,
    CurveModel,
    MeasuredCurve,
    fit_curve,
    identifiability,
    profiles,
)
from softtip.systems.cilia.layout import DieError, read_die
from softtip.systems.cilia.model import CiliaModel
from softtip.systems.cilia.resolution import balance_force_budget, resolution

DIE = read_die()
TRUTH_MOMENT, TRUTH_DIAMETER = 2.5e-6, 215e-6
TRUE_DIE = DIE.with_pillars(replace(DIE.pillars.with_diameter(TRUTH_DIAMETER), moment=TRUTH_MOMENT))
MODEL = CiliaModel(DIE)
FORCE = np.linspace(1e-3, 26e-3, 26)
TRUTH = CiliaModel(TRUE_DIE).curve(FORCE, "X")


@pytest.fixture(scope="module")
def predictor() -> CurveModel:
    return CurveModel(MODEL, FORCE, "X")


def test_a_noise_free_curve_gives_back_its_truth(predictor):
    fit = fit_curve(MODEL, MeasuredCurve(FORCE, TRUTH.change), cache=predictor)
    # the model is the twin's own: only the solver's tolerance is left (measured 2e-13 for both)
    assert fit.moment == pytest.approx(TRUTH_MOMENT, rel=1e-9)
    assert fit.diameter == pytest.approx(TRUTH_DIAMETER, rel=1e-9)
    assert not fit.at_bound


@pytest.mark.slow
def test_noisy_curves_recover_the_truth_within_their_intervals(predictor):
    """1 % of full scale rms noise (the bench's repeatability): 6 curves."""
    rng = np.random.default_rng(11)
    scale = 0.01 * np.abs(TRUTH.change).max()
    inside, errors = 0, []
    for _ in range(6):
        curve = MeasuredCurve(FORCE, TRUTH.change + rng.normal(0, scale, FORCE.size))
        fit = fit_curve(MODEL, curve, cache=predictor)
        errors.append((fit.moment / TRUTH_MOMENT - 1, fit.diameter / TRUTH_DIAMETER - 1))
        inside += (fit.interval_moment[0] <= TRUTH_MOMENT <= fit.interval_moment[1]
                   and fit.interval_diameter[0] <= TRUTH_DIAMETER <= fit.interval_diameter[1])
        assert fit.noise == pytest.approx(scale, rel=0.5)
    errors = np.abs(np.array(errors))
    # measured: moment within 2.0 %, diameter within 1.2 %; the truth inside all 6 95 % intervals (5.7 expected)
    assert errors[:, 0].max() < 0.04 and errors[:, 1].max() < 0.02
    assert inside >= 4


def test_profile_likelihood_agrees_with_the_covariance(predictor):
    rng = np.random.default_rng(5)
    curve = MeasuredCurve(FORCE, TRUTH.change + rng.normal(0, 0.01 * np.abs(TRUTH.change).max(), FORCE.size))
    fit = fit_curve(MODEL, curve, cache=predictor)
    diameter, moment = profiles(fit, predictor, curve)
    for profile, wald, best in ((diameter, fit.interval_diameter, fit.diameter), (moment, fit.interval_moment, fit.moment)):
        low, high = profile.interval
        assert low is not None and high is not None and low < best < high
        # nearly quadratic here: the likelihood-ratio interval is 6 % narrower than Wald's (measured, in log)
        assert math.log(high / low) == pytest.approx(math.log(wald[1] / wald[0]), rel=0.1)
        deviance = fit.points * np.log(profile.rss / profile.rss.min())
        assert deviance.min() == pytest.approx(0.0, abs=0.05) and deviance.max() > CHI2_95


def test_the_linear_part_identifies_only_the_ratio():
    rng = np.random.default_rng(2)
    force = np.concatenate([np.linspace(0.2e-3, 3e-3, 15), np.linspace(4e-3, 26e-3, 12)])
    truth = CiliaModel(TRUE_DIE).curve(force, "X")
    curve = MeasuredCurve(force, truth.change + rng.normal(0, 0.01 * np.abs(truth.change).max(), force.size))
    found = identifiability(MODEL, curve, linear_fraction=0.12)
    linear, whole = found.linear, found.whole

    def width(interval):
        return math.log(interval[1] / interval[0])

    # measured: on the linear part (15 points up to 3 mN) the log parameters correlate at 0.998 and the
    # moment's interval spans a factor 3.0, 4.2 times wider in log than that of moment / diameter⁴ (which
    # lands 2 % from the truth); the whole curve pins the moment to ± 2.1 %
    assert linear.correlation > 0.99
    assert width(linear.interval_moment) > 3 * width(linear.interval_ratio)
    assert width(linear.interval_moment) > 10 * width(whole.interval_moment)
    assert linear.ratio == pytest.approx(TRUTH_MOMENT / TRUTH_DIAMETER**4, rel=0.15)


def test_minimum_force_is_three_sigma_over_the_slope():
    found = resolution(MODEL, "X", 26e-3, points=53)
    sigma = found.noise.total
    # the slope at rest by a small central difference of the model itself
    step = 1e-5
    around = MODEL.curve(np.array([step, 2 * step]), "X")
    slope = (4 * around.change[0] - around.change[1]) / (2 * step)  # one-sided, second order, through zero
    assert found.sensitivity == pytest.approx(slope, rel=0.01)
    assert found.minimum_force_at_rest == pytest.approx(3 * sigma / abs(slope), rel=0.01)
    assert found.smallest_step_at_rest == pytest.approx(max(found.noise.resolution, 3 * math.sqrt(2) * sigma) / abs(slope),
                                                         rel=0.01)
    assert 0 < found.range[1] <= 26e-3
    at_end = np.searchsorted(found.force, found.range[1])
    assert abs(found.slope[at_end]) < 0.1 * abs(found.slope[0]) <= abs(found.slope[at_end - 1])


def test_bad_curves_are_refused_in_one_line():
    with pytest.raises(CurveError, match="curve: expected finite forces and voltages"):
        MeasuredCurve(np.array([1e-3, 2e-3, 3e-3]), np.array([0.0, np.nan, 1.0]))
    with pytest.raises(CurveError, match="expected at least 3 points for 2 parameters, got 2"):
        MeasuredCurve(np.array([1e-3, 2e-3]), np.array([0.0, 1.0]))
    with pytest.raises(CurveError, match="expected forces >= 0 N"):
        MeasuredCurve(np.array([-1e-3, 2e-3, 3e-3]), np.zeros(3))
    with pytest.raises(CurveError, match="of one 1-D shape"):
        MeasuredCurve(np.zeros(3), np.zeros(4))
    with pytest.raises(CurveError, match=r"start = \(-1.0, 0.0002\)"):
        fit_curve(MODEL, MeasuredCurve(FORCE, TRUTH.change), start=(-1.0, 2e-4))
    with pytest.raises(CurveError, match="linear_fraction = 1.5"):
        identifiability(MODEL, MeasuredCurve(FORCE, TRUTH.change), linear_fraction=1.5)


def test_wald_intervals_use_students_t_with_n_minus_2_degrees_of_freedom():
    """Five points, two parameters: three degrees of freedom, where t(0.975) is 3.18 (the normal 1.96,
    t with 2 or 4 degrees of freedom 4.30 and 2.78). The intervals are computed again by hand: the
    Jacobian of the log parameters by central differences of the model, s² = RSS/(n − 2), s²(JᵀJ)⁻¹."""
    force = np.array([2e-3, 6e-3, 12e-3, 19e-3, 26e-3])
    truth = CiliaModel(TRUE_DIE).curve(force, "X")
    rng = np.random.default_rng(3)
    curve = MeasuredCurve(force, truth.change + rng.normal(0, 0.01 * np.abs(truth.change).max(), force.size))
    predictor = CurveModel(MODEL, force, "X")
    fit = fit_curve(MODEL, curve, cache=predictor)
    best = np.log([fit.moment, fit.diameter])

    def predict(log_parameters):
        return predictor.predict(*np.exp(log_parameters))

    step = 1e-4
    jacobian = np.column_stack([(predict(best + step * unit) - predict(best - step * unit)) / (2 * step)
                                for unit in np.eye(2)])
    residual = predict(best) - curve.change
    variance = residual @ residual / (force.size - 2)
    covariance = variance * np.linalg.inv(jacobian.T @ jacobian)
    quantile = 3.182446305284263  # Student's t, 97.5 %, 3 degrees of freedom (statistical tables)
    assert quantile == pytest.approx(stats.t.ppf(0.975, 3), rel=1e-12)
    gradient_ratio = np.array([1.0, -4.0])  # log(moment / diameter⁴)
    for interval, centre, spread in (
            (fit.interval_moment, best[0], math.sqrt(covariance[0, 0])),
            (fit.interval_diameter, best[1], math.sqrt(covariance[1, 1])),
            (fit.interval_ratio, best @ gradient_ratio, math.sqrt(gradient_ratio @ covariance @ gradient_ratio))):
        low, high = np.log(interval)
        # the half-widths agree to 0.4 % (the fit's forward differences against these central ones); a wrong
        # quantile is off by 14 % (t with 4 dof) or more
        assert (high - low) / 2 == pytest.approx(quantile * spread, rel=5e-3)
        assert (high + low) / 2 == pytest.approx(centre, abs=1e-9)
    assert fit.correlation == pytest.approx(covariance[0, 1] / math.sqrt(covariance[0, 0] * covariance[1, 1]), rel=1e-3)


def test_the_balance_tests_force_budget_adds_its_causes_as_computed_by_hand():
    """A straight 2 mV/mN curve whose plate seated δ askew shifts it by 0.1 mV per mrad: every cause's σ by hand."""
    force = np.linspace(0.0, 20e-3, 11)
    slope, per_mrad, delta = 2.0, 0.1e-3 / 1e-3, 1e-3
    change = slope * force
    readout = DIE.meander("X").readout
    rest = 18.7
    found = balance_force_budget(force, change, rest, readout, (change - per_mrad * delta, change + per_mrad * delta, delta),
                                 readability=1e-6, seating=2e-3, warm_up=5.0, dwell=2.0, die_area=9e-6)
    tau = readout.thermal_resistance * 2329.0 * 700.0 * 9e-6 * 0.5e-3  # R_th × ρ c × the die's volume
    warming = readout.current * rest * readout.thermal_resistance  # I² R R_th with R = V / I
    drift = rest * readout.sensor.temperature_coefficient * warming * math.exp(-5.0 / tau) * (1 - math.exp(-2.0 / tau))
    assert np.allclose(found.balance, 1e-6 / math.sqrt(12))
    assert np.allclose(found.plate, per_mrad * 2e-3 / slope, rtol=1e-12)
    assert np.allclose(found.meter, readout.noise(rest).total / slope, rtol=1e-12)
    assert np.allclose(found.drift, drift / slope, rtol=1e-12)
    assert found.time_constant == pytest.approx(tau) and found.warming == pytest.approx(warming)
    total = 3 * np.sqrt(found.balance**2 + found.plate**2 + found.meter**2 + found.drift**2)
    assert np.allclose(found.minimum_force, total, rtol=1e-12)
    assert sum(found.shares(4).values()) == pytest.approx(1.0)
    alone = balance_force_budget(force, change, rest, readout, (change, change, delta), 1e-6, 2e-3, 5.0, 2.0, 9e-6,
                                 parts=("meter",))
    assert np.allclose(alone.minimum_force, 3 * readout.noise(rest).total / slope, rtol=1e-12)
    with pytest.raises(DieError, match=r"parts: expected some of balance, plate, meter, drift, got \['heat'\]"):
        balance_force_budget(force, change, rest, readout, (change, change, delta), 1e-6, 2e-3, 5.0, 2.0, 9e-6,
                             parts=("heat",))
