"""The S2 study on the wearable twin: per-participant models beside the published ranges, the real-time
path as accurate as the offline model, every split and extension reported."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from nfoursid.nfoursid import NFourSID
from scipy import signal

from softtip.lab import load_protocol, run_protocol
from softtip.metrics import r2
from softtip.studies.reproduce import reproduce_study
from softtip.sysid import StateSpaceModel, TransferFunctionModel
from softtip.sysid.recording import Trial
from softtip.sysid.splits import split_by_trial
from softtip.systems.wearable.study import SPLITS, SS, TF, _recording


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
    assert {c["published"] for c in comparisons if c["column"] == "R²"} == {"0.8–0.92", "0.58–0.79"}
    assert {c["published"] for c in comparisons if c["column"] == "|r|"} == {"0.90", "0.77–0.89"}
    for entry in study.outcome.results["participants"].values():
        assert set(entry["splits"]) == set(SPLITS)
        assert set(entry["contacts"]) == {"curved", "edge", "point"}  # the study's extension contacts
        scores = entry["splits"][SPLITS[1]][SS]
        assert scores["full_scale"]["definition"] == "measured"
        assert set(entry["orders"]) == {"tf4", "tf5", "tf6", "ss7", "ss8", "ss9", "ss10"}
    protocol = study.protocol_table
    assert protocol.cells[("parameters.contacts", "where from")].startswith("set by the study")


def _filtered(system, u):
    """``u`` through the discrete (numerator, denominator) ``system``."""
    return signal.lfilter(np.ravel(system[0]), system[1], u)


@pytest.mark.parametrize("model", [StateSpaceModel(8, estimate_covariance=False),
                                   TransferFunctionModel(6, estimate_covariance=False)], ids=["ss8", "tf6"])
def test_known_radial_dynamics_behind_the_chip_readings_are_identified_as_by_nfoursid(model):
    # the twin's own chip readings as inputs, table forces replaced by a known system (scipy.signal): Fx a
    # resonant second order (0.8 Hz, damping 0.5) of the chip's dorsal shear and pressure, Fy and Fz first
    # orders. An x R² below zero on the twin is then the data's, not the estimator's or the axes' bookkeeping.
    protocol = load_protocol("wearable").changed(participants=1, runs=1)
    dataset = run_protocol(protocol)[0]
    recording = _recording(dataset, dataset.column("participant") == 0)
    ts, wn = recording.ts, 2 * np.pi * 0.8
    discrete = [signal.cont2discrete(system, ts, method="zoh")[:2] for system in
                (([wn ** 2], [1, wn, wn ** 2]), ([1.0], [0.3, 1.0]), ([1.0], [0.1, 1.0]))]
    rng = np.random.default_rng(0)

    def truth(u):
        y = np.column_stack([_filtered(discrete[0], 4 * u[:, 2] - 6 * u[:, 1]), _filtered(discrete[1], -10 * u[:, 0]),
                             _filtered(discrete[2], 2 * u[:, 2])])
        return y + 0.01 * rng.normal(size=y.shape)

    known = recording.with_trials([Trial(t.u, truth(t.u), t.id, t.start) for t in recording.trials])
    estimation, validation = split_by_trial(known, 5)
    ours = model.fit(estimation).evaluate(validation).values["r2"]
    u, y = np.vstack([t.u for t in estimation.trials]), np.vstack([t.y for t in estimation.trials])
    frame = pd.DataFrame(np.hstack([u, y]), columns=["u0", "u1", "u2", "y0", "y1", "y2"])
    found = NFourSID(frame, output_columns=["y0", "y1", "y2"], input_columns=["u0", "u1", "u2"], num_block_rows=10)
    found.subspace_identification()
    reference, _ = found.system_identification(rank=4)  # the true order: 2 + 1 + 1
    theirs = r2(np.vstack([t.y for t in validation.trials]),
                np.vstack([signal.dlsim((reference.a, reference.b, reference.c, reference.d, ts), t.u)[1]
                           for t in validation.trials]))
    # measured: state space 0.9999, 0.9975, 0.9999, transfer function the same to 0.0002; nfoursid 0.993, 0.997,
    # 0.998 (Fy: 0.01 N noise on a 0.2 N signal)
    assert np.all(ours > 0.995) and np.all(theirs > 0.99)
    assert ours[0] >= theirs[0] - 0.005
