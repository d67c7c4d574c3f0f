"""A ROS 2 node publishing the live stream on the recording's topics (optional: ``softtip[ros2]``).

Needs ``rclpy`` and the standard message packages (``sensor_msgs``, ``geometry_msgs``,
``std_msgs``, ``std_srvs``) with a middleware: ``pip install 'softtip[ros2]'`` installs them from
ROS 2's PyPI wheels, whose own start-up hook sets the library path (``LD_LIBRARY_PATH``) when Python
starts; a sourced ROS 2 installation serves as well. Neither ``AMENT_PREFIX_PATH`` nor
``RMW_IMPLEMENTATION`` is needed. Without ROS 2 this module still imports: :func:`ros2_problem` says
in one line what is missing and :class:`ROS2Sink` refuses with that line, before rcl could end the
process (as it does when ``RMW_IMPLEMENTATION`` names a middleware that is not installed).

Topics and types are those of :mod:`softtip.realtime.recording.format` (MagneticField per Hall
chip and per baseline, or WrenchStamped per force chip, WrenchStamped estimates, Float64MultiArray
of the estimates, String contact state),
so a node subscribed to the live topics also reads ``ros2 bag play`` of a recording. The
node offers the service ``~/take_baseline`` (std_srvs/srv/Trigger): the insertion task's
"take the baseline" step.

Delivery: the publishers are reliable and keep the last ``qos_depth`` messages per topic for
subscribers that fall behind (2500: five seconds at 500 frames/s), and they are transient-local, so a
subscriber that asks for transient-local durability also receives the messages published before
discovery matched it (discovery took 1.4-2.5 s to match a running subscriber on a 2-core machine at
load average 13), and a volatile subscriber (ROS 2's default) receives only from its match on. At the end the node stays
until it is ``DISCOVERY_S`` old (so a short run still reaches subscribers that were waiting for it),
then waits up to ``ack_timeout_s`` for every reliable subscriber to acknowledge every message.
Messages are packed as CDR bytes with :mod:`struct` (a few µs each, against some 50 µs for building
rclpy message objects) by a publisher thread that sends the frames queued since its last pass every
``publish_interval_s`` (5 ms: at 500 frames/s a few frames per pass), keeping the ROS work out of the
acquisition thread.
"""

from __future__ import annotations

import collections
import importlib
import os
import re
import struct
import sys
import threading
import time
from pathlib import Path

import numpy as np

from softtip._core.extras import MissingExtra, install_hint
from softtip.realtime.frames import FrameResult, StreamInfo
from softtip.realtime.recording.format import (
    DEFAULT_PREFIX,
    MAGNETIC_FIELD,
    VECTOR3_STAMPED,
    WRENCH_FLOATS,
    frame_id,
    in_xyz,
    magnetic_covariance_T2,
    per_message_unit,
    reading_topic,
    wrench_mapping,
    wrench_values,
)
from softtip.realtime.sinks.base import Sink

ROS2_EXTRA = install_hint("ros2")
_MODULES = ("rclpy", "rclpy.executors", "rclpy.qos", "rclpy.duration", "sensor_msgs.msg", "geometry_msgs.msg",
            "std_msgs.msg", "std_srvs.srv")
_MISSING_LIBRARY = re.compile(r"(\S+\.so[.\d]*): cannot open shared object file")
_CDR_LE = b"\x00\x01\x00\x00"  # the encapsulation header of little-endian CDR
DISCOVERY_S = 2.0  # how long discovery may take to match a running subscriber (1.4-2.5 s measured, loaded)


class ROS2Unavailable(MissingExtra):
    """ROS 2 cannot be used here; the message says why and what to install or set, in one line."""


def _library_folders() -> list[Path]:
    """Where the ROS 2 wheels put their shared libraries: the environment's ``lib`` and the wheels'
    ``ros_*.libs`` folders (what their start-up hook puts on ``LD_LIBRARY_PATH``)."""
    site = Path(sys.prefix, "lib", f"python{sys.version_info.major}.{sys.version_info.minor}", "site-packages")
    return [Path(sys.prefix, "lib"), *sorted(site.glob("ros_*.libs"))]


def _middleware_problem() -> str | None:
    """Why the middleware ``RMW_IMPLEMENTATION`` names cannot load, or None (unset: rcl's default)."""
    name = os.environ.get("RMW_IMPLEMENTATION")
    if not name:
        return None
    folders = [Path(p) for p in os.environ.get("LD_LIBRARY_PATH", "").split(os.pathsep) if p] + _library_folders()
    if any((folder / f"lib{name}.so").is_file() for folder in folders):
        return None
    return (f"RMW_IMPLEMENTATION = {name}: no lib{name}.so on the library path; unset it (softtip[ros2] brings "
            f"rmw_fastrtps_cpp) or install that middleware")


def _import_ros() -> dict:
    """The ROS 2 modules this node uses; :class:`ROS2Unavailable` in one line when they cannot be used."""
    try:
        modules = {name: importlib.import_module(name) for name in _MODULES}
    except ImportError as error:
        missing = _MISSING_LIBRARY.search(str(error))
        if missing is None:
            raise ROS2Unavailable(f"ROS 2 is not installed ({error.name or 'rclpy'} does not import): "
                                  f"{ROS2_EXTRA}") from None
        folders = os.pathsep.join(str(folder) for folder in _library_folders())
        raise ROS2Unavailable(f"ROS 2 is installed but its library {missing.group(1)} does not load: Python started "
                              f"without the ROS 2 wheels' library path (their start-up hook was skipped); start it "
                              f"with LD_LIBRARY_PATH={folders}") from None
    problem = _middleware_problem()
    if problem is not None:
        raise ROS2Unavailable(problem)
    return modules


def ros2_problem() -> str | None:
    """Why ROS 2 cannot be used here (one line naming what to install or set), or None when it can."""
    try:
        _import_ros()
    except ROS2Unavailable as error:
        return str(error)
    return None


def ros2_available() -> bool:
    """Whether rclpy, the standard message packages and the middleware can be used."""
    return ros2_problem() is None


def _cdr_string(text: str) -> bytes:
    """A CDR string: its length with the terminating NUL, the bytes, the NUL."""
    data = text.encode() + b"\0"
    return struct.pack("<I", len(data)) + data


def _pad(offset: int, alignment: int) -> int:
    """Bytes that align ``offset`` (from the start of the CDR body) to ``alignment``."""
    return -offset % alignment


class StampedPacker:
    """CDR bytes of a message made of a ``std_msgs/Header`` with a fixed frame id and then ``count``
    float64 (MagneticField: field then covariance; WrenchStamped: force then torque; Vector3Stamped);
    ``constant`` float64 values (a MagneticField's covariance) end every message."""

    def __init__(self, frame: str, count: int, constant: tuple[float, ...] = ()) -> None:
        name = _cdr_string(frame)
        header = 8 + len(name)  # stamp, then the frame id
        self._struct = struct.Struct(f"<4siI{len(name)}s{_pad(header, 8)}x{count + len(constant)}d")
        self._name, self._constant = name, constant

    def pack(self, stamp_ns: int, values) -> bytes:
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        return self._struct.pack(_CDR_LE, sec, nanosec, self._name, *values, *self._constant)


class ArrayPacker:
    """CDR bytes of a ``std_msgs/Float64MultiArray`` of ``size`` values in one dimension labelled ``label``."""

    def __init__(self, label: str, size: int) -> None:
        name = _cdr_string(label)
        # one dimension (its label, size and stride), the data offset, then the data's length
        self._head = (struct.pack("<I", 1) + name + bytes(_pad(4 + len(name), 4))
                      + struct.pack("<IIII", size, size, 0, size))
        self._struct = struct.Struct(f"<4s{len(self._head)}s{_pad(len(self._head), 8)}x{size}d")

    def pack(self, values) -> bytes:
        return self._struct.pack(_CDR_LE, self._head, *values)


def string_message(text: str) -> bytes:
    """CDR bytes of a ``std_msgs/String``."""
    return _CDR_LE + _cdr_string(text)


class ROS2Sink(Sink):
    """Publishes each frame on ROS 2 topics under ``prefix`` from a node named ``node_name``
    (module notes). ``qos_depth``: the messages each publisher keeps for late or slow subscribers."""

    def __init__(self, node_name: str = "softtip_fingertip", *, prefix: str = DEFAULT_PREFIX, qos_depth: int = 2500,
                 publish_interval_s: float = 0.005, ack_timeout_s: float = 2.0) -> None:
        self._ros = _import_ros()
        self.node_name = node_name
        self.prefix = prefix
        self.qos_depth = qos_depth
        self.publish_interval_s = publish_interval_s
        self.ack_timeout_s = ack_timeout_s
        self._queue: collections.deque[FrameResult] = collections.deque()
        self._closing = threading.Event()
        self._threads: list[threading.Thread] = []
        self._owns_context = False
        self._opened_at = 0.0
        self.frames_published = 0
        self.messages_published = 0
        self.unacknowledged: list[str] = []  # topics a subscriber had not acknowledged in full at the end

    def open(self, stream: StreamInfo) -> None:
        rclpy, qos = self._ros["rclpy"], self._ros["rclpy.qos"]
        msg_sensor, msg_geometry, msg_std = (self._ros[n] for n in ("sensor_msgs.msg", "geometry_msgs.msg",
                                                                    "std_msgs.msg"))
        if not rclpy.ok():
            rclpy.init()
            self._owns_context = True
        self._stream = stream
        self._wrench = wrench_mapping(stream.target_names, stream.target_units)
        node = self._node = rclpy.create_node(self.node_name)
        self._opened_at = time.monotonic()
        profile = qos.QoSProfile(depth=self.qos_depth, reliability=qos.ReliabilityPolicy.RELIABLE,
                                 durability=qos.DurabilityPolicy.TRANSIENT_LOCAL)
        prefix = self.prefix
        self._reading = stream.reading
        self._per_message = per_message_unit(stream.reading)
        leaf, _ = reading_topic(stream.reading)
        message = stream.reading.message
        kind = {MAGNETIC_FIELD: msg_sensor.MagneticField, VECTOR3_STAMPED: msg_geometry.Vector3Stamped}.get(
            message, msg_geometry.WrenchStamped)
        # a MagneticField ends with its covariance; a force chip's WrenchStamped with a NaN torque
        values, constant = {MAGNETIC_FIELD: (3, tuple(magnetic_covariance_T2(stream.settings))),
                            VECTOR3_STAMPED: (3, ())}.get(message, (3, (np.nan,) * 3))
        self._chips = [StampedPacker(frame_id(prefix, k), values, constant) for k in range(stream.chips)]
        self._reading_publishers = [node.create_publisher(kind, f"{prefix}/chip{k}/{leaf}", profile)
                                    for k in range(stream.chips)]
        self._baseline_publishers = [node.create_publisher(kind, f"{prefix}/chip{k}/baseline", profile)
                                     for k in range(stream.chips)]
        self._wrench_packer = StampedPacker(frame_id(prefix), WRENCH_FLOATS)
        self._wrench_publisher = (node.create_publisher(msg_geometry.WrenchStamped, f"{prefix}/wrench", profile)
                                  if self._wrench else None)
        self._estimates_packer = ArrayPacker(",".join(stream.target_names), len(stream.target_names))
        self._estimates_publisher = (node.create_publisher(msg_std.Float64MultiArray, f"{prefix}/estimates", profile)
                                     if stream.target_names else None)
        self._states = {state: string_message(state) for state in stream.classes or ()}
        self._state_publisher = (node.create_publisher(msg_std.String, f"{prefix}/contact_state", profile)
                                 if stream.classes is not None else None)
        node.create_service(self._ros["std_srvs.srv"].Trigger, "~/take_baseline", self._take_baseline)
        self._baseline_version = None
        self._executor = self._ros["rclpy.executors"].SingleThreadedExecutor()
        self._executor.add_node(node)
        self._threads = [threading.Thread(target=self._executor.spin, name="ros2-executor", daemon=True),
                         threading.Thread(target=self._publish_loop, name="ros2-publisher", daemon=True)]
        for thread in self._threads:
            thread.start()

    def _take_baseline(self, request, response):
        self._stream.take_baseline()
        response.success = True
        response.message = "taking a new baseline"
        return response

    def report(self) -> dict:
        return {"ros2": {"node": self.node_name, "frames_published": self.frames_published,
                         "messages_published": self.messages_published,
                         "topics_not_acknowledged_at_end": self.unacknowledged}}

    def write(self, frame: FrameResult) -> None:
        self._queue.append(frame)

    def _publish_loop(self) -> None:
        while not self._closing.wait(self.publish_interval_s):
            while self._queue:
                self._publish(self._queue.popleft())

    def _send(self, publisher, data: bytes) -> None:
        publisher.publish(data)
        self.messages_published += 1

    def _publish_chips(self, publishers, stamp_ns: int, readings: np.ndarray) -> None:
        carried = in_xyz(self._reading, readings / self._per_message)  # a message's x, y, z are fixed
        for publisher, packer, values in zip(publishers, self._chips, carried.tolist(), strict=True):
            self._send(publisher, packer.pack(stamp_ns, values))

    def _publish(self, frame: FrameResult) -> None:
        stamp = frame.stamp_ns
        if frame.baseline is not None and frame.baseline_version != self._baseline_version:
            self._baseline_version = frame.baseline_version
            self._publish_chips(self._baseline_publishers, stamp, frame.baseline)
        self._publish_chips(self._reading_publishers, stamp, frame.reading)
        if frame.estimates is not None:
            if self._wrench_publisher is not None:
                self._send(self._wrench_publisher,
                           self._wrench_packer.pack(stamp, wrench_values(frame.estimates, self._wrench).tolist()))
            if self._estimates_publisher is not None:
                self._send(self._estimates_publisher, self._estimates_packer.pack(frame.estimates.tolist()))
        if frame.state is not None and self._state_publisher is not None:
            self._send(self._state_publisher, self._states.get(frame.state) or string_message(frame.state))
        self.frames_published += 1

    def _publishers(self) -> list:
        return [p for p in (*self._reading_publishers, *self._baseline_publishers, self._wrench_publisher,
                            self._estimates_publisher, self._state_publisher) if p is not None]

    def close(self) -> None:
        """Publishes what is queued, waits (``ack_timeout_s`` at most) for the subscribers to acknowledge
        it, and leaves."""
        if not self._threads:
            return
        self._closing.set()
        self._threads[1].join()
        while self._queue:
            self._publish(self._queue.popleft())
        # a young node stays until subscribers already running have had time to discover it
        time.sleep(max(0.0, self._opened_at + DISCOVERY_S - time.monotonic()))
        deadline = time.monotonic() + self.ack_timeout_s
        duration = self._ros["rclpy.duration"].Duration
        self.unacknowledged = [publisher.topic_name for publisher in self._publishers()
                               if not publisher.wait_for_all_acked(
                                   duration(seconds=max(0.0, deadline - time.monotonic())))]
        self._executor.shutdown()
        self._threads[0].join()
        self._node.destroy_node()
        if self._owns_context:
            self._ros["rclpy"].shutdown()
        self._threads = []
