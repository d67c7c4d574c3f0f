"""A Foxglove live view of the stream.

:class:`FoxgloveSink` serves the stream to Foxglove over its WebSocket protocol
(``foxglove-websocket``), JSON-encoded with JSON schemas, on the recording's topics and
with the same field layout (so one Foxglove layout serves live and recorded data), plus
``{prefix}/field_change`` (the change per chip in µT, for live plots; ``force_change`` in N for
a force chip); at most ``max_rate_hz`` frames per second, only on channels a client subscribed to.

Every frame the rate allows reaches every subscribed client: the acquisition thread queues it and
the server thread sends the queue in order, each message once the client's connection has taken the
one before. A client slower than the stream first fills its connection's socket buffers (up to 4 MB
on Linux: a minute of one chip at 50 frames/s, two seconds of four chips unthinned at 500), then
holds the queue up (the server sends to its clients one after the other, so it slows the others too);
past ``queue_frames`` waiting frames (two seconds at the default rate) the oldest is dropped and
counted (:meth:`FoxgloveSink.report`, in ``softtip live``'s summary), so the view stays current,
memory stays bounded and the acquisition never waits. At the end, what is queued still goes out, for
two seconds at most.
"""

from __future__ import annotations

import asyncio
import collections
import json
import logging
import math
import socket
import threading
import warnings

from softtip._core.config import PositiveInteger, PositiveNumber, checked, integer
from softtip.realtime.frames import FrameResult, StreamInfo
from softtip.realtime.recording.format import (
    DEFAULT_PREFIX,
    FLOAT64_MULTI_ARRAY,
    MAGNETIC_FIELD,
    STRING,
    VECTOR3_STAMPED,
    WRENCH_STAMPED,
    frame_id,
    in_xyz,
    reading_fields,
    reading_topic,
    wrench_mapping,
    wrench_values,
)
from softtip.realtime.sinks.base import Sink


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
CHANGE_SCHEMA = _schema({"stamp": _schema({"sec": {"type": "integer"}, "nanosec": {"type": "integer"}}),
                         "chips": {"type": "array", "items": _VECTOR3}})
READING_SCHEMAS = {MAGNETIC_FIELD: MAGNETIC_FIELD_SCHEMA, WRENCH_STAMPED: WRENCH_SCHEMA,
                   VECTOR3_STAMPED: _schema({"header": _HEADER, "vector": _VECTOR3})}


def _finite_or_none(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None  # JSON has no NaN


def _vector(values) -> dict:
    return {axis: _finite_or_none(v) for axis, v in zip("xyz", values, strict=True)}


Port = integer(0, 65535)
DRAIN_TIMEOUT_S = 2.0  # at closing, how long the queue may take to reach the clients
CLOSE_TIMEOUT_S = 1.0  # then how long a client may take to answer the closing handshake


class RateLimit:
    """At most ``rate_hz`` frames per second of their stamps (None: every frame), as a token bucket
    holding up to two frames' credit: a stream at the limit passes whole though its stamps jitter
    (a frame stamped a little early spends the credit a late one left), a faster one is thinned
    evenly."""

    def __init__(self, rate_hz: float | None) -> None:
        self.interval_ns = 0 if rate_hz is None else int(1e9 / checked(PositiveNumber, "max_rate_hz", rate_hz))
        self._credit_ns = 2 * self.interval_ns
        self._last_ns: int | None = None

    def allows(self, stamp_ns: int) -> bool:
        if self._last_ns is not None:
            self._credit_ns = min(self._credit_ns + stamp_ns - self._last_ns, 2 * self.interval_ns)
        self._last_ns = stamp_ns
        if self._credit_ns < self.interval_ns:
            return False
        self._credit_ns -= self.interval_ns
        return True


class FoxgloveSink(Sink):
    """Serves the stream to Foxglove (``ws://host:port``, "Foxglove WebSocket" connection).

    ``port`` 0 picks a free port (read :attr:`port` after opening). Frames are sent at most
    ``max_rate_hz`` per second (None: every frame); ``queue_frames``: the frames that may wait for
    a slow client before the oldest is dropped (module notes).
    """

    def __init__(self, port: int = 8765, host: str = "127.0.0.1", *, max_rate_hz: float | None = 50.0,
                 queue_frames: int = 100, prefix: str = DEFAULT_PREFIX, start_timeout_s: float = 10.0) -> None:
        self.port = checked(Port, "foxglove port", port)
        self.host = host
        self._rate = RateLimit(max_rate_hz)
        self.queue_frames = checked(PositiveInteger, "queue_frames", queue_frames)
        self.prefix = prefix
        self._start_timeout_s = start_timeout_s
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._failure: BaseException | None = None
        self._queue: collections.deque[FrameResult] = collections.deque()
        self._queue_lock = threading.Lock()
        self._wake: asyncio.Event | None = None
        self._closing = False
        self._subscribed: set[int] = set()
        self._channels: dict[str, int] = {}
        self._server = None
        self._stopped: asyncio.Future | None = None
        self.frames_queued = 0
        self.frames_sent = 0
        self.frames_dropped = 0
        self.messages_sent = 0

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

    @property
    def address(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def where_to_open(self) -> str:
        """The line a command prints so that its user can open the view."""
        return f"Foxglove live view: open {self.address} in Foxglove (Open connection, Foxglove WebSocket)"

    def report(self) -> dict:
        """Frames queued for the clients (those the rate allowed while a client was subscribed), sent
        and dropped for a slow client, and the messages sent."""
        return {"foxglove": {"address": self.address, "frames_queued": self.frames_queued,
                             "frames_sent": self.frames_sent, "frames_dropped_slow_client": self.frames_dropped,
                             "messages_sent": self.messages_sent}}

    def write(self, frame: FrameResult) -> None:
        if not self._rate.allows(frame.stamp_ns) or not self._subscribed:
            return
        with self._queue_lock:
            if len(self._queue) == self.queue_frames:
                self._queue.popleft()
                self.frames_dropped += 1
            self._queue.append(frame)
            self.frames_queued += 1
            wake = len(self._queue) == 1  # otherwise the server thread is already sending the queue
        if wake:
            self._loop.call_soon_threadsafe(self._wake.set)

    def close(self) -> None:
        """Sends what is queued (for at most ``DRAIN_TIMEOUT_S``: a client that stopped reading cannot
        hold the session open), then stops the server."""
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
                                    logger=logging.getLogger(f"{__name__}.foxglove"),
                                    server_kwargs={"compression": None, "close_timeout": CLOSE_TIMEOUT_S})
            server.start()
            opened = await asyncio.wait_for(server.wait_opened(), self._start_timeout_s)
        self._server = server
        server.set_listener(Subscriptions())
        self.port = opened.sockets[0].getsockname()[1]
        for topic, name, schema in self._topics():
            self._channels[topic] = await server.add_channel({
                "topic": topic, "encoding": "json", "schemaName": name,
                "schema": json.dumps(schema), "schemaEncoding": "jsonschema"})
        self._wake = asyncio.Event()
        sender = asyncio.create_task(self._send_queued())
        self._ready.set()
        try:
            await self._stopped
            self._closing = True
            self._wake.set()
            await asyncio.wait_for(asyncio.shield(sender), DRAIN_TIMEOUT_S)
        except TimeoutError:
            pass  # a client that stopped reading: what it did not take is left unsent
        finally:
            sender.cancel()
            server.close()
            await server.wait_closed()

    def _topics(self) -> list[tuple[str, str, dict]]:
        stream, prefix = self._stream, self.prefix
        leaf, kind = reading_topic(stream.reading)
        topics = [(f"{prefix}/chip{k}/{topic}", kind, READING_SCHEMAS[kind])
                  for k in range(stream.chips) for topic in (leaf, "baseline")]
        topics.append((f"{prefix}/{leaf}_change", f"softtip/{leaf.capitalize()}Change", CHANGE_SCHEMA))
        if self._wrench:
            topics.append((f"{prefix}/wrench", WRENCH_STAMPED, WRENCH_SCHEMA))
        if stream.target_names:
            topics.append((f"{prefix}/estimates", FLOAT64_MULTI_ARRAY, ESTIMATES_SCHEMA))
        if stream.classes is not None:
            topics.append((f"{prefix}/contact_state", STRING, STATE_SCHEMA))
        return topics

    async def _send_queued(self) -> None:
        """Sends the queued frames in order, each message once the clients' connections took the one
        before (a slow client holds the queue up, and :meth:`write` drops its oldest frames)."""
        while True:
            await self._wake.wait()
            self._wake.clear()
            while True:
                with self._queue_lock:
                    if not self._queue:
                        break
                    frame = self._queue.popleft()
                for topic, message in self.messages(frame).items():
                    channel = self._channels[topic]
                    if channel in self._subscribed:
                        await self._server.send_message(channel, frame.stamp_ns, json.dumps(message).encode())
                        self.messages_sent += 1
                self.frames_sent += 1
            if self._closing:
                return

    def _reading_fields(self, values) -> dict:
        fields = reading_fields(self._stream.reading, values, _vector)
        fields.pop("magnetic_field_covariance", None)  # not sent live: it is in the recording
        return fields

    def messages(self, frame: FrameResult) -> dict[str, dict]:
        """The JSON messages of one frame, by topic (field values in T, forces in N, as in the recording)."""
        prefix, stream = self.prefix, self._stream
        leaf, _ = reading_topic(stream.reading)
        sec, nanosec = divmod(frame.stamp_ns, 1_000_000_000)
        stamp = {"sec": sec, "nanosec": nanosec}
        messages = {}
        for k in range(stream.chips):
            header = {"stamp": stamp, "frame_id": frame_id(prefix, k)}
            messages[f"{prefix}/chip{k}/{leaf}"] = {"header": header, **self._reading_fields(frame.reading[k])}
            if frame.baseline is not None:
                messages[f"{prefix}/chip{k}/baseline"] = {"header": header,
                                                          **self._reading_fields(frame.baseline[k])}
        if frame.change is not None:
            messages[f"{prefix}/{leaf}_change"] = {"stamp": stamp,
                                                   "chips": [_vector(c) for c in in_xyz(stream.reading, frame.change)]}
        if frame.estimates is not None:
            if self._wrench:
                wrench = wrench_values(frame.estimates, self._wrench)
                messages[f"{prefix}/wrench"] = {"header": {"stamp": stamp, "frame_id": frame_id(prefix)},
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
