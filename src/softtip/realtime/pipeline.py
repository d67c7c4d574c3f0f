"""The live pipeline: source -> baseline -> estimators -> sinks.

:class:`Pipeline` turns each :class:`~softtip.hardware.Sample` into a
:class:`~softtip.realtime.frames.FrameResult`:

1. the frame is stamped with its acquisition time on the host's wall clock
   (:class:`~softtip.realtime.clock.AcquisitionClock`);
2. the baseline in use is subtracted (:mod:`softtip.realtime.baseline`), giving the
   change per chip and axis (of flux density in µT for the fingertip's Hall chips, of force in
   N for a force chip: the stream's :class:`~softtip._core.channels.Reading`);
3. every estimator (a calibration model or an identified system,
   :class:`~softtip.realtime.estimator.Estimator`) maps the changes of its input channels to its
   targets: regression models to values, one classifier to a contact state. Frames in which a
   chip reported a fault are not estimated. A dynamic model (an identified system) keeps its
   state from frame to frame and restarts from rest with every baseline taken (at start, on
   command, at rest; not with drift steps): its estimates are the simulation of the frames since;
4. the result goes to every sink (recorder, dashboard, live view, ROS 2; see
   :mod:`softtip.realtime.sinks`) and callback, in the acquisition thread: sinks only
   hand the frame to their own thread, callbacks must be as quick (a controller that
   stops an insertion on a false-insertion state is one).

Everything runs in the driver's reader thread, right after the frame is decoded: no
queue and no thread switch between arrival and estimate. The latency recorded per frame
is the time from the arrival of the bytes completing the frame (the driver's host
timestamp) to the estimate being ready. :mod:`softtip.realtime.session` runs a
fingertip, its driver and a pipeline together.
"""

from __future__ import annotations

import logging
import math
import time
from array import array
from collections.abc import Callable, Mapping, Sequence
from typing import Self

import numpy as np

from softtip import __version__
from softtip._core.channels import MAGNETIC, Reading
from softtip._core.config import PositiveInteger, checked
from softtip.hardware import Sample
from softtip.realtime.baseline import Baseline
from softtip.realtime.clock import AcquisitionClock
from softtip.realtime.estimator import Estimator
from softtip.realtime.frames import FrameResult, StreamInfo
from softtip.realtime.sinks.base import Sink
from softtip.sensors.registry import ChipSettings, stream_settings

logger = logging.getLogger(__name__)


def percentiles_ms(latencies_s: Sequence[float]) -> dict:
    """p50, p99 and maximum in ms (NaN when empty)."""
    values = np.asarray(latencies_s, dtype=np.float64)
    if values.size == 0:
        return {"p50": math.nan, "p99": math.nan, "max": math.nan}
    p50, p99, top = np.percentile(values, [50, 99, 100]) * 1e3
    return {"p50": float(p50), "p99": float(p99), "max": float(top)}


class Pipeline:
    """Baseline, estimators and sinks for a stream of ``chips``-chip samples (module notes).

    ``estimators``: regression models (their targets are concatenated, names must be
    distinct) and at most one classifier. ``baseline``: a :class:`Baseline` (default: the
    mean of the first 50 sound frames, no drift tracking). ``free_states``: the contact
    states in which the fingertip touches nothing; with a classifier, drift tracking only
    runs in them. ``callbacks``: functions of a :class:`FrameResult`, called after the
    sinks. ``settings``, ``rate_hz``, ``metadata``: passed on to the sinks;
    ``source_counters``: the source's counters, merged into :meth:`counters`. ``reading``: what
    the chips read (default: flux density); every model's inputs must be channels of it.

    Use it as a context manager (opens and closes the sinks) and call :meth:`process`
    for every sample, from one thread.
    """

    def __init__(self, chips: int, estimators: Sequence[Estimator] = (), sinks: Sequence[Sink] = (), *,
                 baseline: Baseline | None = None, free_states: Sequence[str] = (),
                 callbacks: Sequence[Callable[[FrameResult], None]] = (), settings: ChipSettings | None = None,
                 rate_hz: float | None = None, metadata: Mapping | None = None,
                 source_counters: Callable[[], Mapping] | None = None, reading: Reading = MAGNETIC) -> None:
        checked(PositiveInteger, "chips", chips)
        self.chips = chips
        self.reading = reading
        stream_settings(settings, reading)
        self.baseline = Baseline(reading=reading) if baseline is None else baseline
        if not isinstance(self.baseline, Baseline):
            raise ValueError(f"baseline = {baseline!r}: expected a Baseline")
        if self.baseline.reading != reading:
            raise ValueError(f"baseline: a baseline of {self.baseline.reading.quantity} for a stream of "
                             f"{reading.quantity}")
        estimators = list(estimators)
        for estimator in estimators:
            if not isinstance(estimator, Estimator):
                raise ValueError(f"estimators: expected Estimator objects, got {type(estimator).__name__}")
            if estimator.sample_time_s is not None and rate_hz is not None \
                    and abs(rate_hz * estimator.sample_time_s - 1.0) > 1e-6:
                raise ValueError(f"model {estimator.name} runs at {1 / estimator.sample_time_s:g} Hz "
                                 f"(sample time {estimator.sample_time_s:g} s); the stream runs at {rate_hz:g} Hz")
            if estimator.reading != reading:
                raise ValueError(f"model {estimator.name} reads {estimator.reading.quantity} "
                                 f"({estimator.input_channels[0]}, ...); the stream reads {reading.quantity}")
            if estimator.chips_needed > chips:
                raise ValueError(f"model {estimator.name} reads chip {estimator.chips_needed - 1}; "
                                 f"the stream has {chips} chips")
        classifiers = [e for e in estimators if e.kind == "classifier"]
        if len(classifiers) > 1:
            raise ValueError(f"models {', '.join(e.name for e in classifiers)}: at most one contact-state classifier")
        self._classifier = classifiers[0] if classifiers else None
        self._regressors = [e for e in estimators if e.kind == "regression"]
        self._dynamic = [e for e in estimators if e.dynamic]
        self._dynamic_since = 0  # the taken baseline the dynamic models' state started from (drift steps are
        # not a new start: the state carries over them)
        names = [n for e in self._regressors for n in e.target_names]
        repeated = sorted({n for n in names if names.count(n) > 1})
        if repeated:
            raise ValueError(f"target {repeated[0]!r} is estimated by more than one model")
        self.target_names = tuple(names)
        self.target_units = tuple(u for e in self._regressors for u in e.target_units)
        self.free_states = frozenset(str(s) for s in free_states)
        if self._classifier is not None:
            unknown = sorted(self.free_states - set(self._classifier.classes))
            if unknown:
                raise ValueError(f"free_states: {unknown[0]!r} is not a class of {self._classifier.name} "
                                 f"({', '.join(self._classifier.classes)})")
            if (self.baseline.drift_time_constant_s is not None or self.baseline.rest_s is not None) \
                    and not self.free_states:
                raise ValueError("free_states: name the contact states in which the fingertip is free "
                                 "(drift tracking and re-zeroing at rest with a contact-state classifier only "
                                 "run in them)")
        self.sinks = list(sinks)
        for sink in self.sinks:
            if not callable(getattr(sink, "write", None)):
                raise ValueError(f"sinks: {type(sink).__name__} has no write(frame) method")
        self.callbacks = list(callbacks)
        for callback in self.callbacks:
            if not callable(callback):
                raise ValueError(f"callbacks: {callback!r} is not callable")
        self.stream = StreamInfo(
            chips=chips, target_names=self.target_names, target_units=self.target_units,
            classes=None if self._classifier is None else self._classifier.classes, settings=settings,
            rate_hz=rate_hz, reading=reading, metadata={
                "softtip_version": __version__,
                "models": [e.describe() for e in estimators],
                "baseline": {"frames": self.baseline.frames,
                             "drift_time_constant_s": self.baseline.drift_time_constant_s,
                             "drift_threshold": self.baseline.drift_threshold,
                             "step": self.baseline.step, "free_states": sorted(self.free_states),
                             "rest_s": self.baseline.rest_s, "rest_band": self.baseline.rest_band},
                "reading": {"quantity": reading.quantity, "unit": reading.unit},
                "sensor": None if settings is None else settings.kind.name,
                "sensor_settings": None if settings is None else settings.to_dict(),
                "rate_hz": rate_hz, **dict(metadata or {})},
            counters=self.counters, take_baseline=self.take_baseline)
        self._source_counters = source_counters
        self._clock = AcquisitionClock()
        self._last_time_s: float | None = None
        self.latencies_s = array("d")
        self.frames = 0
        self.estimated = 0
        self.unsound = 0
        self.sink_errors = 0
        self._failing: set[int] = set()
        self._opened = False

    # ---------------------------------------------------------------- life cycle

    def open(self) -> Pipeline:
        """Opens every sink; if one fails, closes those already open and re-raises."""
        for count, sink in enumerate(self.sinks):
            try:
                sink.open(self.stream)
            except BaseException:
                for opened in self.sinks[:count]:
                    try:
                        opened.close()
                    except Exception:
                        logger.exception("closing sink %s failed", type(opened).__name__)
                raise
        self._opened = True
        return self

    def close(self) -> None:
        """Closes every sink (each gets the chance even if another fails)."""
        if not self._opened:
            return
        self._opened = False
        errors = []
        for sink in self.sinks:
            try:
                sink.close()
            except Exception as error:
                errors.append(error)
        for error in errors[1:]:  # the first is raised; these would be lost
            logger.error("closing a sink failed too: %s", error)
        if errors:
            raise errors[0]

    def __enter__(self) -> Self:
        return self.open()

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def take_baseline(self, frames: int | None = None) -> None:
        """Take a new baseline from the next sound frames (thread-safe)."""
        self.baseline.take(frames)

    # ------------------------------------------------------------------ frames

    def process(self, sample: Sample) -> FrameResult:
        """Stamp, subtract the baseline, estimate, and hand the result to the sinks."""
        host_time_s, device_time_s = sample.host_time_s, sample.device_time_s
        stamp_ns = self._clock.stamp_ns(host_time_s, device_time_s)
        now_s = host_time_s if device_time_s is None else device_time_s
        dt_s = 0.0 if self._last_time_s is None else now_s - self._last_time_s
        self._last_time_s = now_s

        reading = sample.reading
        sound = bool(sample.chip_ok.all())
        baseline = self.baseline.value
        version = self.baseline.version
        change = estimates = state = None
        if baseline is not None:
            change = reading - baseline
            if sound:
                flat = change.reshape(-1)
                if self._dynamic and self.baseline.taken != self._dynamic_since:
                    self._dynamic_since = self.baseline.taken
                    for estimator in self._dynamic:
                        estimator.reset()
                if self._regressors:
                    estimates = self._estimate(flat)
                if self._classifier is not None:
                    state = self._classifier.estimate(flat)
                self.estimated += 1
        latency_s = time.perf_counter() - host_time_s
        if not sound:
            self.unsound += 1
        free = self._classifier is None or state in self.free_states
        self.baseline.update(reading, sound, dt_s, free)

        result = FrameResult(sample.seq, stamp_ns, host_time_s, device_time_s, reading, sample.chip_ok,
                             sample.saturated, baseline, version, change, estimates, state, latency_s)
        self.frames += 1
        self.latencies_s.append(latency_s)
        for index, sink in enumerate(self.sinks):
            try:
                sink.write(result)
            except Exception:
                self._sink_failed(index, type(sink).__name__)
        for index, callback in enumerate(self.callbacks, start=len(self.sinks)):
            try:
                callback(result)
            except Exception:
                self._sink_failed(index, getattr(callback, "__name__", type(callback).__name__))
        return result

    def _estimate(self, flat: np.ndarray) -> np.ndarray:
        if len(self._regressors) == 1:
            return self._regressors[0].estimate(flat)
        return np.concatenate([e.estimate(flat) for e in self._regressors])

    def _sink_failed(self, index: int, name: str) -> None:
        self.sink_errors += 1
        if index not in self._failing:  # log the first failure of each sink, count the others
            self._failing.add(index)
            logger.exception("sink or callback %s failed (later failures are only counted)", name)

    def counters(self, latency_window: int | None = None) -> dict:
        """Frames processed, estimated and with a chip fault, sink failures, baseline state,
        latency percentiles (ms) over the last ``latency_window`` frames (None: all), and
        the source's counters. Safe to call from any thread."""
        # A slice is a copy taken at once: the acquisition thread keeps appending.
        latencies = self.latencies_s[-latency_window:] if latency_window else self.latencies_s[:]
        counters = {
            "frames": self.frames, "estimated": self.estimated, "with_chip_fault": self.unsound,
            "sink_errors": self.sink_errors, "baseline_version": self.baseline.version,
            "baseline_collecting": self.baseline.collecting,
            "baseline_rezeroed_at_rest": self.baseline.rezeroed_at_rest, "latency_ms": percentiles_ms(latencies),
        }
        if self._source_counters is not None:
            counters |= dict(self._source_counters())
        return counters
