"""The Hall fingertip's tolerance sensitivity: one error's effect against a hand-derivable case, the
interval and ranking arithmetic by hand, the stiffness tolerance from Gent's relation, and the ranking
reproducible from its seeds."""

from __future__ import annotations

from dataclasses import replace

import magpylib
import numpy as np
import pytest

from softtip.design.model import load_design
from softtip.lab import run_protocol
from softtip.mechanics.poses import MagnetPoses
from softtip.systems.hall_fingertip.realism import FabricatedUnit, Realism
from softtip.systems.hall_fingertip.studies import HALF_BOARD_MM, METHODS
from softtip.systems.hall_fingertip.tolerance import (ERRORS, FORCE, FORCES, JOINT, ORIENTATION, QUICK, Effect,
                                                      ToleranceStudy, error_named, gent_modulus_MPa, interval,
                                                      nominal_protocol, perturbations, plot_tolerance,
                                                      STIFFNESS_TOLERANCE, tolerance_report, tolerance_study)


@pytest.fixture(scope="module")
def design():
    return load_design("cylindrical-D")


def test_a_magnetisation_spread_scales_each_magnets_field_as_magpylib_does(design):
    """The magnetisation error alone: magnet i's polarisation J_i (1 + s z_i), z_i the unit's draw (the
    stream's second normal draw, after the magnets' placement), so the field at the chips is magpylib's
    with those polarisations, and its change from nominal is linear in s."""
    error = error_named("magnetisation")
    magnets = len(design.magnets)

    def unit(spread: float) -> FabricatedUnit:
        realism = replace(Realism.off(), **{error.setting: spread})
        return FabricatedUnit(design, realism, np.random.default_rng(7))

    stream = np.random.default_rng(7)
    stream.normal(size=(magnets, 3))
    z = stream.normal(size=magnets)
    rest = MagnetPoses(np.zeros((1, magnets, 3)), np.zeros((1, magnets, 3)))
    spread = error.tolerance
    expected = magpylib.getB([magpylib.magnet.Cylinder(polarization=(0, 0, m.polarization * (1 + spread * zi)),
                                                       dimension=(m.diameter, m.height), position=m.center)
                              for m, zi in zip(design.magnets, z, strict=True)], design.sensor_positions, sumup=True)
    np.testing.assert_allclose(unit(spread).field(rest)[0], np.reshape(expected, (-1, 3)), rtol=1e-6, atol=1e-12)
    nominal = unit(0.0).field(rest)
    np.testing.assert_allclose(unit(2 * spread).field(rest) - nominal, 2 * (unit(spread).field(rest) - nominal),
                               rtol=1e-9, atol=1e-15)


@pytest.mark.slow
def test_a_magnetisation_spread_changes_the_readings_in_proportion(design):
    """The field is linear in each magnet's polarisation: with the unit's draw z, a spread s gives
    readings X0 + s * sum_i z_i X_i, so the change at 2 s is twice the change at s, sample by sample.
    Noise and the temperature walk are off so that nothing else differs between the runs."""
    error = error_named("magnetisation")
    # a coarse mesh: linearity in the polarisation holds on any mesh, and the test's cache starts empty
    protocol = nominal_protocol(FORCE, design, 3, True, ERRORS).changed(calibration_trials=1, validation_trials=1,
                                                                        mesh_size_mm=3.0)
    quiet = replace(protocol, realism=replace(protocol.realism, noise=False, drift_K_per_sqrt_s=0.0))

    def readings(spread: float) -> np.ndarray:
        return run_protocol(replace(quiet, realism=replace(quiet.realism, **{error.setting: spread})))[0].X()

    nominal, once, twice = readings(0.0), readings(error.tolerance), readings(2 * error.tolerance)
    change = once - nominal
    assert np.sqrt(np.mean(change**2)) > 1e-3 * np.sqrt(np.mean(nominal**2))  # the spread does act
    np.testing.assert_allclose(twice - nominal, 2 * change, rtol=1e-6, atol=1e-9 * np.abs(nominal).max())


def test_the_tables_name_what_the_pushing_study_does():
    assert ORIENTATION == tuple(f"orientation · {method}" for method in METHODS)
    assert error_named("board-edge").tolerance == HALF_BOARD_MM
    assert all(error.source() for error in ERRORS)


def test_offsets_run_either_side_of_nominal_and_spreads_at_their_tolerance():
    assert perturbations(error_named("stage-axis"), 1.0, 1.0) == {"-1 mm": 0.0, "+1 mm": 2.0}
    assert perturbations(error_named("magnet-position"), 0.1, 0.0) == {"sd 0.1 mm": 0.1}


def test_the_stiffness_tolerance_is_three_shore_a_points_by_gents_relation():
    # Gent's relation by hand: E(27) = 0.0981 * 261.83 / (0.137505 * 185.42) = 1.0075 MPa;
    # E(30) = 27.931 / 24.449 = 1.1424 MPa, E(24) = 23.440 / 26.544 = 0.8831 MPa
    assert gent_modulus_MPa(27) == pytest.approx(1.0075, abs=2e-4)
    assert gent_modulus_MPa(30) == pytest.approx(1.1424, abs=2e-4)
    assert gent_modulus_MPa(24) == pytest.approx(0.8831, abs=2e-4)
    assert STIFFNESS_TOLERANCE == pytest.approx((1.1424 - 0.8831) / (2 * 1.0075), abs=3e-4)


def test_interval_ranking_and_scatter_by_hand():
    # values 1, 2, 3: mean 2, sd 1, t(0.975, 2) = 4.3027, half-width 4.3027 / sqrt(3) = 2.4842
    mean, low, high = interval(np.array([1.0, 2.0, 3.0]))
    assert (mean, low, high) == pytest.approx((2.0, 2.0 - 2.4842, 2.0 + 2.4842), abs=1e-4)
    estimate = FORCES[2]
    effects = (Effect("small", 0.1, {"sd 0.1": {estimate: np.array([0.01, -0.01, 0.02])}}),
               Effect("large", 1.0, {"-1": {estimate: np.array([0.1, 0.1, 0.12])},
                                     "+1": {estimate: np.array([0.5, 0.52, 0.51])}}),
               Effect(JOINT, None, {JOINT: {estimate: np.array([0.6, 0.5, 0.55])}}))
    study = ToleranceStudy("x", (1, 2, 3), True, (estimate,), {estimate: np.array([0.2, 0.21, 0.19])}, effects)
    ranked = study.ranking(estimate)
    assert [(r.name, r.run) for r in ranked] == [("large", "+1"), ("small", "sd 0.1")]
    assert not ranked[0].inside_scatter and ranked[1].inside_scatter
    report = study.to_dict()["estimates"][estimate]
    assert report["ranking"][0]["apart_from_next"] and not report["ranking"][1]["apart_from_next"]
    assert report["joint"]["degradation_mean"] == pytest.approx(0.55)
    page = tolerance_report(study, plot_tolerance(study)).html()
    assert page.index("1. large") < page.index("2. small") and page.count("data:image/png") == 1


@pytest.mark.slow
def test_the_ranking_is_reproducible_from_the_seeds(design, monkeypatch):
    # the quick protocol on the coarse mesh the test above builds: whether a ranking comes back from its
    # seeds does not depend on the mesh, and ten runs of the force protocol on the 1.5 mm one cost minutes
    monkeypatch.setitem(QUICK, FORCE, {**QUICK[FORCE], "mesh_size_mm": 3.0})

    def study():
        return tolerance_study(design, (1, 2), ("magnetisation", "stiffness"), estimates=(FORCES[2],),
                               quick=True).to_dict()

    first, second = study(), study()
    assert first == second  # every run's validation error, hence the ranking and its intervals
    assert sorted(r["error"] for r in first["estimates"][FORCES[2]]["ranking"]) == ["magnetisation", "stiffness"]
    runs = first["estimates"][FORCES[2]]["runs"]["stiffness"]
    assert set(runs) == {"-0.129", "+0.129"} and all(len(values) == 2 for values in runs.values())
