"""Published studies end to end on coarse meshes: the numbers come out where physics puts them."""

from __future__ import annotations

import math
import re

import pytest
from scipy.optimize import brentq

from softtip.studies.reproduce import reproduce_study


@pytest.fixture(scope="module")
def hysteresis_study(coarse_protocol):
    path = coarse_protocol("hysteresis", "rectangular", 3.0, "trials = 2\n")
    return reproduce_study("hysteresis", protocol_path=path)


@pytest.mark.slow
def test_hysteresis_study_compares_the_thesis_cycle_as_a_prediction(hysteresis_study, tmp_path):
    results = hysteresis_study.outcome.results
    per_speed, causes = results["per_speed"], results["causes"]
    # the material is set on the fit's own cycle (0.25 mm/s, 1 s rest): the noise-free cycle gives the 7.3 % back
    assert causes["the fit's cycle (0.25 mm/s, 1 s rest)"]["hysteresis (%)"] == pytest.approx(7.3, abs=1e-6)
    # the thesis's cycle (1 mm/s, 3 s rest) is judged as a prediction against the published figure, not as fitted
    [comparison] = hysteresis_study.comparisons()
    assert comparison["column"] == "1 mm/s, 3 s rest" and comparison["published"] == "7.3"
    assert comparison["verdict"] == "outside" and comparison["softtip"] == pytest.approx(
        per_speed["1"]["hysteresis_percent_mean"], abs=1e-6)
    # the noisy trials (two, on a coarse mesh, off-centre by the contact's scatter) sit near the noise-free
    # centred cycle (measured: 5.25 against 5.51 %)
    assert per_speed["1"]["hysteresis_percent_mean"] == pytest.approx(
        causes["the thesis's cycle (1 mm/s, 3 s rest)"]["hysteresis (%)"], abs=0.4)
    # the magnets sit beside the chip's axis, where their Bz is negative; pressing brings them closer
    assert per_speed["1"]["sensitivity_mT_per_N"][2] < 0
    # the one published setting the protocol does not follow is marked: softtip adds two slower speeds
    assert [d.setting for d in hysteresis_study.procedure_differences] == ["parameters.speeds_mm_s"]
    assert hysteresis_study.protocol_table.cells[("parameters.rest_s", "published procedure")] == "same"
    assert hysteresis_study.protocol_table.cells[("parameters.speeds_mm_s", "published procedure")] == (
        "differs: published [1.0]")


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
def test_the_table_of_causes_follows_the_closed_form_qlv_response(hysteresis_study):
    causes = hysteresis_study.outcome.results["causes"]
    # The material relaxes with one time constant, the fit's cycle's time to its peak (3 mm at 0.25 mm/s:
    # 12 s), and its weight is set for 7.3 % on that cycle (1 s rest). The closed form for a linear material,
    # set the same way, predicts every other cycle of the table of causes: speed, rest, a time constant or
    # weight scaled. The fingertip's stiffening with depth moves the mid-force crossing (measured: within
    # 3.5 %); the gap between the closed form's cycles is far larger (3.1 to 8.6 %).
    weight = brentq(lambda w: _linear_material_hysteresis(w, 12.0, 3.0, 0.25, 1.0) - 7.3, 1e-6, 0.99)
    thesis = "the thesis's cycle (1 mm/s, 3 s rest)"
    expected = {"the thesis's speed, the fit's rest (1 mm/s, 1 s)": (weight, 12.0, 1.0, 1.0),
                "the fit's speed, the thesis's rest (0.25 mm/s, 3 s)": (weight, 12.0, 0.25, 3.0),
                thesis: (weight, 12.0, 1.0, 3.0),
                f"{thesis}, time constant x0.5 (6.02 s)": (weight, 6.0, 1.0, 3.0),
                f"{thesis}, time constant x2 (24.1 s)": (weight, 24.0, 1.0, 3.0),
                f"{thesis}, relaxing weight x0.5 ({0.5 * causes[thesis]['relaxing weight']:.3g})":
                    (weight / 2, 12.0, 1.0, 3.0)}
    for row, (w, tau, speed, rest) in expected.items():
        assert causes[row]["hysteresis (%)"] == pytest.approx(
            _linear_material_hysteresis(w, tau, 3.0, speed, rest), rel=0.05), row
    # the gap's cause: at the thesis's speed the material has less time to relax than on the fit's cycle
    assert causes[thesis]["hysteresis (%)"] < 7.3 - 0.6


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
