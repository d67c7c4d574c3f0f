"""The devices ``softtip haptics render`` drives: the simulated device and a real one on a serial port,
behind one small interface (:class:`ServoDevice`).

The render loop renders every 1 kHz tick; at the first tick of each servo frame (50 Hz) it sends the
frame's position command, resolved to the servos' dead band, with :meth:`ServoDevice.send`, and at
the frame's end asks :meth:`ServoDevice.frame` what the device did over its ticks.
:class:`SimulatedDevice` answers with the device model (the servos slewing towards the command, the
wrench the platform then applies to the fingertip, read by the sensor under it); :class:`SerialDevice`
writes the command to the device's controller and answers nothing (a serial device reports nothing
back: the loop then has no rendered wrench to compare).

**The serial line protocol** (host to device only, ASCII, one line per message, each ended by
``\\n``; 115200 baud, 8N1 by default):

``H 1 <rate_hz>``
    Hello, sent once on opening: the protocol's version (1) and the command rate in Hz (``50``).
``F <frame> <angle1_deg> <angle2_deg> <angle3_deg>``
    A frame's position command, sent at the frame's first tick: ``frame`` counts the frames from 0;
    the angles are the three servos' commands in degrees with three decimals, already resolved to
    the servo's dead band and within 0 .. ``angle_max_deg`` (the device file's); servo k winds the
    cable at the device file's k-th attachment angle. The controller sets each servo on receipt.
``R``
    Release, sent when the stream ends or is interrupted: every servo back to 0 degrees (cables
    unwound, the platform off the finger).

A line is at most :data:`LONGEST_LINE` bytes, so 50 lines a second need at least
:func:`least_baud` baud (10 bits a byte on the wire).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import serial

from softtip.hardware.driver import PortError, open_serial
from softtip.sensors.wrench import read_wrenches
from softtip.systems.haptics.collection import CollectionSettings
from softtip.systems.haptics.device import DeviceSpec, servo_angles
from softtip.systems.haptics.fingertips import Fingertip, loaded_contact

PROTOCOL_VERSION = 1
DEFAULT_BAUD = 115_200
MAX_FRAMES = 10**7  # frame numbers up to 7 digits: 55 hours at 50 Hz
LONGEST_LINE = len(f"F {MAX_FRAMES - 1} 999.999 999.999 999.999\n")
BITS_PER_BYTE = 10  # start, 8 data bits, stop


class ServoLinkError(ValueError):
    """The serial device cannot be opened or stopped taking commands."""


@dataclass(frozen=True)
class FrameResponse:
    """What the device did over one frame's ticks: the servos' angles (ticks, 3) in rad, the wrench
    the sensor under the fingertip read (ticks, 6) in N and N·m, and where it saturated (ticks, 3)."""

    angles: np.ndarray
    wrench: np.ndarray
    saturated: np.ndarray


class ServoDevice(Protocol):
    """What the render loop drives."""

    def send(self, frame: int, command: np.ndarray) -> None:
        """The frame's position command (rad, (3,)), as the servos resolve it."""

    def frame(self, ticks: int) -> FrameResponse | None:
        """What the device did over the current frame's ``ticks`` loop ticks; None if it reports nothing."""

    def close(self) -> None:
        """The stream is over: release the finger."""


class SimulatedDevice:
    """The device model on ``fingertip``: the servos from rest, slewing towards each frame's command
    at the loop's rate; the sensor under the fingertip reads each tick (``rng`` None: exact)."""

    def __init__(self, device: DeviceSpec, fingertip: Fingertip, loop_rate_hz: float,
                 rng: np.random.Generator | None, collection: CollectionSettings = CollectionSettings()):
        self.device, self.fingertip, self.loop_rate_hz = device, fingertip, loop_rate_hz
        self.rng, self.collection = rng, collection
        self.angle = np.zeros(3)
        self.command = np.zeros(3)
        self.sent: list[np.ndarray] = []  # every frame's command, in order

    def send(self, frame: int, command: np.ndarray) -> None:
        self.command = np.array(command, dtype=float)
        self.sent.append(self.command)

    def frame(self, ticks: int) -> FrameResponse:
        angles = servo_angles(self.device, self.angle, np.broadcast_to(self.command, (ticks, 3)), self.loop_rate_hz)
        self.angle = angles[-1]
        _, on_finger = loaded_contact(self.fingertip, self.device, angles)
        wrench, saturated = read_wrenches(on_finger, self.collection.sensor, self.rng)
        return FrameResponse(angles, wrench, saturated[:, :3])

    def close(self) -> None:
        self.command = np.zeros(3)


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

    def __init__(self, port: str, device: DeviceSpec, baud: int = DEFAULT_BAUD, port_option: str = "port",
                 baud_option: str = "baud"):
        rate = device.servo.command_rate_hz
        check_baud(baud, rate, baud_option)
        self.option, self.port_name = port_option, port
        try:
            self.port = open_serial(port, baud)
        except PortError as problem:
            raise ServoLinkError(str(problem).replace("port = ", f"{port_option} = ", 1)) from None
        self._write(f"H {PROTOCOL_VERSION} {rate:g}\n")

    def send(self, frame: int, command: np.ndarray) -> None:
        if not 0 <= frame < MAX_FRAMES:
            raise ServoLinkError(f"frame = {frame}: expected 0 to {MAX_FRAMES - 1} (the protocol's frame numbers)")
        degrees = np.degrees(command)
        self._write(f"F {frame} {degrees[0]:.3f} {degrees[1]:.3f} {degrees[2]:.3f}\n")

    def frame(self, ticks: int) -> None:
        return None

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
