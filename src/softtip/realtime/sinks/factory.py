"""The command line's choice of sinks."""

from __future__ import annotations

import os
import sys

from rich.console import Console

from softtip.realtime.sinks.base import Sink
from softtip.realtime.sinks.dashboard import DashboardSink
from softtip.realtime.sinks.foxglove import FoxgloveSink
from softtip.realtime.sinks.recorder import RecorderSink
from softtip.realtime.sinks.ros2 import ROS2Sink


def live_sinks(*, dashboard: bool = True, record: str | os.PathLike | None = None, foxglove_port: int | None = None,
               ros2: bool = False, console: Console | None = None) -> list[Sink]:
    """The sinks of ``softtip live``: the dashboard (its re-zero key read from standard input when
    that is a terminal), an MCAP recording, a Foxglove live view on ``foxglove_port`` and a ROS 2
    node, each when asked for."""
    sinks: list[Sink] = []
    if dashboard:
        sinks.append(DashboardSink(console, keys=sys.stdin.fileno() if sys.stdin and sys.stdin.isatty() else None))
    if record is not None:
        sinks.append(RecorderSink(record))
    if foxglove_port is not None:
        sinks.append(FoxgloveSink(foxglove_port))
    if ros2:
        sinks.append(ROS2Sink())
    return sinks
