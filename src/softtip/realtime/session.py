"""A fingertip (or an emulated one in a child process, or a source on a thread of its own), its
driver and a live pipeline, run together.

:class:`LiveSession` runs a source, a driver and a :class:`~softtip.realtime.pipeline.Pipeline`
together; :func:`run_live` is its one-call form for the command line.
"""

from __future__ import annotations

import math
import signal
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Self

import numpy as np

from softtip._core.stopping import STOP_SIGNALS, interrupt
from softtip.hardware import EmulatorLog, EmulatorProcess, FaultPlan, PressCycle, Sample, ThreadedSource
from softtip.hardware.drivers import FirmwareStream, PortRequest, firmware_settings
from softtip.realtime.baseline import Baseline
from softtip.realtime.estimator import Estimator
from softtip.realtime.frames import FrameResult
from softtip.realtime.pipeline import Pipeline
from softtip.realtime.sinks.base import Sink
from softtip.sensors.registry import ChipSettings

BASELINE_FRAMES = 50  # the frames a stream's baseline averages before it estimates

EMULATOR = "emulator"


class LiveSession:
    """A live source and a pipeline of its reading and settings: a
    :class:`~softtip.hardware.ThreadedSource` (a registered driver's board,
    :mod:`softtip.hardware.drivers`; an emulated sensor's :class:`~softtip.hardware.PacedSource`), or
    softtip's fingertip firmware (``source_spec``: a serial device path or pyserial URL, or
    ``"emulator"`` for an emulated fingertip in a child process) with its chips at ``settings``
    (default: their power-on settings).

    ``with LiveSession(...) as session: session.wait(duration_s)``; afterwards
    :meth:`summary` reports frames, lost frames, latency and the CPU time of this process
    while streaming. ``chips`` defaults to what the device reports (the emulator: the
    models' chips, or 4). Other arguments: see :class:`Pipeline` and :class:`Baseline`.
    """

    def __init__(self, source_spec: str | ThreadedSource, estimators: Sequence[Estimator] = (), sinks: Sequence[Sink] = (), *,
                 rate_hz: int = 50, chips: int | None = None, settings: ChipSettings | None = None,
                 baseline: Baseline | None = None, free_states: Sequence[str] = (),
                 callbacks: Sequence[Callable[[FrameResult], None]] = (),
                 emulator_source: Callable[[float], np.ndarray] | None = None,
                 emulator_faults: FaultPlan | None = None, emulator_seed: int | None = 0) -> None:
        self.threaded = source_spec if isinstance(source_spec, ThreadedSource) else None
        if self.threaded is None and (not isinstance(source_spec, str) or not source_spec.strip()):
            raise ValueError(f"source = {source_spec!r}: expected a serial port, {EMULATOR!r} or a threaded source")
        if self.threaded is not None and settings is not None:
            raise ValueError(f"settings: the source {self.threaded.name!r} states its own chips' settings")
        self.source_spec = source_spec if self.threaded is None else self.threaded.name
        self.estimators = list(estimators)
        self.sinks = list(sinks)
        self.rate_hz = rate_hz if self.threaded is None else self.threaded.rate_hz
        self.settings = self.threaded.settings if self.threaded is not None else firmware_settings(settings)
        self.baseline = baseline
        self.free_states = free_states
        self.callbacks = list(callbacks)
        self.emulated = source_spec == EMULATOR
        needed = max((e.chips_needed for e in self.estimators), default=1)
        self.chips = (self.threaded.chips if self.threaded is not None else
                      chips if chips is not None else (max(needed, 4) if self.emulated else None))
        self._emulator = (EmulatorProcess(emulator_source or PressCycle(self.chips), rate_hz, self.chips,
                                          self.settings.values, emulator_faults, emulator_seed)
                          if self.emulated else None)
        self.emulator_log: EmulatorLog | None = None
        self.pipeline: Pipeline | None = None
        self._cpu_s = self._wall_s = 0.0
        self._started = False

    def start(self) -> LiveSession:
        try:
            if self.threaded is None:
                port = self._emulator.start().port if self._emulator is not None else self.source_spec
                self.threaded = FirmwareStream(PortRequest(port, self.chips, self.rate_hz, self.settings))
            source = self.threaded
            source.open()
            self.pipeline = Pipeline(source.chips, self.estimators, self.sinks, baseline=self.baseline,
                                     free_states=self.free_states, callbacks=self.callbacks, settings=self.settings,
                                     rate_hz=source.rate_hz, metadata={"source": self.source_spec,
                                                                       "device": source.name},
                                     source_counters=source.counters, reading=source.reading)
            self.pipeline.open()
            self._cpu_s, self._wall_s = time.process_time(), time.perf_counter()
            source.start(self._forward)
            self._started = True
        except BaseException:
            self.close()
            raise
        return self

    def _forward(self, sample: Sample) -> None:
        self.pipeline.process(sample)  # the pipeline exists once the device has said how many chips

    def wait(self, duration_s: float | None = None, stop: threading.Event | None = None) -> None:
        """Stream for duration_s seconds (None: until ``stop`` is set or Ctrl-C), or until a threaded
        source that does not loop has delivered its last frame."""
        stop = threading.Event() if stop is None else stop
        deadline = None if duration_s is None else time.monotonic() + duration_s
        try:
            while not stop.is_set() and not (self.threaded is not None and self.threaded.finished):
                remaining = None if deadline is None else deadline - time.monotonic()
                if remaining is not None and remaining <= 0:
                    break
                stop.wait(0.1 if remaining is None else min(remaining, 0.1))
        except KeyboardInterrupt:
            pass

    def close(self) -> None:
        """Stops the stream and closes the driver, the sinks and the emulator."""
        if self._started:
            self._cpu_s = time.process_time() - self._cpu_s
            self._wall_s = time.perf_counter() - self._wall_s
            self._started = False
        try:
            if self.threaded is not None:
                self.threaded.close()
        finally:
            try:
                if self.pipeline is not None:
                    self.pipeline.close()
            finally:
                if self._emulator is not None:
                    self.emulator_log = self._emulator.close()

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def summary(self) -> dict:
        """Counters, latency percentiles and CPU use (% of one core) of the session so far."""
        counters = self.pipeline.counters() if self.pipeline is not None else {}
        def percent(cpu_s: float) -> float:
            return 100.0 * cpu_s / self._wall_s if self._wall_s > 0 else math.nan

        summary = {"source": self.source_spec, "chips": None if self.pipeline is None else self.pipeline.chips,
                   "rate_hz": self.rate_hz, "streaming_s": self._wall_s, "cpu_percent": percent(self._cpu_s),
                   **counters}
        return summary


def run_live(source_spec: str | ThreadedSource, model_paths: Sequence[str | Path] = (), sinks: Sequence[Sink] = (),
             duration_s: float | None = None, *, rate_hz: int = 50, chips: int | None = None,
             settings: ChipSettings | None = None, baseline_frames: int = BASELINE_FRAMES,
             drift_time_constant_s: float | None = None, drift_threshold: float | None = None,
             rest_s: float | None = None, rest_band: float | None = None,
             free_states: Sequence[str] = (), callbacks: Sequence[Callable[[FrameResult], None]] = (),
             stop: threading.Event | None = None, emulator_source: Callable[[float], np.ndarray] | None = None) -> dict:
    """Stream from a fingertip (or ``"emulator"``, or a :class:`~softtip.hardware.ThreadedSource`) through
    the saved models (calibration models or identified systems) in
    ``model_paths`` to ``sinks`` for ``duration_s`` seconds (None: until Ctrl-C, SIGTERM, SIGHUP or
    ``stop``), and return :meth:`LiveSession.summary`. In the main thread, SIGUSR1
    takes a new baseline (``kill -USR1 <pid>``), and SIGTERM and SIGHUP end the session as Ctrl-C
    does: the sinks are closed, a recording gets its summary. ``emulator_source``: what the emulated
    fingertip's chips read (a picklable ``source(t_s) -> (chips, 3)`` µT). ``drift_threshold``:
    in the reading's unit (default: the reading's). ``rest_s``, ``rest_band``: re-zero at rest
    (:class:`~softtip.realtime.baseline.Baseline`)."""
    estimators = [Estimator.from_file(path) for path in model_paths]
    reading = (source_spec if isinstance(source_spec, ThreadedSource) else FirmwareStream).reading
    baseline = Baseline(baseline_frames, drift_time_constant_s=drift_time_constant_s,
                        drift_threshold=drift_threshold, rest_s=rest_s, rest_band=rest_band, reading=reading)
    session = LiveSession(source_spec, estimators, sinks, rate_hz=rate_hz, chips=chips, settings=settings,
                          baseline=baseline, free_states=free_states, callbacks=callbacks,
                          emulator_source=emulator_source)
    in_main_thread = threading.current_thread() is threading.main_thread() and hasattr(signal, "SIGUSR1")
    stopping = {number: signal.signal(number, interrupt) for number in STOP_SIGNALS} if in_main_thread else {}
    try:
        with session:
            if in_main_thread:
                previous = signal.signal(signal.SIGUSR1, lambda *_: session.pipeline.take_baseline())
            try:
                session.wait(duration_s, stop)
            finally:
                if in_main_thread:
                    signal.signal(signal.SIGUSR1, previous)
                    for number in stopping:  # a second stop signal must not cut the closing of the sinks short
                        signal.signal(number, signal.SIG_IGN)
    finally:
        for number, handler in stopping.items():
            signal.signal(number, handler)
    return session.summary()
