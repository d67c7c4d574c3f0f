"""The base of the live pipeline's sinks."""

from __future__ import annotations

import math

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


def positive(name: str, value: object) -> float:
    """``value`` as a float, or a one-line ValueError naming ``name`` unless it is a finite positive number."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0 or not math.isfinite(value):
        raise ValueError(f"{name} = {value!r}: expected a positive number")
    return float(value)
