"""Host driver for the softtip fingertip firmware over a serial port.

A background thread reads the port, decodes frames, stamps each with the host
clock, counts frames lost in transit from sequence-number gaps, converts the raw
register words to microtesla with the MLX90393 model and hands Samples to a
bounded queue and/or a callback. When the port fails (unplugged cable, board
reset) the thread closes it, logs "disconnected", retries opening it every
reconnect_interval_s, logs "reconnected" and sends the configuration, the rate
and START again, so a board that rebooted with power-on settings resumes the
stream it was asked for.
"""

from __future__ import annotations

import contextlib
import logging
import os
import queue
import select
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import serial
from numpy.typing import ArrayLike

from softtip._core.config import PositiveInteger, PositiveNumber, checked, instance, integer
from softtip.hardware.protocol import (CHIP_FAULTS, Ack, Command, ErrorCode, ErrorReply, Frame, FrameDecoder, FrameType,
                                       Identity, LinkEnd, checked_rate_hz, configure_command, encode_frame,
                                       identify_command, set_rate_command, start_command, stop_command)
from softtip.sensors.mlx90393 import MLX90393, MLX90393Settings

logger = logging.getLogger(__name__)

# Datasheet: the temperature word is 46244 at 25 degC (typical; the chip's own
# reference is in register 0x24) and changes by 45.2 counts per kelvin.
TEMPERATURE_REFERENCE_COUNTS = 46244
TEMPERATURE_REFERENCE_C = 25.0
TEMPERATURE_COUNTS_PER_K = 45.2

_UINT16_MODULUS = 1 << 16
_UINT32_MODULUS = 1 << 32
_READ_TIMEOUT_S = 0.05
_WRITE_TIMEOUT_S = 1.0


def temperature_C(temperature_raw: ArrayLike) -> np.ndarray:
    """Chip temperature in degC from raw temperature words (datasheet typical reference)."""
    raw = np.asarray(temperature_raw, dtype=np.float64)
    return TEMPERATURE_REFERENCE_C + (raw - TEMPERATURE_REFERENCE_COUNTS) / TEMPERATURE_COUNTS_PER_K


def temperature_to_raw(temperature_c: ArrayLike) -> np.ndarray:
    """Raw temperature words (uint16) for temperatures in degC: inverse of temperature_C."""
    excess_K = np.asarray(temperature_c, dtype=np.float64) - TEMPERATURE_REFERENCE_C
    counts = TEMPERATURE_REFERENCE_COUNTS + excess_K * TEMPERATURE_COUNTS_PER_K
    return np.clip(np.rint(counts), 0, _UINT16_MODULUS - 1).astype(np.uint16)


# --------------------------------------------------------------------------
# Errors
# --------------------------------------------------------------------------


class PortError(ValueError):
    """The serial port cannot be opened (wrong name, missing device, no permission)."""


class DeviceError(RuntimeError):
    """The device refused a command; code is the protocol ErrorCode."""

    def __init__(self, message: str, code: int, detail: int) -> None:
        super().__init__(message)
        self.code = code
        self.detail = detail


class DeviceTimeout(TimeoutError):
    """The device did not reply in time."""


class DeviceDisconnected(ConnectionError):
    """The serial link is down (the driver is reconnecting or closed)."""


def _read_available(port: serial.SerialBase) -> bytes:
    """What has arrived, waiting up to the port's timeout for the first byte.

    A POSIX port is read with one select and one read per wake-up (pyserial's read costs an
    ioctl, a select and a read per call, and splits a frame that is still arriving); other
    ports (pyserial URLs) go through pyserial."""
    fileno = getattr(port, "fileno", None)
    if os.name != "posix" or fileno is None or not isinstance(port, serial.Serial):
        return port.read(max(1, port.in_waiting))
    fd = fileno()
    ready, _, _ = select.select([fd], [], [], port.timeout)
    if not ready:
        return b""
    data = os.read(fd, 4096)
    if not data:  # readable but empty: the device went away
        raise serial.SerialException("device reports readiness to read but returned no data")
    return data


def open_serial(port: str, baudrate: int, read_timeout_s: float = _READ_TIMEOUT_S) -> serial.SerialBase:
    """Open a serial device path or pyserial URL; PortError with a one-line reason if it fails."""
    if not isinstance(port, str) or not port.strip():
        raise PortError(f"port = {port!r}: expected a serial device path or a pyserial URL")
    try:
        return serial.serial_for_url(
            port, baudrate=baudrate, timeout=read_timeout_s, write_timeout=_WRITE_TIMEOUT_S
        )
    except (serial.SerialException, OSError, ValueError) as error:
        errno = getattr(error, "errno", None)
        reason = os.strerror(errno) if errno else " ".join(str(error).split())
        raise PortError(f"port = {port!r}: cannot open: {reason}") from None


# --------------------------------------------------------------------------
# Samples and counters
# --------------------------------------------------------------------------


class Sample(NamedTuple):
    """One reading of every chip.

    seq: the frame's sequence number (uint16, wraps) or a running record count
      for streams without one. device_time_s: the device clock at the trigger,
      unwrapped, or None when the stream has no device clock. host_time_s:
      time.perf_counter_ns() / 1e9 when the bytes completing the frame arrived.
    reading: (n, 3) what each chip reads (flux density in µT for the fingertip's Hall chips), NaN for
      chips whose status reports a fault.
    status: (n,) ChipStatus bytes; chip_ok: (n,) no fault bit set;
    saturated: (n, 3) axes at the limit of their output range.
    temperature_C: (n,) chip temperatures in degC, or None.
    """

    seq: int
    device_time_s: float | None
    host_time_s: float
    reading: np.ndarray
    status: np.ndarray
    chip_ok: np.ndarray
    saturated: np.ndarray
    temperature_C: np.ndarray | None = None

    # a tuple's equality would compare the arrays element-wise: identity, as for any object
    __eq__ = object.__eq__
    __ne__ = object.__ne__
    __hash__ = object.__hash__


@dataclass(frozen=True)
class DriverStats:
    """Counters since the driver was opened.

    frames: samples delivered; dropped: frames lost in transit (sequence gaps);
    crc_errors, malformed, bytes_discarded: from the frame decoder;
    reconnects: successful reopenings of the port; queue_overflows: samples
    pushed out of the full queue by newer ones.
    """

    frames: int
    dropped: int
    crc_errors: int
    malformed: int
    bytes_discarded: int
    reconnects: int
    queue_overflows: int


class StreamTracker:
    """Frames lost between consecutive frames, and the unwrapped device clock.

    The sequence number counts the device's frames since it powered on, modulo
    2^16; the first BOOT_FRAMES frames after power-on carry the BOOT flag. A
    BOOT frame that does not continue a run of BOOT frames starts a new device
    session: the frames of that session before it (its seq) are counted as lost,
    and the device clock restarts. Frames lost at the end of the previous session
    cannot be known and are not counted.
    """

    def __init__(self) -> None:
        self._last_seq: int | None = None
        self._last_boot = False
        self._last_time_us = 0
        self._time_offset_us = 0

    def update(self, frame: Frame) -> tuple[int, float]:
        """(frames lost just before this one, device time in s) for the next frame."""
        new_session = frame.boot and not (
            self._last_boot and self._last_seq is not None and frame.seq > self._last_seq
        )
        if new_session:
            lost = frame.seq
            self._time_offset_us = 0
        elif self._last_seq is None:
            lost = 0
        else:
            lost = (frame.seq - self._last_seq - 1) % _UINT16_MODULUS
            if frame.device_time_us < self._last_time_us:
                self._time_offset_us += _UINT32_MODULUS
        self._last_seq = frame.seq
        self._last_boot = frame.boot
        self._last_time_us = frame.device_time_us
        return lost, (self._time_offset_us + frame.device_time_us) * 1e-6


class _PendingReply:
    """A command waiting for its reply; on_applied runs in the reader thread."""

    def __init__(self, command: Command, on_applied: Callable[[], None] | None) -> None:
        self.command = command
        self.on_applied = on_applied
        self.reply: Identity | Ack | ErrorReply | None = None
        self.done = threading.Event()


# --------------------------------------------------------------------------
# Driver
# --------------------------------------------------------------------------


SensorSettings = instance(MLX90393Settings)
QueueSize = integer(0)


class FingertipDriver(LinkEnd):
    """Streams Samples from a fingertip board on a serial port.

    port: a device path (/dev/ttyACM0, COM3) or a pyserial URL. open() opens it,
    waits up to boot_timeout_s for the board to answer IDENTIFY (an Uno restarts
    when its port opens) and sends the settings and rate; start() starts the
    stream. Each command waits reply_timeout_s for its reply. Samples go to
    callback (called in the reader thread) and to a queue of queue_size samples
    read with read()/drain(); when the queue is full the oldest sample is dropped.
    queue_size=0 disables the queue.
    """

    def __init__(
        self,
        port: str,
        baudrate: int = 1_000_000,
        settings: MLX90393Settings | None = None,
        rate_hz: int = 50,
        *,
        callback: Callable[[Sample], None] | None = None,
        queue_size: int = 4096,
        reply_timeout_s: float = 0.5,
        boot_timeout_s: float = 3.0,
        reconnect_interval_s: float = 0.2,
    ) -> None:
        if not isinstance(port, str) or not port.strip():
            raise PortError(f"port = {port!r}: expected a serial device path or a pyserial URL")
        baudrate = checked(PositiveInteger, "baudrate", baudrate)
        queue_size = checked(QueueSize, "queue_size", queue_size)
        if callback is not None and not callable(callback):
            raise ValueError(f"callback = {callback!r}: expected a callable taking a Sample")
        if queue_size == 0 and callback is None:
            raise ValueError("queue_size = 0 without a callback: no one would receive the samples")
        self._port_name = port
        self._baudrate = baudrate
        self._settings = checked(SensorSettings, "settings", MLX90393Settings() if settings is None else settings)
        self._rate_hz = checked_rate_hz(rate_hz)
        self._callback = callback
        self._queue: queue.Queue[Sample] | None = queue.Queue(queue_size) if queue_size else None
        self._reply_timeout_s = checked(PositiveNumber, "reply_timeout_s", reply_timeout_s)
        self._boot_timeout_s = checked(PositiveNumber, "boot_timeout_s", boot_timeout_s)
        self._reconnect_interval_s = checked(PositiveNumber, "reconnect_interval_s", reconnect_interval_s)

        self._lock = threading.Lock()  # guards _serial, _pending, _next_tag
        self._command_lock = threading.Lock()  # one command in flight at a time
        self._serial: serial.SerialBase | None = None
        self._pending: dict[int, _PendingReply] = {}
        self._next_tag = 0
        self._streaming = False
        self._closing = threading.Event()
        self._reader: threading.Thread | None = None
        self._restorer: threading.Thread | None = None
        self._decoder = FrameDecoder()
        self._tracker = StreamTracker()
        # The model of the settings the device applies to the frames now arriving:
        # switched by the reader thread when the CONFIGURE reply arrives.
        self._model = MLX90393(self._settings)
        self._all_ok: dict[int, np.ndarray] = {}  # chip count -> all-True chip_ok mask
        self._frames = 0
        self._dropped = 0
        self._reconnects = 0
        self._queue_overflows = 0
        self.identity: Identity | None = None

    # ---------------------------------------------------------------- life cycle

    def open(self) -> FingertipDriver:
        if self._reader is not None:
            raise RuntimeError(f"driver for {self._port_name!r} is already open")
        self._serial = open_serial(self._port_name, self._baudrate)
        self._closing.clear()
        self._reader = threading.Thread(target=self._read_loop, name="fingertip-reader", daemon=True)
        self._reader.start()
        try:
            self._bring_up()
        except BaseException:
            self.close()
            raise
        return self

    def close(self) -> None:
        """Stop the stream (best effort), the reader thread, and close the port."""
        if self._reader is None:
            return
        if self._streaming and self.connected:
            with contextlib.suppress(DeviceTimeout, DeviceDisconnected, DeviceError):
                self.stop()
        self._closing.set()
        self._fail_pending()
        self._reader.join()
        if self._restorer is not None:
            self._restorer.join()
        with self._lock:
            port, self._serial = self._serial, None
        if port is not None:
            port.close()
        self._reader = None

    def __enter__(self) -> FingertipDriver:
        return self.open()

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    @property
    def connected(self) -> bool:
        return self._serial is not None

    @property
    def stats(self) -> DriverStats:
        return DriverStats(
            frames=self._frames,
            dropped=self._dropped,
            crc_errors=self._decoder.crc_errors,
            malformed=self._decoder.malformed,
            bytes_discarded=self._decoder.bytes_discarded,
            reconnects=self._reconnects,
            queue_overflows=self._queue_overflows,
        )

    # ------------------------------------------------------------------ commands

    def identify(self) -> Identity:
        # _handle_reply accepts only an Identity (or an error) for IDENTIFY.
        self.identity = self._command(identify_command)
        return self.identity

    def configure(self, settings: MLX90393Settings) -> None:
        """Write settings to every chip; later samples are converted with them."""
        settings = checked(SensorSettings, "settings", settings)
        self._settings = settings
        model = MLX90393(settings)

        def use_model() -> None:
            self._model = model

        self._command(lambda tag: configure_command(tag, settings), on_applied=use_model)

    def set_rate(self, rate_hz: int) -> None:
        self._rate_hz = checked_rate_hz(rate_hz)
        self._command(lambda tag: set_rate_command(tag, self._rate_hz))

    def start(self) -> None:
        self._streaming = True
        self._command(start_command)

    def stop(self) -> None:
        self._streaming = False
        self._command(stop_command)

    # ------------------------------------------------------------------- samples

    def read(self, timeout: float | None = None) -> Sample | None:
        """The oldest queued sample, waiting up to timeout seconds (None: forever)."""
        if self._queue is None:
            raise ValueError("read(): the driver was created with queue_size = 0")
        try:
            return self._queue.get(timeout=timeout)
        except queue.Empty:
            return None

    def drain(self) -> list[Sample]:
        """Every queued sample, oldest first, without waiting."""
        if self._queue is None:
            raise ValueError("drain(): the driver was created with queue_size = 0")
        samples = []
        while True:
            try:
                samples.append(self._queue.get_nowait())
            except queue.Empty:
                return samples

    # ------------------------------------------------------------------ internals

    def _bring_up(self) -> None:
        """Wait for the board, then send the settings, the rate and, if streaming, START.

        A chip that refuses the settings does not stop the others: its frames
        carry its fault status (NaN fields) and the firmware keeps retrying it.
        """
        deadline = time.monotonic() + self._boot_timeout_s
        while True:
            try:
                self.identify()
                break
            except DeviceTimeout:
                if time.monotonic() >= deadline or self._closing.is_set():
                    raise DeviceTimeout(
                        f"port {self._port_name!r}: no reply to IDENTIFY "
                        f"within {self._boot_timeout_s:g} s"
                    ) from None
        try:
            self.configure(self._settings)
        except DeviceError as error:
            if error.code != ErrorCode.CHIP_FAILURE:
                raise
            logger.error("%s: %s", self._port_name, error)
        self.set_rate(self._rate_hz)
        if self._streaming:
            self.start()

    def _command(
        self,
        make_command: Callable[[int], Command],
        on_applied: Callable[[], None] | None = None,
    ) -> Identity | Ack:
        with self._command_lock:
            with self._lock:
                port = self._serial
                if port is None:
                    raise DeviceDisconnected(f"port {self._port_name!r} is disconnected")
                tag = self._next_tag
                self._next_tag = (tag + 1) % 256
                command = make_command(tag)
                pending = _PendingReply(command, on_applied)
                self._pending[tag] = pending
            name = FrameType(command.code).name
            try:
                port.write(encode_frame(command))
            except (serial.SerialException, OSError) as error:
                raise DeviceDisconnected(
                    f"port {self._port_name!r}: writing {name} failed: {error}"
                ) from None
            # A reply that arrives after the timeout still runs on_applied: the
            # pending entry stays until its tag is reused.
            if not pending.done.wait(self._reply_timeout_s):
                raise DeviceTimeout(
                    f"port {self._port_name!r}: no reply to {name} within {self._reply_timeout_s:g} s"
                )
        reply = pending.reply
        if reply is None:
            raise DeviceDisconnected(f"port {self._port_name!r} disconnected while waiting for {name}")
        if isinstance(reply, ErrorReply):
            known = reply.code in ErrorCode._value2member_map_
            code = ErrorCode(reply.code).name if known else reply.code
            raise DeviceError(
                f"device refused {name}: {code} (detail {reply.detail:#04x})", reply.code, reply.detail
            )
        return reply

    def _handle_reply(self, reply: Identity | Ack | ErrorReply) -> None:
        with self._lock:
            pending = self._pending.get(reply.tag)
        if pending is None or pending.done.is_set():
            return
        expected = pending.command.code
        if isinstance(reply, Identity):
            if expected != FrameType.IDENTIFY:
                return
        elif reply.command != expected:
            return
        applied = isinstance(reply, Ack) or (
            isinstance(reply, ErrorReply) and reply.code == ErrorCode.CHIP_FAILURE
        )
        if applied and pending.on_applied is not None:
            pending.on_applied()
        pending.reply = reply
        pending.done.set()

    def _fail_pending(self) -> None:
        with self._lock:
            pending, self._pending = list(self._pending.values()), {}
        for entry in pending:
            entry.done.set()

    def _read_loop(self) -> None:
        while not self._closing.is_set():
            port = self._serial
            if port is None:
                self._try_reconnect()
                continue
            try:
                data = _read_available(port)
            except (serial.SerialException, OSError) as error:
                self._disconnected(port, error)
                continue
            if not data:
                continue
            host_time_s = time.perf_counter_ns() * 1e-9
            for message in self._decoder.feed(data):
                if isinstance(message, Frame):
                    self._deliver(message, host_time_s)
                elif isinstance(message, (Identity, Ack, ErrorReply)):
                    self._handle_reply(message)

    def _disconnected(self, port: serial.SerialBase, error: BaseException) -> None:
        with self._lock:
            if self._serial is not port:
                return
            self._serial = None
        with contextlib.suppress(serial.SerialException, OSError):
            port.close()
        self._decoder.clear()
        self._fail_pending()
        logger.warning("disconnected from %s: %s", self._port_name, error)

    def _try_reconnect(self) -> None:
        try:
            port = open_serial(self._port_name, self._baudrate)
        except PortError:
            self._closing.wait(self._reconnect_interval_s)
            return
        with self._lock:
            self._serial = port
        self._reconnects += 1
        logger.warning("reconnected to %s", self._port_name)
        if self._restorer is not None:
            self._restorer.join()
        self._restorer = threading.Thread(target=self._restore, name="fingertip-restore", daemon=True)
        self._restorer.start()

    def _restore(self) -> None:
        try:
            self._bring_up()
        except DeviceError as error:
            logger.error("%s: restoring the configuration: %s", self._port_name, error)
        except (DeviceTimeout, DeviceDisconnected) as error:
            if self._closing.is_set():
                return
            logger.error(
                "%s: restoring the configuration failed, reconnecting: %s", self._port_name, error
            )
            port = self._serial
            if port is not None:
                self._disconnected(port, error)

    def _deliver(self, frame: Frame, host_time_s: float) -> None:
        lost, device_time_s = self._tracker.update(frame)
        self._dropped += lost
        field, saturated = self._model.decode(frame.raw)
        status = frame.status
        # the usual frame has clear status bytes: one test, then a shared read-only mask
        chip_ok = (status & CHIP_FAULTS) == 0 if status.any() else None
        if chip_ok is not None and not chip_ok.all():
            field[~chip_ok] = np.nan
            saturated &= chip_ok[:, None]
        else:
            chip_ok = self._all_ok.get(len(status))
            if chip_ok is None:
                chip_ok = self._all_ok[len(status)] = np.ones(len(status), dtype=bool)
                chip_ok.setflags(write=False)
        temperature = None if frame.temperature_raw is None else temperature_C(frame.temperature_raw)
        sample = Sample(
            seq=frame.seq,
            device_time_s=device_time_s,
            host_time_s=host_time_s,
            reading=field,
            status=frame.status,
            chip_ok=chip_ok,
            saturated=saturated,
            temperature_C=temperature,
        )
        self._frames += 1
        if self._callback is not None:
            try:
                self._callback(sample)
            except Exception:
                logger.exception("sample callback failed")
        if self._queue is not None:
            while True:
                try:
                    self._queue.put_nowait(sample)
                    break
                except queue.Full:
                    try:
                        self._queue.get_nowait()
                        self._queue_overflows += 1
                    except queue.Empty:
                        pass
