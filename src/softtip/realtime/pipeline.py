"""The live pipeline: source -> baseline -> estimators -> sinks.

:class:`Pipeline` turns each :class:`~softtip.hardware.Sample` into a :class:`FrameResult`:

1. the frame is stamped with its acquisition time on the host's wall clock
   (:class:`AcquisitionClock`);
2. the baseline in use is subtracted (:mod:`softtip.realtime.baseline`), giving the
   change of flux density per chip and axis in µT;
3. every estimator (a calibration model, :class:`Estimator`) maps the changes of its
   input channels to its targets: regression models to values, one classifier to a
   contact state. Frames in which a chip reported a fault are not estimated;
4. the result goes to every sink (recorder, dashboard, live view, ROS 2; see
   :mod:`softtip.realtime.sinks`) and callback, in the acquisition thread: sinks only
   hand the frame to their own thread, callbacks must be as quick (a controller that
   stops an insertion on a false-insertion state is one).

Everything runs in the driver's reader thread, right after the frame is decoded: no
queue and no thread switch between arrival and estimate. The latency recorded per frame
is the time from the arrival of the bytes completing the frame (the driver's host
timestamp) to the estimate being ready.

:class:`LiveSession` runs a source (a fingertip on a serial port, or an emulated one in
a child process), a driver and a pipeline together; :func:`run_live` is its one-call
form for the command line.
"""

from __future__ import annotations

import logging
import math
import multiprocessing
import resource
import signal
import threading
import time
from array import array
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple, Self

import numpy as np

from softtip import __version__
from softtip.data.dataset import AXES, CHANNEL_PATTERN
from softtip.hardware import Emulator, FaultPlan, FingertipDriver, FrameFate, Sample
from softtip.realtime.baseline import Baseline
from softtip.sensors.mlx90393 import MLX90393Settings

logger = logging.getLogger(__name__)

EMULATOR = "emulator"
INPUT_UNITS_PER_UT = {"uT": 1.0, "µT": 1.0, "mT": 1e-3, "T": 1e-6}
CLOCK_LEAK = 1e-4  # twice the ±50 ppm of a common crystal: the device clock's drift is followed


class FrameResult(NamedTuple):
    """One frame after the pipeline.

    stamp_ns: acquisition time, ns since the Unix epoch; host_time_s: the driver's arrival
    stamp (perf_counter clock); device_time_s: the device clock, or None.
    field_uT: (chips, 3) reading, NaN for a faulty chip; chip_ok (chips,), saturated (chips, 3).
    baseline_uT: the baseline in use (read-only, replaced when it changes) or None before
    the first one; baseline_version counts the baselines used so far.
    change_uT: field minus baseline, or None. estimates: the regression targets in
    :attr:`StreamInfo.target_names` order, state: the contact state; both None when the
    frame was not estimated. latency_s: arrival to estimate ready.
    """

    seq: int
    stamp_ns: int
    host_time_s: float
    device_time_s: float | None
    field_uT: np.ndarray
    chip_ok: np.ndarray
    saturated: np.ndarray
    baseline_uT: np.ndarray | None
    baseline_version: int
    change_uT: np.ndarray | None
    estimates: np.ndarray | None
    state: str | None
    latency_s: float


@dataclass(frozen=True)
class StreamInfo:
    """What sinks are told when the pipeline opens.

    counters(latency_window=None) returns the live counters (frames, lost frames, latency
    percentiles over the last latency_window frames...) as a dict; take_baseline() asks
    for a new baseline (a sink may offer it as a command).
    """

    chips: int
    target_names: tuple[str, ...]
    target_units: tuple[str, ...]
    classes: tuple[str, ...] | None
    settings: MLX90393Settings | None
    rate_hz: float | None
    metadata: dict = field(default_factory=dict)
    counters: Callable[..., dict] = lambda latency_window=None: {}
    take_baseline: Callable[[], None] = lambda: None


class Sink:
    """A consumer of frames. ``write`` runs in the acquisition thread and must not block:
    a sink with slow work hands frames to its own thread."""

    def open(self, stream: StreamInfo) -> None:
        """Called once, before the first frame."""

    def write(self, frame: FrameResult) -> None:
        raise NotImplementedError

    def close(self) -> None:
        """Called once, after the last frame; finishes the sink's work."""


# --------------------------------------------------------------------------
# Estimators
# --------------------------------------------------------------------------


def channel_index(name: str) -> int:
    """Position of channel ``s{k}_b{axis}_uT`` in a frame's flattened (chips, 3) reading."""
    match = CHANNEL_PATTERN.fullmatch(name) if isinstance(name, str) else None
    if match is None:
        raise ValueError(f"input channel {name!r}: expected a channel name like s0_bx_uT")
    return 3 * int(match[1]) + AXES.index(match[2])


class Estimator:
    """A calibration model in the live path.

    ``model``: any object with ``predict(X)`` (X of shape (1, n_inputs)); its
    ``predict_one(x)`` (x 1-D float64) is used when present. ``input_channels``: the
    channel of each input, e.g. ``s0_bx_uT``; ``input_units``: their unit (µT as stored
    in datasets, or mT, T). ``kind``: ``"regression"`` (``target_names`` and
    ``target_units`` required) or ``"classifier"`` (the predicted label is the contact
    state; ``classes`` from the model's ``classes_``); ``"auto"``: a classifier when the
    model has ``classes_``.
    """

    def __init__(self, model: Any, input_channels: Sequence[str], *, target_names: Sequence[str] | None = None,
                 target_units: str | Sequence[str] | None = None, input_units: str | Sequence[str] = "uT",
                 kind: str = "auto", name: str = "model") -> None:
        if not callable(getattr(model, "predict", None)):
            raise ValueError(f"model {name}: expected an object with a predict(X) method, got {type(model).__name__}")
        self.name = name
        self.model = model
        self.input_channels = tuple(input_channels)
        if not self.input_channels:
            raise ValueError(f"model {name}: input_channels is empty")
        self.input_index = np.array([channel_index(c) for c in self.input_channels], dtype=np.intp)
        units = [input_units] * len(self.input_channels) if isinstance(input_units, str) else list(input_units)
        if len(units) != len(self.input_channels):
            raise ValueError(f"model {name}: {len(units)} input units for {len(self.input_channels)} input channels")
        unknown = sorted({u for u in units if u not in INPUT_UNITS_PER_UT})
        if unknown:
            raise ValueError(f"model {name}: input unit {unknown[0]!r} is not one of {', '.join(INPUT_UNITS_PER_UT)}")
        scale = np.array([INPUT_UNITS_PER_UT[u] for u in units])
        self._scale = None if np.all(scale == 1.0) else scale
        self.chips_needed = int(self.input_index.max()) // 3 + 1
        if kind == "auto":
            kind = "classifier" if hasattr(model, "classes_") else "regression"
        if kind == "classifier":
            self.classes = tuple(str(c) for c in getattr(model, "classes_", ()))
            self.target_names: tuple[str, ...] = ("contact_state",)
            self.target_units: tuple[str, ...] = ("1",)
        elif kind == "regression":
            self.classes = None
            if target_names is None or target_units is None:
                raise ValueError(f"model {name}: a regression model needs target_names and target_units")
            self.target_names = tuple(target_names)
            self.target_units = ((target_units,) * len(self.target_names) if isinstance(target_units, str)
                                 else tuple(target_units))
            if len(self.target_units) != len(self.target_names) or not self.target_names:
                raise ValueError(f"model {name}: expected one unit per target, got {len(self.target_names)} targets "
                                 f"and {len(self.target_units)} units")
        else:
            raise ValueError(f"kind = {kind!r}: expected 'regression', 'classifier' or 'auto'")
        self.kind = kind
        # Inputs that are the first channels in storage order are a slice: a view, no copy.
        self._leading_inputs = np.array_equal(self.input_index, np.arange(len(self.input_index)))
        predict_one = getattr(model, "predict_one", None)
        self._predict_one = predict_one if callable(predict_one) else self._predict_via_batch

    @classmethod
    def from_file(cls, path: str | Path) -> Estimator:
        """A model saved by :func:`softtip.calibration.save_model`, with its channels and targets."""
        from softtip.calibration.persistence import load_model

        model, meta = load_model(path)
        return cls(model, meta.input_channels, target_names=meta.target_names, target_units=meta.target_units,
                   input_units=meta.input_units, name=Path(path).name)

    def _predict_via_batch(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(self.model.predict(x[None, :]))[0]

    def inputs(self, change_flat: np.ndarray) -> np.ndarray:
        """The model's input vector from a frame's flattened change (µT)."""
        x = change_flat[:len(self.input_index)] if self._leading_inputs else change_flat[self.input_index]
        return x if self._scale is None else x * self._scale

    def estimate(self, change_flat: np.ndarray) -> np.ndarray | str:
        """Target values (regression, 1-D float64) or the contact state (classifier)."""
        output = self._predict_one(self.inputs(change_flat))
        if self.kind == "classifier":
            return str(output)
        # the real-time models already return a 1-D float64 array: no conversion for them
        values = output if type(output) is np.ndarray and output.dtype == np.float64 and output.ndim == 1 else (
            np.asarray(output, dtype=np.float64).reshape(-1))
        if len(values) != len(self.target_names):
            raise ValueError(f"model {self.name}: {values.size} outputs for {len(self.target_names)} target names")
        return values

    def describe(self) -> dict:
        return {"name": self.name, "kind": self.kind, "model": type(self.model).__name__,
                "input_channels": list(self.input_channels), "target_names": list(self.target_names),
                "target_units": list(self.target_units), "classes": None if self.classes is None else list(self.classes)}


# --------------------------------------------------------------------------
# Time stamps
# --------------------------------------------------------------------------


class AcquisitionClock:
    """Acquisition times on the host's wall clock, from the device clock.

    The arrival time is the acquisition time plus a transport delay that is never
    negative and at its smallest most of the time. So the offset host - device is
    estimated as its running minimum, allowed to grow by ``leak`` seconds per second so
    that a device clock slower than the host's is followed:
    ``t = d (1 + leak) + min_j [h_j - d_j (1 + leak)]``. A device clock that goes back
    (the device restarted) starts a new minimum. Without a device clock the arrival time
    is used. Stamps are strictly increasing (by 1 ns at least).
    """

    def __init__(self, leak: float = CLOCK_LEAK) -> None:
        self._factor = 1.0 + leak
        self._wall_minus_perf_ns = time.time_ns() - time.perf_counter_ns()
        self._offset = math.inf
        self._last_device: float | None = None
        self._last_ns = -1

    def stamp_ns(self, host_time_s: float, device_time_s: float | None) -> int:
        if device_time_s is None:
            acquired = host_time_s
        else:
            if self._last_device is not None and device_time_s < self._last_device:
                self._offset = math.inf
            self._last_device = device_time_s
            scaled = device_time_s * self._factor
            self._offset = min(self._offset, host_time_s - scaled)
            acquired = scaled + self._offset
        stamp = round(acquired * 1e9) + self._wall_minus_perf_ns
        if stamp <= self._last_ns:
            stamp = self._last_ns + 1
        self._last_ns = stamp
        return stamp


# --------------------------------------------------------------------------
# The pipeline
# --------------------------------------------------------------------------


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
    ``source_counters``: the source's counters, merged into :meth:`counters`.

    Use it as a context manager (opens and closes the sinks) and call :meth:`process`
    for every sample, from one thread.
    """

    def __init__(self, chips: int, estimators: Sequence[Estimator] = (), sinks: Sequence[Sink] = (), *,
                 baseline: Baseline | None = None, free_states: Sequence[str] = (),
                 callbacks: Sequence[Callable[[FrameResult], None]] = (), settings: MLX90393Settings | None = None,
                 rate_hz: float | None = None, metadata: Mapping | None = None,
                 source_counters: Callable[[], Mapping] | None = None) -> None:
        if isinstance(chips, bool) or not isinstance(chips, int) or chips < 1:
            raise ValueError(f"chips = {chips!r}: expected an integer >= 1")
        self.chips = chips
        self.baseline = Baseline() if baseline is None else baseline
        if not isinstance(self.baseline, Baseline):
            raise ValueError(f"baseline = {baseline!r}: expected a Baseline")
        estimators = list(estimators)
        for estimator in estimators:
            if not isinstance(estimator, Estimator):
                raise ValueError(f"estimators: expected Estimator objects, got {type(estimator).__name__}")
            if estimator.chips_needed > chips:
                raise ValueError(f"model {estimator.name} reads chip {estimator.chips_needed - 1}; "
                                 f"the stream has {chips} chips")
        classifiers = [e for e in estimators if e.kind == "classifier"]
        if len(classifiers) > 1:
            raise ValueError(f"models {', '.join(e.name for e in classifiers)}: at most one contact-state classifier")
        self._classifier = classifiers[0] if classifiers else None
        self._regressors = [e for e in estimators if e.kind == "regression"]
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
            if self.baseline.drift_time_constant_s is not None and not self.free_states:
                raise ValueError("free_states: name the contact states in which the fingertip is free "
                                 "(drift tracking with a contact-state classifier only runs in them)")
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
            rate_hz=rate_hz, metadata={
                "softtip_version": __version__,
                "models": [e.describe() for e in estimators],
                "baseline": {"frames": self.baseline.frames,
                             "drift_time_constant_s": self.baseline.drift_time_constant_s,
                             "drift_threshold_uT": self.baseline.drift_threshold_uT,
                             "step_uT": self.baseline.step_uT, "free_states": sorted(self.free_states)},
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
                logger.exception("closing sink %s failed", type(sink).__name__)
                errors.append(error)
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

        field_uT = sample.field_uT
        sound = bool(sample.chip_ok.all())
        baseline = self.baseline.value_uT
        version = self.baseline.version
        change = estimates = state = None
        if baseline is not None:
            change = field_uT - baseline
            if sound:
                flat = change.reshape(-1)
                if self._regressors:
                    estimates = self._estimate(flat)
                if self._classifier is not None:
                    state = self._classifier.estimate(flat)
                self.estimated += 1
        latency_s = time.perf_counter() - host_time_s
        if not sound:
            self.unsound += 1
        free = self._classifier is None or state in self.free_states
        self.baseline.update(field_uT, sound, dt_s, free)

        result = FrameResult(sample.seq, stamp_ns, host_time_s, device_time_s, field_uT, sample.chip_ok,
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
            "baseline_collecting": self.baseline.collecting, "latency_ms": percentiles_ms(latencies),
        }
        if self._source_counters is not None:
            counters |= dict(self._source_counters())
        return counters


# --------------------------------------------------------------------------
# Emulated fingertip in a child process
# --------------------------------------------------------------------------


@dataclass(frozen=True)
class PressCycle:
    """A field source for the emulator: each chip's resting field plus repeated presses.

    Every ``period_s`` a press rises and falls as a raised cosine over ``press_s``;
    chip k's axes change by ``amplitude_uT`` times fixed gains in [-1, 1] (drawn from
    ``seed``), on resting fields of a few hundred µT (x, y) and 2-3 mT (z).
    """

    chips: int = 4
    period_s: float = 2.0
    press_s: float = 1.0
    amplitude_uT: float = 400.0
    seed: int = 0

    def __post_init__(self) -> None:
        rng = np.random.default_rng(self.seed)
        resting = np.column_stack([rng.uniform(-400, 400, self.chips), rng.uniform(-400, 400, self.chips),
                                   rng.uniform(2000, 3000, self.chips)])
        object.__setattr__(self, "_resting", resting)
        object.__setattr__(self, "_gains", rng.uniform(-1, 1, (self.chips, 3)))

    def press(self, t_s: float) -> float:
        """Press depth in [0, 1] at time t_s."""
        phase = t_s % self.period_s
        return 0.5 * (1.0 - math.cos(2 * math.pi * phase / self.press_s)) if phase < self.press_s else 0.0

    def __call__(self, t_s: float) -> np.ndarray:
        return self._resting + self.amplitude_uT * self.press(t_s) * self._gains


_FATES = tuple(FrameFate)


@dataclass(frozen=True)
class EmulatorLog:
    """The frames an emulator generated, in order: session, sequence number and fate."""

    session: np.ndarray
    seq: np.ndarray
    fate: np.ndarray  # index into FATES
    cpu_s: float

    FATES = _FATES

    def count(self, fate: FrameFate) -> int:
        return int(np.count_nonzero(self.fate == _FATES.index(fate)))


def _serve_emulator(connection, source, rate_hz: int, chips: int, settings, faults, seed) -> None:
    """Child process: run an Emulator until told to stop, then send its log back."""
    try:
        emulator = Emulator(source, rate_hz=rate_hz, chips=chips, settings=settings, faults=faults, seed=seed)
        emulator.start()
    except Exception as error:
        connection.send(("error", f"{type(error).__name__}: {error}"))
        return
    connection.send(("port", emulator.port))
    connection.recv()
    try:
        emulator.close()
        error = None
    except RuntimeError as failure:
        error = str(failure)
    log = emulator.log
    usage = resource.getrusage(resource.RUSAGE_SELF)
    connection.send(("log", np.array([f.session for f in log], dtype=np.int32),
                     np.array([f.seq for f in log], dtype=np.int32),
                     np.array([_FATES.index(f.fate) for f in log], dtype=np.uint8),
                     usage.ru_utime + usage.ru_stime, error))


class EmulatorProcess:
    """An :class:`~softtip.hardware.Emulator` in a spawned child process: its work neither
    counts in the pipeline process's CPU time nor competes for its interpreter lock.

    ``source`` must be picklable (a module-level function or a :class:`PressCycle`).
    ``close()`` returns the :class:`EmulatorLog`.
    """

    def __init__(self, source: Callable[[float], np.ndarray], rate_hz: int = 50, chips: int = 4,
                 settings: MLX90393Settings | None = None, faults: FaultPlan | None = None,
                 seed: int | None = 0, start_timeout_s: float = 60.0) -> None:
        self._arguments = (source, rate_hz, chips, settings, faults, seed)
        self._start_timeout_s = start_timeout_s
        self._process: multiprocessing.process.BaseProcess | None = None
        self._connection = None
        self.port: str | None = None

    def start(self) -> EmulatorProcess:
        context = multiprocessing.get_context("spawn")
        parent, child = context.Pipe()
        process = context.Process(target=_serve_emulator, args=(child, *self._arguments),
                                  name="softtip-emulator", daemon=True)
        try:
            process.start()
        finally:
            child.close()
        self._process, self._connection = process, parent
        if not parent.poll(self._start_timeout_s):
            self._kill()
            raise RuntimeError(f"the emulator process did not start within {self._start_timeout_s:g} s")
        kind, value = parent.recv()
        if kind != "port":
            self._kill()
            raise RuntimeError(f"the emulator process failed: {value}")
        self.port = value
        return self

    def close(self) -> EmulatorLog | None:
        if self._process is None:
            return None
        try:
            self._connection.send("stop")
            _, session, seq, fate, cpu_s, error = self._connection.recv()
        except (EOFError, OSError) as problem:
            self._kill()
            raise RuntimeError(f"the emulator process died: {problem}") from None
        self._process.join(10.0)
        self._kill()
        if error:
            raise RuntimeError(error)
        return EmulatorLog(session, seq, fate, cpu_s)

    def _kill(self) -> None:
        if self._process is not None and self._process.is_alive():
            self._process.kill()
            self._process.join()
        self._process = None
        if self._connection is not None:
            self._connection.close()
            self._connection = None

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        if self._process is not None:
            self._kill()


# --------------------------------------------------------------------------
# Running a source, a driver and a pipeline together
# --------------------------------------------------------------------------


class LiveSession:
    """A fingertip (``source_spec``: a serial device path or pyserial URL, or
    ``"emulator"`` for an emulated one in a child process), its driver and a pipeline.

    ``with LiveSession(...) as session: session.wait(duration_s)``; afterwards
    :meth:`summary` reports frames, lost frames, latency and the CPU time of this process
    while streaming. ``chips`` defaults to what the device reports (the emulator: the
    models' chips, or 4). Other arguments: see :class:`Pipeline` and :class:`Baseline`.
    """

    def __init__(self, source_spec: str, estimators: Sequence[Estimator] = (), sinks: Sequence[Sink] = (), *,
                 rate_hz: int = 50, chips: int | None = None, settings: MLX90393Settings | None = None,
                 baudrate: int = 1_000_000, baseline: Baseline | None = None, free_states: Sequence[str] = (),
                 callbacks: Sequence[Callable[[FrameResult], None]] = (),
                 emulator_source: Callable[[float], np.ndarray] | None = None,
                 emulator_faults: FaultPlan | None = None, emulator_seed: int | None = 0) -> None:
        if not isinstance(source_spec, str) or not source_spec.strip():
            raise ValueError(f"source = {source_spec!r}: expected a serial port or {EMULATOR!r}")
        self.source_spec = source_spec
        self.estimators = list(estimators)
        self.sinks = list(sinks)
        self.rate_hz = rate_hz
        self.settings = MLX90393Settings() if settings is None else settings
        self.baudrate = baudrate
        self.baseline = baseline
        self.free_states = free_states
        self.callbacks = list(callbacks)
        self.emulated = source_spec == EMULATOR
        needed = max((e.chips_needed for e in self.estimators), default=1)
        self.chips = chips if chips is not None else (max(needed, 4) if self.emulated else None)
        self._emulator = (EmulatorProcess(emulator_source or PressCycle(self.chips), rate_hz, self.chips,
                                          self.settings, emulator_faults, emulator_seed)
                          if self.emulated else None)
        self.emulator_log: EmulatorLog | None = None
        self.driver: FingertipDriver | None = None
        self.pipeline: Pipeline | None = None
        self._cpu_s = self._wall_s = 0.0
        self._started = False

    def start(self) -> LiveSession:
        try:
            port = self._emulator.start().port if self._emulator is not None else self.source_spec
            self.driver = FingertipDriver(port, self.baudrate, self.settings, self.rate_hz,
                                          callback=self._forward, queue_size=0)
            self.driver.open()
            chips = self.driver.identity.chips if self.chips is None else self.chips
            if chips != self.driver.identity.chips:
                raise ValueError(f"chips = {chips}: the device at {self.source_spec!r} reports "
                                 f"{self.driver.identity.chips}")
            self.pipeline = Pipeline(chips, self.estimators, self.sinks, baseline=self.baseline,
                                     free_states=self.free_states, callbacks=self.callbacks, settings=self.settings,
                                     rate_hz=self.rate_hz, metadata={"source": self.source_spec,
                                                                     "device": self.driver.identity.name},
                                     source_counters=self._driver_counters)
            self.pipeline.open()
            self._cpu_s, self._wall_s = time.process_time(), time.perf_counter()
            self.driver.start()
            self._started = True
        except BaseException:
            self.close()
            raise
        return self

    def _forward(self, sample: Sample) -> None:
        self.pipeline.process(sample)  # the pipeline exists once the device has said how many chips

    def _driver_counters(self) -> dict:
        stats = self.driver.stats
        return {"delivered": stats.frames, "lost_in_transit": stats.dropped, "crc_errors": stats.crc_errors,
                "malformed": stats.malformed, "bytes_discarded": stats.bytes_discarded,
                "reconnects": stats.reconnects}

    def wait(self, duration_s: float | None = None, stop: threading.Event | None = None) -> None:
        """Stream for duration_s seconds (None: until ``stop`` is set or Ctrl-C)."""
        stop = threading.Event() if stop is None else stop
        deadline = None if duration_s is None else time.monotonic() + duration_s
        try:
            while not stop.is_set():
                remaining = None if deadline is None else deadline - time.monotonic()
                if remaining is not None and remaining <= 0:
                    break
                stop.wait(0.5 if remaining is None else min(remaining, 0.5))
        except KeyboardInterrupt:
            pass

    def close(self) -> None:
        """Stops the stream and closes the driver, the sinks and the emulator."""
        if self._started:
            self._cpu_s = time.process_time() - self._cpu_s
            self._wall_s = time.perf_counter() - self._wall_s
            self._started = False
        try:
            if self.driver is not None:
                self.driver.close()
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


def run_live(source_spec: str, model_paths: Sequence[str | Path] = (), sinks: Sequence[Sink] = (),
             duration_s: float | None = None, *, rate_hz: int = 50, chips: int | None = None,
             settings: MLX90393Settings | None = None, baudrate: int = 1_000_000, baseline_frames: int = 50,
             drift_time_constant_s: float | None = None, drift_threshold_uT: float = 20.0,
             free_states: Sequence[str] = (), callbacks: Sequence[Callable[[FrameResult], None]] = (),
             stop: threading.Event | None = None, emulator_source: Callable[[float], np.ndarray] | None = None) -> dict:
    """Stream from a fingertip (or ``"emulator"``) through the saved models in
    ``model_paths`` to ``sinks`` for ``duration_s`` seconds (None: until Ctrl-C or
    ``stop``), and return :meth:`LiveSession.summary`. In the main thread, SIGUSR1
    takes a new baseline (``kill -USR1 <pid>``). ``emulator_source``: what the emulated
    fingertip's chips read (a picklable ``source(t_s) -> (chips, 3)`` µT)."""
    estimators = [Estimator.from_file(path) for path in model_paths]
    baseline = Baseline(baseline_frames, drift_time_constant_s=drift_time_constant_s,
                        drift_threshold_uT=drift_threshold_uT)
    session = LiveSession(source_spec, estimators, sinks, rate_hz=rate_hz, chips=chips, settings=settings,
                          baudrate=baudrate, baseline=baseline, free_states=free_states, callbacks=callbacks,
                          emulator_source=emulator_source)
    in_main_thread = threading.current_thread() is threading.main_thread() and hasattr(signal, "SIGUSR1")
    previous = None
    with session:
        if in_main_thread:
            previous = signal.signal(signal.SIGUSR1, lambda *_: session.pipeline.take_baseline())
        try:
            session.wait(duration_s, stop)
        finally:
            if in_main_thread:
                signal.signal(signal.SIGUSR1, previous)
    return session.summary()
