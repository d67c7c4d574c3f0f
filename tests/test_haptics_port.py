"""Methods A, B+ and A+ on a real port: the user's data driven on a serial device (the emulated
controller on a pty, answering each frame with the device model's wrench) and read back from its
``W`` lines, against the same personalisation read on the device model directly; a device that
sends no wrench is refused before the loop."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from typer.testing import CliRunner

from softtip.cli.main import app
from softtip.realtime.recording.reader import read_recording
from softtip.systems.haptics.collection import CollectionSettings, motor_grid, sensed_contact
from softtip.systems.haptics.device import load_device, quantised
from softtip.systems.haptics.fingertips import TEST_FINGERTIPS
from softtip.systems.haptics.live import LOOP_RATE_HZ, fs_collection, personalised_renderer, synthetic_sensation
from softtip.systems.haptics.personalisation import press_configurations
from softtip.systems.haptics.servos import EmulatedController, SerialDevice
from softtip.systems.haptics.study import StudySettings

from test_haptics_commands import LineReader

runner = CliRunner()
HELD = CollectionSettings(hold_s=0.4, window_s=0.08)  # 20 frames: the servos cross their 180 degrees in 15


class EmulatedPort:
    """The emulated controller (exact readings) on the device end of a pty; ``port`` for the host."""

    def __init__(self, fingertip):
        self.master, self.slave = os.openpty()
        self.port = os.ttyname(self.slave)
        self.controller = EmulatedController(self.master, load_device(), fingertip, LOOP_RATE_HZ, None)

    def close(self):
        self.controller.stop()
        os.close(self.slave)
        os.close(self.master)

    def commands(self) -> list[tuple[int, np.ndarray]]:
        """Every F line it took: the frame and the command (rad)."""
        return [(int(line.split()[1]), np.radians([float(word) for word in line.split()[2:]]))
                for line in self.controller.lines if line.startswith("F")]


def exact_model_drive(device, fingertip):
    """The reference: configurations read on the device model by exact sensors (the DS's own wrench)."""
    return lambda motor_inputs: sensed_contact(device, fingertip, motor_inputs, HELD, None)


@pytest.mark.parametrize("method", ["B+", "A", pytest.param("A+", marks=pytest.mark.slow)])
def test_the_users_data_read_on_the_device_personalise_as_on_the_model(method):
    device, finger = load_device(), TEST_FINGERTIPS[2]
    fs = fs_collection(device, 7, np.random.default_rng(2))
    settings = StudySettings(user_levels=3, adaptive_budget=35, fs_levels=7)
    emulated, batches = EmulatedPort(finger), []

    def drive(motor_inputs):
        batches.append(motor_inputs)
        return serial.collect(finger, motor_inputs, HELD, paced=False)

    try:
        serial = SerialDevice(emulated.port, device, 115_200)
        on_device, flagged = personalised_renderer(device, method, finger, fs.motor_inputs, fs.finger_wrenches,
                                                   fs.platform_wrenches, 1, settings, HELD, drive=drive)
        serial.close()
    finally:
        emulated.close()
    on_model, model_flagged = personalised_renderer(
        device, method, finger, fs.motor_inputs, fs.finger_wrenches, fs.platform_wrenches, 1, settings, HELD,
        drive=exact_model_drive(device, finger))
    # each batch's configurations held 20 frames, then one frame released (its last reports come at its end),
    # the frames numbered on from batch to batch
    frames, commands = zip(*emulated.commands())
    assert list(frames) == list(range(len(frames)))
    sent = np.vstack([np.vstack([np.repeat(quantised(device, batch), 20, axis=0), np.zeros((1, 3))])
                      for batch in batches])
    assert np.allclose(np.array(commands), sent, atol=np.radians(0.0005))
    expected = {"B+": press_configurations(device, finger.radius), "A": motor_grid(device, 3)}.get(method)
    assert (np.array_equal(np.vstack(batches), expected) if expected is not None
            else [len(batch) for batch in batches] == [27, 8])  # A+: its first 3³ grid, then one batch
    # the same wanted wrenches rendered by both: the same servo commands
    wanted = np.vstack([fs.finger_wrenches[::5], synthetic_sensation(device, 0.5, np.random.default_rng(3))[::10]])
    port_commands = quantised(device, on_device.render(wanted).motor_inputs)
    model_commands = quantised(device, on_model.render(wanted).motor_inputs)
    assert np.array_equal(port_commands, model_commands) and flagged == model_flagged
    # and the personalisation changed the table: not the standard renderer's commands
    standard, _ = personalised_renderer(device, "standard", finger, fs.motor_inputs, fs.finger_wrenches,
                                        fs.platform_wrenches, 1)
    assert not np.array_equal(quantised(device, standard.render(wanted).motor_inputs), port_commands)


def test_render_with_b_plus_on_a_port_reads_the_presses_back_and_records_the_measured_wrench(tmp_path):
    device = load_device()
    finger = next(f for f in TEST_FINGERTIPS if f.name == "FS cast (7.5 mm)")
    emulated = EmulatedPort(finger)
    path = tmp_path / "port.mcap"
    try:
        result = runner.invoke(app, ["haptics", "render", "--method", "B+", "--port", emulated.port, "--duration",
                                     "0.2", "--fs-levels", "7", "--no-priority", "--record", str(path), "--json"])
        emulated.controller.thread.join(10.0)
    finally:
        emulated.close()
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["user_data_read_by"] == "device" and summary["method"] == "B+"
    frames, commands = zip(*emulated.commands())
    assert list(frames) == list(range(len(frames)))
    presses, loop = np.array(commands[:250]), np.array(commands[-10:])
    # five presses held 50 frames each (1 s at 50 Hz), then the release, then the loop's ten frames
    assert np.allclose(presses, np.repeat(quantised(device, press_configurations(device, finger.radius)), 50, axis=0),
                       atol=np.radians(0.0005))
    # released a frame at a time until the last press's reports came (one frame if the emulator keeps up)
    released = np.array(commands[250:-10])
    assert len(released) >= 1 and np.all(released == 0) and summary["servo_frames"] == 10
    # the reference: the same seed's FS table and sensation, B+ fitted on presses the device model reads exactly
    rng = np.random.default_rng(1)
    fs = fs_collection(device, 7, rng)
    reference, _ = personalised_renderer(device, "B+", finger, fs.motor_inputs, fs.finger_wrenches,
                                         fs.platform_wrenches, 1, drive=exact_model_drive(device, finger))
    wanted = synthetic_sensation(device, 0.2, rng)
    expected = quantised(device, np.array([reference.render_one(w)[0] for w in wanted[::20]]))
    assert np.allclose(loop, expected, atol=np.radians(0.0005))
    # the loop's measured wrench, as the device reported it, is what the recording holds
    replied = np.array([w for frame, w in emulated.controller.replied if frame >= frames[-10]])
    wrench = read_recording(path).topics["/fingertip/wrench"].decoded()
    recorded = np.array([[w.wrench.force.x, w.wrench.force.y, w.wrench.force.z, w.wrench.torque.x,
                          w.wrench.torque.y, w.wrench.torque.z] for w in wrench])
    measured = np.unique(recorded[np.isfinite(recorded[:, 0])], axis=0)
    assert len(measured) >= 1 and summary["device_replies"] >= 1
    assert all(np.isclose(row, replied, rtol=1e-5, atol=1e-9).all(axis=1).any() for row in measured)


@pytest.mark.parametrize("method", ["A", "B+", "A+"])
def test_a_device_that_sends_no_wrench_is_refused_before_the_loop(method):
    reader = LineReader()
    result = runner.invoke(app, ["haptics", "render", "--method", method, "--port", reader.port, "--fs-levels", "5",
                                 "--duration", "0.2", "--fast"])
    lines = reader.lines()
    assert result.exit_code == 2, result.output
    # one error line (beside the progress lines of the stages before it)
    error = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert len(error) == 1 and "Traceback" not in result.stderr
    assert f"--method {method} with --port: the device sent no wrench report (a W line" in error[0]
    assert "within 1 s of its first command" in error[0]
    # unpaced, it sent the first configuration's first two frames, waited for the first's report, and released
    # the servos: no loop ran
    assert lines[0] == ["H", "2", "50"] and lines[-1] == ["R"] and [line[:2] for line in lines[1:-1]] == [["F", "0"],
                                                                                                      ["F", "1"]]
