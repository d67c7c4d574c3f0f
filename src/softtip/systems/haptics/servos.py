"""The devices ``softtip haptics render`` drives: the simulated device and a real one on a serial port,
behind one small interface (:class:`ServoDevice`), and an emulated controller that answers the serial
protocol with the device model (:class:`EmulatedController`).

The render loop ticks at 1 kHz; at the first tick of each servo frame (50 Hz) it renders the frame's
position command, resolved to the servos' dead band, and sends it with :meth:`ServoDevice.send`,
and at the frame's end asks :meth:`ServoDevice.frame` what the device did over its ticks.
:class:`SimulatedDevice` answers with the device model (the servos slewing towards the command, the
wrench the platform then applies to the fingertip, read by the sensor under it every tick);
:class:`SerialDevice` writes the command to the device's controller and answers with the wrench
reports the controller sent back since (none from a device without a sensor).

**The serial line protocol** (version 2; ASCII, one line per message, each ended by ``\\n``; 115200
baud, 8N1 by default). Host to device:

``H 2 <rate_hz>``
    Hello, sent once on opening: the protocol's version (2) and the command rate in Hz (``50``).
``F <frame> <angle1_deg> <angle2_deg> <angle3_deg>``
    A frame's position command, sent at the frame's first tick: ``frame`` counts the frames from 0;
    the angles are the three servos' commands in degrees with three decimals, already resolved to
    the servo's dead band and within 0 .. ``angle_max_deg`` (the device file's); servo k winds the
    cable at the device file's k-th attachment angle. The controller sets each servo on receipt.
``R``
    Release, sent when the stream ends or is interrupted: every servo back to 0 degrees (cables
    unwound, the platform off the finger).

Device to host, only from a device with a force sensor under the fingertip (version 1 had no
replies; a device without a sensor sends none, and the host then reports the error "not measured"):

``W <frame> <fx_N> <fy_N> <fz_N> <tx_Nm> <ty_Nm> <tz_Nm>``
    The wrench the sensor under the fingertip read at the end of frame ``frame`` (its last sample
    before the next command took effect), in the sensor's axes, N and N·m, each a decimal number
    (``%.6g``); sent when the frame ends, which for the host is during the next frame. The host holds
    the newest from the frame after the one it read it in, and scores each against the wanted force
    at the last tick of frame ``frame``.

The host reads what arrived once a frame and never waits for it; a line it cannot parse is counted
(``malformed_replies``) and skipped. A command line is at most :data:`LONGEST_LINE` bytes, so 50
lines a second need at least :func:`least_baud` baud (10 bits a byte on the wire); a reply line is
at most :data:`LONGEST_REPLY` bytes: 50 a second need 44,000 baud from the device.

**The user's data driven on the device** (methods A, B+ and A+, :meth:`SerialDevice.collect`): before
the render loop the host drives each configuration of the user's table, presses or adaptive table
with ``F`` lines for ``hold_s`` of frames and averages the ``W`` replies of the hold's last
``window_s`` (the procedure the device model follows, :mod:`.collection`); frame numbers run on from
there into the loop. A device that sends no ``W`` line within :data:`WRENCH_WAIT_S` of the first
command has no sensor to read the user by (:class:`NoWrenchReports`). The personalisations read the
device-mounted sensor's wrench (the DS's, on the platform); the ``W`` lines carry the fingertip's,
so the host turns each into its reaction on the platform, about the platform's centroid in its axes
at the commanded configuration (:func:`~.fingertips.platform_wrench` on the kinematics' pose: the
cables' give moves the platform along its normal only, which changes neither its axes nor, the
contact being frictionless, the torque about its centroid).
"""

from __future__ import annotations

import math
import os
import select
import threading
import time
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import serial

from softtip._core.progress import Task
from softtip.hardware.driver import PortError, open_serial
from softtip.sensors.wrench import WrenchSensorSpec, read_wrenches
from softtip.systems.haptics.collection import Collection, CollectionSettings
from softtip.systems.haptics.device import DeviceSpec, forward_kinematics, quantised, servo_angles
from softtip.systems.haptics.fingertips import Fingertip, loaded_contact, platform_wrench

PROTOCOL_VERSION = 2
DEFAULT_BAUD = 115_200
MAX_FRAMES = 10**7  # frame numbers up to 7 digits: 55 hours at 50 Hz
LONGEST_LINE = len(f"F {MAX_FRAMES - 1} 999.999 999.999 999.999\n")
LONGEST_REPLY = len(f"W {MAX_FRAMES - 1}" + " -1.23457e-05" * 6 + "\n")
WRENCH_REPLY = "W"
BITS_PER_BYTE = 10  # start, 8 data bits, stop
WRENCH_WAIT_S = 1.0  # a device's first wrench report comes a frame (20 ms) after its first command: 50 frames late


class ServoLinkError(ValueError):
    """The serial device cannot be opened or stopped taking commands."""


class NoWrenchReports(ServoLinkError):
    """The device sent no wrench report: it has no sensor to read the user by."""


@dataclass(frozen=True)
class FrameResponse:
    """What the device did over one frame's ticks: the servos' angles (ticks, 3) in rad, the wrench
    the sensor under the fingertip read (ticks, 6) in N and N·m, and where it saturated (ticks, 3);
    NaN where the device does not say. ``reported``: the wrench reports (frame, (6,)) a serial
    device sent back during the frame, None for the device model (its ``wrench`` is read every tick)."""

    angles: np.ndarray
    wrench: np.ndarray
    saturated: np.ndarray
    reported: list[tuple[int, np.ndarray]] | None = None


class ServoDevice(Protocol):
    """What the render loop drives: ``measured_by`` names who reads the rendered wrench; ``replies``
    and ``malformed`` count the device's wrench reports and the lines it sent that were none."""

    measured_by: str
    replies: int
    malformed: int

    def send(self, frame: int, command: np.ndarray) -> None:
        """The frame's position command (rad, (3,)), as the servos resolve it."""

    def frame(self, ticks: int) -> FrameResponse:
        """What the device did over the current frame's ``ticks`` loop ticks."""

    def close(self) -> None:
        """The stream is over: release the finger."""


class SimulatedDevice:
    """The device model on ``fingertip``: the servos from rest, slewing towards each frame's command
    at the loop's rate; the sensor under the fingertip reads each tick (``rng`` None: exact). Each
    :meth:`frame` models the next frame sent and not yet modelled, so the loop may send the next
    command before it asks what the last one did."""

    measured_by, replies, malformed = "device model", 0, 0

    def __init__(self, device: DeviceSpec, fingertip: Fingertip, loop_rate_hz: float,
                 rng: np.random.Generator | None, collection: CollectionSettings = CollectionSettings()):
        self.device, self.fingertip, self.loop_rate_hz = device, fingertip, loop_rate_hz
        self.rng, self.collection = rng, collection
        self.angle = np.zeros(3)
        self.sent: list[np.ndarray] = []  # every frame's command, in order
        self.modelled = 0  # frames modelled so far

    def send(self, frame: int, command: np.ndarray) -> None:
        self.sent.append(np.array(command, dtype=float))

    def frame(self, ticks: int) -> FrameResponse:
        command = self.sent[self.modelled]
        self.modelled += 1
        angles = servo_angles(self.device, self.angle, np.broadcast_to(command, (ticks, 3)), self.loop_rate_hz)
        self.angle = angles[-1]
        _, on_finger = loaded_contact(self.fingertip, self.device, angles)
        wrench, saturated = read_wrenches(on_finger, self.collection.sensor, self.rng)
        return FrameResponse(angles, wrench, saturated[:, :3])

    def close(self) -> None:
        """The model has no finger to release: what it did is already read."""


def least_baud(rate_hz: float) -> int:
    """The lowest baud rate that carries the longest command line ``rate_hz`` times a second."""
    return math.ceil(LONGEST_LINE * BITS_PER_BYTE * rate_hz)


def check_baud(baud: int, rate_hz: float, name: str = "baud") -> int:
    """``baud`` if it is an integer fast enough for the commands, else a one-line refusal."""
    least = least_baud(rate_hz)
    if isinstance(baud, bool) or not isinstance(baud, int) or not least <= baud <= 10_000_000:
        raise ServoLinkError(f"{name} = {baud!r}: expected an integer baud rate from {least} (the {LONGEST_LINE}-byte "
                             f"command lines at {rate_hz:g} Hz) to 10000000")
    return baud


class SerialDevice:
    """The device's controller on a serial port (a device path or a pyserial URL), spoken to in the
    module's line protocol. Opening it sends the hello; a port that cannot be opened, or a baud rate
    too slow for the commands, is refused in one line naming the option (``port_option``, ``baud_option``)."""

    measured_by = "device"

    def __init__(self, port: str, device: DeviceSpec, baud: int = DEFAULT_BAUD, port_option: str = "port",
                 baud_option: str = "baud"):
        rate = device.servo.command_rate_hz
        check_baud(baud, rate, baud_option)
        self.device, self.option, self.port_name = device, port_option, port
        self.held = np.full(6, np.nan)  # the newest wrench report, held from the frame after it came
        self.replies = self.malformed = 0
        self.reported_any = False  # whether any wrench report came, collections' included
        self.first_loop_frame = 0  # the wire's frame number of the loop's frame 0: the collections' frames come first
        self._pending = b""
        try:
            self.port = open_serial(port, baud)
        except PortError as problem:
            raise ServoLinkError(str(problem).replace("port = ", f"{port_option} = ", 1)) from None
        self._write(f"H {PROTOCOL_VERSION} {rate:g}\n")

    def send(self, frame: int, command: np.ndarray) -> None:
        self._command(self.first_loop_frame + frame, command)

    def _command(self, frame: int, command: np.ndarray) -> None:
        if not 0 <= frame < MAX_FRAMES:
            raise ServoLinkError(f"frame = {frame}: expected 0 to {MAX_FRAMES - 1} (the protocol's frame numbers)")
        degrees = np.degrees(command)
        self._write(f"F {frame} {degrees[0]:.3f} {degrees[1]:.3f} {degrees[2]:.3f}\n")

    def frame(self, ticks: int) -> FrameResponse:
        wrench = np.tile(self.held, (ticks, 1))
        # a collection's late reports (frames before the loop's) are not the loop's
        first = self.first_loop_frame
        reported = [(frame - first, wrench) for frame, wrench in self._replies() if frame >= first]
        self.replies += len(reported)
        if reported:
            self.held = reported[-1][1]
        return FrameResponse(np.full((ticks, 3), np.nan), wrench, np.zeros((ticks, 3), bool), reported)

    def collect(self, fingertip: Fingertip, motor_inputs, settings: CollectionSettings, paced: bool = True,
                task: Task | None = None) -> Collection:
        """``motor_inputs`` (entries, 3, rad) driven on the device in order, each held ``settings.hold_s``
        and read as the mean of the ``W`` reports over its last ``settings.window_s`` (whole frames);
        ``paced``: a command every frame period, else each as soon as the report of the frame before
        came (a device model answering at once). The fingertip's wrench as reported, its reaction on
        the platform (``fingertip``'s geometry at the commanded pose, see the module's notes), the
        entries whose reports reached the sensor's range, and the collection's measured time; ``task``
        advances once per configuration. A device that sends no report within :data:`WRENCH_WAIT_S`
        raises :class:`NoWrenchReports`."""
        motor_inputs = np.asarray(motor_inputs, dtype=float).reshape(-1, 3)
        commands = quantised(self.device, motor_inputs)  # the table keeps the inputs asked for, as the model's does
        if not len(commands):
            raise ValueError("motor_inputs: expected at least one configuration to drive")
        rate = self.device.servo.command_rate_hz
        hold = max(1, round(settings.hold_s * rate))
        window = min(hold, max(1, round(settings.window_s * rate)))
        first = self.first_loop_frame
        sums, counts = np.zeros((len(commands), 6)), np.zeros(len(commands), int)
        saturated = np.zeros(len(commands), bool)

        def take(reports) -> None:
            for frame, wrench in reports:
                entry, k = divmod(frame - first, hold)
                if 0 <= entry < len(commands) and k >= hold - window:
                    sums[entry] += wrench
                    counts[entry] += 1
                    saturated[entry] |= at_range_end(wrench, settings.sensor)

        started = period_start = time.monotonic()
        for entry, command in enumerate(commands):
            for k in range(hold):
                frame = first + entry * hold + k
                self._command(frame, command)
                take(self._reports_until(frame - 1, paced, started, period_start + 1 / rate))
                period_start += 1 / rate
            if task is not None:
                task.advance()
        # the last window's reports: the device answers a frame when it ends, so the platform is released
        # a frame at a time until they are in (a device model answers a frame at the next command)
        frame, deadline = first + len(commands) * hold, time.monotonic() + WRENCH_WAIT_S
        while counts[-1] < window and time.monotonic() < deadline:
            self._command(frame, np.zeros(3))
            take(self._reports_until(frame - 1, paced, started, period_start + 1 / rate))
            period_start, frame = period_start + 1 / rate, frame + 1
        self.first_loop_frame = frame
        if not counts.all():
            missing = int(np.flatnonzero(counts == 0)[0])
            raise ServoLinkError(f"{self.option} = {self.port_name!r}: the device sent no wrench report over the "
                                 f"last {window} frames of configuration {missing} (frames {first + missing * hold} "
                                 f"to {first + (missing + 1) * hold - 1})")
        finger = sums / counts[:, None]
        pose = forward_kinematics(self.device, commands)
        return Collection(motor_inputs, finger, platform_wrench(fingertip, self.device, pose, finger), saturated,
                          time.monotonic() - started)

    def _reports_until(self, frame: int, paced: bool, started: float,
                       period_end: float) -> list[tuple[int, np.ndarray]]:
        """The reports that arrived: paced, once the frame's period ``period_end`` (monotonic) is over;
        unpaced, as soon as the report of ``frame`` came. None at all within :data:`WRENCH_WAIT_S` of
        ``started`` raises :class:`NoWrenchReports`; an unpaced wait as long for ``frame``'s report,
        :class:`ServoLinkError`."""
        reports, waited_from = [], time.monotonic()
        while True:
            reports += self._replies()
            now = time.monotonic()
            if not self.reported_any and now - started > WRENCH_WAIT_S:
                raise NoWrenchReports(
                    f"the device sent no wrench report (a W line of protocol version {PROTOCOL_VERSION}) within "
                    f"{WRENCH_WAIT_S:g} s of its first command: it has no sensor under the fingertip, or speaks "
                    "version 1")
            if paced:
                if now >= period_end:
                    return reports
                time.sleep(min(period_end - now, 0.002))
            else:
                if frame < self.first_loop_frame or any(f >= frame for f, _ in reports):
                    return reports
                if now - waited_from > WRENCH_WAIT_S:
                    raise ServoLinkError(f"{self.option} = {self.port_name!r}: the device sent no wrench report for "
                                         f"frame {frame} within {WRENCH_WAIT_S:g} s")
                time.sleep(0.0005)

    def _replies(self) -> list[tuple[int, np.ndarray]]:
        """The wrench reports that arrived since the last call, without waiting."""
        try:
            waiting = self.port.in_waiting
            data = self.port.read(waiting) if waiting else b""
        except (serial.SerialException, OSError) as problem:
            raise ServoLinkError(f"{self.option} = {self.port_name!r}: the device stopped answering "
                                 f"({' '.join(str(problem).split())})") from None
        *lines, self._pending = (self._pending + data).split(b"\n")
        if len(self._pending) > LONGEST_REPLY:  # no line end in sight: noise, not a reply
            self._pending, self.malformed = b"", self.malformed + 1
        reported = []
        for line in lines:
            parsed = parse_reply(line)
            if parsed is None:
                self.malformed += line.strip() != b""
            else:
                reported.append(parsed)
        self.reported_any |= bool(reported)
        return reported

    def close(self) -> None:
        if self.port is None:
            return
        try:
            self._write("R\n")
            self.port.flush()
        finally:
            self.port.close()
            self.port = None

    def _write(self, line: str) -> None:
        try:
            self.port.write(line.encode("ascii"))
        except (serial.SerialException, OSError) as problem:
            raise ServoLinkError(f"{self.option} = {self.port_name!r}: the device stopped taking commands "
                                 f"({' '.join(str(problem).split())})") from None


def at_range_end(wrench: np.ndarray, sensor: WrenchSensorSpec) -> bool:
    """Whether a reported wrench (6,) reached ``sensor``'s range on any axis: it read its range's end."""
    lowest = np.concatenate([sensor.force.lowest, sensor.torque.lowest])
    highest = np.concatenate([sensor.force.highest, sensor.torque.highest])
    return bool(np.any((wrench <= lowest) | (wrench >= highest)))


def parse_reply(line: bytes) -> tuple[int, np.ndarray] | None:
    """A ``W`` line's frame and finite wrench (6,), or None for anything else."""
    words = line.decode("ascii", "replace").split()
    if len(words) != 8 or words[0] != WRENCH_REPLY or not words[1].isdigit():
        return None
    try:
        wrench = np.array([float(word) for word in words[2:]])
    except ValueError:
        return None
    return (int(words[1]), wrench) if np.all(np.isfinite(wrench)) else None


def wrench_reply(frame: int, wrench: np.ndarray) -> str:
    """The ``W`` line reporting ``wrench`` (6,: N, N·m) read at the end of ``frame``."""
    return f"{WRENCH_REPLY} {frame} " + " ".join(f"{value:.6g}" for value in wrench) + "\n"


class EmulatedController:
    """A device controller with a sensor under the fingertip, emulated on the device end of a serial
    link (``link``: a file descriptor, the master of a pty pair whose slave the host opens): it takes
    the protocol's lines and moves the device model (:class:`SimulatedDevice`) accordingly, a frame of
    ``loop_rate_hz / command_rate_hz`` ticks per command, and answers each frame's end (the next ``F``
    or the ``R``) with the model's wrench at its last tick in a ``W`` line. Runs in a thread until
    the release, the host's end closed or :meth:`stop`; ``lines`` keeps every line it took."""

    def __init__(self, link: int, device: DeviceSpec, fingertip: Fingertip, loop_rate_hz: float,
                 rng: np.random.Generator | None) -> None:
        self.link, self.model = link, SimulatedDevice(device, fingertip, loop_rate_hz, rng)
        self.ticks = int(round(loop_rate_hz / device.servo.command_rate_hz))
        self.lines: list[str] = []
        self.replied: list[tuple[int, np.ndarray]] = []
        self._frame: int | None = None
        self._stopping = threading.Event()
        self.thread = threading.Thread(target=self._serve, name="emulated-haptic-device", daemon=True)
        self.thread.start()

    def stop(self, timeout_s: float = 10.0) -> None:
        self._stopping.set()
        self.thread.join(timeout_s)

    def _serve(self) -> None:
        pending = b""
        while not self._stopping.is_set():
            ready, _, _ = select.select([self.link], [], [], 0.05)
            if not ready:
                continue
            try:
                data = os.read(self.link, 4096)
            except OSError:  # the host closed its end
                return
            *lines, pending = (pending + data).split(b"\n")
            for line in lines:
                text = line.decode("ascii").strip()
                self.lines.append(text)
                words = text.split()
                if words and words[0] in ("F", "R"):
                    self._end_frame()
                if words and words[0] == "F":
                    self._frame = int(words[1])
                    self.model.send(self._frame, np.radians([float(word) for word in words[2:5]]))
                elif words and words[0] == "R":
                    self.model.close()
                    return

    def _end_frame(self) -> None:
        """The current frame's ticks on the model, and its last reading sent back."""
        if self._frame is None:
            return
        wrench = self.model.frame(self.ticks).wrench[-1]
        self.replied.append((self._frame, wrench))
        os.write(self.link, wrench_reply(self._frame, wrench).encode("ascii"))
