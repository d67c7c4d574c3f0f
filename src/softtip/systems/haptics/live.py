"""Real-time rendering: a sensation sequence (recorded or synthetic, or synthetic without end) through
the renderer to the device model or a real device, a loop on 1 kHz deadlines whose commands the
servos take at their 50 Hz frame rate, out on the live pipeline's sinks.

At the first tick of each servo frame a command is due: the renderer turns that tick's wanted wrench
into motor inputs (:meth:`NearestNeighbourRenderer.render_one`, timed: its latency), resolved to the
servos' dead band, and it goes to the device (:mod:`.servos`). The renderer runs only then (once in
20 ticks for softtip's 50 Hz servos; a device file whose servos take a command every tick, 1000 Hz,
is rendered every tick): the servos would not read the other renderings. At the frame's end
:class:`FrameWork`, on a thread of its own, asks the device what it did: the simulated one slews its
servos towards the command and the sensor under the fingertip reads the wrench the platform applies,
one sample a tick with its noise; a real one on a serial port (:class:`~.servos.SerialDevice`) answers
with the wrench reports its sensor sent back, if it has one. Frames go to the sinks as the live
pipeline's :class:`~softtip.realtime.frames.FrameResult`: the reading is the wanted force
(:data:`~softtip.systems.haptics.WANTED`), the estimates are the commanded motor inputs (held over
the frame), the servos' angles, the rendered wrench (recorded on the ``wrench`` topic as
``geometry_msgs/WrenchStamped``), NaN where a device reports none, and the tick's lateness.

Time is measured: paced, each tick waits for its deadline on the monotonic clock
(:class:`~softtip.realtime.clock.DeadlineClock`: a sleep, then a short spin), at real-time priority
where Linux permits (:func:`~softtip.realtime.clock.realtime_thread`); each frame's stamp is its
tick's actual start, and its lateness (the start after the deadline) is recorded beside the
estimates and summarised (p50, p99, maximum). Unpaced (``--fast``), the loop runs as fast as the
machine allows and the lateness is NaN.
"""

from __future__ import annotations

import os
import queue
import subprocess
import sys
import tempfile
import threading
import time
from array import array
from collections.abc import Iterable, Iterator
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from softtip._core.files import not_a_file
from softtip.data import Dataset, DatasetError, is_dataset_file
from softtip.data.dataset import TIME
from softtip.realtime.clock import DeadlineClock, Timing, loop_cpu, realtime_thread
from softtip.realtime.frames import FrameResult, StreamInfo
from softtip.realtime.sinks.base import Sink
from softtip.realtime.sinks.recorder import RecorderSink
from softtip.systems.haptics import WANTED
from softtip.systems.haptics.adaptive import Drive
from softtip.systems.haptics.collection import Collection, CollectionSettings, motor_grid, sensed_contact
from softtip.systems.haptics.device import DeviceSpec, load_device, quantised
from softtip.systems.haptics.fingertips import FINGERTIP_SENSOR, TEST_FINGERTIPS, Fingertip
from softtip.systems.haptics.limits import (
    DURATION_EXPECTED,
    LOOP_RATE_HZ,
    MAX_DURATION_S,
    MAX_SENSATION_ROWS,
    METHOD_ALIASES,
    SHORT_NAMES,
)
from softtip.systems.haptics.personalisation import personalise_geometric, press_configurations
from softtip.systems.haptics.rendering import NearestNeighbourRenderer, Rendering
from softtip.systems.haptics.servos import ServoDevice, SimulatedDevice
from softtip.systems.haptics.study import (
    StudySettings,
    adaptive_stream,
    adaptive_table,
    collect_user_data,
    data_driven_table,
    force_model_table,
)

MOTORS = ("motor1_rad", "motor2_rad", "motor3_rad")
SERVOS = ("servo1_rad", "servo2_rad", "servo3_rad")
WRENCH = ("fx_N", "fy_N", "fz_N", "tx_Nm", "ty_Nm", "tz_Nm")
LATENESS = "lateness_s"  # the tick's start after its deadline (NaN when unpaced)
TARGET_NAMES = MOTORS + SERVOS + WRENCH + (LATENESS,)
TARGET_UNITS = ("rad",) * 6 + ("N",) * 3 + ("Nm",) * 3 + ("s",)
KEPT_FRAMES = 50  # a device's wrench report for a frame older than this (1 s at 50 Hz) is not scored
SENSATION_COLUMNS = ("time_s", "fx_N", "fy_N", "fz_N")


class SensationError(ValueError):
    """A sensation file or sequence that cannot be rendered."""


UNTOUCHED_DRAWS = 128  # random configurations in a row that miss the FS before a device is refused


def synthetic_holds(device: DeviceSpec, rng: np.random.Generator, hold_s: float = 0.5,
                    collection: CollectionSettings = CollectionSettings(), batch: int = 16) -> Iterator[np.ndarray]:
    """Wanted wrenches at 1 kHz without end, one hold (ticks, 6) at a time: sensations recorded by the FS
    at random configurations that touch it (as the study's targets are), each held ``hold_s`` and
    reached from the one before by a raised-cosine blend over the hold's first quarter; ``8 batch``
    configurations drawn at a time, at most ``batch`` of them used (a small batch keeps each draw's
    sensor noise, one call to the generator, short: a stream drawn beside the loop uses 1)."""
    per_hold = int(round(hold_s * LOOP_RATE_HZ))
    blend = (1 - np.cos(np.pi * np.clip(np.arange(per_hold) / per_hold * 4, 0, 1)))[:, None] / 2
    previous, missed = None, 0
    while True:
        read = sensed_contact(device, FINGERTIP_SENSOR, rng.uniform(0.0, device.angle_max, (8 * batch, 3)),
                              collection, rng)
        touching = read.finger_wrenches[np.linalg.norm(read.finger_wrenches[:, :3], axis=1) > 0.1][:batch]
        missed = 0 if len(touching) else missed + 8 * batch
        if missed >= UNTOUCHED_DRAWS:
            raise SensationError(f"synthetic sensation: none of {missed} random configurations touches the FS on "
                                 "this device")
        for wrench in touching:
            if previous is not None:
                yield previous * (1 - blend) + wrench * blend
            previous = wrench


def synthetic_sensation(device: DeviceSpec, duration_s: float, rng: np.random.Generator,
                        hold_s: float = 0.5, collection: CollectionSettings = CollectionSettings()) -> np.ndarray:
    """The first ``duration_s`` of :func:`synthetic_holds`: wanted wrenches (ticks, 6) at 1 kHz."""
    ticks = max(int(round(duration_s * LOOP_RATE_HZ)), 1)
    holds = synthetic_holds(device, rng, hold_s, collection)
    return np.concatenate([next(holds) for _ in range(-(-ticks // int(round(hold_s * LOOP_RATE_HZ))))])[:ticks]


def recorded_sensation(path: str | Path, duration_s: float | None) -> np.ndarray:
    """Wanted wrenches (ticks, 6) at 1 kHz from a CSV or Parquet file with columns ``time_s``, ``fx_N``,
    ``fy_N``, ``fz_N`` (increasing times, finite forces), held between samples (zero-order, as a
    stream is), cut to ``duration_s``."""
    table = table_columns(Path(path), "sensation file", SensationError)
    missing = [name for name in SENSATION_COLUMNS if name not in table]
    if missing:
        raise SensationError(f"sensation file {path}: missing column {missing[0]} (expected {', '.join(SENSATION_COLUMNS)})")
    times = np.asarray(table["time_s"], dtype=float)
    if len(times) > MAX_SENSATION_ROWS:
        raise SensationError(f"sensation file {path}: {len(times)} rows, expected at most {MAX_SENSATION_ROWS} (one a "
                             f"tick at {LOOP_RATE_HZ:g} Hz over --duration's limit of {MAX_DURATION_S:g} s)")
    forces = np.column_stack([np.asarray(table[name], dtype=float) for name in SENSATION_COLUMNS[1:]])
    if len(times) < 1 or not (np.all(np.isfinite(times)) and np.all(np.isfinite(forces))):
        raise SensationError(f"sensation file {path}: expected finite times and forces, at least one row")
    if np.any(np.diff(times) <= 0):
        raise SensationError(f"sensation file {path}: time_s must increase from row to row")
    if duration_s is None and not times[-1] - times[0] <= MAX_DURATION_S:
        raise SensationError(f"sensation file {path}: time_s spans {times[-1] - times[0]:.6g} s, expected "
                             f"{DURATION_EXPECTED}: --duration's limit; --duration renders the first part")
    end = times[-1] - times[0] if duration_s is None else duration_s
    ticks = np.arange(max(int(round(end * LOOP_RATE_HZ)), 1)) / LOOP_RATE_HZ + times[0]
    held = forces[np.searchsorted(times, ticks, side="right") - 1]
    return np.hstack([held, np.zeros((len(held), 3))])


def table_columns(path: Path, what: str, error: type[ValueError]) -> dict[str, np.ndarray]:
    """The columns of a CSV or Parquet file, a ``what`` ("sensation file" ...); a file of another kind,
    missing or unreadable raises ``error`` naming it. A softtip dataset (``softtip import``'s) is read
    as one, verified: its time, channels and labels by name (:func:`dataset_columns`)."""
    import pyarrow as pa
    from pyarrow import csv, parquet

    readers = {".csv": csv.read_csv, ".parquet": parquet.read_table}
    if path.suffix.lower() not in readers:
        raise error(f"{what} {path}: expected a .csv or .parquet file")
    problem = not_a_file(path)
    if problem:
        raise error(f"{what} {path} {problem}")
    if is_dataset_file(path):
        return dataset_columns(path, what, error)
    try:
        table = readers[path.suffix.lower()](path)
    except (pa.ArrowException, OSError) as problem:
        raise error(f"{what} {path}: unreadable ({' '.join(str(problem).split())})") from None
    return {name: table.column(name).to_numpy(zero_copy_only=False) for name in table.column_names}


# the units a column's name may end in, as a table or sensation file names them
NAMED_UNITS = {"N": "N", "Nm": "N m", "rad": "rad", "deg": "deg", "s": "s"}


def dataset_columns(path: Path, what: str, error: type[ValueError]) -> dict[str, np.ndarray]:
    """A softtip dataset's ``time_s``, channels and labels by name, read and verified as every dataset
    is (its checksum, its declared columns); a label whose declared unit is not the one its name ends
    in (``fx_N`` in grams) is refused naming it, since the name is what the table's reader trusts."""
    try:
        dataset = Dataset.read(path)
    except DatasetError as problem:
        raise error(f"{what} {problem}") from None
    for name, unit in dataset.labels.items():
        named = NAMED_UNITS.get(name.rsplit("_", 1)[-1])
        if named is not None and unit.replace(" ", "") != named.replace(" ", ""):
            raise error(f"{what} {path}: label {name} is declared in {unit}, expected {named} as its name says")
    return {name: dataset.column(name) for name in (TIME, *dataset.channels, *dataset.labels)}


def _percentiles(samples: np.ndarray, scale: float = 1e6) -> tuple[float | None, float | None, float | None]:
    """p50, p99 and the maximum of ``samples`` times ``scale`` (None for no samples)."""
    if not len(samples):
        return None, None, None
    p50, p99 = np.percentile(samples, (50, 99))
    return float(p50 * scale), float(p99 * scale), float(samples.max() * scale)


@dataclass(frozen=True)
class RenderSummary:
    """What a rendering run did: its ticks, the renderings (one per servo command), each tick's
    lateness (its start after its deadline, s; empty when unpaced), the renderer's latency (s), the
    force error (N) between wanted and what the device's sensor read (empty when it reports none), the
    renderings flagged outside the table, whether Ctrl-C ended it and what Linux granted the loop."""

    ticks: int
    frames: int  # servo commands sent, one rendering each
    lateness_s: np.ndarray
    render_latency_s: np.ndarray
    errors_N: np.ndarray
    error_source: str | None  # who read the rendered wrench: the device model, the device, or nobody
    replies: int  # wrench reports the device sent back
    malformed_replies: int
    outside: int
    wall_s: float
    interrupted: bool
    timing: Timing

    @property
    def late_ticks(self) -> int:
        """Ticks that started more than one period after their deadline."""
        return int(np.count_nonzero(self.lateness_s > 1 / LOOP_RATE_HZ))

    def to_dict(self) -> dict:
        late_p50, late_p99, late_max = _percentiles(self.lateness_s)
        render_p50, render_p99, _ = _percentiles(self.render_latency_s)
        measured = len(self.errors_N) > 0
        return {"ticks": self.ticks, "loop_rate_hz": LOOP_RATE_HZ, "servo_frames": self.frames,
                "renderings": len(self.render_latency_s), "late_ticks": self.late_ticks,
                "lateness_p50_us": late_p50, "lateness_p99_us": late_p99, "lateness_max_us": late_max,
                "latency_p50_us": render_p50, "latency_p99_us": render_p99,
                "median_error_N": float(np.median(self.errors_N)) if measured else None,
                "p90_error_N": float(np.percentile(self.errors_N, 90)) if measured else None,
                "error_measured_by": self.error_source if measured else None, "device_replies": self.replies,
                "malformed_replies": self.malformed_replies, "outside_table": self.outside, "wall_s": self.wall_s,
                "interrupted": self.interrupted, "timing": self.timing.to_dict()}


def sensation_frames(sensation: np.ndarray | Iterable[np.ndarray], frame_ticks: int) -> Iterator[np.ndarray]:
    """The wanted wrenches (ticks, 6), or blocks of them one after another (:func:`synthetic_holds`), cut
    into servo frames of ``frame_ticks`` ticks (the last one shorter if the sensation ends)."""
    blocks = [sensation] if isinstance(sensation, np.ndarray) else sensation
    pending = np.empty((0, 6))
    for block in blocks:
        pending = np.concatenate([pending, block]) if len(pending) else np.asarray(block, dtype=float)
        whole = len(pending) // frame_ticks * frame_ticks
        for first in range(0, whole, frame_ticks):
            yield pending[first:first + frame_ticks]
        pending = pending[whole:]
    if len(pending):
        yield pending


PREFETCHED_FRAMES = 100  # servo frames of the sensation made ahead of the loop: 2 s at 50 Hz


class Prefetched:
    """``frames`` made up to ``depth`` ahead on a thread of their own, from construction on, so that
    drawing a synthetic sensation's next holds does not hold up a tick; iterating yields them, an error
    in making them is raised there; :meth:`close` stops the thread."""

    def __init__(self, frames: Iterator[np.ndarray], depth: int = PREFETCHED_FRAMES) -> None:
        self._frames, self._made = frames, queue.Queue(maxsize=depth)
        self._ended, self._stop = threading.Event(), threading.Event()
        self.thread = threading.Thread(target=self._make, name="haptics-sensation", daemon=True)
        self.thread.start()

    def wait_ahead(self) -> None:
        """Until ``depth`` frames are made, or all of them."""
        while not (self._made.full() or self._ended.is_set()):
            time.sleep(0.01)

    def _make(self) -> None:
        try:
            for frame in self._frames:
                if not self._put(frame):
                    return
            self._put(None)
        except BaseException as problem:  # raised to the loop
            self._put(problem)
        finally:
            self._ended.set()

    def _put(self, item) -> bool:
        while not self._stop.is_set():
            try:
                self._made.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def __iter__(self) -> Iterator[np.ndarray]:
        while (frame := self._made.get()) is not None:
            if isinstance(frame, BaseException):
                raise frame
            yield frame

    def close(self) -> None:
        self._stop.set()


class FrameWork:
    """What the loop hands off at the end of each servo frame, done on a thread of its own so that the
    loop's thread only waits, renders and sends: what the device did over the frame
    (:meth:`~.servos.ServoDevice.frame`: the device model's physics, or a serial device's replies),
    the force errors, and the frame's ticks to the sinks. A failure here (a sink, the device's
    link) stops the loop at its next frame (:meth:`check`)."""

    def __init__(self, servos: ServoDevice, sinks: list[Sink], wall_minus_perf_ns: int) -> None:
        self.servos, self.sinks, self.wall_minus_perf_ns = servos, sinks, wall_minus_perf_ns
        self.lateness, self.errors = array("d"), array("d")
        self.wanted_at_frame: dict[int, np.ndarray] = {}  # the last frames' wanted force, for late replies
        self.failure: BaseException | None = None
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self.thread = threading.Thread(target=self._run, name="haptics-frames", daemon=True)
        self.thread.start()

    def put(self, frame: int, seq: int, wanted: np.ndarray, starts: np.ndarray, work: np.ndarray,
            command: np.ndarray, lateness: np.ndarray) -> None:
        self._jobs.put((frame, seq, wanted, starts, work, command, lateness))

    def check(self) -> None:
        if self.failure is not None:
            raise self.failure

    def finish(self) -> None:
        """Does what is queued, then ends the thread; raises its failure, if any."""
        self._jobs.put(None)
        self.thread.join()
        self.check()

    def _run(self) -> None:
        while (job := self._jobs.get()) is not None:
            if self.failure is None:
                try:
                    self._frame(*job)
                except BaseException as problem:  # raised in the loop's thread
                    self.failure = problem

    def _frame(self, frame: int, seq: int, wanted: np.ndarray, starts: np.ndarray, work: np.ndarray,
               command: np.ndarray, lateness: np.ndarray) -> None:
        response = self.servos.frame(len(wanted))
        self.lateness.extend(lateness)
        if response.reported is None:  # read every tick: the model's sensor
            self.errors.extend(np.linalg.norm(response.wrench[:, :3] - wanted[:, :3], axis=1))
        else:
            self.wanted_at_frame[frame] = wanted[-1, :3]
            for reported, wrench in response.reported:
                if reported in self.wanted_at_frame:
                    self.errors.append(float(np.linalg.norm(wrench[:3] - self.wanted_at_frame[reported])))
            self.wanted_at_frame.pop(frame - KEPT_FRAMES, None)
        estimates = np.hstack([np.broadcast_to(command, (len(wanted), 3)), response.angles, response.wrench,
                               lateness[:, None]])
        for k in range(len(wanted)):
            result = FrameResult(
                seq=seq + k, stamp_ns=self.wall_minus_perf_ns + round(starts[k] * 1e9), host_time_s=starts[k],
                device_time_s=(seq + k) / LOOP_RATE_HZ, reading=wanted[k, None, :3], chip_ok=np.ones(1, bool),
                saturated=response.saturated[k, None], baseline=None, baseline_version=0, change=None,
                estimates=estimates[k], state=None, latency_s=work[k])
            for sink in self.sinks:
                sink.write(result)


def render_stream(device: DeviceSpec, renderer: NearestNeighbourRenderer, servos: ServoDevice,
                  sensation: np.ndarray | Iterable[np.ndarray], sinks: list[Sink], metadata: dict | None = None,
                  paced: bool = True, realtime: bool = True) -> RenderSummary:
    """Streams ``sensation`` (ticks, 6, or blocks of them without end) through ``renderer`` to
    ``servos`` (the simulated device or a real one), and the frames to ``sinks``, until it ends or
    Ctrl-C. ``paced``: each tick at its 1 kHz deadline on the monotonic clock
    (:class:`~softtip.realtime.clock.DeadlineClock`), with ``realtime`` the process's threads at
    real-time priority, the loop's pinned, where Linux permits (:func:`~softtip.realtime.clock.realtime_thread`).
    The renderer runs when the servos take a command (their frame's first tick; a device taking one
    every tick is rendered every tick); the rest of a frame's work is :class:`FrameWork`'s. Every
    tick's actual start is its frame's stamp. The servos are released (closed) and the sinks closed
    however it ends."""
    frame_ticks = int(round(LOOP_RATE_HZ / device.servo.command_rate_hz))
    info = StreamInfo(chips=1, target_names=TARGET_NAMES, target_units=TARGET_UNITS, classes=None, settings=None,
                      rate_hz=LOOP_RATE_HZ, metadata=dict(metadata or {}), reading=WANTED)
    render_s = array("d")
    outside, frames, seq, interrupted = 0, 0, 0, False
    clock = DeadlineClock(1 / LOOP_RATE_HZ)
    opened, worker = [], None
    started = time.perf_counter()
    try:
        for sink in sinks:
            sink.open(info)
            opened.append(sink)
        worker = FrameWork(servos, opened, time.time_ns() - time.perf_counter_ns())
        frames_ahead = Prefetched(sensation_frames(sensation, frame_ticks))
        frames_ahead.wait_ahead()
        with realtime_thread(paced and realtime) as timing:
            started = clock.start()
            try:
                for wanted in frames_ahead:
                    starts, work = np.empty(len(wanted)), np.empty(len(wanted))
                    for k in range(len(wanted)):
                        starts[k] = clock.wait(seq + k) if paced else time.perf_counter()
                        if k == 0:  # a command is due: the servos read one a frame
                            command, flagged = renderer.render_one(wanted[0])
                            servos.send(frames, quantised(device, command))
                            frames += 1
                            outside += flagged
                        work[k] = time.perf_counter() - starts[k]
                    render_s.append(work[0])
                    lateness = (starts - clock.deadline(seq + np.arange(len(wanted))) if paced
                                else np.full(len(wanted), np.nan))
                    worker.put(frames - 1, seq, wanted, starts, work, command, lateness)
                    seq += len(wanted)
                    worker.check()
            except KeyboardInterrupt:
                interrupted = True
            finally:
                frames_ahead.close()
            wall_s = time.perf_counter() - started
    finally:
        try:
            if worker is not None:
                worker.finish()
        finally:
            try:
                servos.close()
            finally:
                for sink in opened:
                    sink.close()
    lateness = np.array(worker.lateness)
    return RenderSummary(seq, frames, lateness[np.isfinite(lateness)], np.array(render_s), np.array(worker.errors),
                         servos.measured_by if len(worker.errors) else None, servos.replies, servos.malformed,
                         outside, wall_s, interrupted, timing)


def personalised_renderer(device: DeviceSpec, method: str, fingertip: Fingertip, motor_inputs, finger_wrenches,
                          platform_wrenches, seed: int, settings: StudySettings = StudySettings(),
                          collection: CollectionSettings = CollectionSettings(),
                          drive: Drive | None = None) -> tuple[NearestNeighbourRenderer, int]:
    """The renderer on an FS table (its motor inputs, the FS's wrenches and the DS's, None if not read)
    personalised for ``fingertip`` by ``method`` (:data:`~.limits.SHORT_NAMES`) as the study does it, and how many
    entries the personalisation flagged (out of reach, or outside the user's table). A, B+ and A+
    collect the user's data first: with ``drive`` on a real device (``drive(motor_inputs)`` drives and
    reads them, :meth:`~.servos.SerialDevice.collect`), only what the method needs (A the user table,
    B+ the presses, A+ the adaptive table); without, on the device model with ``fingertip`` in it, each
    on the study's own stream at ``seed`` (:func:`~.study.collect_user_data`: the user table and the
    presses; and A+'s adaptive table, as for the study's first fingertip)."""
    method = METHOD_ALIASES.get(method, method)
    if method not in SHORT_NAMES:
        raise ValueError(f"method = {method!r}: expected one of {', '.join(SHORT_NAMES)}")
    if method in ("A", "A+") and platform_wrenches is None:
        raise ValueError(f"method {method} personalises the FS table by its DS readings (ds_fx_N ... ds_tz_Nm), "
                         "which this table has none of")
    if method == "standard":
        personal = Rendering(np.asarray(motor_inputs, dtype=float), np.zeros(len(motor_inputs), bool))
    elif method == "B":
        personal = personalise_geometric(device, motor_inputs, FINGERTIP_SENSOR.radius, fingertip.radius)
    elif method == "A+":
        personal = adaptive_table(device, fingertip, motor_inputs, platform_wrenches, settings, collection,
                                  adaptive_stream(seed, 0), drive)[0]
    else:
        if drive is None:
            user = collect_user_data(device, fingertip, settings, collection, seed, 0)
            user_table, presses = user.user_table, user.presses
        elif method == "A":
            user_table = drive(motor_grid(device, settings.user_levels))
        else:
            presses = drive(press_configurations(device, fingertip.radius))
        if method == "A":
            personal = data_driven_table(device, motor_inputs, platform_wrenches, user_table, settings)
        else:
            personal = force_model_table(device, fingertip, motor_inputs, finger_wrenches, presses, settings)[0]
    renderer = NearestNeighbourRenderer(settings.n_neighbours, settings.contact_threshold, settings.weighting_power)
    return renderer.fit(finger_wrenches, personal.motor_inputs), int(personal.outside.sum())


def fs_collection(device: DeviceSpec, fs_levels: int, rng: np.random.Generator,
                  collection: CollectionSettings = CollectionSettings()) -> Collection:
    """An FS table of ``fs_levels``³ configurations collected on ``device``, its saturated entries left out."""
    return sensed_contact(device, FINGERTIP_SENSOR, motor_grid(device, fs_levels), collection, rng).unsaturated()


def fs_renderer(device: DeviceSpec, fs_levels: int, rng: np.random.Generator,
                collection: CollectionSettings = CollectionSettings(), **renderer) -> NearestNeighbourRenderer:
    """The standard renderer on an FS table of ``fs_levels``³ configurations collected on ``device``."""
    table = fs_collection(device, fs_levels, rng, collection)
    return NearestNeighbourRenderer(**renderer).fit(table.finger_wrenches, table.motor_inputs)


IDLE_P99_TARGET_S, LOADED_P99_TARGET_S = 1e-3, 2e-3  # issue 40: p99 lateness idle, and with the other core busy


@contextmanager
def busy_other_cores(loop_cpu: int) -> Iterator[list[int]]:
    """A process spinning on each CPU this process may use other than ``loop_cpu`` (on one CPU alone:
    on that one), ended when the block ends; the CPUs it keeps busy."""
    cpus = sorted(os.sched_getaffinity(0) - {loop_cpu}) or [loop_cpu]
    spinners = []
    try:
        for cpu in cpus:
            spinner = subprocess.Popen([sys.executable, "-c", "while True: pass"])
            spinners.append(spinner)
            os.sched_setaffinity(spinner.pid, {cpu})
        yield cpus
    finally:
        for spinner in spinners:
            spinner.kill()
            spinner.wait()


def loop_timing(seconds: float, record: bool, realtime: bool, seed: int = 1, fs_levels: int = 9) -> dict:
    """One paced run of the render loop (device model, synthetic sensation, with ``record`` an MCAP
    recording to a temporary file) for ``seconds``: its lateness and what Linux granted (``realtime``:
    asked for), with the load average before and after."""
    device = load_device()
    rng = np.random.default_rng(seed)
    renderer = fs_renderer(device, fs_levels, rng)
    wanted = synthetic_sensation(device, seconds, rng)
    load = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="softtip-bench-loop-") as folder:
        sinks = [RecorderSink(Path(folder) / "loop.mcap")] if record else []
        summary = render_stream(device, renderer, SimulatedDevice(device, TEST_FINGERTIPS[0], LOOP_RATE_HZ, rng),
                                wanted, sinks, paced=True, realtime=realtime).to_dict()
    keep = ("ticks", "late_ticks", "lateness_p50_us", "lateness_p99_us", "lateness_max_us", "latency_p99_us",
            "timing")
    return {**{key: summary[key] for key in keep}, "load_average_before": list(load),
            "load_average_after": list(os.getloadavg())}


def bench_loop(seconds: float, record: bool = True, seed: int = 1) -> dict:
    """The render loop's lateness idle and with the other cores busy (:func:`busy_other_cores`), each
    with real-time priority asked for and, as the baseline of the same run, without."""
    report = {"seconds": seconds, "record": record, "targets_p99_us": {"idle": IDLE_P99_TARGET_S * 1e6,
                                                                        "loaded": LOADED_P99_TARGET_S * 1e6}}
    for case in ("idle", "loaded"):
        with (busy_other_cores(loop_cpu()) if case == "loaded" else nullcontext([])) as busy:
            runs = {kind: loop_timing(seconds, record, kind == "real-time", seed) for kind in ("real-time", "baseline")}
        target = IDLE_P99_TARGET_S if case == "idle" else LOADED_P99_TARGET_S
        runs["busy_cpus"] = busy
        runs["meets_target"] = runs["real-time"]["lateness_p99_us"] <= target * 1e6
        report[case] = runs
    return report
