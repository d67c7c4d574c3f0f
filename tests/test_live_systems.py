"""Identified systems in the live path: frame-by-frame estimates equal the batch simulation (scipy's
``dlsim`` on the model's matrices), and the wearable sensor streams, records and converts."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.signal
from typer.testing import CliRunner

from softtip._core.channels import MAGNETIC
from softtip.systems.wearable.reading import FORCE
from softtip.calibration import ModelFileError
from softtip.cli.main import app
from softtip.hardware import PacedSource, Sample
from softtip.realtime import Baseline, Estimator, Pipeline, RecorderSink, convert, run_live
from softtip.sysid import Recording, StateSpaceModel, save_model

INPUTS = FORCE.channel_names(1)
OUTPUTS = ("fx_N", "fy_N", "fz_N")
PRELOAD_N = np.array([0.05, -0.1, 0.8])  # what the chip reads before contact: the baseline takes it out


def identified(ts: float, seed: int = 0) -> StateSpaceModel:
    """A 4th-order state-space model identified from three trials of a known stable 3 x 3 system."""
    rng = np.random.default_rng(seed)
    A = np.diag([0.9, 0.7, 0.5, -0.3])
    B, C, D = rng.normal(size=(4, 3)), rng.normal(size=(3, 4)), 0.1 * rng.normal(size=(3, 3))
    inputs = [scipy.signal.lfilter([0.2], [1, -0.8], rng.normal(size=(300, 3)), axis=0) for _ in range(3)]
    outputs = [scipy.signal.dlsim((A, B, C, D, ts), u)[1] + 1e-3 * rng.normal(size=(300, 3)) for u in inputs]
    recording = Recording.from_arrays(inputs, outputs, ts, inputs=INPUTS, outputs=OUTPUTS, input_units="N",
                                      output_units="N", source="known system")
    return StateSpaceModel(4).fit(recording)


def simulated(model: StateSpaceModel, u: np.ndarray) -> np.ndarray:
    """The independent batch reference: scipy's discrete simulation from the zero state."""
    system = model.system_
    return scipy.signal.dlsim((system.A, system.B, system.C, system.D, model.ts_), u)[1]


def assert_within_full_scale(streamed: np.ndarray, batch: np.ndarray, fraction: float = 1e-9) -> None:
    full_scale = batch.max(axis=0) - batch.min(axis=0)
    assert np.all(full_scale > 0)
    assert np.abs(streamed - batch).max(axis=0) / full_scale == pytest.approx(0, abs=fraction)


def sample(k: int, reading: np.ndarray, ts: float) -> Sample:
    return Sample(seq=k, device_time_s=k * ts, host_time_s=0.0, reading=reading[None, :],
                  status=np.zeros(1, np.uint8), chip_ok=np.ones(1, bool), saturated=np.zeros((1, 3), bool))


def test_a_dynamic_model_in_the_pipeline_equals_its_batch_simulation_and_restarts_with_a_new_baseline():
    ts = 0.1
    model = identified(ts)
    estimator = Estimator(model, INPUTS, target_names=OUTPUTS, target_units="N", name="system")
    assert estimator.dynamic and estimator.reading == FORCE and estimator.sample_time_s == ts
    rng = np.random.default_rng(3)
    u = scipy.signal.lfilter([0.3], [1, -0.9], rng.normal(size=(240, 3)), axis=0)
    readings = PRELOAD_N + u
    # drift tracking moves the baseline by small steps: the state carries over them (no restart)
    pipeline = Pipeline(1, [estimator], baseline=Baseline(1, drift_time_constant_s=30.0, drift_threshold=10.0,
                                                          reading=FORCE), reading=FORCE, rate_hz=1 / ts)
    retake = 120
    results = []
    for k, reading in enumerate(readings):
        if k == retake:
            pipeline.take_baseline()
        results.append(pipeline.process(sample(k, reading, ts)))
    assert results[0].estimates is None
    first = np.arange(1, retake + 1)  # the new baseline is taken from frame `retake`, used from the next
    assert len({r.baseline_version for r in results[1:retake + 1]}) > 1  # drift steps happened
    changes = np.array([results[k].change[0] for k in first])
    assert_within_full_scale(np.array([results[k].estimates for k in first]), simulated(model, changes))
    second = np.arange(retake + 1, len(readings))
    np.testing.assert_array_equal(results[retake + 1].baseline[0], readings[retake])
    changes = np.array([results[k].change[0] for k in second])
    assert_within_full_scale(np.array([results[k].estimates for k in second]), simulated(model, changes))


def test_the_emulated_wearable_sensor_streams_records_and_converts_with_the_batch_estimates(tmp_path):
    ts = 0.01  # a fast system keeps the real-time test short
    model = identified(ts, seed=1)
    model_path = save_model(tmp_path / "system.npz", model)
    rng = np.random.default_rng(4)
    readings = PRELOAD_N + scipy.signal.lfilter([0.3], [1, -0.9], rng.normal(size=(150, 3)), axis=0)
    source = PacedSource(readings[:, None, :], 1 / ts, reading=FORCE, loop=False, name="test chip")
    path = tmp_path / "live.mcap"
    live = []
    summary = run_live(source, [model_path], [RecorderSink(path)], baseline_frames=1, callbacks=[live.append])
    assert summary["delivered"] == 150 and summary["frames"] == 150 and summary["estimated"] == 149
    assert summary["sink_errors"] == 0 and summary["rate_hz"] == pytest.approx(100.0)

    dataset = convert(path, gap_s=None).dataset
    assert dataset.channel_units == dict.fromkeys(INPUTS, "N")
    changes = dataset.X(INPUTS)
    np.testing.assert_allclose(changes, readings - readings[0], rtol=0, atol=1e-12)
    recorded = dataset.y(OUTPUTS)
    assert np.isnan(recorded[0]).all()
    assert_within_full_scale(recorded[1:], simulated(model, changes[1:]))
    np.testing.assert_array_equal(recorded[1:], np.array([frame.estimates for frame in live[1:]]))
    # the estimates named fx_N ... in N fill the recording's wrench topic too
    np.testing.assert_array_equal(dataset.y(["Fx", "Fy", "Fz"])[1:], recorded[1:])


def test_a_saved_system_is_loaded_with_its_channels_and_bad_inputs_are_refused_with_one_line(tmp_path):
    model = identified(0.1)
    path = save_model(tmp_path / "system.npz", model)
    estimator = Estimator.from_file(path)
    assert estimator.input_channels == INPUTS and estimator.target_names == OUTPUTS
    assert estimator.target_units == ("N",) * 3 and estimator.dynamic
    assert estimator.describe()["reading"] == "force"

    def refused(error, match, call, *args, **kwargs):
        with pytest.raises(error, match=match) as refusal:
            call(*args, **kwargs)
        assert "\n" not in str(refusal.value)

    refused(ValueError, "runs at 10 Hz .*the stream runs at 50 Hz", Pipeline, 1, [estimator], reading=FORCE,
            rate_hz=50)
    refused(ValueError, "reads force .*the stream reads flux density", Pipeline, 1, [estimator], rate_hz=10)
    refused(ValueError, "one sensor kind", Estimator, model, ["s0_bx_uT", "side_fy_N", "side_fz_N"],
            target_names=OUTPUTS, target_units="N")
    refused(ValueError, "input unit 'uT' is not one of N, mN", Estimator, model, INPUTS, input_units="uT",
            target_names=OUTPUTS, target_units="N")
    refused(ValueError, "a baseline of flux density for a stream of force", Pipeline, 1, [estimator],
            baseline=Baseline(reading=MAGNETIC), reading=FORCE)
    refused(ValueError, r"readings: expected shape \(frames, chips, 3\)", PacedSource, np.zeros((5, 3)), 10, reading=FORCE)
    refused(ValueError, "rate_hz", PacedSource, np.zeros((5, 1, 3)), 0, reading=FORCE)
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(path.read_bytes()[:200])
    refused(ModelFileError, "truncated.npz", Estimator.from_file, truncated)


def test_softtip_live_streams_the_emulated_wearable_sensor_through_its_identified_model(tmp_path):
    record = tmp_path / "wearable.mcap"
    result = CliRunner().invoke(app, ["live", "--emulate", "--scenario", "wearable", "--duration", "2",
                                      "--record", str(record), "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["chips"] == 1 and summary["rate_hz"] == 10 and summary["estimated"] >= 15
    assert summary["sink_errors"] == 0 and summary["late"] == 0
    dataset = convert(record).dataset
    assert list(dataset.channels) == list(INPUTS) and {"fx_N", "fy_N", "fz_N"} <= set(dataset.labels)
    refusal = CliRunner().invoke(app, ["live", "--emulate", "--scenario", "wearable", "--chips", "2"])
    assert refusal.exit_code != 0 and "--chips = 2: the wearable scenario streams 1" in refusal.output


@pytest.mark.slow
def test_the_wearable_demo_tares_each_trial_and_its_live_estimates_are_the_offline_simulation():
    from softtip.systems.wearable.live import run_wearable_demo

    report = run_wearable_demo(seed=1, duration_s=17.0, dashboard=False)  # past the first trial's 150 frames
    assert report["estimated_frames"] >= 160 and report["pipeline"]["late"] == 0
    assert report["pipeline"]["baseline_version"] == 2  # at start and at the second trial's first frame
    assert max(report["live_minus_offline_over_full_scale"]) < 1e-9
    assert report["live"]["samples"] == report["estimated_frames"] - 1  # the second trial's tare frame is not scored
