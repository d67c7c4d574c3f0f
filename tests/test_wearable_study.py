"""The S2 study on the wearable twin: per-participant models beside the published ranges, the real-time
path as accurate as the offline model, every split and extension reported."""

from __future__ import annotations

import numpy as np
import pytest

from softtip.studies.reproduce import reproduce_study
from softtip.systems.wearable.study import SPLITS, SS, TF


@pytest.fixture(scope="module")
def study(coarse_protocol):
    return reproduce_study("wearable", protocol_path=coarse_protocol("wearable", "", fewer=True))


@pytest.mark.slow
def test_the_model_run_frame_by_frame_scores_as_the_offline_model(study):
    for entry in study.outcome.results["participants"].values():
        offline = entry["splits"][SPLITS[1]][TF]["outputs"]
        mean_r2 = np.mean([offline[axis]["r2"] for axis in ("fx_N", "fy_N", "fz_N")])
        # the published real-time model lost 10-20 points of R²; the realised transfer function loses none
        assert entry["streaming_r2"] == pytest.approx(mean_r2, abs=1e-9)


@pytest.mark.slow
def test_every_axis_faces_the_published_range_and_every_split_is_scored(study):
    comparisons = study.comparisons()
    rows = {c["row"] for c in comparisons}
    assert {f"{model} · {axis}" for model in (TF, SS) for axis in ("Fx", "Fy", "Fz", "mean")} == rows
    assert {c["published"] for c in comparisons if c["column"] == "R²"} == {"0.8–0.92", "0.6–0.82"}
    for entry in study.outcome.results["participants"].values():
        assert set(entry["splits"]) == set(SPLITS)
        assert set(entry["contacts"]) == {"curved", "edge", "point"}  # the study's extension contacts
        scores = entry["splits"][SPLITS[1]][SS]
        assert scores["full_scale"]["definition"] == "measured"
        assert set(entry["orders"]) == {"tf4", "tf5", "tf6", "ss7", "ss8", "ss9", "ss10"}
    protocol = study.protocol_table
    assert protocol.cells[("parameters.contacts", "where from")].startswith("set by the study")
