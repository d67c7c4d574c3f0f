"""Published studies end to end on coarse meshes: the numbers come out where physics puts them."""

from __future__ import annotations

import math
import re

import pytest
from scipy.optimize import brentq

from softtip.studies.reproduce import reproduce_study


@pytest.fixture(scope="module")
def hysteresis_study(coarse_protocol):
    path = coarse_protocol("hysteresis", "cylindrical-D", 2.5, "trials = 2\n")
    return reproduce_study("hysteresis", protocol_path=path)


@pytest.mark.slow
def test_hysteresis_study_reproduces_its_calibration_cycle(hysteresis_study, tmp_path):
    per_speed = hysteresis_study.outcome.results["per_speed"]
    # a calibration check, not a prediction: the material was set from this 7.3 % cycle at 0.25 mm/s;
    # here it is measured on noisy trials with the S1 formula
    assert per_speed["0.25"]["hysteresis_percent_mean"] == pytest.approx(7.3, abs=0.6)
    # the magnets sit beside the chip's axis, where their Bz is negative; pressing brings them closer
    assert per_speed["0.25"]["sensitivity_mT_per_N"][2] < 0
    # the published figure it was set from sits beside it, judged as fitted, not as a prediction
    [comparison] = hysteresis_study.comparisons()
    assert comparison["published"] == "7.3" and comparison["verdict"] == "fitted"
    assert comparison["difference"] == pytest.approx(per_speed["0.25"]["hysteresis_percent_mean"] - 7.3, abs=1e-6)


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
    per_speed = hysteresis_study.outcome.results["per_speed"]
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
def test_contact_states_are_told_apart_by_the_two_fingers(coarse_protocol):
    path = coarse_protocol("contact-states", "rectangular", 3.0, fewer=True)
    results = reproduce_study("contact-states", protocol_path=path).outcome.results
    trained = results["trained"]["mean_probability_of_true_class"]
    # Point A and Point B load the two fingers in mirror image: a classifier cannot confuse them
    assert trained["point-a"] > 0.8 and trained["point-b"] > 0.8
    assert results["trained"]["accuracy"] > 0.7


@pytest.mark.slow
def test_each_untrained_contact_angle_is_explained_by_its_own_confusion(coarse_protocol):
    path = coarse_protocol("contact-states", "rectangular", 3.0, """
        phi_deg = [20.0]
        psi_deg = [10.0]
        untrained_phi_deg = [15.0, 35.0]
        untrained_psi_deg = [12.0]
        approach_inclines_deg = [45.0]
        positions_mm = [[0.0, 0.0], [5.0, 5.0]]
    """)
    outcome = reproduce_study("contact-states", protocol_path=path).outcome
    pooled = outcome.results["untrained-angles"]
    names = {"Point A": "point-a", "Point B": "point-b", "Edge": "edge"}
    counts = {}  # state -> [(right, samples) of each angle whose note names it]
    for angle in (15, 35):
        note = outcome.tables[0].notes.get(f"untrained φ {angle}°")
        if note is None:  # every cell of the row within the published tolerance
            continue
        assert f"(over the untrained-angles samples at φ {angle}°)" in note
        for name, right, samples in re.findall(r"(Point A|Point B|Edge): (\d+) of (\d+) of its samples", note):
            counts.setdefault(names[name], []).append((int(right), int(samples)))
    assert counts, "no untrained angle has a figure outside its tolerance: nothing to check"
    for state, per_angle in counts.items():
        k = pooled["labels"].index(state)
        row = pooled["confusion"][k]
        # each angle has samples of every state: one angle's count is below the pooled one ...
        assert all(samples < sum(row) for _, samples in per_angle), state
        if len(per_angle) == 2:  # ... and the two angles' counts are the pooled ones
            assert [sum(column) for column in zip(*per_angle)] == [row[k], sum(row)], state
