"""A ROS 2 node publishing the live stream on the recording's topics (optional).

Needs ``rclpy`` and the standard message packages (``sensor_msgs``, ``geometry_msgs``,
``std_msgs``, ``std_srvs``), which come with a ROS 2 installation, not from PyPI: source
the ROS 2 setup script before starting Python. Without them this module still imports;
:func:`ros2_available` says False and :class:`ROS2Sink` refuses with one line.

Topics and types are those of :mod:`softtip.realtime.recording.format` (MagneticField per Hall
chip and per baseline, or WrenchStamped per force chip, WrenchStamped estimates, Float64MultiArray
of the estimates, String contact state),
so a node subscribed to the live topics also reads ``ros2 bag play`` of a recording. The
node offers the service ``~/take_baseline`` (std_srvs/srv/Trigger): the insertion task's
"take the baseline" step. A publisher thread sends the frames queued since its last pass
every ``publish_interval_s`` (default 5 ms: at 500 frames/s a few frames per pass),
keeping the ROS work out of the acquisition thread.
"""

from __future__ import annotations

import collections
import importlib
import threading

import numpy as np

from softtip.realtime.frames import FrameResult, StreamInfo
from softtip.realtime.recording.format import (
    DEFAULT_PREFIX,
    MAGNETIC_FIELD,
    VECTOR3_STAMPED,
    WRENCH_STAMPED,
    frame_id,
    magnetic_covariance_T2,
    per_message_unit,
    reading_topic,
    wrench_mapping,
    wrench_values,
)
from softtip.realtime.sinks.base import Sink


def _import_ros():
    """The ROS 2 modules this node uses, or None when they are not importable."""
    try:
        return {name: importlib.import_module(name) for name in
                ("rclpy", "rclpy.executors", "sensor_msgs.msg", "geometry_msgs.msg", "std_msgs.msg",
                 "std_srvs.srv")}
    except ImportError:
        return None


def ros2_available() -> bool:
    """Whether rclpy and the standard message packages can be imported."""
    return _import_ros() is not None


class ROS2Sink(Sink):
    """Publishes each frame on ROS 2 topics under ``prefix`` from a node named ``node_name``
    (module notes). ``qos_depth``: the publishers' history depth."""

    def __init__(self, node_name: str = "softtip_fingertip", *, prefix: str = DEFAULT_PREFIX, qos_depth: int = 100,
                 publish_interval_s: float = 0.005) -> None:
        self._ros = _import_ros()
        if self._ros is None:
            raise RuntimeError("ROS 2 is not available: rclpy and the standard message packages do not import "
                               "(source the ROS 2 setup script first)")
        self.node_name = node_name
        self.prefix = prefix
        self.qos_depth = qos_depth
        self.publish_interval_s = publish_interval_s
        self._queue: collections.deque[FrameResult] = collections.deque()
        self._closing = threading.Event()
        self._threads: list[threading.Thread] = []
        self._owns_context = False

    def open(self, stream: StreamInfo) -> None:
        rclpy = self._ros["rclpy"]
        msg_sensor, msg_geometry, msg_std = (self._ros[n] for n in ("sensor_msgs.msg", "geometry_msgs.msg",
                                                                    "std_msgs.msg"))
        if not rclpy.ok():
            rclpy.init()
            self._owns_context = True
        self._stream = stream
        self._wrench = wrench_mapping(stream.target_names, stream.target_units)
        self._covariance = magnetic_covariance_T2(stream.settings).tolist()
        node = self._node = rclpy.create_node(self.node_name)
        depth, prefix = self.qos_depth, self.prefix
        self._per_message = per_message_unit(stream.reading)
        leaf, _ = reading_topic(stream.reading)
        kind = {MAGNETIC_FIELD: msg_sensor.MagneticField, VECTOR3_STAMPED: msg_geometry.Vector3Stamped}.get(
            stream.reading.message, msg_geometry.WrenchStamped)
        self._reading_publishers = [node.create_publisher(kind, f"{prefix}/chip{k}/{leaf}", depth)
                                    for k in range(stream.chips)]
        self._baseline_publishers = [node.create_publisher(kind, f"{prefix}/chip{k}/baseline", depth)
                                     for k in range(stream.chips)]
        self._wrench_publisher = (node.create_publisher(msg_geometry.WrenchStamped, f"{prefix}/wrench", depth)
                                  if self._wrench else None)
        self._estimates_publisher = (node.create_publisher(msg_std.Float64MultiArray, f"{prefix}/estimates", depth)
                                     if stream.target_names else None)
        self._state_publisher = (node.create_publisher(msg_std.String, f"{prefix}/contact_state", depth)
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

    def write(self, frame: FrameResult) -> None:
        self._queue.append(frame)

    def _publish_loop(self) -> None:
        while not self._closing.wait(self.publish_interval_s):
            while self._queue:
                self._publish(self._queue.popleft())

    def _header(self, frame: FrameResult, frame_id: str):
        header = self._ros["std_msgs.msg"].Header(frame_id=frame_id)
        header.stamp.sec, header.stamp.nanosec = divmod(frame.stamp_ns, 1_000_000_000)
        return header

    def _wrench_stamped(self, frame: FrameResult, frame_id: str, wrench: np.ndarray):
        """A WrenchStamped of force (N) and torque (N m): 6 values."""
        message = self._ros["geometry_msgs.msg"].WrenchStamped(header=self._header(frame, frame_id))
        (message.wrench.force.x, message.wrench.force.y, message.wrench.force.z,
         message.wrench.torque.x, message.wrench.torque.y, message.wrench.torque.z) = map(float, wrench)
        return message

    def _reading(self, frame: FrameResult, chip: int, reading: np.ndarray):
        """Chip ``chip``'s reading: a MagneticField (T), or a force chip's WrenchStamped (N, torque NaN)."""
        msg_sensor, msg_geometry = self._ros["sensor_msgs.msg"], self._ros["geometry_msgs.msg"]
        x, y, z = (float(v) / self._per_message for v in reading)
        if self._stream.reading.message == VECTOR3_STAMPED:
            return msg_geometry.Vector3Stamped(header=self._header(frame, frame_id(self.prefix, chip)),
                                               vector=msg_geometry.Vector3(x=x, y=y, z=z))
        if self._stream.reading.message == WRENCH_STAMPED:
            return self._wrench_stamped(frame, frame_id(self.prefix, chip), np.r_[x, y, z, np.full(3, np.nan)])
        return msg_sensor.MagneticField(header=self._header(frame, frame_id(self.prefix, chip)),
                                        magnetic_field=msg_geometry.Vector3(x=x, y=y, z=z),
                                        magnetic_field_covariance=self._covariance)

    def _publish(self, frame: FrameResult) -> None:
        msg_std = self._ros["std_msgs.msg"]
        if frame.baseline is not None and frame.baseline_version != self._baseline_version:
            self._baseline_version = frame.baseline_version
            for k, publisher in enumerate(self._baseline_publishers):
                publisher.publish(self._reading(frame, k, frame.baseline[k]))
        for k, publisher in enumerate(self._reading_publishers):
            publisher.publish(self._reading(frame, k, frame.reading[k]))
        if frame.estimates is not None:
            if self._wrench_publisher is not None:
                self._wrench_publisher.publish(self._wrench_stamped(frame, frame_id(self.prefix),
                                                                    wrench_values(frame.estimates, self._wrench)))
            if self._estimates_publisher is not None:
                n = len(frame.estimates)
                message = msg_std.Float64MultiArray(data=[float(v) for v in frame.estimates])
                message.layout.dim = [msg_std.MultiArrayDimension(label=",".join(self._stream.target_names),
                                                                  size=n, stride=n)]
                self._estimates_publisher.publish(message)
        if frame.state is not None and self._state_publisher is not None:
            self._state_publisher.publish(msg_std.String(data=frame.state))

    def close(self) -> None:
        if not self._threads:
            return
        self._closing.set()
        self._threads[1].join()
        while self._queue:
            self._publish(self._queue.popleft())
        self._executor.shutdown()
        self._threads[0].join()
        self._node.destroy_node()
        if self._owns_context:
            self._ros["rclpy"].shutdown()
        self._threads = []
