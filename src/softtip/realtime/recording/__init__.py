"""MCAP recordings of the live stream in ROS 2 message types, reading them back, and their
conversion to the trial dataset.

- :mod:`~softtip.realtime.recording.format`: the message types, topics and units;
- :mod:`~softtip.realtime.recording.writer`: :class:`McapRecorder`, flushed chunk by chunk;
- :mod:`~softtip.realtime.recording.reader`: :func:`read_recording`, also of a cut-short file;
- :mod:`~softtip.realtime.recording.convert`: :func:`convert`, a recording to a Parquet dataset.
"""

from softtip.realtime.recording.convert import Conversion, convert
from softtip.realtime.recording.format import RecordingError
from softtip.realtime.recording.reader import Recording, TopicMessages, read_recording
from softtip.realtime.recording.writer import McapRecorder

__all__ = [
    "Conversion",
    "McapRecorder",
    "Recording",
    "RecordingError",
    "TopicMessages",
    "convert",
    "read_recording",
]
