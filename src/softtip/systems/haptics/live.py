"""Real-time rendering: a sensation sequence (recorded or synthetic) through the renderer and the device
model, a 1 kHz loop whose commands the servos take at their 50 Hz frame rate, out on the live
pipeline's sinks.

Each tick the renderer turns the wanted wrench into motor inputs (:meth:`NearestNeighbourRenderer.render_one`,
timed: its latency); at the first tick of each servo frame (50 Hz) that command, resolved to the
servos' dead band, goes to the device (:mod:`.servos`): the simulated one slews its servos towards it
and the sensor under the fingertip reads the wrench the platform applies, one sample a tick with its
noise; a real one on a serial port (:class:`~.servos.SerialDevice`) takes it as a line of text.
Frames go to the sinks as the live pipeline's :class:`~softtip.realtime.frames.FrameResult`: the
reading is the wanted force (:data:`~softtip.systems.haptics.WANTED`), the estimates are the
commanded motor inputs, the servos' angles and the rendered wrench (recorded on the ``wrench`` topic
as ``geometry_msgs/WrenchStamped``), NaN where a real device reports none.

Paced, each tick starts on the wall clock at its 1 kHz time (a tick that starts more than one period
late is counted); unpaced, the loop runs as fast as the machine allows. Either way the frames' stamps
are the 1 kHz ticks.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from softtip._core.files import not_a_file
from softtip.data import Dataset, DatasetError, is_dataset_file
from softtip.data.dataset import TIME
from softtip.realtime.frames import FrameResult, StreamInfo
from softtip.realtime.sinks.base import Sink
from softtip.systems.haptics import WANTED
from softtip.systems.haptics.collection import CollectionSettings, motor_grid, sensed_contact
from softtip.systems.haptics.device import DeviceSpec, quantised
from softtip.systems.haptics.fingertips import FINGERTIP_SENSOR
from softtip.systems.haptics.limits import DURATION_EXPECTED, LOOP_RATE_HZ, MAX_DURATION_S, MAX_SENSATION_ROWS
from softtip.systems.haptics.rendering import NearestNeighbourRenderer
from softtip.systems.haptics.servos import FrameResponse, ServoDevice

MOTORS = ("motor1_rad", "motor2_rad", "motor3_rad")
SERVOS = ("servo1_rad", "servo2_rad", "servo3_rad")
WRENCH = ("fx_N", "fy_N", "fz_N", "tx_Nm", "ty_Nm", "tz_Nm")
TARGET_NAMES = MOTORS + SERVOS + WRENCH
TARGET_UNITS = ("rad",) * 6 + ("N",) * 3 + ("Nm",) * 3
SENSATION_COLUMNS = ("time_s", "fx_N", "fy_N", "fz_N")


class SensationError(ValueError):
    """A sensation file or sequence that cannot be rendered."""


def synthetic_sensation(device: DeviceSpec, duration_s: float, rng: np.random.Generator,
                        hold_s: float = 0.5, collection: CollectionSettings = CollectionSettings()) -> np.ndarray:
    """Wanted wrenches (ticks, 6) at 1 kHz: sensations recorded by the FS at random configurations that
    touch it (as the study's targets are), each held ``hold_s`` and joined by a raised-cosine blend."""
    ticks = max(int(round(duration_s * LOOP_RATE_HZ)), 1)
    per_hold = int(round(hold_s * LOOP_RATE_HZ))
    count = ticks // per_hold + 2
    read = sensed_contact(device, FINGERTIP_SENSOR, rng.uniform(0.0, device.angle_max, (8 * count, 3)), collection, rng)
    touching = read.finger_wrenches[np.linalg.norm(read.finger_wrenches[:, :3], axis=1) > 0.1][:count]
    if len(touching) < 2:
        raise SensationError("synthetic sensation: too few random configurations touch the FS on this device")
    phase = np.arange(ticks) / per_hold
    index = np.minimum(phase.astype(int), len(touching) - 2)
    blend = (1 - np.cos(np.pi * np.clip((phase - index) * 4, 0, 1))) / 2  # the first quarter of each hold moves
    return touching[index] * (1 - blend[:, None]) + touching[index + 1] * blend[:, None]


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


@dataclass(frozen=True)
class RenderSummary:
    """What a rendering run did: ticks, the renderer's latency (s), the force error (N) between
    wanted and rendered (None when the device reports no wrench), the targets flagged outside the table."""

    ticks: int
    frames: int  # servo commands sent
    late_ticks: int  # paced ticks that started more than one period after their time
    latency_p50_s: float
    latency_p99_s: float
    median_error_N: float | None
    p90_error_N: float | None
    outside: int
    wall_s: float

    def to_dict(self) -> dict:
        return {"ticks": self.ticks, "loop_rate_hz": LOOP_RATE_HZ, "servo_frames": self.frames,
                "late_ticks": self.late_ticks, "latency_p50_us": self.latency_p50_s * 1e6,
                "latency_p99_us": self.latency_p99_s * 1e6, "median_error_N": self.median_error_N,
                "p90_error_N": self.p90_error_N, "outside_table": self.outside, "wall_s": self.wall_s}


def render_stream(device: DeviceSpec, renderer: NearestNeighbourRenderer, servos: ServoDevice,
                  sensation: np.ndarray, sinks: list[Sink], metadata: dict | None = None,
                  paced: bool = True) -> RenderSummary:
    """Streams ``sensation`` (ticks, 6) through ``renderer`` to ``servos`` (the simulated device or a
    real one), and the frames to ``sinks``; ``paced``: each tick on the wall clock at 1 kHz. The
    servos are released (closed) when the stream ends, however it ends."""
    frame_ticks = int(round(LOOP_RATE_HZ / device.servo.command_rate_hz))
    info = StreamInfo(chips=1, target_names=TARGET_NAMES, target_units=TARGET_UNITS, classes=None, settings=None,
                      rate_hz=LOOP_RATE_HZ, metadata=dict(metadata or {}), reading=WANTED)
    latencies, errors = np.empty(len(sensation)), np.full(len(sensation), np.nan)
    unknown = FrameResponse(np.full((frame_ticks, 3), np.nan), np.full((frame_ticks, 6), np.nan),
                            np.zeros((frame_ticks, 3), bool))
    outside, late, frames, started = 0, 0, 0, time.perf_counter()
    stamp0 = time.time_ns()
    opened = []
    try:
        for sink in sinks:
            sink.open(info)
            opened.append(sink)
        for first in range(0, len(sensation), frame_ticks):
            wanted = sensation[first:first + frame_ticks]
            commands = np.empty((len(wanted), 3))
            for k, wrench in enumerate(wanted):
                if paced:
                    ahead = started + (first + k) / LOOP_RATE_HZ - time.perf_counter()
                    if ahead > 0:
                        time.sleep(ahead)
                    late += ahead < -1 / LOOP_RATE_HZ
                tick = time.perf_counter()
                commands[k], flagged = renderer.render_one(wrench)
                latencies[first + k] = time.perf_counter() - tick
                outside += flagged
                if k == 0:  # the servos read one command a frame: the frame's first
                    servos.send(frames, quantised(device, commands[0]))
                    frames += 1
            response = servos.frame(len(wanted)) or unknown
            rendered = response.wrench[:len(wanted), :3]
            errors[first:first + len(wanted)] = np.linalg.norm(rendered - wanted[:, :3], axis=1)
            for k in range(len(wanted)):
                seq = first + k
                frame = FrameResult(
                    seq=seq, stamp_ns=stamp0 + int(seq * 1e9 / LOOP_RATE_HZ), host_time_s=time.perf_counter(),
                    device_time_s=seq / LOOP_RATE_HZ, reading=wanted[k, None, :3], chip_ok=np.ones(1, bool),
                    saturated=response.saturated[k, None], baseline=None, baseline_version=0, change=None,
                    estimates=np.concatenate([commands[k], response.angles[k], response.wrench[k]]), state=None,
                    latency_s=latencies[seq])
                for sink in opened:
                    sink.write(frame)
    finally:
        try:
            servos.close()
        finally:
            for sink in opened:
                sink.close()
    measured = np.isfinite(errors).all()
    return RenderSummary(len(sensation), frames, int(late), float(np.percentile(latencies, 50)),
                         float(np.percentile(latencies, 99)), float(np.median(errors)) if measured else None,
                         float(np.percentile(errors, 90)) if measured else None, int(outside),
                         time.perf_counter() - started)


def fs_renderer(device: DeviceSpec, fs_levels: int, rng: np.random.Generator,
                collection: CollectionSettings = CollectionSettings(), **renderer) -> NearestNeighbourRenderer:
    """The standard renderer on an FS table of ``fs_levels``³ configurations collected on ``device``."""
    table = sensed_contact(device, FINGERTIP_SENSOR, motor_grid(device, fs_levels), collection, rng).unsaturated()
    return NearestNeighbourRenderer(**renderer).fit(table.finger_wrenches, table.motor_inputs)
