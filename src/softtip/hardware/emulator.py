"""The fingertip firmware emulated on a pseudo-terminal, with fault injection.

Emulator opens a pty and behaves like a board running the firmware: it answers
the host commands exactly as the firmware does (but identifies itself as
"softtip-emulator/1"), and while streaming sends one DATA frame per period with
the field of source(t_s) -> (chips, 3) uT converted to register words by the
MLX90393 model. Any program that can open a serial port can use .port.

Faults (FaultPlan) apply to DATA frames only, every Nth generated frame:
  * corrupt: one byte after the header is XORed with a random non-zero value
    (a CRC-16 detects every single-byte error, so the frame is always rejected);
  * drop byte: one random byte of the frame is left out;
  * stall: the frame is written in two parts with a pause in between;
  * chip error: one chip of the frame reports CHIP_ERROR with zero words;
  * disconnect: after the frame, the emulator waits until the host has read
    everything written, closes the pty and, disconnect_ms later, opens a new
    one. A new pty has a new device path, so .port is a symbolic link in a
    private directory that is re-pointed at each new pty: a driver that reopens
    .port finds the new device, as it would find a replugged board's stable
    name. By default the emulated board stays powered (a native-USB board on
    its own supply): it keeps acquiring, and the frames it acquires until the
    host's first command on the new link are logged NOT_SENT. With
    reboot_on_disconnect the board loses power instead: it comes back with its
    power-on settings, stopped, sequence numbers from 0 and the BOOT flag.

log records every generated DATA frame in order with its session (power-on
count), sequence number and FrameFate, so that tests can account exactly for
what the host received.
"""

from __future__ import annotations

import contextlib
import fcntl
import logging
import os
import select
import shutil
import struct
import tempfile
import termios
import threading
import time
import tty
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum

import numpy as np

from softtip._core.config import Flag, checked, instance, integer, number
from softtip._core.threads import BackgroundThread
from softtip._core.units import UT_PER_T
from softtip.hardware.driver import SensorSettings, temperature_to_raw
from softtip.hardware.protocol import (BOOT_FRAMES, HEADER_SIZE, MAX_CHIPS, Ack, ChipStatus, Command, CommandError,
                                       ErrorCode, ErrorReply, Frame, FrameDecoder, FrameType, Identity, LinkEnd,
                                       checked_rate_hz, decode_configure, decode_set_rate, encode_frame)
from softtip.sensors.mlx90393 import MLX90393, MLX90393Settings

logger = logging.getLogger(__name__)

EMULATOR_NAME = "softtip-emulator/1"
_UINT16_MODULUS = 1 << 16
_UINT32_MODULUS = 1 << 32
_IDLE_POLL_S = 0.05
_WRITE_TIMEOUT_S = 0.05
_DRAIN_TIMEOUT_S = 0.5
_DRAIN_SETTLE_S = 0.01
_COMMANDS = frozenset(
    {FrameType.IDENTIFY, FrameType.CONFIGURE, FrameType.START, FrameType.STOP, FrameType.SET_RATE}
)


class FrameFate(Enum):
    SENT = "sent"  # written intact
    CORRUPTED = "corrupted"  # one byte altered
    TRUNCATED = "truncated"  # one or more bytes missing
    NOT_SENT = "not sent"  # acquired while no host was connected, or the host stopped reading


@dataclass(frozen=True)
class LoggedFrame:
    session: int
    seq: int
    fate: FrameFate


Every = integer(0, expected="an integer >= 0 (0: never)")
DurationMs = number("a duration >= 0 in ms", ge=0)


@dataclass(frozen=True)
class FaultPlan:
    """Which generated DATA frames are damaged: every Nth one (0 disables a fault)."""

    corrupt_every: int = 0
    drop_byte_every: int = 0
    stall_every: int = 0
    stall_ms: float = 0.0
    chip_error_every: int = 0
    disconnect_every: int = 0
    disconnect_ms: float = 0.0
    reboot_on_disconnect: bool = False
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("corrupt_every", "drop_byte_every", "stall_every", "chip_error_every", "disconnect_every"):
            checked(Every, f"faults.{name}", getattr(self, name))
        for name in ("stall_ms", "disconnect_ms"):
            checked(DurationMs, f"faults.{name}", getattr(self, name))
        checked(Flag, "faults.reboot_on_disconnect", self.reboot_on_disconnect)

    @staticmethod
    def hits(every: int, index: int) -> bool:
        """Whether the frame with 0-based generation index is an Nth frame."""
        return every > 0 and (index + 1) % every == 0


Faults = instance(FaultPlan, "a FaultPlan")
ChipCount = integer(1, MAX_CHIPS)


class Emulator(LinkEnd):
    """A fingertip board on a pseudo-terminal (see the module docstring).

    source(t_s) returns the field in uT, shape (chips, 3), at device time t_s
    (seconds since the emulated power-on). settings and rate_hz are the board's
    power-on configuration; the host changes them with CONFIGURE and SET_RATE.
    noise adds the sensor model's noise (rng seeded with seed); temperature_C is
    reported when the settings ask for the temperature.
    """

    def __init__(
        self,
        source: Callable[[float], np.ndarray],
        rate_hz: int = 50,
        chips: int = 4,
        settings: MLX90393Settings | None = None,
        faults: FaultPlan | None = None,
        *,
        noise: bool = True,
        seed: int | None = None,
        temperature_C: float = 25.0,
    ) -> None:
        if not callable(source):
            raise ValueError(f"source = {source!r}: expected a callable t_s -> field_uT (chips, 3)")
        chips = checked(ChipCount, "chips", chips)
        settings = checked(SensorSettings, "settings", MLX90393Settings() if settings is None else settings)
        faults = checked(Faults, "faults", FaultPlan() if faults is None else faults)
        self._source = source
        self._chips = chips
        self._power_on_settings = settings
        self._power_on_rate_hz = checked_rate_hz(rate_hz)
        self._faults = faults
        self._noise = bool(noise)
        self._noise_rng = np.random.default_rng(seed)
        self._fault_rng = np.random.default_rng(faults.seed)
        self._temperature_raw = temperature_to_raw(np.full(chips, float(temperature_C)))

        self._lock = threading.Lock()  # guards the logs
        self._log: list[LoggedFrame] = []
        self._received: list[tuple[int, Command]] = []
        self._worker = BackgroundThread("fingertip-emulator")
        self._error: BaseException | None = None
        self._directory: str | None = None
        self._master_fd: int | None = None
        self._slave_fd: int | None = None
        self._link_down_until: float | None = None
        self._frame_index = 0
        self._session = -1
        self._power_on()

    # ---------------------------------------------------------------- life cycle

    def start(self) -> Emulator:
        if self._worker.running:
            raise RuntimeError("emulator already started")
        self._directory = tempfile.mkdtemp(prefix="softtip-emulator-")
        self._open_pty()
        self._boot_time = self._next_frame = time.perf_counter()
        self._worker.start(self._run)
        return self

    def close(self) -> None:
        """Stop the emulator and remove its pty; re-raises a failure of the source."""
        if not self._worker.stop():
            return
        self._close_pty()
        if self._directory is not None:
            shutil.rmtree(self._directory, ignore_errors=True)
            self._directory = None
        if self._error is not None:
            raise RuntimeError(f"emulator stopped: {self._error}") from self._error

    def __enter__(self) -> Emulator:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # ----------------------------------------------------------------- state

    @property
    def port(self) -> str:
        """Stable path of the emulated serial device (a symlink to the current pty)."""
        if self._directory is None:
            raise RuntimeError("emulator not started")
        return os.path.join(self._directory, "fingertip")

    @property
    def log(self) -> list[LoggedFrame]:
        with self._lock:
            return list(self._log)

    @property
    def received(self) -> list[tuple[int, Command]]:
        """Every host command received, with the session it arrived in."""
        with self._lock:
            return list(self._received)

    @property
    def streaming(self) -> bool:
        return self._streaming

    @property
    def session(self) -> int:
        return self._session

    # ------------------------------------------------------------------ internals

    def _power_on(self) -> None:
        self._session += 1
        self._settings = self._power_on_settings
        self._model = MLX90393(self._settings)
        self._rate_hz = self._power_on_rate_hz
        self._period_s = self._period_of(self._rate_hz)
        self._streaming = False
        self._seq = 0
        self._boot_frames_left = BOOT_FRAMES
        self._boot_time = time.perf_counter()
        self._next_frame = self._boot_time
        self._host_present = False
        self._decoder = FrameDecoder()

    @staticmethod
    def _period_of(rate_hz: int) -> float:
        # The firmware keeps the period in whole microseconds.
        return (1_000_000 // rate_hz) * 1e-6

    def _open_pty(self) -> None:
        master_fd, slave_fd = os.openpty()
        tty.setraw(slave_fd)
        os.set_blocking(master_fd, False)
        # The emulator keeps the slave open: the pty then survives the host closing
        # and reopening its side, and its input queue can be measured (drain).
        self._master_fd, self._slave_fd = master_fd, slave_fd
        temporary = self.port + ".new"
        os.symlink(os.ttyname(slave_fd), temporary)
        os.replace(temporary, self.port)

    def _close_pty(self) -> None:
        if self._master_fd is None:
            return
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.port)
        os.close(self._master_fd)
        os.close(self._slave_fd)
        self._master_fd = self._slave_fd = None

    def _run(self) -> None:
        try:
            while not self._worker.closing.is_set():
                now = time.perf_counter()
                if self._link_down_until is not None:
                    self._while_link_down(now)
                    continue
                timeout = _IDLE_POLL_S
                if self._streaming:
                    timeout = min(timeout, max(0.0, self._next_frame - now))
                readable, _, _ = select.select([self._master_fd], [], [], timeout)
                if readable:
                    self._receive()
                if self._streaming and time.perf_counter() >= self._next_frame:
                    self._acquire_and_send()
        except Exception as error:  # the error is re-raised by close()
            logger.exception("emulator stopped")
            self._error = error

    def _while_link_down(self, now: float) -> None:
        if now >= self._link_down_until:
            self._link_down_until = None
            if self._faults.reboot_on_disconnect:
                self._power_on()
            self._host_present = False
            self._open_pty()
            return
        wake = self._link_down_until
        if self._streaming:
            wake = min(wake, self._next_frame)
            if now >= self._next_frame:
                self._acquire_and_send()
                return
        self._worker.closing.wait(max(0.0, wake - now))

    def _receive(self) -> None:
        try:
            data = os.read(self._master_fd, 4096)
        except BlockingIOError:
            return
        for message in self._decoder.feed(data):
            if isinstance(message, Command):
                self._host_present = True
                with self._lock:
                    self._received.append((self._session, message))
                self._reply(self._execute(message))

    def _execute(self, command: Command) -> Identity | Ack | ErrorReply:
        """Carry out a host command as the firmware does and return the reply."""

        def error(code: ErrorCode) -> ErrorReply:
            return ErrorReply(command.code, command.tag, code, 0)

        code = command.code
        if code not in _COMMANDS:
            return error(ErrorCode.UNKNOWN_COMMAND)
        if code in (FrameType.IDENTIFY, FrameType.START, FrameType.STOP) and command.args:
            return error(ErrorCode.BAD_LENGTH)
        if code == FrameType.IDENTIFY:
            return Identity(command.tag, self._chips, EMULATOR_NAME)
        try:
            if code == FrameType.CONFIGURE:
                self._settings = decode_configure(command)
                self._model = MLX90393(self._settings)
            elif code == FrameType.SET_RATE:
                self._rate_hz = decode_set_rate(command)
                self._period_s = self._period_of(self._rate_hz)
            elif code == FrameType.START:
                if not self._streaming:
                    self._next_frame = time.perf_counter()
                self._streaming = True
            elif code == FrameType.STOP:
                self._streaming = False
        except CommandError as refused:
            return error(refused.code)
        return Ack(command.code, command.tag)

    def _reply(self, reply: Identity | Ack | ErrorReply) -> None:
        self._write(encode_frame(reply))

    def _write(self, data: bytes) -> int:
        """Write to the pty; returns the bytes written before the host stopped reading."""
        written = 0
        deadline = time.perf_counter() + _WRITE_TIMEOUT_S
        while written < len(data):
            remaining = deadline - time.perf_counter()
            _, writable, _ = select.select([], [self._master_fd], [], max(0.0, remaining))
            if not writable:
                break
            try:
                written += os.write(self._master_fd, data[written:])
            except BlockingIOError:
                continue
        return written

    def _acquire(self, index: int) -> Frame:
        now = time.perf_counter()
        field_uT = np.asarray(self._source(now - self._boot_time), dtype=np.float64)
        if field_uT.shape != (self._chips, 3):
            raise ValueError(
                f"source returned shape {field_uT.shape}: expected ({self._chips}, 3) in uT"
            )
        raw = self._model.to_counts(field_uT / UT_PER_T, rng=self._noise_rng, noise=self._noise)
        status = np.zeros(self._chips, dtype=np.uint8)
        every = self._faults.chip_error_every
        if FaultPlan.hits(every, index):
            failed = (index // every) % self._chips
            status[failed] = ChipStatus.CHIP_ERROR
            raw[failed] = 0  # the firmware skips RM for a chip whose SM failed
        device_time_us = int((now - self._boot_time) * 1e6) % _UINT32_MODULUS
        frame = Frame(
            seq=self._seq,
            device_time_us=device_time_us,
            status=status,
            raw=raw,
            temperature_raw=self._temperature_raw if self._settings.temperature else None,
            boot=self._boot_frames_left > 0,
        )
        self._seq = (self._seq + 1) % _UINT16_MODULUS
        self._boot_frames_left = max(0, self._boot_frames_left - 1)
        return frame

    def _acquire_and_send(self) -> None:
        index = self._frame_index
        self._frame_index += 1
        frame = self._acquire(index)
        self._next_frame += self._period_s
        if self._link_down_until is not None or not self._host_present:
            fate = FrameFate.NOT_SENT
        else:
            fate = self._send(encode_frame(frame), index)
        with self._lock:
            self._log.append(LoggedFrame(self._session, frame.seq, fate))
        # Behind schedule: restart it from now rather than send a burst (as the firmware).
        now = time.perf_counter()
        if now > self._next_frame:
            self._next_frame = now
        if self._link_down_until is None and FaultPlan.hits(self._faults.disconnect_every, index):
            self._disconnect()

    def _send(self, frame_bytes: bytes, index: int) -> FrameFate:
        faults, rng = self._faults, self._fault_rng
        data = bytearray(frame_bytes)
        fate = FrameFate.SENT
        if FaultPlan.hits(faults.corrupt_every, index):
            data[int(rng.integers(HEADER_SIZE, len(data)))] ^= int(rng.integers(1, 256))
            fate = FrameFate.CORRUPTED
        if FaultPlan.hits(faults.drop_byte_every, index):
            del data[int(rng.integers(0, len(data)))]
            fate = FrameFate.TRUNCATED
        if FaultPlan.hits(faults.stall_every, index):
            split = int(rng.integers(1, len(data)))
            written = self._write(bytes(data[:split]))
            self._worker.closing.wait(faults.stall_ms * 1e-3)
            if written == split:
                written += self._write(bytes(data[split:]))
        else:
            written = self._write(bytes(data))
        if written == 0:
            return FrameFate.NOT_SENT
        if written < len(data):
            return FrameFate.TRUNCATED
        return fate

    def _unread_bytes(self) -> int:
        buffer = bytearray(4)
        fcntl.ioctl(self._slave_fd, termios.FIONREAD, buffer)
        return struct.unpack("i", buffer)[0]

    def _drain(self) -> None:
        """Wait until the host has read every byte written, or _DRAIN_TIMEOUT_S."""
        deadline = time.perf_counter() + _DRAIN_TIMEOUT_S
        # Two empty readings a settle time apart: bytes can be in flight inside the pty.
        empty_readings = 0
        while empty_readings < 2 and time.perf_counter() < deadline:
            empty_readings = empty_readings + 1 if self._unread_bytes() == 0 else 0
            self._worker.closing.wait(_DRAIN_SETTLE_S)

    def _disconnect(self) -> None:
        self._drain()
        self._close_pty()
        if self._faults.reboot_on_disconnect:
            self._streaming = False  # powered off until the link comes back
        self._link_down_until = time.perf_counter() + self._faults.disconnect_ms * 1e-3
