"""Real-time estimation: the live pipeline, its sinks, MCAP recording and conversion.

- :mod:`~softtip.realtime.pipeline`: :class:`Pipeline` (source -> baseline -> estimators
  -> sinks, in the acquisition thread), :class:`Estimator` (any model with ``predict``,
  ``predict_one`` used when present), :class:`LiveSession` and :func:`run_live` (a
  fingertip or an emulated one, its driver and a pipeline), :class:`EmulatorProcess`;
- :mod:`~softtip.realtime.baseline`: initial-value subtraction at start and on command,
  optional gated drift tracking;
- :mod:`~softtip.realtime.sinks`: :class:`RecorderSink` (MCAP), :class:`DashboardSink`
  (terminal), :class:`FoxgloveSink` (Foxglove WebSocket live view), :func:`live_sinks`;
- :mod:`~softtip.realtime.mcap_record`: ROS 2 message types in CDR, written chunk by chunk
  so that a killed process leaves a readable file, and :func:`read_recording`;
- :mod:`~softtip.realtime.convert`: MCAP recordings to the Parquet trial dataset;
- :mod:`~softtip.realtime.ros2`: :class:`ROS2Sink`, a ROS 2 node on the same topics (needs
  rclpy);
- :mod:`~softtip.realtime.bench`: :func:`soak`, the endurance and speed benchmark.
"""

from softtip.realtime.baseline import Baseline, drift_step
from softtip.realtime.bench import soak
from softtip.realtime.convert import Conversion, convert
from softtip.realtime.mcap_record import (
    McapRecorder,
    Recording,
    RecordingError,
    read_recording,
)
from softtip.realtime.pipeline import (
    EMULATOR,
    AcquisitionClock,
    EmulatorProcess,
    Estimator,
    FrameResult,
    LiveSession,
    Pipeline,
    PressCycle,
    Sink,
    StreamInfo,
    run_live,
)
from softtip.realtime.ros2 import ROS2Sink, ros2_available
from softtip.realtime.sinks import DashboardSink, FoxgloveSink, RecorderSink, live_sinks

__all__ = [
    "EMULATOR",
    "AcquisitionClock",
    "Baseline",
    "Conversion",
    "DashboardSink",
    "EmulatorProcess",
    "Estimator",
    "FoxgloveSink",
    "FrameResult",
    "LiveSession",
    "McapRecorder",
    "Pipeline",
    "PressCycle",
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
    "soak",
]
