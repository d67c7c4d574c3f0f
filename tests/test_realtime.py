"""Live pipeline, baseline, MCAP recording and conversion, sinks, and the emulated stream.

References: hand-built models whose outputs are computed here with numpy from the
readings and the baseline (the mean of the first frames, computed independently); the
analytic lag of a first-order filter on a ramp; an independent ROS 2 CDR decoder
(mcap-ros2-support) and CDR bytes packed by hand with struct; the emulator's exact log of
the frames it sent; a Foxglove WebSocket client written from the protocol's byte layout.
"""

import asyncio
import dataclasses
import io
import json
import math
import signal
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import NonSeekingReader, make_reader
from rich.console import Console

from softtip._core.channels import MAGNETIC
from softtip.data import Dataset, channel_names
from softtip.hardware import FaultPlan, FrameFate, PressCycle, Sample
from softtip.bench.live import soak
from softtip.realtime import (
    AcquisitionClock,
    Baseline,
    DashboardSink,
    Estimator,
    FoxgloveSink,
    FrameResult,
    LiveSession,
    McapRecorder,
    Pipeline,
    RecorderSink,
    RecordingError,
    ROS2Sink,
    StreamInfo,
    convert,
    drift_step,
    read_recording,
    run_live,
)
from softtip.realtime.recording.format import schema_text

CHIPS = 4
CHANNELS = channel_names(CHIPS)
RNG_SEED = 7
# How long a test waits for what it waits for: reaching it means a hang, never the expected way out.
HANG_GUARD_S = 60.0


class LinearModel:
    """y = W x + b, with predict only: the pipeline must fall back to predict on a batch of one."""

    def __init__(self, weights, bias):
        self.weights, self.bias = np.asarray(weights), np.asarray(bias)

    def predict(self, X):
        return np.asarray(X) @ self.weights.T + self.bias


class CountingLinearModel(LinearModel):
    """The same with predict_one, counting its calls."""

    def __init__(self, weights, bias):
        super().__init__(weights, bias)
        self.calls = 0

    def predict_one(self, x):
        self.calls += 1
        return self.weights @ x + self.bias


class ThresholdClassifier:
    """'pressed' when the single input exceeds 50, else 'free'."""

    classes_ = np.array(["free", "pressed"])

    def predict(self, X):
        return np.where(np.asarray(X)[:, 0] > 50.0, "pressed", "free")


def readings(n, seed=RNG_SEED, period_s=0.01):
    """(device times, fields (n, chips, 3) in uT): resting fields, presses, noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * period_s
    resting = rng.uniform(-500, 500, (CHIPS, 3))
    gains = rng.uniform(-1, 1, (CHIPS, 3))
    gains[2, 2] = 1.0
    press = np.clip(np.sin(2 * np.pi * t / 0.5), 0, None) * 200.0
    return t, resting + press[:, None, None] * gains + rng.normal(0, 0.3, (n, CHIPS, 3))


def make_sample(seq, device_time_s, field_uT, host_zero_s, faulty=()):
    chip_ok = np.ones(CHIPS, dtype=bool)
    chip_ok[list(faulty)] = False
    field = np.array(field_uT, dtype=np.float64)
    field[~chip_ok] = np.nan
    return Sample(seq=seq, device_time_s=device_time_s, host_time_s=host_zero_s + device_time_s + 3e-4,
                  reading=field, status=np.where(chip_ok, 0, 2).astype(np.uint8), chip_ok=chip_ok,
                  saturated=np.zeros((CHIPS, 3), dtype=bool))


def run(pipeline, times, fields, faulty=None, before=None):
    """Feed frames to an opened pipeline; ``before(i)`` runs ahead of frame i."""
    host_zero = time.perf_counter()
    results = []
    for i, (t, field) in enumerate(zip(times, fields, strict=True)):
        if before is not None:
            before(i)
        results.append(pipeline.process(make_sample(i % 65536, t, field, host_zero, (faulty or {}).get(i, ()))))
    return results


def three_estimators():
    rng = np.random.default_rng(1)
    forces = Estimator(LinearModel(rng.normal(size=(3, 12)), rng.normal(size=3)), CHANNELS,
                       target_names=["Fx", "Fy", "Fz"], target_units="N", name="forces")
    grip_channels = ["s3_bz_uT", "s0_bx_uT", "s1_by_uT"]
    grip = Estimator(CountingLinearModel(rng.normal(size=(1, 3)), [0.5]), grip_channels,
                     target_names=["grip_force"], target_units="N", input_units="mT", name="grip")
    state = Estimator(ThresholdClassifier(), ["s2_bz_uT"], name="state")
    return forces, grip, state


# --------------------------------------------------------------------------
# Pipeline and baseline
# --------------------------------------------------------------------------


def test_estimates_equal_the_models_of_the_change_from_the_initial_baseline():
    times, fields = readings(80)
    forces, grip, state = three_estimators()
    seen = []
    with Pipeline(CHIPS, [forces, grip, state], baseline=Baseline(10), callbacks=[seen.append]) as pipeline:
        results = run(pipeline, times, fields)
    assert pipeline.target_names == ("Fx", "Fy", "Fz", "grip_force")
    assert pipeline.stream.classes == ("free", "pressed")
    baseline = fields[:10].mean(axis=0)
    for i, result in enumerate(results):
        if i < 10:  # the baseline is taken from these frames
            assert result.baseline is None and result.estimates is None and result.state is None
            continue
        change = fields[i] - baseline
        np.testing.assert_allclose(result.baseline, baseline, rtol=0, atol=1e-9)
        np.testing.assert_allclose(result.change, change, rtol=0, atol=1e-9)
        expected_forces = forces.model.weights @ change.ravel() + forces.model.bias
        grip_inputs = np.array([change[3, 2], change[0, 0], change[1, 1]]) * 1e-3  # uT -> mT
        expected_grip = grip.model.weights @ grip_inputs + grip.model.bias
        np.testing.assert_allclose(result.estimates, np.r_[expected_forces, expected_grip], rtol=1e-12, atol=1e-9)
        assert result.state == ("pressed" if change[2, 2] > 50 else "free")
    assert {r.state for r in results[10:]} == {"free", "pressed"}
    assert grip.model.calls == 70  # the real-time path was used
    assert seen == results and pipeline.estimated == 70
    assert np.all(np.diff([r.stamp_ns for r in results]) > 0)


def test_frames_with_a_faulty_chip_are_neither_estimated_nor_in_the_baseline():
    times, fields = readings(40)
    forces, _, _ = three_estimators()
    with Pipeline(CHIPS, [forces], baseline=Baseline(10)) as pipeline:
        results = run(pipeline, times, fields, faulty={3: [1], 25: [0, 2]})
    sound_first = [i for i in range(11) if i != 3]  # ten sound frames: 0-2 and 4-10
    baseline = fields[sound_first].mean(axis=0)
    np.testing.assert_allclose(results[12].baseline, baseline, atol=1e-9)
    assert results[10].estimates is None  # the tenth sound frame completes the baseline
    assert results[25].estimates is None and np.isnan(results[25].reading[[0, 2]]).all()
    assert results[26].estimates is not None
    counters = pipeline.counters()
    assert counters["with_chip_fault"] == 2 and counters["estimated"] == 40 - 11 - 1
    assert counters["frames"] == 40 and math.isfinite(counters["latency_ms"]["p99"])


def test_a_new_baseline_on_command_replaces_the_old_one_once_complete():
    times, fields = readings(60)
    fields[30:] += 150.0  # a grasp: every channel moves
    with Pipeline(CHIPS, baseline=Baseline(10)) as pipeline:
        results = run(pipeline, times, fields, before=lambda i: pipeline.take_baseline(5) if i == 30 else None)
    first, second = fields[:10].mean(axis=0), fields[30:35].mean(axis=0)
    for i in range(30, 35):  # while the new one is taken the old one stays in use
        np.testing.assert_allclose(results[i].change, fields[i] - first, atol=1e-9)
        assert results[i].baseline_version == 1
    for i in range(35, 60):
        np.testing.assert_allclose(results[i].change, fields[i] - second, atol=1e-9)
        assert results[i].baseline_version == 2


def test_drift_tracking_follows_a_slow_ramp_with_the_filters_lag_and_freezes_during_contact():
    dt, tau, slope = 0.1, 1.0, 1.0  # s, s, uT/s
    alpha = -math.expm1(-dt / tau)
    lag = slope * dt * (1 - alpha) / alpha  # steady lag of x - b for b <- b + a (x - b) on a ramp
    baseline = Baseline(1, drift_time_constant_s=tau, drift_threshold=20.0, step=1e-6)
    resting = np.linspace(-300, 300, 12).reshape(CHIPS, 3)
    history = []
    for k in range(600):  # 60 s of ramp; a contact from 30 s to 35 s
        t = k * dt
        contact = 200.0 if 30.0 <= t < 35.0 else 0.0
        baseline.update(resting + slope * t + contact, True, dt)
        history.append((t, baseline.value.copy()))
    ramp_error = [resting + slope * t - b for t, b in history if 20.0 <= t < 30.0]
    np.testing.assert_allclose(ramp_error, lag, atol=1e-5)
    during = np.array([b for t, b in history if 30.0 <= t < 35.0])
    assert np.all(during == during[0])  # the contact is not absorbed
    np.testing.assert_array_equal(during[0], [b for t, b in history if t < 30.0][-1])
    # After the release the change (ramp + lag, below the threshold) is tracked again.
    np.testing.assert_allclose(resting + slope * history[-1][0] - history[-1][1], lag, atol=1e-5)
    # A contact state stops it as well, whatever the change.
    frozen = baseline.value.copy()
    assert not baseline.update(resting + slope * 61.0, True, dt, free=False)
    np.testing.assert_array_equal(baseline.value, frozen)


def test_drift_step_is_one_gated_exponential_step():
    filtered = np.zeros((2, 3))
    reading = np.full((2, 3), 4.0)
    stepped, moved = drift_step(filtered, reading, 0.25, 5.0)
    assert moved and np.allclose(stepped, 1.0)
    reading[1, 2] = 6.0  # one channel above the threshold: no update at all
    held, moved = drift_step(filtered, reading, 0.25, 5.0)
    assert not moved and held is filtered


def test_acquisition_stamps_recover_the_device_clock_on_the_host_clock():
    rng = np.random.default_rng(3)
    device = np.arange(2000) * 0.002
    true_offset = 12.5  # host clock minus device clock, s
    delays = rng.exponential(5e-4, device.size)
    delays[::50] = 0.0  # now and then a frame arrives without delay
    wall_minus_perf_ns = 1_700_000_000 * 10**9  # the host's wall clock read 1.7e9 s at perf_counter 0
    clock = AcquisitionClock(leak=1e-4, wall_minus_perf_ns=wall_minus_perf_ns)
    stamps = np.array([clock.stamp_ns(h, d) for h, d in zip(device + true_offset + delays, device, strict=True)])
    acquired = device + true_offset
    error_s = (stamps - wall_minus_perf_ns) * 1e-9 - acquired
    # The estimate is late by min_j [delay_j + leak (d_k - d_j)] >= 0: at most the leak over
    # the 100 ms since the last undelayed frame. 2 ns: rounding to whole ns and of the sums.
    assert error_s.min() > -2e-9 and error_s.max() < 1e-4 * 0.1 + 2e-9
    assert error_s.max() > 0.9 * 1e-4 * 0.1  # the leak's lag is there, just before each undelayed frame
    assert np.all(np.diff(stamps) > 0)
    # The device restarts: its clock goes back, a new minimum starts from that frame.
    restart = clock.stamp_ns(true_offset + 100.0, 0.0)
    assert abs((restart - wall_minus_perf_ns) * 1e-9 - (true_offset + 100.0)) < 2e-9


def test_saved_calibration_model_runs_in_the_pipeline(tmp_path):
    from softtip.calibration import PolynomialFit, save_model

    rng = np.random.default_rng(4)
    X = rng.normal(0, 100, (200, 6))
    y = np.column_stack([X[:, 0] * 0.01 + (X[:, 4] * 0.001) ** 3, X[:, 2] * -0.02])
    model = PolynomialFit(3).fit(X, y)
    path = save_model(tmp_path / "poly.npz", model, input_channels=channel_names(2), input_units="uT",
                      target_names=["Fz", "Fx"], target_units="N")
    estimator = Estimator.from_file(path)
    x = rng.normal(0, 100, 6)
    np.testing.assert_allclose(estimator.estimate(np.r_[x, np.zeros(6)]), model.predict(x[None])[0], rtol=1e-12)
    assert estimator.target_names == ("Fz", "Fx") and estimator.chips_needed == 2


# --------------------------------------------------------------------------
# MCAP recording
# --------------------------------------------------------------------------


def frame(seq, stamp_ns, field_uT, baseline_uT, version, estimates, state):
    return FrameResult(seq, stamp_ns, 0.0, None, field_uT, np.isfinite(field_uT).all(axis=1),
                       np.zeros(field_uT.shape, bool), baseline_uT, version,
                       None if baseline_uT is None else field_uT - baseline_uT, estimates, state, 0.0)


def synthetic_frames(n, chips=2):
    rng = np.random.default_rng(5)
    fields = rng.uniform(-3000, 3000, (n, chips, 3))
    baseline = fields[0] + 0.5
    frames = []
    for i in range(n):
        estimated = i >= 3
        frames.append(frame(i, 1_700_000_000_000_000_000 + i * 2_000_000, fields[i], baseline if i >= 3 else None,
                            1 if i >= 3 else 0, np.array([i * 0.1, -i * 0.2, 3.0]) if estimated else None,
                            ("pressed" if i % 2 else "free") if estimated else None))
    return fields, baseline, frames


def test_recording_reads_back_as_ros2_messages_with_an_independent_decoder(tmp_path):
    from mcap_ros2.decoder import DecoderFactory

    fields, baseline, frames = synthetic_frames(20)
    path = tmp_path / "run.mcap"
    recorder = McapRecorder(path, 2, target_names=["Fz", "grip_force", "Tx"], target_units=["N", "N", "N m"],
                            classes=["free", "pressed"], covariance_T2=np.eye(3).ravel() * 1e-14)
    recorder.write_frames(frames[:7])
    recorder.write_frames(frames[7:])
    recorder.close()

    with path.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        decoded = {}
        for schema, channel, message, ros in reader.iter_decoded_messages():
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            decoded.setdefault(channel.topic, []).append((schema.name, message, ros))
    assert sorted(decoded) == ["/fingertip/chip0/baseline", "/fingertip/chip0/field", "/fingertip/chip1/baseline",
                               "/fingertip/chip1/field", "/fingertip/contact_state", "/fingertip/estimates",
                               "/fingertip/wrench"]
    for k in range(2):
        messages = decoded[f"/fingertip/chip{k}/field"]
        assert len(messages) == 20 and {name for name, _, _ in messages} == {"sensor_msgs/msg/MagneticField"}
        for i, (_, message, ros) in enumerate(messages):
            vector = ros.magnetic_field
            np.testing.assert_array_equal([vector.x, vector.y, vector.z], fields[i, k] / 1e6)
            assert ros.header.frame_id == f"fingertip_chip{k}"
            assert ros.header.stamp.sec * 10**9 + ros.header.stamp.nanosec == frames[i].stamp_ns == message.log_time
            assert message.sequence == i
            np.testing.assert_array_equal(ros.magnetic_field_covariance, np.eye(3).ravel() * 1e-14)
        (_, _, ros), = decoded[f"/fingertip/chip{k}/baseline"]
        np.testing.assert_array_equal([ros.magnetic_field.x, ros.magnetic_field.y, ros.magnetic_field.z],
                                      baseline[k] / 1e6)
    wrenches = decoded["/fingertip/wrench"]
    assert len(wrenches) == 17
    for (_, _, ros), source in zip(wrenches, frames[3:], strict=True):
        assert ros.wrench.force.z == source.estimates[0] and ros.wrench.torque.x == source.estimates[2]
        assert math.isnan(ros.wrench.force.x) and math.isnan(ros.wrench.torque.z)
    for (_, _, ros), source in zip(decoded["/fingertip/estimates"], frames[3:], strict=True):
        assert list(ros.data) == list(source.estimates) and ros.layout.dim[0].label == "Fz,grip_force,Tx"
    assert [ros.data for _, _, ros in decoded["/fingertip/contact_state"]] == [f.state for f in frames[3:]]


def test_recorded_messages_are_the_bytes_of_hand_packed_cdr(tmp_path):
    # Little-endian plain CDR: encapsulation 00 01 00 00, each primitive aligned to its size
    # counted from the end of that header, strings as uint32 length (with the NUL) + bytes + NUL.
    stamp_ns = 1_234_567_890_123_456_789
    field_uT = np.array([[0.0, 0.0, 0.0], [100.0, -200.0, 3500.0]])
    covariance = np.arange(9) * 1e-12
    path = tmp_path / "one.mcap"
    recorder = McapRecorder(path, 2, target_names=["grip_force", "Fz"], target_units=["N", "N"],
                            classes=["free", "pressed"], covariance_T2=covariance)
    recorder.write_frames([frame(7, stamp_ns, field_uT, None, 0, np.array([0.25, -1.5]), "pressed")])
    recorder.close()
    topics = read_recording(path).topics
    frame_id = b"fingertip_chip1\x00"  # 16 bytes: the body is at 12 + 16 = 28, the doubles at 32
    assert topics["/fingertip/chip1/field"].data == [
        b"\x00\x01\x00\x00" + struct.pack("<iII", 1_234_567_890, 123_456_789, len(frame_id)) + frame_id
        + b"\x00" * 4 + struct.pack("<12d", 1e-4, -2e-4, 3.5e-3, *covariance)]
    label = b"grip_force,Fz\x00"  # 14 bytes from 8: size at 24 (aligned), stride, data_offset, count, data at 40
    assert topics["/fingertip/estimates"].data == [
        b"\x00\x01\x00\x00" + struct.pack("<II", 1, len(label)) + label + b"\x00" * 2
        + struct.pack("<IIII", 2, 2, 0, 2) + struct.pack("<2d", 0.25, -1.5)]
    assert topics["/fingertip/contact_state"].data == [b"\x00\x01\x00\x00" + struct.pack("<I", 8) + b"pressed\x00"]
    assert topics["/fingertip/chip1/field"].sequences == [7] and topics["/fingertip/chip1/field"].log_times == [stamp_ns]


OLD_RECORDING = Path(__file__).parent / "data" / "recording-0.1.0.mcap"


def test_a_recording_written_by_softtip_0_1_0_reads_and_converts():
    # Written by the 0.1.0 recorder (its own CDR encoder): 2 chips, 12 frames 2 ms apart, chip 1
    # faulty in frame 6, baselines taken at frames 3 and 8, estimates Fz, grip_force, Tx (N m).
    def field_uT(i):
        return np.array([[1000.0 * (k + 1) - 250.0 * a + 3.5 * i for a in range(3)] for k in range(2)])

    recording = read_recording(OLD_RECORDING)
    assert not recording.truncated and recording.metadata["softtip"]["softtip_version"] == "0.1.0"
    _, second = recording.topics["/fingertip/chip1/baseline"].decoded()
    vector = second.magnetic_field
    assert [vector.x, vector.y, vector.z] == list((field_uT(7)[1] - 1.25) / 1e6)
    dataset = convert(OLD_RECORDING).dataset
    kept = [i for i in range(12) if i != 6]
    baselines = {i: field_uT(0) + 0.5 if i < 8 else field_uT(7) - 1.25 for i in kept}  # frames 0-2: the first
    expected = np.array([field_uT(i) - baselines[i] for i in kept]).reshape(len(kept), -1)
    np.testing.assert_allclose(dataset.X(), expected, rtol=0, atol=1e-9)
    assert dataset.labels == {"Fz": "N", "Tx": "N m", "grip_force": "N", "contact_state": "1"}
    estimated = np.array(kept) >= 3
    np.testing.assert_array_equal(dataset.column("Fz")[estimated], [0.1 * i for i in kept if i >= 3])
    np.testing.assert_array_equal(dataset.column("grip_force")[estimated], [-0.2 * i for i in kept if i >= 3])
    np.testing.assert_array_equal(dataset.column("Tx")[estimated], [0.01 * i for i in kept if i >= 3])
    assert np.isnan(dataset.column("Fz")[~estimated]).all()
    assert list(dataset.column("contact_state")) == ["", "", ""] + [
        "pressed" if i % 2 else "free" for i in kept if i >= 3]
    np.testing.assert_allclose(dataset.column("time_s"), np.array(kept) * 2e-3, rtol=0, atol=1e-12)


def test_schemas_list_every_dependency_once():
    text = schema_text("geometry_msgs/msg/WrenchStamped")
    assert text.startswith("std_msgs/Header header\ngeometry_msgs/Wrench wrench\n")
    assert [line for line in text.splitlines() if line.startswith("MSG: ")] == [
        "MSG: std_msgs/Header", "MSG: builtin_interfaces/Time", "MSG: geometry_msgs/Wrench",
        "MSG: geometry_msgs/Vector3"]


KILLED_WRITER = """
import sys, time
import numpy as np
from softtip.hardware import Sample
from softtip.realtime import Baseline, Pipeline, RecorderSink

sink = RecorderSink(sys.argv[1], flush_interval_s=0.05)
pipeline = Pipeline(2, [], [sink], baseline=Baseline(1)).open()
zero = time.perf_counter()
i = 0
while True:
    t = i * 0.001
    field = np.array([[i, -i, 0.5 * i], [1000.0 + i, 2.0 * i, -3.0]])
    pipeline.process(Sample(i % 65536, t, zero + t, field, np.zeros(2, np.uint8), np.ones(2, bool),
                            np.zeros((2, 3), bool)))
    i += 1
    if i % 100 == 0:
        time.sleep(0.08)
        print(sink.frames_flushed, flush=True)
"""


@pytest.mark.realtime
def test_a_killed_recorder_leaves_a_complete_file_up_to_its_last_flush(tmp_path):
    path = tmp_path / "killed.mcap"
    child = subprocess.Popen([sys.executable, "-c", KILLED_WRITER, str(path)], stdout=subprocess.PIPE, text=True)
    try:
        flushed, deadline = 0, time.monotonic() + HANG_GUARD_S
        while flushed < 600 and time.monotonic() < deadline:
            line = child.stdout.readline()
            assert line, "the recording process ended early"
            flushed = int(line)
        assert flushed >= 600, "the recording process did not flush in time"
        time.sleep(0.03)  # kill it somewhere in the middle of its work
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
        child.stdout.close()
    recording = read_recording(path)
    assert not recording.truncated  # sealed at every flush
    messages = recording.topics["/fingertip/chip1/field"]
    assert len(messages.data) >= flushed
    values = [(m.magnetic_field.x, m.magnetic_field.y, m.magnetic_field.z) for m in messages.decoded()]
    i = np.arange(len(values))
    np.testing.assert_allclose(values, np.column_stack([1000.0 + i, 2.0 * i, np.full(i.size, -3.0)]) * 1e-6,
                               rtol=1e-15)
    # The mcap library's indexed reader and its stream reader read the same messages, without a torn tail.
    for read in (make_reader, NonSeekingReader):
        with path.open("rb") as stream:
            count = sum(channel.topic == "/fingertip/chip1/field"
                        for _, channel, _ in read(stream).iter_messages(log_time_order=False))
        assert count == len(messages.data)


def test_convert_reproduces_the_pipelines_changes_labels_and_trials(tmp_path):
    times, fields = readings(120)
    times[60:] += 5.0  # a 5 s pause: a second trial
    forces, _, state = three_estimators()
    path = tmp_path / "live.mcap"
    with Pipeline(CHIPS, [forces, state], [RecorderSink(path, flush_interval_s=0.01)], baseline=Baseline(10)) as p:
        results = run(p, times, fields, faulty={70: [3]},
                      before=lambda i: p.take_baseline(5) if i == 90 else None)
    conversion = convert(path, tmp_path / "live.parquet", gap_s=1.0)
    dataset = Dataset.read(tmp_path / "live.parquet")
    assert conversion.frames == 119 and conversion.fault_frames == 1 and not conversion.truncated
    kept = [r for i, r in enumerate(results) if i != 70]
    first_baseline = kept[20].baseline
    expected_change = np.array([r.reading - (first_baseline if r.baseline is None else r.baseline)
                                for r in kept])
    np.testing.assert_allclose(dataset.X(), expected_change.reshape(len(kept), -1), rtol=0, atol=1e-9)
    assert list(dataset.trials) == [0, 1] and list(dataset.trial_lengths) == [60, 59]
    stamps = np.array([r.stamp_ns for r in kept])
    np.testing.assert_allclose(dataset.column("time_s")[:60], (stamps[:60] - stamps[0]) * 1e-9, atol=1e-12)
    np.testing.assert_allclose(dataset.column("time_s")[60:], (stamps[60:] - stamps[60]) * 1e-9, atol=1e-12)
    assert dataset.labels == {"Fx": "N", "Fy": "N", "Fz": "N", "contact_state": "1"}
    estimated = np.array([r.estimates is not None for r in kept])
    np.testing.assert_array_equal(dataset.y(["Fx", "Fy", "Fz"])[estimated],
                                  np.array([r.estimates for r in kept if r.estimates is not None]))
    assert np.isnan(dataset.y(["Fx", "Fy", "Fz"])[~estimated]).all()
    assert list(dataset.column("contact_state")) == [r.state or "" for r in kept]
    assert dataset.metadata.protocol["baseline"] == "recorded"


def test_convert_without_recorded_baselines_subtracts_each_trials_initial_value(tmp_path):
    times = np.r_[np.arange(30) * 0.01, 10.0 + np.arange(25) * 0.01]
    _, fields = readings(55)
    stamps = 1_600_000_000_000_000_000 + np.round(times * 1e9).astype(np.int64)
    path = tmp_path / "plain.mcap"
    recorder = McapRecorder(path, CHIPS)
    recorder.write_frames([frame(i, int(stamps[i]), fields[i], None, 0, None, None) for i in range(55)])
    recorder.close()
    dataset = convert(path, baseline_frames=8).dataset
    expected = np.concatenate([fields[:30] - fields[:8].mean(axis=0), fields[30:] - fields[30:38].mean(axis=0)])
    np.testing.assert_allclose(dataset.X(), expected.reshape(55, -1), atol=1e-9)
    assert list(dataset.trial_lengths) == [30, 25] and dataset.labels == {}


# --------------------------------------------------------------------------
# Emulated fingertip through the driver
# --------------------------------------------------------------------------


class FrameCollector:
    """A pipeline callback keeping every frame; ``enough`` is set once ``count`` have arrived."""

    def __init__(self, count):
        self.frames, self.count = [], count
        self.enough = threading.Event()

    def __call__(self, frame):
        self.frames.append(frame)
        if len(self.frames) >= self.count:
            self.enough.set()


@pytest.mark.realtime
def test_emulated_stream_with_faults_delivers_every_intact_frame_and_counts_the_rest():
    forces, _, _ = three_estimators()
    collector = FrameCollector(300)
    faults = FaultPlan(corrupt_every=17, drop_byte_every=23, chip_error_every=13, seed=2)
    session = LiveSession("emulator", [forces], rate_hz=250, chips=CHIPS, baseline=Baseline(20),
                          callbacks=[collector], emulator_faults=faults, emulator_source=PressCycle(CHIPS))
    with session:
        session.wait(HANG_GUARD_S, collector.enough)
    log, summary, frames = session.emulator_log, session.summary(), collector.frames
    sent = log.fate == log.FATES.index(FrameFate.SENT)
    assert collector.enough.is_set() and len(frames) >= 300
    np.testing.assert_array_equal([f.seq for f in frames], log.seq[sent])
    # A frame is known lost when a later one arrives: count those before the last intact frame.
    damaged = np.count_nonzero(~sent[:np.flatnonzero(sent)[-1]])
    assert damaged > 10 and summary["lost_in_transit"] == damaged
    generation = np.arange(log.seq.size)
    assert summary["with_chip_fault"] == np.count_nonzero(sent & ((generation + 1) % 13 == 0)) > 0
    sound = [f for f in frames if f.chip_ok.all()]
    np.testing.assert_allclose(frames[-1].baseline, np.mean([f.reading for f in sound[:20]], axis=0),
                               atol=1e-9)
    for f in frames:
        if f.estimates is not None:
            change = f.reading - f.baseline
            np.testing.assert_allclose(f.estimates, forces.model.weights @ change.ravel() + forces.model.bias,
                                       rtol=1e-12, atol=1e-9)
        else:
            assert f.baseline is None or not f.chip_ok.all()


@pytest.mark.realtime
def test_live_estimates_recorded_equal_the_saved_models_batch_predictions_on_the_converted_data(tmp_path):
    from softtip.calibration import PolynomialFit, save_model

    rng = np.random.default_rng(8)
    X = rng.normal(0, 150, (300, 6))
    model = PolynomialFit(2).fit(X, np.column_stack([X[:, 2] * 0.01 + (X[:, 5] * 0.01) ** 2, X[:, 0] * -0.003]))
    model_path = save_model(tmp_path / "force.npz", model, input_channels=channel_names(2), input_units="uT",
                            target_names=["Fz", "Fx"], target_units="N")
    recording = tmp_path / "live.mcap"
    collector = FrameCollector(100)
    summary = run_live("emulator", [model_path], [RecorderSink(recording)], duration_s=HANG_GUARD_S, rate_hz=100,
                       chips=2, baseline_frames=10, callbacks=[collector], stop=collector.enough)
    assert summary["frames"] >= 100 and summary["lost_in_transit"] == 0 and summary["sink_errors"] == 0
    dataset = convert(recording).dataset
    estimated = np.isfinite(dataset.y(["Fz", "Fx"])).all(axis=1)
    assert np.count_nonzero(estimated) == summary["frames"] - 10
    np.testing.assert_allclose(dataset.y(["Fz", "Fx"])[estimated], model.predict(dataset.X()[estimated]),
                               rtol=1e-9, atol=1e-9)


@pytest.mark.realtime
@pytest.mark.slow
def test_twenty_second_soak_at_500_frames_per_second_loses_no_frame(tmp_path):
    # The CI version of `softtip bench live --duration 600`. How many frames the emulator gets
    # out in 20 s depends on the machine's load (it restarts its schedule when late, as the
    # firmware does, and a frame it cannot write within 50 ms is damaged or not sent): every
    # frame sent intact must arrive in order and be recorded, every damaged one be counted.
    report = soak(20.0, rate_hz=500, chips=CHIPS, record_path=tmp_path / "soak.mcap")
    frames = report["frames"]
    assert frames["lost"] == 0 and frames["every_intact_frame_delivered_in_order"]
    assert frames["every_damaged_frame_counted"]
    assert frames["delivered"] == frames["sent_intact"] > 0 and report["recording"]["complete"]
    assert report["streaming_s"] >= 20.0 and report["sink_errors"] == 0


# --------------------------------------------------------------------------
# Sinks
# --------------------------------------------------------------------------


def stream_info(chips=2, target_names=("Fz", "grip_force"), classes=("free", "pressed")):
    return StreamInfo(chips=chips, target_names=tuple(target_names), target_units=("N",) * len(target_names),
                      classes=classes, settings=None, rate_hz=50.0,
                      counters=lambda latency_window=None: {"frames": 1234, "lost_in_transit": 5,
                                                            "latency_ms": {"p50": 0.25, "p99": 1.5}})


def test_dashboard_shows_the_changes_estimates_state_and_counters():
    console = Console(file=io.StringIO(), width=160, color_system=None)
    dashboard = DashboardSink(console)
    dashboard.open(stream_info())
    field = np.array([[10.0, 20.0, 30.0], [1.0, 2.0, 3.0]])
    dashboard.write(frame(1, 5, field, np.array([[0.0, 0.0, 0.0], [0.5, 0.5, 0.5]]), 1,
                          np.array([1.2345, -0.5]), "pressed"))
    console.print(dashboard.render())
    dashboard.close()
    text = console.file.getvalue()
    for expected in ("10.0", "20.0", "30.0", "0.5", "1.5", "2.5", "1.234", "-0.500", "grip_force",
                     "contact state: pressed", "frames 1234", "lost 5", "p99 1.50 ms"):
        assert expected in text


def foxglove_received(sink, wanted: dict[str, int], sent) -> tuple[dict, dict[int, bytes]]:
    """A foxglove.websocket.v1 client of ``sink``: subscribes to ``wanted`` (topic -> subscription id), has
    the sink write ``sent`` and returns the advertised channels by topic and each subscription's message."""
    import websockets

    async def client():
        async with websockets.connect(f"ws://127.0.0.1:{sink.port}", subprotocols=["foxglove.websocket.v1"]) as ws:
            assert json.loads(await ws.recv())["op"] == "serverInfo"
            channels = {c["topic"]: c for c in json.loads(await ws.recv())["channels"]}
            await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": sub, "channelId": channels[topic]["id"]} for topic, sub in wanted.items()]}))
            while len(sink.subscribed_topics) < len(wanted):
                await asyncio.sleep(0.01)
            sink.write(sent)
            received = {}
            while len(received) < len(wanted):
                data = await asyncio.wait_for(ws.recv(), 5)
                received[struct.unpack_from("<BIQ", data)[1]] = data
            return channels, received

    try:
        return asyncio.run(client())
    finally:
        sink.close()


def test_foxglove_live_view_serves_the_frames_to_a_websocket_client():
    sink = FoxgloveSink(port=0, max_rate_hz=None)
    sink.open(stream_info(target_names=("Fz",), classes=None))
    field = np.array([[10.0, -20.0, 30.0], [1.0, 2.0, 3.0]])
    sent = frame(9, 1_700_000_000_123_456_789, field, np.zeros((2, 3)), 1, np.array([0.75]), None)
    channels, messages = foxglove_received(
        sink, {"/fingertip/chip1/field": 1, "/fingertip/wrench": 2, "/fingertip/field_change": 3}, sent)
    received = {}
    for subscription, data in messages.items():
        opcode, _, timestamp = struct.unpack_from("<BIQ", data)
        assert opcode == 1 and timestamp == sent.stamp_ns
        received[subscription] = json.loads(data[13:])
    assert channels["/fingertip/chip1/field"]["schemaName"] == "sensor_msgs/msg/MagneticField"
    assert "/fingertip/contact_state" not in channels
    vector = received[1]["magnetic_field"]
    assert [vector["x"], vector["y"], vector["z"]] == [1e-6, 2e-6, 3e-6]
    assert received[1]["header"]["stamp"] == {"sec": 1_700_000_000, "nanosec": 123_456_789}
    assert received[2]["wrench"]["force"] == {"x": None, "y": None, "z": 0.75}
    assert received[3]["chips"][0] == {"x": 10.0, "y": -20.0, "z": 30.0}


def test_foxglove_places_a_one_axis_chips_reading_in_the_messages_z_leaving_x_and_y_empty():
    one_axis = dataclasses.replace(MAGNETIC, axes=("z",))
    sink = FoxgloveSink(port=0, max_rate_hz=None)
    sink.open(dataclasses.replace(stream_info(target_names=("Fz",), classes=None), reading=one_axis))
    field = np.array([[30.0], [3.0]])
    sent = frame(2, 1_700_000_000_000_000_000, field, np.zeros((2, 1)), 1, np.array([0.5]), None)
    _, messages = foxglove_received(sink, {"/fingertip/chip1/field": 1, "/fingertip/field_change": 2}, sent)
    received = {subscription: json.loads(data[13:]) for subscription, data in messages.items()}
    assert received[1]["magnetic_field"] == {"x": None, "y": None, "z": 3e-6}
    assert received[2]["chips"] == [{"x": None, "y": None, "z": 30.0}, {"x": None, "y": None, "z": 3.0}]


# --------------------------------------------------------------------------
# Refusals
# --------------------------------------------------------------------------


def refused(error, match, call, *args, **kwargs):
    with pytest.raises(error, match=match) as refusal:
        call(*args, **kwargs)
    assert "\n" not in str(refusal.value)


def test_bad_input_is_refused_with_one_line(tmp_path):
    forces, _, state = three_estimators()
    refused(ValueError, "input channel 's0_bw_uT'", Estimator, forces.model, ["s0_bw_uT"], target_names=["Fx"],
            target_units="N")
    refused(ValueError, "needs target_names", Estimator, forces.model, CHANNELS)
    refused(ValueError, "input unit 'gauss'", Estimator, forces.model, CHANNELS, target_names=["Fx", "Fy", "Fz"],
            target_units="N", input_units="gauss")
    refused(ValueError, "at most one contact-state classifier", Pipeline, CHIPS,
            [state, Estimator(ThresholdClassifier(), ["s0_bx_uT"], name="other")])
    refused(ValueError, "reads chip 3; the stream has 2 chips", Pipeline, 2, [forces])
    refused(ValueError, "free_states", Pipeline, CHIPS, [state], baseline=Baseline(5, drift_time_constant_s=10.0))
    refused(ValueError, "^baseline frames = 0: expected a positive integer$", Baseline, 0)
    refused(ValueError, "^frames = 2.5: expected an integer$", Baseline(5).take, 2.5)
    refused(ValueError, "^step = -0.01: expected a positive number$", Baseline, step=-0.01)
    refused(ValueError, "^refresh_hz = 0: expected a positive number$", DashboardSink, refresh_hz=0)
    refused(ValueError, "^foxglove port = 70000: expected an integer 0..65535$", FoxgloveSink, port=70000)
    refused(ValueError, "^max_rate_hz = True: expected a number$", FoxgloveSink, max_rate_hz=True)
    not_mcap = tmp_path / "x.mcap"
    not_mcap.write_bytes(b"PAR1 not an mcap file at all")
    refused(RecordingError, "is not an MCAP file", read_recording, not_mcap)
    refused(RecordingError, "directory .* does not exist", RecorderSink, tmp_path / "missing" / "x.mcap")
    refused(ValueError, "gap_s = 0", convert, not_mcap, gap_s=0)
    refused(RecordingError, "unit 'kg'", McapRecorder, tmp_path / "y.mcap", 1, target_names=["Fz"],
            target_units=["kg"])


def test_ros2_sink_refuses_with_one_line_when_ros2_is_missing(monkeypatch):
    monkeypatch.setitem(sys.modules, "rclpy", None)  # rclpy does not import, as where it is not installed
    refused(RuntimeError, r"^ROS 2 is not installed \(rclpy does not import\): pip install 'softtip\[ros2\]'$",
            ROS2Sink)
