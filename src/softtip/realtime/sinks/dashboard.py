"""A terminal dashboard of the live stream.

:class:`DashboardSink` keeps the latest frame for a `rich` live display refreshed a few
times per second (the change per chip and axis, the estimates, the contact state, the
frame rate, lost frames, latency and baseline state). Given a terminal to read keys from
(``keys``: its file descriptor), it puts that terminal in cbreak mode while open and takes a new
baseline when ``z`` is pressed (re-zero), as ``kill -USR1`` does.
"""

from __future__ import annotations

import collections
import math
import os
import select
import termios
import time
import tty

from rich.console import Console, Group
from rich.live import Live
from rich.table import Table
from rich.text import Text

from softtip._core.config import PositiveNumber, checked
from softtip._core.threads import BackgroundThread
from softtip.realtime.frames import FrameResult, StreamInfo
from softtip.realtime.sinks.base import Sink


REZERO_KEY = "z"
_KEY_POLL_S = 0.1  # how often the key thread looks whether to stop


def _number(value: float, digits: int = 1) -> str:
    return "—" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


class DashboardSink(Sink):
    """A live terminal display (rich), refreshed ``refresh_hz`` times per second; rates and
    latency percentiles are over the last ``window_s`` seconds. ``keys``: the file descriptor of a
    terminal whose ``z`` key re-zeroes (module notes), or None."""

    def __init__(self, console: Console | None = None, *, refresh_hz: float = 4.0, window_s: float = 5.0,
                 keys: int | None = None) -> None:
        self.console = console
        self.refresh_hz = checked(PositiveNumber, "refresh_hz", refresh_hz)
        self.window_s = checked(PositiveNumber, "window_s", window_s)
        self._stream: StreamInfo | None = None
        self._latest: FrameResult | None = None
        self._frames = 0
        self._history: collections.deque[tuple[float, int]] = collections.deque()
        self._live: Live | None = None
        self.keys = keys
        self.rezero_requests = 0
        self._key_thread = BackgroundThread("dashboard-keys")
        self._terminal_mode: list | None = None

    def open(self, stream: StreamInfo) -> None:
        self._stream = stream
        if self.keys is not None:
            self._terminal_mode = termios.tcgetattr(self.keys)
            tty.setcbreak(self.keys)  # keys arrive one by one and are not echoed over the display
            self._key_thread.start(self._read_keys)
        self._live = Live(get_renderable=self.render, console=self.console, refresh_per_second=self.refresh_hz)
        self._live.start()

    def _read_keys(self) -> None:
        while not self._key_thread.closing.is_set():
            readable, _, _ = select.select([self.keys], [], [], _KEY_POLL_S)
            if not readable:
                continue
            key = os.read(self.keys, 1)
            if not key:  # the terminal is gone
                return
            if key.decode(errors="replace").lower() == REZERO_KEY:
                self.rezero_requests += 1
                self._stream.take_baseline()

    def write(self, frame: FrameResult) -> None:
        self._latest = frame
        self._frames += 1

    def close(self) -> None:
        self._key_thread.stop()
        if self._terminal_mode is not None:
            termios.tcsetattr(self.keys, termios.TCSADRAIN, self._terminal_mode)
            self._terminal_mode = None
        if self._live is not None:
            self._live.stop()
            if not self._live.console.is_terminal:  # the last display ends without a newline there
                self._live.console.line()
            self._live = None

    def _rate_hz(self) -> float:
        now, frames = time.monotonic(), self._frames
        self._history.append((now, frames))
        while self._history[0][0] < now - self.window_s:
            self._history.popleft()
        then, earlier = self._history[0]
        return (frames - earlier) / (now - then) if now > then else math.nan

    def render(self) -> Group:
        """The display for the latest frame and the current counters."""
        stream, frame = self._stream, self._latest
        rate = self._rate_hz()
        nominal_hz = stream.rate_hz or (rate if math.isfinite(rate) else 1.0)
        counters = stream.counters(latency_window=max(1, int(nominal_hz * self.window_s)))
        reading = stream.reading
        chips = Table(title=f"Change of {reading.quantity} ({reading.shown_unit})", expand=False)
        for column in ("chip", *(f"Δ{reading.symbol}{axis}" for axis in reading.axes), ""):
            chips.add_column(column, justify="right")
        for k in range(stream.chips):
            if frame is None or frame.change is None:
                values = ["—"] * len(reading.axes)
            else:
                values = [_number(v, reading.decimals) for v in frame.change[k]]
            flags = "" if frame is None else (
                "fault" if not frame.chip_ok[k] else ("saturated" if frame.saturated[k].any() else "ok"))
            chips.add_row(str(k), *values, flags)
        parts: list = [chips]
        if stream.target_names:
            estimates = Table(title="Estimates", expand=False)
            for column in ("target", "value", "unit"):
                estimates.add_column(column, justify="right")
            for i, (name, unit) in enumerate(zip(stream.target_names, stream.target_units, strict=True)):
                value = None if frame is None or frame.estimates is None else float(frame.estimates[i])
                estimates.add_row(name, _number(value, 3), unit)
            parts.append(estimates)
        if stream.classes is not None:
            state = "—" if frame is None or frame.state is None else frame.state
            parts.append(Text(f"contact state: {state}", style="bold"))
        latency = counters.get("latency_ms", {})
        baseline = ("taking" if counters.get("baseline_collecting") else "in use") + \
            f" (#{counters.get('baseline_version', 0)}, {counters.get('baseline_rezeroed_at_rest', 0)} at rest)"
        parts.append(Text(
            f"frames {counters.get('frames', 0)}  rate {_number(rate)} Hz  "
            f"lost {counters.get('lost_in_transit', 0)}  CRC errors {counters.get('crc_errors', 0)}  "
            f"chip faults {counters.get('with_chip_fault', 0)}  "
            f"latency p50 {_number(latency.get('p50'), 2)} / p99 {_number(latency.get('p99'), 2)} ms  "
            f"baseline {baseline}"))
        if self.keys is not None:
            parts.append(Text(f"{REZERO_KEY}: re-zero (take a new baseline)  Ctrl-C: stop", style="dim"))
        return Group(*parts)
