"""S3's commands: ``softtip haptics render`` (recorded to MCAP and read back; driving a serial device,
read on the other end of a pty pair) and ``softtip bench haptics``, and their refusals of bad input."""

from __future__ import annotations

import _thread
import functools
import json
import os
import select
import socket
import sys
import threading
import time

import numpy as np
import pytest
from typer.testing import CliRunner

from softtip.cli.main import app
from softtip.realtime.recording.reader import read_recording
from softtip.systems.haptics.device import DEVICE_FILE, load_device, quantised, servo_angles
from softtip.systems.haptics.fingertips import TEST_FINGERTIPS
from softtip.realtime.sinks.base import Sink
from softtip.realtime.sinks.recorder import RecorderSink
from softtip.systems.haptics.live import (
    LOOP_RATE_HZ,
    TARGET_NAMES,
    fs_collection,
    fs_renderer,
    personalised_renderer,
    render_stream,
    synthetic_holds,
    synthetic_sensation,
)
from softtip.systems.haptics.servos import (
    EmulatedController,
    SerialDevice,
    SimulatedDevice,
    parse_reply,
    wrench_reply,
)

runner = CliRunner()


@functools.cache
def _fs_table_9():
    """A 9³ FS table on the shipped device, its saturated entries left out."""
    return fs_collection(load_device(), 9, np.random.default_rng(1))


def run(*args: str):
    """The command as softtip mounts it: ``haptics render``, and ``bench`` for ``bench haptics``."""
    words = ["bench", "haptics", *args[1:]] if args[0] == "bench" else list(args)
    return runner.invoke(app, words)


def test_render_records_the_stream_and_reads_back(tmp_path):
    path = tmp_path / "render.mcap"
    result = run("haptics", "render", "--duration", "0.2", "--fs-levels", "7", "--record", str(path), "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["ticks"] == 200 and summary["loop_rate_hz"] == LOOP_RATE_HZ
    assert 0.199 <= summary["wall_s"] < 5  # paced: the last tick starts no sooner than 199 periods after the first
    # one rendering per servo command (50 Hz), not one per tick
    assert summary["renderings"] == summary["servo_frames"] == 10
    recording = read_recording(path)
    assert not recording.truncated
    estimates = recording.topics["/fingertip/estimates"]
    assert len(estimates.data) == 200
    values = np.array([m.data for m in estimates.decoded()])
    commands, servos = values[:, 0:3], values[:, 3:6]
    assert np.array_equal(commands, np.repeat(commands[::20], 20, axis=0))  # held over each frame's 20 ticks
    # the servos as the device model moves them: 50 Hz frames of the 1 kHz commands (recomputed here)
    assert np.allclose(servos, servo_angles(load_device(), np.zeros(3), commands, LOOP_RATE_HZ))
    wrench = recording.topics["/fingertip/wrench"].decoded()
    rendered = np.array([[w.wrench.force.x, w.wrench.force.y, w.wrench.force.z] for w in wrench])
    assert np.allclose(rendered, values[:, 6:9])
    wanted = recording.topics["/fingertip/chip0/wanted_force"].decoded()
    assert len(wanted) == 200 and all(np.isfinite(w.wrench.force.z) for w in wanted)
    assert json.loads(recording.metadata["softtip"]["target_names"]) == list(TARGET_NAMES)


def test_render_plays_a_recorded_sensation(tmp_path):
    sensation = tmp_path / "s.csv"
    sensation.write_text("time_s,fx_N,fy_N,fz_N\n0,0,0,0\n0.05,0,0,1.0\n0.1,0.1,0,1.5\n")
    result = run("haptics", "render", "--sensation", str(sensation), "--fs-levels", "7", "--json")
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["ticks"] == 100  # 0.1 s held at 1 kHz


@pytest.mark.parametrize(("args", "words"), [
    (("--duration", "nan"), "--duration = nan"),
    (("--duration", "-1"), "--duration = -1"),
    (("--duration", "inf"), "--duration = inf"),
    (("--duration", "1e9"), "expected at most 3600 s"),
    (("--fingertip", "thumb"), "--fingertip = 'thumb'"),
    (("--method", "magic"), "--method = 'magic'"),
    (("--fs-levels", "1"), "--fs-levels = 1"),
    (("--seed", "-2"), "--seed = -2"),
    (("--foxglove-port", "0"), "--foxglove-port = 0"),
    (("--device", "missing.toml"), "missing.toml"),
    (("--sensation", "missing.csv"), "missing.csv"),
    (("--sensation", "bad.txt"), "expected a .csv or .parquet"),
    (("--ros2",), "--ros2: ROS 2 is not installed (rclpy does not import): pip install 'softtip[ros2]'"),
])
def test_render_refuses_bad_input_in_one_line(args, words, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rclpy", None)  # for --ros2: as where ROS 2 is not installed
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.txt").write_text("x")
    result = run("haptics", "render", *args)
    assert result.exit_code == 2, result.output
    assert words in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_render_refuses_bad_sensation_files_and_outputs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for name, text, words in (("nan.csv", "time_s,fx_N,fy_N,fz_N\n0,0,0,nan\n", "finite"),
                              ("back.csv", "time_s,fx_N,fy_N,fz_N\n0,0,0,1\n0,0,0,1\n", "increase"),
                              ("cols.csv", "time_s,fx_N\n0,1\n", "missing column fy_N"),
                              ("span.csv", "time_s,fx_N,fy_N,fz_N\n0,0,0,1\n1e9,0,0,1\n",
                               "time_s spans 1e+09 s, expected at most 3600 s")):
        (tmp_path / name).write_text(text)
        result = run("haptics", "render", "--sensation", name)
        assert result.exit_code == 2 and words in result.stderr, result.output
    # the same span cut by --duration is a sensation like any other
    result = run("haptics", "render", "--sensation", "span.csv", "--duration", "0.1", "--fs-levels", "5", "--fast",
                 "--json")
    assert result.exit_code == 0 and json.loads(result.stdout)["ticks"] == 100, result.output
    (tmp_path / "taken.mcap").write_text("")
    result = run("haptics", "render", "--record", "taken.mcap")
    assert result.exit_code == 2 and "--record" in result.stderr and "--force" in result.stderr
    broken = tmp_path / "device.toml"
    broken.write_text(DEVICE_FILE.read_text().replace("stiffness = 200.0",
                                                                                   "stiffness = -1.0"))
    result = run("haptics", "render", "--device", "device.toml")
    assert result.exit_code == 2 and "stiffness" in result.stderr


def test_bench_reports_each_figure_beside_its_baseline():
    result = run("bench", "--queries", "300", "--repeats", "1", "--no-reproduce", "--json")
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    rendering, table = report["rendering"], report["personalised_table_13^3"]
    assert rendering["queries"] == 300 and rendering["p99_us"] >= rendering["p50_us"] > 0
    assert rendering["baseline_cKDTree_query_p99_us"] > 0 and table["entries"] > 1000
    assert table["geometric_ms"] > 0 and table["data_driven_ms"] > 0
    for args, words in ((("--queries", "0"), "--queries = 0"), (("--repeats", "-1"), "--repeats = -1"),
                        (("--queries", "10000000"), "from 1 to 1000000"),
                        (("--seed", "-1"), "--seed = -1")):
        result = run("bench", *args)
        assert result.exit_code == 2 and words in result.stderr, result.output


def test_render_with_the_geometric_table_follows_a_large_finger():
    common = ("haptics", "render", "--duration", "0.5", "--fs-levels", "9", "--fingertip", "large cast (8.5 mm)",
              "--json")
    standard = json.loads(run(*common).stdout)
    geometric = json.loads(run(*common, "--method", "geometric").stdout)
    # the standard table presses an 8.5 mm finger as if it were the 7.5 mm FS: far too hard (measured: 5.4 times
    # the geometric method's median error; the 10 mm finger is pressed 3.4 N by the released device, every
    # method's floor there)
    assert geometric["median_error_N"] < standard["median_error_N"] / 3
    # a larger finger sits lower: the FS entries with the platform lowest cannot be placed lower still
    assert geometric["table_entries_flagged"] > 0 and standard["table_entries_flagged"] == 0


def test_a_sensation_beyond_the_table_is_flagged_every_tick(tmp_path):
    sensation = tmp_path / "hard.csv"
    sensation.write_text("time_s,fx_N,fy_N,fz_N\n0,0,0,500\n0.05,0,0,500\n")
    result = run("haptics", "render", "--sensation", str(sensation), "--fs-levels", "7", "--fast", "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    # 50 ticks: three servo commands (20, 20 and 10 ticks), each rendered once and flagged
    assert summary["ticks"] == 50 and summary["outside_table"] == summary["renderings"] == 3


class LineReader:
    """The device end of a pty pair: collects what the host writes, line by line, until the release."""

    def __init__(self):
        self.master, slave = os.openpty()
        self.port = os.ttyname(slave)
        self._slave = slave  # held open so the pty lives while the host opens and closes its end
        self.text = ""
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self):
        while "R\n" not in self.text.replace("\r", ""):
            ready, _, _ = select.select([self.master], [], [], 10.0)
            if not ready:
                return
            self.text += os.read(self.master, 4096).decode("ascii")

    def lines(self) -> list[list[str]]:
        self.thread.join(10.0)
        os.close(self.master)
        os.close(self._slave)
        return [line.split() for line in self.text.replace("\r", "").splitlines()]


def test_a_serial_device_takes_the_simulated_devices_commands():
    device = load_device()
    rng = np.random.default_rng(3)
    renderer = fs_renderer(device, 7, rng)
    wanted = synthetic_sensation(device, 0.41, rng)
    simulated = SimulatedDevice(device, TEST_FINGERTIPS[1], LOOP_RATE_HZ, None)
    modelled = render_stream(device, renderer, simulated, wanted, [], paced=False)
    reader = LineReader()
    real = render_stream(device, renderer, SerialDevice(reader.port, device), wanted, [], paced=False)
    lines = reader.lines()
    # the hello, one command per 50 Hz frame of the 410 ticks (21 frames, the last a short one), the release
    assert lines[0] == ["H", "2", "50"] and lines[-1] == ["R"]
    commands = lines[1:-1]
    assert [c[0] for c in commands] == ["F"] * 21 and [int(c[1]) for c in commands] == list(range(21))
    sent = np.radians(np.array([[float(a) for a in c[2:]] for c in commands]))
    assert np.allclose(sent, np.array(simulated.sent), atol=np.radians(0.0005))  # three decimals of a degree
    # each is the renderer's command at its frame's first tick, resolved to the servos' 0.54 degree dead band
    first_ticks = np.array([renderer.render_one(w)[0] for w in wanted[::20]])
    assert np.allclose(np.array(simulated.sent), quantised(device, first_ticks))
    assert np.allclose(np.degrees(sent) / 0.54, np.round(np.degrees(sent) / 0.54), atol=1e-5)
    assert (modelled.frames, real.frames) == (21, 21) and real.to_dict()["median_error_N"] is None
    assert modelled.to_dict()["median_error_N"] is not None and modelled.outside == real.outside


def test_render_drives_a_serial_device_from_the_command_line(tmp_path):
    reader = LineReader()
    path = tmp_path / "real.mcap"
    result = run("haptics", "render", "--duration", "0.1", "--fs-levels", "7", "--port", reader.port, "--baud",
                 "19200", "--record", str(path), "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    lines = reader.lines()
    assert summary["servo_frames"] == 5 == len(lines) - 2 and summary["device"] == reader.port
    assert summary["median_error_N"] is None  # nothing comes back from the device
    values = np.array([m.data for m in read_recording(path).topics["/fingertip/estimates"].decoded()])
    # commands; no angles, no wrench; each tick's lateness
    assert np.all(np.isfinite(values[:, :3])) and np.all(np.isnan(values[:, 3:12])) and np.all(values[:, 12] >= 0)


@pytest.mark.parametrize(("args", "words"), [
    (("--port", "/dev/no-such-serial-port"), "--port = '/dev/no-such-serial-port': cannot open"),
    (("--port", ""), "--port = '': expected a serial device path"),
    (("--port", "loop://", "--baud", "9600"), "--baud = 9600: expected an integer baud rate from 17000"),
    (("--baud", "0"), "--baud = 0"),
])
def test_render_refuses_a_port_it_cannot_drive_in_one_line(args, words, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    started = time.perf_counter()
    result = run("haptics", "render", *args)
    assert time.perf_counter() - started < 5  # before the FS table is collected
    assert result.exit_code == 2, result.output
    assert words in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_the_emulated_device_answers_each_frame_with_the_models_wrench_and_the_loop_records_it(tmp_path):
    device = load_device()
    rng = np.random.default_rng(4)
    renderer = fs_renderer(device, 7, rng)
    wanted = synthetic_sensation(device, 0.2, rng)
    master, slave = os.openpty()
    controller = EmulatedController(master, device, TEST_FINGERTIPS[1], LOOP_RATE_HZ, None)
    path = tmp_path / "replies.mcap"
    try:
        # paced (at normal priority): the replies come while the loop runs
        summary = render_stream(device, renderer, SerialDevice(os.ttyname(slave), device), wanted,
                                [RecorderSink(path)], realtime=False)
        controller.thread.join(10.0)  # it ends at the release
    finally:
        os.close(slave)
        os.close(master)
    # the reference: the device model driven by the same commands, frame by frame, read at each frame's end
    model = SimulatedDevice(device, TEST_FINGERTIPS[1], LOOP_RATE_HZ, None)
    commands = [np.radians([float(word) for word in line.split()[2:]]) for line in controller.lines if line[0] == "F"]
    expected = []
    for frame, command in enumerate(commands):
        model.send(frame, command)
        expected.append(model.frame(20).wrench[-1])
    replied = np.array([wrench for _, wrench in controller.replied])
    assert [frame for frame, _ in controller.replied] == list(range(10)) and np.allclose(replied, expected)
    # the host read those that came while it ran (frames 0-8: the last answers the release; measured 9 of 9),
    # and holds the newest from the frame after it read it, to the line's 6 digits
    values = np.array([m.data for m in read_recording(path).topics["/fingertip/estimates"].decoded()])
    held = values[:, 6:12]
    read = np.unique(held[np.isfinite(held[:, 0])], axis=0)
    assert 5 <= summary.replies <= 9 and len(read) >= 1 and summary.malformed_replies == 0
    assert all(np.isclose(row, replied, rtol=1e-5, atol=1e-9).all(axis=1).any() for row in read)
    assert summary.error_source == "device" and len(summary.errors_N) == summary.replies
    # each scored against the wanted force at its frame's last tick, by hand for the first
    assert np.isclose(summary.errors_N[0], np.linalg.norm(replied[0, :3] - wanted[19, :3]), rtol=1e-5)


def test_a_garbled_reply_is_counted_and_skipped():
    assert parse_reply(wrench_reply(7, np.array([0.1, -0.2, 1.5, 1e-4, -2e-5, 0.0])).encode())[0] == 7
    for line in (b"W 7 0.1 0.2", b"W x 1 2 3 4 5 6", b"W 7 nan 0 0 0 0 0", b"Q 7 1 2 3 4 5 6", b"W 7 a b c d e f"):
        assert parse_reply(line) is None


def render_on_the_model(seed, wanted, sinks):
    """The FS table's rendering (7³) on the device model with the first test fingertip, of ``wanted(device,
    rng)``, into ``sinks``."""
    device = load_device()
    rng = np.random.default_rng(seed)
    return render_stream(device, fs_renderer(device, 7, rng),
                         SimulatedDevice(device, TEST_FINGERTIPS[0], LOOP_RATE_HZ, rng), wanted(device, rng), sinks)


@pytest.mark.realtime
def test_each_ticks_measured_start_is_its_stamp_and_its_lateness_is_recorded(tmp_path):
    path = tmp_path / "timed.mcap"
    summary = render_on_the_model(5, lambda device, rng: synthetic_sensation(device, 0.5, rng), [RecorderSink(path)])
    recording = read_recording(path)
    messages = recording.topics["/fingertip/estimates"]
    lateness = np.array([m.data for m in messages.decoded()])[:, 12]
    stamps = np.array([w.header.stamp.sec * 10**9 + w.header.stamp.nanosec
                       for w in recording.topics["/fingertip/wrench"].decoded()], dtype=np.int64)
    # a stamp less its tick's lateness is the tick's deadline: one grid of 1 ms steps (to the ns of the stamps)
    deadlines = stamps - np.round(lateness * 1e9).astype(np.int64)
    assert np.abs(np.diff(deadlines) - 1e6).max() <= 2
    assert np.all(lateness >= 0) and np.array_equal(np.sort(lateness), np.sort(summary.lateness_s))
    assert len(np.unique(np.diff(stamps))) > 1  # measured, not nominal
    report = summary.to_dict()
    assert report["lateness_p50_us"] <= report["lateness_p99_us"] <= report["lateness_max_us"] == lateness.max() * 1e6


class CtrlC(Sink):
    """Presses Ctrl-C (interrupts the main thread) once it has been handed ``after`` frames."""

    def __init__(self, after: int):
        self.after, self.written = after, 0

    def write(self, frame):
        self.written += 1
        if self.written == self.after:
            _thread.interrupt_main()


def test_ctrl_c_ends_an_endless_rendering_and_keeps_the_recording(tmp_path):
    path = tmp_path / "endless.mcap"
    summary = render_on_the_model(6, synthetic_holds, [RecorderSink(path), CtrlC(after=300)])
    assert summary.interrupted and summary.ticks >= 300
    recording = read_recording(path)
    assert not recording.truncated and len(recording.topics["/fingertip/estimates"].data) == summary.ticks


def test_the_synthetic_sensation_holds_each_touch_after_a_raised_cosine_blend():
    device = load_device()
    holds = synthetic_holds(device, np.random.default_rng(7))
    first, second = next(holds), next(holds)
    assert first.shape == second.shape == (500, 6)
    # each hold reaches its touch after its first quarter and holds it; the next starts from there
    assert np.allclose(first[125:], first[-1]) and np.allclose(second[0], first[-1])
    blend = (1 - np.cos(np.pi * 25 / 125)) / 2  # 25 ticks into the 125-tick raised cosine
    assert np.allclose(first[25], first[0] * (1 - blend) + first[-1] * blend)
    assert np.linalg.norm(first[-1, :3]) > 0.1 and np.linalg.norm(second[-1, :3]) > 0.1


@pytest.mark.parametrize(("method", "fraction"), [("A", 10), ("B+", 3), ("A+", 10)])
def test_the_personalised_methods_render_a_large_finger_live(method, fraction):
    device = load_device()
    finger = next(f for f in TEST_FINGERTIPS if f.name == "large cast (8.5 mm)")
    fs = _fs_table_9()
    errors = {}
    for name in ("standard", method):
        renderer, _ = personalised_renderer(device, name, finger, fs.motor_inputs, fs.finger_wrenches,
                                            fs.platform_wrenches, seed=1)
        rng = np.random.default_rng(8)
        summary = render_stream(device, renderer, SimulatedDevice(device, finger, LOOP_RATE_HZ, rng),
                                synthetic_sensation(device, 3.0, rng), [], paced=False)
        errors[name] = summary.to_dict()["median_error_N"]
    # the FS table presses the 8.5 mm finger far too hard (measured: 1.54 N median); personalised, the
    # median error is 12.1 (A), 3.7 (B+) and 11.8 (A+) times smaller on the 9³ table (other sensations'
    # seeds: 8.6-12.2, 3.8-7.9, 6.7-9.8)
    assert errors[method] < errors["standard"] / fraction


def test_foxglove_port_prints_the_address_to_open():
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    result = run("haptics", "render", "--duration", "0.05", "--fs-levels", "5", "--foxglove-port", str(port), "--json")
    assert result.exit_code == 0, result.output
    assert f"ws://127.0.0.1:{port}" in result.stderr


def test_bench_loop_times_each_case_beside_its_baseline_with_the_load():
    result = runner.invoke(app, ["bench", "haptics-loop", "--seconds", "0.2", "--no-record", "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["targets_p99_us"] == {"idle": 1000.0, "loaded": 2000.0}
    for case in ("idle", "loaded"):
        runs = report[case]
        for kind in ("real-time", "baseline"):
            run_ = runs[kind]
            assert run_["ticks"] == 200 and 0 <= run_["lateness_p50_us"] <= run_["lateness_p99_us"] <= run_["lateness_max_us"]
            assert len(run_["load_average_before"]) == 3
        assert runs["baseline"]["timing"]["granted"] == "normal priority"
        assert runs["meets_target"] == (runs["real-time"]["lateness_p99_us"] <= report["targets_p99_us"][case])
    assert report["idle"]["busy_cpus"] == [] and len(report["loaded"]["busy_cpus"]) >= 1
    for args, words in ((("--seconds", "0.01"), "--seconds = 0.01"), (("--seed", "-1"), "--seed = -1")):
        result = runner.invoke(app, ["bench", "haptics-loop", *args])
        assert result.exit_code == 2 and words in result.stderr, result.output


class FailingSink(Sink):
    """A sink whose disk fills at its 50th frame."""

    def __init__(self):
        self.written, self.closed = 0, False

    def write(self, frame):
        self.written += 1
        if self.written == 50:
            raise OSError(28, "No space left on device")

    def close(self):
        self.closed = True


def test_a_failing_sink_stops_the_loop_and_the_servos_are_released():
    device = load_device()
    rng = np.random.default_rng(9)
    sink, servos = FailingSink(), SerialDevice("loop://", device)
    with pytest.raises(OSError, match="No space left"):
        render_stream(device, fs_renderer(device, 7, rng), servos, synthetic_holds(device, rng), [sink],
                      realtime=False)
    # stopped within a frame or two of the failure (50 frames of 20 ticks would be a second), all closed
    assert 50 <= sink.written < 100 and sink.closed and servos.port is None
