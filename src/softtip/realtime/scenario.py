"""Live scenarios: what ``softtip live --emulate --scenario NAME`` streams, as a registered system
describes it - an emulated sensor and the models that come with it.

A system's scenario function, ``scenario(progress, check) -> LiveScenario``, computes the readings
from its twin and trains or identifies its models once, keeping both in the cache (keyed by the
protocol, the design and the code: :func:`softtip.lab.protocols.trained_model_path`), so a warm start
streams its first frame within seconds. It calls ``check(chips, rate_hz)`` (a :data:`StreamCheck`)
with the stream's chips and own rate (None: the command's) as soon as it knows them, before any of
that work, so a command whose options disagree with the scenario stops at once.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from softtip.hardware import PacedSource
from softtip.sensors.registry import ChipSettings

StreamCheck = Callable[[int, float | None], None]


def accept_any_stream(chips: int, rate_hz: float | None) -> None:
    """The :data:`StreamCheck` of a caller that takes the scenario as it comes."""


@dataclass(frozen=True)
class LiveScenario:
    """An emulated stream: ``source`` is ``"emulator"`` (a fingertip board behind a pseudo-terminal in
    the firmware's protocol, its chips reading ``emulator_source(t_s) -> (chips, 3)`` µT at
    ``settings``, a registered sensor at its settings, :meth:`softtip.sensors.registry.SensorKind.at`)
    or a :class:`~softtip.hardware.PacedSource` (a sensor with no softtip firmware, stating its own);
    ``models``: the model files it comes with; ``chips``: how many it streams; ``rate_hz``: its own
    rate, when it has one (a paced source), else the command's; ``baseline_frames``: the frames its
    baseline averages (a protocol's tare is one)."""

    description: str
    source: str | PacedSource
    models: tuple[Path, ...]
    chips: int
    emulator_source: Callable[[float], np.ndarray] | None = None
    settings: ChipSettings | None = None
    rate_hz: float | None = None
    baseline_frames: int = 50
