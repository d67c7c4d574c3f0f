"""What the live pipeline hands on: one frame's result, and what sinks learn about the stream."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from softtip._core.channels import MAGNETIC, Reading
from softtip.sensors.registry import ChipSettings


class FrameResult(NamedTuple):
    """One frame after the pipeline.

    stamp_ns: acquisition time, ns since the Unix epoch; host_time_s: the driver's arrival
    stamp (perf_counter clock); device_time_s: the device clock, or None.
    reading: (chips, axes) reading in the stream's unit, on its axes only (:attr:`StreamInfo.reading`),
    NaN for a faulty chip; chip_ok (chips,), saturated (chips, axes).
    baseline: the baseline in use (read-only, replaced when it changes) or None before
    the first one; baseline_version counts the baselines used so far.
    change: reading minus baseline, or None. estimates: the regression targets in
    :attr:`StreamInfo.target_names` order, state: the contact state; both None when the
    frame was not estimated. latency_s: arrival to estimate ready.
    """

    seq: int
    stamp_ns: int
    host_time_s: float
    device_time_s: float | None
    reading: np.ndarray
    chip_ok: np.ndarray
    saturated: np.ndarray
    baseline: np.ndarray | None
    baseline_version: int
    change: np.ndarray | None
    estimates: np.ndarray | None
    state: str | None
    latency_s: float


@dataclass(frozen=True)
class StreamInfo:
    """What sinks are told when the pipeline opens.

    ``reading``: what the chips read and in which unit (flux density in µT, or force in N);
    ``settings``: the chips' registered sensor at its settings (None when the source does not state them).

    counters(latency_window=None) returns the live counters (frames, lost frames, latency
    percentiles over the last latency_window frames...) as a dict; take_baseline() asks
    for a new baseline (a sink may offer it as a command).
    """

    chips: int
    target_names: tuple[str, ...]
    target_units: tuple[str, ...]
    classes: tuple[str, ...] | None
    settings: ChipSettings | None
    rate_hz: float | None
    metadata: dict = field(default_factory=dict)
    reading: Reading = MAGNETIC
    counters: Callable[..., dict] = lambda latency_window=None: {}
    take_baseline: Callable[[], None] = lambda: None
