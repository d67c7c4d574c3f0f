"""Sinks of the live pipeline; each sink's ``write`` runs in the acquisition thread and only hands
the frame over.

- :mod:`~softtip.realtime.sinks.base`: :class:`Sink`, the interface;
- :mod:`~softtip.realtime.sinks.recorder`: :class:`RecorderSink`, the MCAP recording;
- :mod:`~softtip.realtime.sinks.dashboard`: :class:`DashboardSink`, a terminal display;
- :mod:`~softtip.realtime.sinks.foxglove`: :class:`FoxgloveSink`, a Foxglove WebSocket live view;
- :mod:`~softtip.realtime.sinks.ros2`: :class:`ROS2Sink`, a ROS 2 node on the recording's topics
  (needs rclpy);
- :mod:`~softtip.realtime.sinks.factory`: :func:`live_sinks`, the command line's choice.
"""

from softtip.realtime.sinks.base import Sink
from softtip.realtime.sinks.dashboard import DashboardSink
from softtip.realtime.sinks.factory import live_sinks
from softtip.realtime.sinks.foxglove import FoxgloveSink
from softtip.realtime.sinks.recorder import RecorderSink
from softtip.realtime.sinks.ros2 import ROS2Sink, ros2_available

__all__ = ["DashboardSink", "FoxgloveSink", "ROS2Sink", "RecorderSink", "Sink", "live_sinks", "ros2_available"]
