"""Real-time estimation: the live pipeline, its sinks, MCAP recording and conversion.

- :mod:`~softtip.realtime.frames`: :class:`FrameResult` (one frame after the pipeline) and
  :class:`StreamInfo` (what sinks learn about the stream);
- :mod:`~softtip.realtime.estimator`: :class:`Estimator` (any model with ``predict``,
  ``predict_one`` used when present);
- :mod:`~softtip.realtime.clock`: :class:`AcquisitionClock`, acquisition times on the host's
  wall clock from the device clock;
- :mod:`~softtip.realtime.baseline`: initial-value subtraction at start and on command,
  optional gated drift tracking;
- :mod:`~softtip.realtime.pipeline`: :class:`Pipeline` (source -> baseline -> estimators
  -> sinks, in the acquisition thread);
- :mod:`~softtip.realtime.session`: :class:`LiveSession` and :func:`run_live` (a fingertip or
  an emulated one in a child process, its driver and a pipeline);
- :mod:`~softtip.realtime.sinks`: :class:`RecorderSink` (MCAP), :class:`DashboardSink`
  (terminal), :class:`FoxgloveSink` (Foxglove WebSocket live view), :class:`ROS2Sink` (a ROS 2
  node, needs rclpy), :func:`live_sinks`;
- :mod:`~softtip.realtime.recording`: ROS 2 message types in MCAP, written chunk by chunk so
  that a killed process leaves a readable file, :func:`read_recording`, and :func:`convert`
  to the Parquet trial dataset.

The soak benchmark is :func:`softtip.bench.live.soak`.
"""

from softtip.realtime.baseline import Baseline, drift_step
from softtip.realtime.clock import AcquisitionClock
from softtip.realtime.estimator import Estimator
from softtip.realtime.frames import FrameResult, StreamInfo
from softtip.realtime.pipeline import Pipeline
from softtip.realtime.recording import Conversion, McapRecorder, Recording, RecordingError, convert, read_recording
from softtip.realtime.session import EMULATOR, LiveSession, run_live
from softtip.realtime.sinks import (
    DashboardSink,
    FoxgloveSink,
    RecorderSink,
    ROS2Sink,
    Sink,
    live_sinks,
    ros2_available,
)

__all__ = [
    "EMULATOR",
    "AcquisitionClock",
    "Baseline",
    "Conversion",
    "DashboardSink",
    "Estimator",
    "FoxgloveSink",
    "FrameResult",
    "LiveSession",
    "McapRecorder",
    "Pipeline",
    "ROS2Sink",
    "RecorderSink",
    "Recording",
    "RecordingError",
    "Sink",
    "StreamInfo",
    "convert",
    "drift_step",
    "live_sinks",
    "read_recording",
    "ros2_available",
    "run_live",
]
