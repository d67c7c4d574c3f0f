"""The base of the live pipeline's sinks."""

from __future__ import annotations

from softtip.realtime.frames import FrameResult, StreamInfo


class Sink:
    """A consumer of frames. ``write`` runs in the acquisition thread and must not block:
    a sink with slow work hands frames to its own thread."""

    def open(self, stream: StreamInfo) -> None:
        """Called once, before the first frame."""

    def write(self, frame: FrameResult) -> None:
        raise NotImplementedError

    def close(self) -> None:
        """Called once, after the last frame; finishes the sink's work."""

    def report(self) -> dict:
        """What the sink counted, for the session's summary, under the sink's name ({}: nothing)."""
        return {}

