"""The MCAP recorder sink: frames queued for a writer thread that flushes the file every interval.

:class:`RecorderSink` queues frames for a writer thread that, every ``flush_interval_s``,
serialises the batch (:class:`~softtip.realtime.recording.writer.McapRecorder`) and flushes
it to the file, so a killed process loses at most that interval.
"""

from __future__ import annotations

import collections
import os
from pathlib import Path

from softtip._core.config import PositiveNumber, checked
from softtip._core.threads import BackgroundThread
from softtip.realtime.frames import FrameResult, StreamInfo
from softtip.realtime.recording.format import DEFAULT_PREFIX, RecordingError, magnetic_covariance_T2
from softtip.realtime.recording.writer import McapRecorder
from softtip.realtime.sinks.base import Sink


class RecorderSink(Sink):
    """Records the stream to an MCAP file (see :mod:`softtip.realtime.recording`).

    A writer thread serialises and writes the frames queued since its last pass every
    ``flush_interval_s`` and then flushes the file; ``chunk_size``, ``compression``,
    ``fsync`` and ``prefix`` go to the recorder. The queue is unbounded: it only grows
    while the disk stalls (about 100 kB per second at 500 frames/s).
    """

    def __init__(self, path: str | os.PathLike, *, flush_interval_s: float = 0.5, chunk_size: int = 256 * 1024,
                 compression: str = "zstd", fsync: bool = False, prefix: str = DEFAULT_PREFIX) -> None:
        self.path = Path(path)
        if not self.path.parent.is_dir():
            raise RecordingError(f"recording {self.path}: directory {self.path.parent} does not exist")
        self.flush_interval_s = checked(PositiveNumber, "flush_interval_s", flush_interval_s)
        self._options = {"chunk_size": chunk_size, "compression": compression, "fsync": fsync, "prefix": prefix}
        self._queue: collections.deque[FrameResult] = collections.deque()
        self._writer = BackgroundThread("mcap-writer")
        self.recorder: McapRecorder | None = None
        self.error: BaseException | None = None
        self.frames_flushed = 0  # frames in the file even if the process is killed now

    def open(self, stream: StreamInfo) -> None:
        covariance = magnetic_covariance_T2(stream.settings)
        self.recorder = McapRecorder(self.path, stream.chips, target_names=stream.target_names,
                                     target_units=stream.target_units, classes=stream.classes,
                                     covariance_T2=covariance, metadata=stream.metadata, reading=stream.reading,
                                     **self._options)
        self._writer.start(self._run)

    def write(self, frame: FrameResult) -> None:
        self._queue.append(frame)

    def _write_queued(self) -> None:
        batch = [self._queue.popleft() for _ in range(len(self._queue))]
        self.recorder.write_frames(batch)
        self.recorder.flush()
        self.frames_flushed = self.recorder.frames_written

    def _run(self) -> None:
        try:
            while not self._writer.closing.wait(self.flush_interval_s):
                self._write_queued()
        except Exception as error:  # the stream goes on; close() reports the failure in one line
            self.error = error

    def close(self) -> None:
        """Writes what is queued, then the summary and footer."""
        if not self._writer.stop():
            return
        if self.error is None:
            try:
                self._write_queued()
            except Exception as error:  # reported below, once the file is closed
                self.error = error
        self.recorder.close()
        if self.error is not None:
            raise RecordingError(f"recording {self.path} stopped early: {self.error}") from self.error
