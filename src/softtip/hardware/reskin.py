"""Reader for the binary stream of ReSkin / AnySkin boards.

Their firmware sends one record per reading of its chips (5 on a ReSkin
board): for each chip four little-endian float32 values t, x, y, z, then CR LF;
82 bytes for 5 chips. t is the chip temperature in degC and x, y, z the field in
uT, as the MLX90393 Arduino library those boards use prints them (assumed here:
the stream carries no units). There is no sequence number, device clock, CRC or
per-chip status, so lost records cannot be counted; Sample.seq is the running
count of decoded records and Sample.device_time_s is None.

Finding the record boundaries: CR LF may also occur inside the float data, so
one CR LF is not proof of a boundary. While unsynchronised, the decoder accepts a
start position only if the next confirm_records records all end with CR LF
where the record length puts it and all hold plausible values (finite, |B| below
200 mT, temperature within -50..150 degC). A false start needs a CR LF pair
inside the data at the same offset of consecutive records (a slowly changing
value can do that) and, read at the wrong offset, plausible values for every
chip of every confirming record: unlikely for real readings, whose temperatures
are near room temperature, but not impossible for readings that hardly change.
Once synchronised, each record only needs its own
terminator and plausible values; on a failure the decoder searches again.

:class:`ReSkinStream` runs a reader on a thread of its own and hands every Sample to the live
pipeline, as :class:`~softtip.hardware.PacedSource` does. :class:`ReSkinBoard` emulates such a board
on a pseudo-terminal: records of ``source(t_s)`` at a rate, as the boards' burst-mode firmware
(the AnySkin repository's ``5X_binary_burst_stream``) writes them.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
import time
import tty
from collections.abc import Callable
from typing import Self

import numpy as np

from softtip._core.channels import MAGNETIC
from softtip._core.config import PositiveInteger, PositiveNumber, checked
from softtip._core.threads import BackgroundThread
from softtip.hardware.driver import Sample, open_serial

TERMINATOR = b"\r\n"
VALUES_PER_CHIP = 4  # t, x, y, z
RESKIN_CHIPS = 5
RESKIN_BAUDRATE = 115_200
_READ_WAIT_S = 0.1  # how long the stream's thread waits for bytes before it looks whether to stop
# Above every MLX90393 range (the widest is about 0.14 T on Z).
PLAUSIBLE_FIELD_UT = 200_000.0
PLAUSIBLE_TEMPERATURE_C = (-50.0, 150.0)


class ReSkinDecoder:
    """Streaming decoder of ReSkin records into Samples (see the module docstring).

    Counters: records (samples returned), bytes_discarded (bytes in no returned
    record) and resyncs (times the record boundary was lost after being found).
    """

    def __init__(self, chips: int = RESKIN_CHIPS, confirm_records: int = 2) -> None:
        self._chips = chips = checked(PositiveInteger, "chips", chips)
        self._confirm = checked(PositiveInteger, "confirm_records", confirm_records)
        self.record_size = chips * VALUES_PER_CHIP * 4 + len(TERMINATOR)
        self._buffer = bytearray()
        self._synchronised = False
        self.records = 0
        self.bytes_discarded = 0
        self.resyncs = 0

    def feed(self, data: bytes | bytearray | memoryview, host_time_s: float) -> list[Sample]:
        """Samples of the complete records in the stream so far, stamped host_time_s."""
        buffer = self._buffer
        buffer += data
        size, record_size = len(buffer), self.record_size
        position = 0
        samples: list[Sample] = []
        while True:
            if self._synchronised:
                if position + record_size > size:
                    break
                values = self._record_values(buffer, position)
                if values is None:
                    self._synchronised = False
                    self.resyncs += 1
                    continue
                samples.append(self._sample(values, host_time_s))
                position += record_size
                continue
            start = self._find_start(buffer, position, size)
            if start is None:
                # Starts up to here are ruled out; later ones need more bytes to decide.
                undecided = max(position, size - self._confirm * record_size + 1)
                self.bytes_discarded += undecided - position
                position = undecided
                break
            self.bytes_discarded += start - position
            position = start
            self._synchronised = True
        del buffer[:position]
        return samples

    def _find_start(self, buffer: bytearray, position: int, size: int) -> int | None:
        record_size = self.record_size
        last_decidable = size - self._confirm * record_size
        search = position + record_size - len(TERMINATOR)
        while True:
            terminator = buffer.find(TERMINATOR, search)
            start = terminator + len(TERMINATOR) - record_size
            if terminator < 0 or start > last_decidable:
                return None
            if all(
                self._record_values(buffer, start + k * record_size) is not None
                for k in range(self._confirm)
            ):
                return start
            search = terminator + 1

    def _record_values(self, buffer: bytearray, start: int) -> np.ndarray | None:
        """(chips, 4) values t, x, y, z of the record at start, or None if it is not one."""
        end = start + self.record_size
        if buffer[end - len(TERMINATOR) : end] != TERMINATOR:
            return None
        values = np.frombuffer(buffer, dtype="<f4", count=self._chips * VALUES_PER_CHIP, offset=start)
        values = values.astype(np.float64).reshape(self._chips, VALUES_PER_CHIP)
        temperature, field = values[:, 0], values[:, 1:]
        low, high = PLAUSIBLE_TEMPERATURE_C
        if not (
            np.isfinite(values).all()
            and (np.abs(field) < PLAUSIBLE_FIELD_UT).all()
            and ((temperature >= low) & (temperature <= high)).all()
        ):
            return None
        return values

    def _sample(self, values: np.ndarray, host_time_s: float) -> Sample:
        sample = Sample(
            seq=self.records,
            device_time_s=None,
            host_time_s=host_time_s,
            reading=values[:, 1:].copy(),
            status=np.zeros(self._chips, dtype=np.uint8),
            chip_ok=np.ones(self._chips, dtype=bool),
            saturated=np.zeros((self._chips, 3), dtype=bool),
            temperature_C=values[:, 0].copy(),
        )
        self.records += 1
        return sample


class ReSkinReader:
    """Reads Samples from a ReSkin / AnySkin board on a serial port (device path or pyserial URL)."""

    def __init__(self, port: str, baudrate: int = RESKIN_BAUDRATE, chips: int = RESKIN_CHIPS) -> None:
        self.decoder = ReSkinDecoder(chips)
        self._serial = open_serial(port, baudrate)

    def read(self, timeout: float = 1.0) -> list[Sample]:
        """Samples decoded from the bytes that arrive within timeout seconds (at least one if any)."""
        deadline = time.monotonic() + timeout
        samples: list[Sample] = []
        while not samples and time.monotonic() < deadline:
            data = self._serial.read(max(1, self._serial.in_waiting))
            if data:
                samples = self.decoder.feed(data, time.perf_counter_ns() * 1e-9)
        return samples

    def close(self) -> None:
        self._serial.close()

    def __enter__(self) -> ReSkinReader:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


class ReSkinStream:
    """A ReSkin / AnySkin board on ``port`` as a live source: ``open()`` opens the port and
    ``start(deliver)`` calls ``deliver(sample)`` for every record as it is decoded, on the stream's
    thread. The boards send no rate: :attr:`rate_hz` is None and the samples carry no device time
    (the pipeline then stamps them with their arrival)."""

    reading = MAGNETIC
    settings = None  # the board's firmware sets its chips; it does not send how
    rate_hz = None
    finished = False  # a board streams until it is closed

    def __init__(self, port: str, chips: int = RESKIN_CHIPS, baudrate: int = RESKIN_BAUDRATE,
                 name: str = "anyskin") -> None:
        self.port = port
        self.chips = checked(PositiveInteger, "chips", chips)
        self.baudrate = baudrate
        self.name = f"{name} board on {port}"
        self._reader: ReSkinReader | None = None
        self._decoder = ReSkinDecoder(self.chips)  # replaced by the reader's: its counters outlive the port
        self._thread = BackgroundThread(f"reskin-{port}")

    def open(self) -> Self:
        self._reader = ReSkinReader(self.port, self.baudrate, self.chips)
        self._decoder = self._reader.decoder
        return self

    def start(self, deliver: Callable[[Sample], None]) -> Self:
        self._thread.start(lambda: self._run(deliver))
        return self

    def _run(self, deliver: Callable[[Sample], None]) -> None:
        while not self._thread.closing.is_set():
            for sample in self._reader.read(_READ_WAIT_S):
                deliver(sample)

    def counters(self) -> dict:
        """Records delivered, bytes in no record, and times the record boundary was lost."""
        decoder = self._decoder
        return {"delivered": decoder.records, "bytes_discarded": decoder.bytes_discarded, "resyncs": decoder.resyncs}

    def close(self) -> None:
        self._thread.stop()
        if self._reader is not None:
            self._reader.close()
            self._reader = None


class ReSkinBoard:
    """A ReSkin / AnySkin board on a pseudo-terminal: every ``1 / rate_hz`` s one record of
    ``source(t_s)`` (µT, shape (chips, 3); t_s since :meth:`start`) with the chips at
    ``temperature_C``, in float32 as the boards send it. :attr:`port` is the device to open;
    :attr:`sent` counts the records generated, :attr:`dropped` those not written because no host
    was reading (a full pty, as a board's USB buffer fills). :meth:`close` re-raises a failure of
    ``source``."""

    def __init__(self, source: Callable[[float], np.ndarray], rate_hz: float = 100.0, chips: int = RESKIN_CHIPS,
                 temperature_C: float = 25.0) -> None:
        if not callable(source):
            raise ValueError(f"source = {source!r}: expected a callable t_s -> field_uT (chips, 3)")
        self._source = source
        self.rate_hz = checked(PositiveNumber, "rate_hz", rate_hz)
        self.chips = checked(PositiveInteger, "chips", chips)
        self.temperature_C = float(temperature_C)
        self.sent = self.dropped = 0
        self._thread = BackgroundThread("reskin-board")
        self._directory: str | None = None
        self._master_fd = self._slave_fd = None
        self._error: Exception | None = None

    @property
    def port(self) -> str:
        if self._directory is None:
            raise RuntimeError("board not started")
        return os.path.join(self._directory, "anyskin")

    def start(self) -> Self:
        self._master_fd, self._slave_fd = os.openpty()
        tty.setraw(self._slave_fd)
        os.set_blocking(self._master_fd, False)
        self._directory = tempfile.mkdtemp(prefix="softtip-anyskin-")
        os.symlink(os.ttyname(self._slave_fd), self.port)
        self._thread.start(self._run)
        return self

    def record(self, t_s: float) -> bytes:
        """The bytes of the record the board sends at t_s."""
        field = np.asarray(self._source(t_s), dtype=np.float64)
        if field.shape != (self.chips, 3):
            raise ValueError(f"source: expected a field of shape ({self.chips}, 3), got {field.shape}")
        values = np.column_stack([np.full(self.chips, self.temperature_C), field]).astype("<f4")
        return values.tobytes() + TERMINATOR

    def _run(self) -> None:
        period, started = 1.0 / self.rate_hz, time.perf_counter()
        try:
            while not self._thread.closing.wait(max(started + self.sent * period - time.perf_counter(), 0.0)):
                try:
                    os.write(self._master_fd, self.record(self.sent * period))
                except BlockingIOError:
                    self.dropped += 1
                self.sent += 1
        except Exception as error:  # re-raised by close()
            self._error = error

    def close(self) -> None:
        self._thread.stop()
        if self._master_fd is not None:
            os.close(self._master_fd)
            os.close(self._slave_fd)
            self._master_fd = self._slave_fd = None
        if self._directory is not None:
            with contextlib.suppress(FileNotFoundError):
                shutil.rmtree(self._directory)
            self._directory = None
        if self._error is not None:
            raise RuntimeError(f"board emulator stopped: {self._error}") from self._error

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.close()
