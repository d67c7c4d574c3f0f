"""Sinks of the live pipeline: the MCAP recorder, a terminal dashboard and a Foxglove live view.

Each sink's ``write`` runs in the acquisition thread and only hands the frame over:

* :class:`RecorderSink` queues frames for a writer thread that, every
  ``flush_interval_s``, encodes the batch (:class:`~softtip.realtime.mcap_record.McapRecorder`)
  and flushes it to the file, so a killed process loses at most that interval;
* :class:`DashboardSink` keeps the latest frame for a `rich` live display refreshed a few
  times per second (the change per chip and axis, the estimates, the contact state, the
  frame rate, lost frames, latency and baseline state);
* :class:`FoxgloveSink` serves the stream to Foxglove over its WebSocket protocol
  (``foxglove-websocket``), JSON-encoded with JSON schemas, on the recording's topics and
  with the same field layout (so one Foxglove layout serves live and recorded data), plus
  ``{prefix}/field_change`` (the change per chip in µT, for live plots); at most
  ``max_rate_hz`` frames per second, only on channels a client subscribed to.
"""

from __future__ import annotations

import asyncio
import collections
import json
import logging
import math
import os
import socket
import threading
import time
import warnings
from pathlib import Path

import numpy as np
from rich.console import Console, Group
from rich.live import Live
from rich.table import Table
from rich.text import Text

from softtip.realtime.mcap_record import (
    DEFAULT_PREFIX,
    WRENCH_FLOATS,
    McapRecorder,
    RecordingError,
    magnetic_covariance_T2,
    wrench_mapping,
)
from softtip.realtime.pipeline import FrameResult, Sink, StreamInfo
from softtip.sensors.mlx90393 import lsb_uT, noise_rms_uT

logger = logging.getLogger(__name__)


def _positive(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0 or not math.isfinite(value):
        raise ValueError(f"{name} = {value!r}: expected a positive number")
    return float(value)


# --------------------------------------------------------------------------
# Recorder
# --------------------------------------------------------------------------


class RecorderSink(Sink):
    """Records the stream to an MCAP file (see :mod:`softtip.realtime.mcap_record`).

    A writer thread encodes and writes the frames queued since its last pass every
    ``flush_interval_s`` and then flushes the file; ``chunk_size``, ``compression``,
    ``fsync`` and ``prefix`` go to the recorder. The queue is unbounded: it only grows
    while the disk stalls (about 100 kB per second at 500 frames/s).
    """

    def __init__(self, path: str | os.PathLike, *, flush_interval_s: float = 0.5, chunk_size: int = 256 * 1024,
                 compression: str = "zstd", fsync: bool = False, prefix: str = DEFAULT_PREFIX) -> None:
        self.path = Path(path)
        if not self.path.parent.is_dir():
            raise RecordingError(f"recording {self.path}: directory {self.path.parent} does not exist")
        self.flush_interval_s = _positive("flush_interval_s", flush_interval_s)
        self._options = {"chunk_size": chunk_size, "compression": compression, "fsync": fsync, "prefix": prefix}
        self._queue: collections.deque[FrameResult] = collections.deque()
        self._closing = threading.Event()
        self._thread: threading.Thread | None = None
        self.recorder: McapRecorder | None = None
        self.error: BaseException | None = None
        self.frames_flushed = 0  # frames in the file even if the process is killed now

    def open(self, stream: StreamInfo) -> None:
        settings = stream.settings
        covariance = magnetic_covariance_T2(None if settings is None else noise_rms_uT(settings),
                                            None if settings is None else lsb_uT(settings))
        self.recorder = McapRecorder(self.path, stream.chips, target_names=stream.target_names,
                                     target_units=stream.target_units, classes=stream.classes,
                                     covariance_T2=covariance, metadata=stream.metadata, **self._options)
        self._thread = threading.Thread(target=self._run, name="mcap-writer", daemon=True)
        self._thread.start()

    def write(self, frame: FrameResult) -> None:
        self._queue.append(frame)

    def _write_queued(self) -> None:
        batch = [self._queue.popleft() for _ in range(len(self._queue))]
        self.recorder.write_frames(batch)
        self.recorder.flush()
        self.frames_flushed = self.recorder.frames_written

    def _run(self) -> None:
        try:
            while not self._closing.wait(self.flush_interval_s):
                self._write_queued()
        except Exception as error:  # the stream goes on; close() reports the failure
            logger.exception("recording to %s failed", self.path)
            self.error = error

    def close(self) -> None:
        """Writes what is queued, then the summary and footer."""
        if self._thread is None:
            return
        self._closing.set()
        self._thread.join()
        self._thread = None
        try:
            if self.error is None:
                self._write_queued()
        finally:
            self.recorder.close()
        if self.error is not None:
            raise RecordingError(f"recording {self.path} stopped early: {self.error}") from self.error


# --------------------------------------------------------------------------
# Terminal dashboard
# --------------------------------------------------------------------------


def _number(value: float, digits: int = 1) -> str:
    return "—" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


class DashboardSink(Sink):
    """A live terminal display (rich), refreshed ``refresh_hz`` times per second; rates and
    latency percentiles are over the last ``window_s`` seconds."""

    def __init__(self, console: Console | None = None, *, refresh_hz: float = 4.0, window_s: float = 5.0) -> None:
        self.console = console
        self.refresh_hz = _positive("refresh_hz", refresh_hz)
        self.window_s = _positive("window_s", window_s)
        self._stream: StreamInfo | None = None
        self._latest: FrameResult | None = None
        self._frames = 0
        self._history: collections.deque[tuple[float, int]] = collections.deque()
        self._live: Live | None = None

    def open(self, stream: StreamInfo) -> None:
        self._stream = stream
        self._live = Live(get_renderable=self.render, console=self.console, refresh_per_second=self.refresh_hz)
        self._live.start()

    def write(self, frame: FrameResult) -> None:
        self._latest = frame
        self._frames += 1

    def close(self) -> None:
        if self._live is not None:
            self._live.stop()
            if not self._live.console.is_terminal:  # the last display ends without a newline there
                self._live.console.line()
            self._live = None

    def _rate_hz(self) -> float:
        now, frames = time.monotonic(), self._frames
        self._history.append((now, frames))
        while self._history[0][0] < now - self.window_s:
            self._history.popleft()
        then, earlier = self._history[0]
        return (frames - earlier) / (now - then) if now > then else math.nan

    def render(self) -> Group:
        """The display for the latest frame and the current counters."""
        stream, frame = self._stream, self._latest
        rate = self._rate_hz()
        nominal_hz = stream.rate_hz or (rate if math.isfinite(rate) else 1.0)
        counters = stream.counters(latency_window=max(1, int(nominal_hz * self.window_s)))
        chips = Table(title="Change of flux density (µT)", expand=False)
        for column in ("chip", "ΔBx", "ΔBy", "ΔBz", ""):
            chips.add_column(column, justify="right")
        for k in range(stream.chips):
            if frame is None or frame.change_uT is None:
                values = ["—"] * 3
            else:
                values = [_number(v) for v in frame.change_uT[k]]
            flags = "" if frame is None else (
                "fault" if not frame.chip_ok[k] else ("saturated" if frame.saturated[k].any() else "ok"))
            chips.add_row(str(k), *values, flags)
        parts: list = [chips]
        if stream.target_names:
            estimates = Table(title="Estimates", expand=False)
            for column in ("target", "value", "unit"):
                estimates.add_column(column, justify="right")
            for i, (name, unit) in enumerate(zip(stream.target_names, stream.target_units, strict=True)):
                value = None if frame is None or frame.estimates is None else float(frame.estimates[i])
                estimates.add_row(name, _number(value, 3), unit)
            parts.append(estimates)
        if stream.classes is not None:
            state = "—" if frame is None or frame.state is None else frame.state
            parts.append(Text(f"contact state: {state}", style="bold"))
        latency = counters.get("latency_ms", {})
        baseline = ("taking" if counters.get("baseline_collecting") else "in use") + \
            f" (#{counters.get('baseline_version', 0)})"
        parts.append(Text(
            f"frames {counters.get('frames', 0)}  rate {_number(rate)} Hz  "
            f"lost {counters.get('lost_in_transit', 0)}  CRC errors {counters.get('crc_errors', 0)}  "
            f"chip faults {counters.get('with_chip_fault', 0)}  "
            f"latency p50 {_number(latency.get('p50'), 2)} / p99 {_number(latency.get('p99'), 2)} ms  "
            f"baseline {baseline}"))
        return Group(*parts)


# --------------------------------------------------------------------------
# Foxglove live view
# --------------------------------------------------------------------------


def _schema(properties: dict) -> dict:
    return {"type": "object", "properties": properties}


_NUMBER = {"type": ["number", "null"]}
_VECTOR3 = _schema({"x": _NUMBER, "y": _NUMBER, "z": _NUMBER})
_HEADER = _schema({"stamp": _schema({"sec": {"type": "integer"}, "nanosec": {"type": "integer"}}),
                   "frame_id": {"type": "string"}})
MAGNETIC_FIELD_SCHEMA = _schema({"header": _HEADER, "magnetic_field": _VECTOR3,
                                 "magnetic_field_covariance": {"type": "array", "items": _NUMBER}})
WRENCH_SCHEMA = _schema({"header": _HEADER, "wrench": _schema({"force": _VECTOR3, "torque": _VECTOR3})})
ESTIMATES_SCHEMA = _schema({
    "layout": _schema({"dim": {"type": "array", "items": _schema({"label": {"type": "string"},
                                                                  "size": {"type": "integer"},
                                                                  "stride": {"type": "integer"}})},
                       "data_offset": {"type": "integer"}}),
    "data": {"type": "array", "items": _NUMBER}})
STATE_SCHEMA = _schema({"data": {"type": "string"}})
FIELD_CHANGE_SCHEMA = _schema({"stamp": _schema({"sec": {"type": "integer"}, "nanosec": {"type": "integer"}}),
                               "chips": {"type": "array", "items": _VECTOR3}})


def _finite_or_none(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None  # JSON has no NaN


def _vector(values) -> dict:
    return {axis: _finite_or_none(v) for axis, v in zip("xyz", values, strict=True)}


class FoxgloveSink(Sink):
    """Serves the stream to Foxglove (``ws://host:port``, "Foxglove WebSocket" connection).

    ``port`` 0 picks a free port (read :attr:`port` after opening). Frames are sent at most
    ``max_rate_hz`` per second (None: every frame).
    """

    def __init__(self, port: int = 8765, host: str = "127.0.0.1", *, max_rate_hz: float | None = 50.0,
                 prefix: str = DEFAULT_PREFIX, start_timeout_s: float = 10.0) -> None:
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise ValueError(f"foxglove port = {port!r}: expected an integer 0..65535")
        self.port = port
        self.host = host
        self._min_interval_ns = 0 if max_rate_hz is None else int(1e9 / _positive("max_rate_hz", max_rate_hz))
        self.prefix = prefix
        self._start_timeout_s = start_timeout_s
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._failure: BaseException | None = None
        self._latest: FrameResult | None = None
        self._wake_pending = False
        self._last_sent_ns = -(1 << 62)
        self._subscribed: set[int] = set()
        self._channels: dict[str, int] = {}
        self._server = None
        self._stopped: asyncio.Future | None = None
        self.frames_sent = 0

    def open(self, stream: StreamInfo) -> None:
        self._stream = stream
        self._wrench = wrench_mapping(stream.target_names, stream.target_units)
        self._thread = threading.Thread(target=self._serve, name="foxglove-server", daemon=True)
        self._thread.start()
        if not self._ready.wait(self._start_timeout_s):
            raise RuntimeError(f"the Foxglove server on {self.host}:{self.port} did not start "
                               f"within {self._start_timeout_s:g} s")
        if self._failure is not None:
            raise ValueError(f"foxglove port {self.port}: cannot serve on {self.host}: {self._failure}")

    @property
    def subscribed_topics(self) -> list[str]:
        """The topics at least one client subscribed to."""
        return [topic for topic, channel in self._channels.items() if channel in self._subscribed]

    def write(self, frame: FrameResult) -> None:
        if frame.stamp_ns - self._last_sent_ns < self._min_interval_ns:
            return
        self._last_sent_ns = frame.stamp_ns
        self._latest = frame
        if not self._wake_pending:  # the server thread sends the latest frame when it gets to it
            self._wake_pending = True
            self._loop.call_soon_threadsafe(self._send_latest)

    def close(self) -> None:
        if self._thread is None:
            return
        if self._loop is not None and self._stopped is not None:
            self._loop.call_soon_threadsafe(self._stopped.set_result, None)
        self._thread.join()
        self._thread = None

    # ---------------------------------------------------------- server thread

    def _serve(self) -> None:
        try:
            asyncio.run(self._main())
        except Exception as error:
            self._failure = error
            self._ready.set()

    async def _main(self) -> None:
        with warnings.catch_warnings():
            # foxglove-websocket 0.1 uses the legacy websockets server API.
            warnings.simplefilter("ignore", DeprecationWarning)
            from foxglove_websocket.server import FoxgloveServer, FoxgloveServerListener

        sink = self

        class Subscriptions(FoxgloveServerListener):
            def on_subscribe(self, server, channel_id) -> None:
                sink._subscribed.add(channel_id)

            def on_unsubscribe(self, server, channel_id) -> None:
                sink._subscribed.discard(channel_id)

        self._loop = asyncio.get_running_loop()
        self._stopped = self._loop.create_future()
        if self.port:
            # The server task swallows a failure to listen; find it out first, with one line.
            with socket.socket(socket.AF_INET6 if ":" in self.host else socket.AF_INET) as probe:
                probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                probe.bind((self.host, self.port))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            server = FoxgloveServer(self.host, self.port, "softtip", supported_encodings=["json"],
                                    logger=logging.getLogger(f"{__name__}.foxglove"))
            server.start()
            opened = await asyncio.wait_for(server.wait_opened(), self._start_timeout_s)
        self._server = server
        server.set_listener(Subscriptions())
        self.port = opened.sockets[0].getsockname()[1]
        for topic, name, schema in self._topics():
            self._channels[topic] = await server.add_channel({
                "topic": topic, "encoding": "json", "schemaName": name,
                "schema": json.dumps(schema), "schemaEncoding": "jsonschema"})
        self._ready.set()
        try:
            await self._stopped
        finally:
            server.close()
            await server.wait_closed()

    def _topics(self) -> list[tuple[str, str, dict]]:
        stream, prefix = self._stream, self.prefix
        topics = [(f"{prefix}/chip{k}/{kind}", "sensor_msgs/msg/MagneticField", MAGNETIC_FIELD_SCHEMA)
                  for k in range(stream.chips) for kind in ("field", "baseline")]
        topics.append((f"{prefix}/field_change", "softtip/FieldChange", FIELD_CHANGE_SCHEMA))
        if self._wrench:
            topics.append((f"{prefix}/wrench", "geometry_msgs/msg/WrenchStamped", WRENCH_SCHEMA))
        if stream.target_names:
            topics.append((f"{prefix}/estimates", "std_msgs/msg/Float64MultiArray", ESTIMATES_SCHEMA))
        if stream.classes is not None:
            topics.append((f"{prefix}/contact_state", "std_msgs/msg/String", STATE_SCHEMA))
        return topics

    def _send_latest(self) -> None:
        self._wake_pending = False
        frame = self._latest
        if frame is None or not self._subscribed:
            return
        for topic, message in self.messages(frame).items():
            channel = self._channels[topic]
            if channel in self._subscribed:
                asyncio.ensure_future(self._server.send_message(channel, frame.stamp_ns,
                                                                json.dumps(message).encode()))
        self.frames_sent += 1

    def messages(self, frame: FrameResult) -> dict[str, dict]:
        """The JSON messages of one frame, by topic (field values in T, as in the recording)."""
        prefix, stream = self.prefix, self._stream
        sec, nanosec = divmod(frame.stamp_ns, 1_000_000_000)
        stamp = {"sec": sec, "nanosec": nanosec}
        frame_prefix = prefix.strip("/").replace("/", "_")
        messages = {}
        for k in range(stream.chips):
            header = {"stamp": stamp, "frame_id": f"{frame_prefix}_chip{k}"}
            messages[f"{prefix}/chip{k}/field"] = {"header": header,
                                                   "magnetic_field": _vector(frame.field_uT[k] * 1e-6)}
            if frame.baseline_uT is not None:
                messages[f"{prefix}/chip{k}/baseline"] = {"header": header,
                                                          "magnetic_field": _vector(frame.baseline_uT[k] * 1e-6)}
        if frame.change_uT is not None:
            messages[f"{prefix}/field_change"] = {"stamp": stamp, "chips": [_vector(c) for c in frame.change_uT]}
        if frame.estimates is not None:
            if self._wrench:
                wrench = np.full(WRENCH_FLOATS, np.nan)
                for target, component, factor in self._wrench:
                    wrench[component] = frame.estimates[target] * factor
                messages[f"{prefix}/wrench"] = {"header": {"stamp": stamp, "frame_id": frame_prefix},
                                                "wrench": {"force": _vector(wrench[:3]),
                                                           "torque": _vector(wrench[3:])}}
            n = len(frame.estimates)
            messages[f"{prefix}/estimates"] = {
                "layout": {"dim": [{"label": ",".join(stream.target_names), "size": n, "stride": n}],
                           "data_offset": 0},
                "data": [_finite_or_none(v) for v in frame.estimates]}
        if frame.state is not None:
            messages[f"{prefix}/contact_state"] = {"data": frame.state}
        return messages


# --------------------------------------------------------------------------
# The command line's choice of sinks
# --------------------------------------------------------------------------


def live_sinks(*, dashboard: bool = True, record: str | os.PathLike | None = None, foxglove_port: int | None = None,
               ros2: bool = False, console: Console | None = None) -> list[Sink]:
    """The sinks of ``softtip live``: the dashboard, an MCAP recording, a Foxglove live view
    on ``foxglove_port`` and a ROS 2 node, each when asked for."""
    sinks: list[Sink] = []
    if dashboard:
        sinks.append(DashboardSink(console))
    if record is not None:
        sinks.append(RecorderSink(record))
    if foxglove_port is not None:
        sinks.append(FoxgloveSink(foxglove_port))
    if ros2:
        from softtip.realtime.ros2 import ROS2Sink

        sinks.append(ROS2Sink())
    return sinks
