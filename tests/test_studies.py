"""Published studies end to end on coarse meshes: the numbers come out where physics puts them."""

from __future__ import annotations

import math
import textwrap

import pytest
from scipy.optimize import brentq

from softtip.report.html import write_report
from softtip.studies.published import run_published_study


def _protocol(tmp_path, name, design, mesh, extra=""):
    path = tmp_path / f"{name}.toml"
    path.write_text(textwrap.dedent(f"""
        protocol = "{name}"
        design = "{design}"
        seed = 2
        [parameters]
        mesh_size_mm = {mesh}
    """) + textwrap.dedent(extra))
    return path


@pytest.fixture(scope="module")
def hysteresis_study(tmp_path_factory):
    path = _protocol(tmp_path_factory.mktemp("hysteresis"), "hysteresis", "cylindrical-D", 2.5, "trials = 2\n")
    return run_published_study("hysteresis", protocol_path=path)


@pytest.mark.slow
def test_hysteresis_study_reproduces_its_calibration_cycle(hysteresis_study, tmp_path):
    results, figures, notes, _ = hysteresis_study
    per_speed = results["per_speed"]
    # a calibration check, not a prediction: the material was set from this 7.3 % cycle at 0.25 mm/s;
    # here it is measured on noisy trials with the S1 formula
    assert per_speed["0.25"]["hysteresis_percent_mean"] == pytest.approx(7.3, abs=0.6)
    # the magnets sit beside the chip's axis, where their Bz is negative; pressing brings them closer
    assert per_speed["0.25"]["sensitivity_mT_per_N"][2] < 0
    report = write_report(tmp_path / "h.html", "hysteresis", [{"heading": "r", "results": results,
                                                               "figures": figures, "notes": notes}])
    text = report.read_text()
    assert "<table>" in text and "data:image/png;base64," in text


def _linear_material_hysteresis(weight: float, tau: float, depth: float, speed: float, rest: float) -> float:
    """S1 hysteresis (%) of a push to ``depth`` at ``speed``, a ``rest`` and a release at ``speed``, for a
    linear material (F_e = k d) relaxing as G(t) = 1 - w + w exp(-t / tau) and a sensor linear in depth,
    from the closed-form QLV force: loading, F / (k v) = (1 - w) t + w tau (1 - e^(-t/tau)); after the
    peak at T = depth / speed, s into the release, F / (k v) = (1 - w)(T - s)
    + w tau ((1 - e^(-T/tau)) e^(-(rest + s)/tau) - (1 - e^(-s/tau))). The depths where the two branches
    cross the mid force differ by the hysteresis."""
    ramp = depth / speed
    relaxing = tau * (1 - math.exp(-ramp / tau))
    peak = (1 - weight) * ramp + weight * relaxing

    def loading(t):
        return (1 - weight) * t + weight * tau * (1 - math.exp(-t / tau)) - peak / 2

    def unloading(s):
        return ((1 - weight) * (ramp - s) + weight * (relaxing * math.exp(-(rest + s) / tau)
                                                       - tau * (1 - math.exp(-s / tau))) - peak / 2)

    return abs(brentq(loading, 0, ramp) - (ramp - brentq(unloading, 0, ramp))) / ramp * 100


@pytest.mark.slow
def test_hysteresis_at_the_other_speeds_follows_the_closed_form_qlv_response(hysteresis_study):
    per_speed = hysteresis_study[0]["per_speed"]
    # The material relaxes with one time constant, the calibration cycle's time to its peak (3 mm at
    # 0.25 mm/s: 12 s), and its weight is set for 7.3 % on that cycle (1 s rest). The closed form for a
    # linear material, set the same way, predicts how the loop narrows at 0.5 and 1 mm/s: a faster cycle
    # gives the material less time to relax. The fingertip's stiffening with depth moves the mid-force
    # crossing, so the ratios agree to 10 % (measured: 1.5 % and 6 %); a time constant half or twice as
    # long would miss by 13-39 %.
    def closed_form(weight, speed):
        return _linear_material_hysteresis(weight, 12.0, 3.0, speed, 1.0)

    weight = brentq(lambda w: closed_form(w, 0.25) - 7.3, 1e-6, 0.99)
    calibrated = per_speed["0.25"]["hysteresis_percent_mean"]
    for speed in (0.5, 1.0):
        measured = per_speed[f"{speed:g}"]["hysteresis_percent_mean"] / calibrated
        assert measured == pytest.approx(closed_form(weight, speed) / 7.3, rel=0.1), speed
    assert per_speed["1"]["hysteresis_percent_mean"] < per_speed["0.5"]["hysteresis_percent_mean"] < calibrated


@pytest.mark.slow
def test_contact_states_are_told_apart_by_the_two_fingers(tmp_path):
    path = _protocol(tmp_path, "contact-states", "rectangular", 3.0, """
        phi_deg = [20.0]
        psi_deg = [10.0]
        untrained_phi_deg = [25.0]
        untrained_psi_deg = [12.0]
        approach_inclines_deg = [45.0]
        positions_mm = [[0.0, 0.0], [5.0, 5.0]]
    """)
    results, _, _, _ = run_published_study("contact-states", protocol_path=path)
    trained = results["trained"]["mean_probability_of_true_class"]
    # Point A and Point B load the two fingers in mirror image: a classifier cannot confuse them
    assert trained["point-a"] > 0.8 and trained["point-b"] > 0.8
    assert results["trained"]["accuracy"] > 0.7
