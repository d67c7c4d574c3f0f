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
"""

from __future__ import annotations

import time

import numpy as np

from softtip._core.config import PositiveInteger, checked
from softtip.hardware.driver import Sample, open_serial

TERMINATOR = b"\r\n"
VALUES_PER_CHIP = 4  # t, x, y, z
RESKIN_CHIPS = 5
RESKIN_BAUDRATE = 115_200
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
