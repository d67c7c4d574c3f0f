"""Readings played at their sample rate in this process: a sensor with no softtip firmware.

A sensor with no firmware of softtip's and no published interface (a system's force chip) is not
emulated behind a serial link: :class:`PacedSource` hands the live pipeline one frame of
``readings`` per sample period on a thread of its own, as a driver would on arrival. The same
serves to replay readings of any sensor at their rate. :class:`ThreadedSource` is what the live
session asks of such a source (a ReSkin / AnySkin board's stream is another).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Protocol, Self, runtime_checkable

import numpy as np

from softtip._core.channels import Reading
from softtip._core.config import PositiveNumber, checked
from softtip._core.threads import BackgroundThread
from softtip.hardware.driver import Sample
from softtip.sensors.registry import ChipSettings, stream_settings

_SEQ_MODULUS = 1 << 16  # sequence numbers wrap as the firmware's do


@runtime_checkable
class ThreadedSource(Protocol):
    """A source that delivers Samples on a thread of its own: ``name``, ``chips``, ``rate_hz``
    (None: no stated rate), ``reading`` (what its chips read), ``settings`` (its chips' registered
    sensor at their settings, or None when it does not know them), ``finished`` (its last frame is
    delivered), ``open()`` (takes its device, before the live session opens its sinks),
    ``start(deliver)``, ``counters()`` and ``close()``."""

    name: str
    chips: int
    rate_hz: float | None
    reading: Reading
    settings: ChipSettings | None

    @property
    def finished(self) -> bool: ...

    def open(self) -> Self: ...

    def start(self, deliver: Callable[[Sample], None]) -> Self: ...

    def counters(self) -> dict: ...

    def close(self) -> None: ...


class PacedSource:
    """``readings`` (N, chips, the reading's axes, in its unit) delivered one per ``1 / rate_hz``
    seconds, from the first again after the last when ``loop``; ``saturated`` (its shape) marks
    axes at the end of their range; ``settings``: the registered sensor that read them, at its settings.
    ``start(deliver)`` calls ``deliver(sample)`` for every frame on the source's thread; the device
    time of frame k is k / rate_hz. A frame the thread wakes for more than one period late is still
    delivered, and counted as late.
    """

    def __init__(self, readings: np.ndarray, rate_hz: float, *, reading: Reading,
                 saturated: np.ndarray | None = None, loop: bool = True, name: str = "replay",
                 settings: ChipSettings | None = None) -> None:
        readings = np.asarray(readings, dtype=np.float64)
        if readings.ndim != 3 or readings.shape[2] != len(reading.axes) or not len(readings) or readings.shape[1] < 1:
            raise ValueError(f"readings: expected shape (frames, chips, {len(reading.axes)}) with frames and chips "
                             f">= 1, got {readings.shape}")
        self.readings = readings
        self.rate_hz = checked(PositiveNumber, "rate_hz", rate_hz)
        self.reading = reading
        self.settings = stream_settings(settings, reading)
        self.saturated = np.zeros(readings.shape, bool) if saturated is None else np.asarray(saturated, bool)
        if self.saturated.shape != readings.shape:
            raise ValueError(f"saturated: expected shape {readings.shape}, got {self.saturated.shape}")
        self.loop = loop
        self.name = name
        self.chips = readings.shape[1]
        self.delivered = 0
        self.late = 0
        self._thread = BackgroundThread(f"paced-{name}")
        self._ok = np.ones(self.chips, bool)
        self._status = np.zeros(self.chips, np.uint8)

    @property
    def finished(self) -> bool:
        """Every frame delivered (never, when looping)."""
        return not self.loop and self.delivered >= len(self.readings)

    def open(self) -> Self:
        """Nothing to take: the readings are in memory."""
        return self

    def start(self, deliver: Callable[[Sample], None]) -> Self:
        self._thread.start(lambda: self._run(deliver))
        return self

    def _run(self, deliver: Callable[[Sample], None]) -> None:
        period, frames = 1.0 / self.rate_hz, len(self.readings)
        started = time.perf_counter()
        k = 0
        while self.loop or k < frames:
            due = started + k * period
            if self._thread.closing.wait(max(due - time.perf_counter(), 0.0)):
                return
            now = time.perf_counter()
            if now - due > period:
                self.late += 1
            row = k % frames
            deliver(Sample(seq=k % _SEQ_MODULUS, device_time_s=k * period, host_time_s=now,
                           reading=self.readings[row], status=self._status, chip_ok=self._ok,
                           saturated=self.saturated[row]))
            self.delivered += 1
            k += 1

    def counters(self) -> dict:
        return {"delivered": self.delivered, "late": self.late}

    def close(self) -> None:
        self._thread.stop()
