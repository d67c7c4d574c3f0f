"""The whisker live: its twin brushed past a row of pegs, streamed at the TLV493D's low-power rate."""

from __future__ import annotations

import numpy as np

from softtip.plugin import MAGNETIC, LiveScenario, PacedSource
from softtip_whisker.bench import Realism
from softtip_whisker.tlv493d import TLV493DSettings, read_uT
from softtip_whisker.whisker import MM, Whisker, field_at_chip

SECONDS = 8.0
PEGS_PER_SECOND = 1.5
DEFLECTION_MM = 2.5
REST_S = 0.5  # still at the start: the stream's baseline


def brushing(whisker: Whisker, rate_hz: float) -> np.ndarray:
    """Sideways tip forces (N, 2) of a whisker swept past pegs: a deflection that rises and falls with each
    peg, its direction turning slowly as the sweep curves."""
    t = np.arange(round(SECONDS * rate_hz)) / rate_hz
    sweeping = t >= REST_S
    deflection = DEFLECTION_MM * MM * np.sin(np.pi * PEGS_PER_SECOND * (t - REST_S)) ** 2 * sweeping
    direction = 2 * np.pi * (t - REST_S) / SECONDS
    return np.column_stack([np.cos(direction), np.sin(direction)]) * (deflection / whisker.tip_compliance)[:, None]


def whisker_scenario(progress, check) -> LiveScenario:
    settings = TLV493DSettings()
    check(1, settings.rate_hz)
    whisker = Whisker()
    force = brushing(whisker, settings.rate_hz)
    with progress.task("the whisker's field along the sweep", total=1) as task:
        read, saturated = read_uT(field_at_chip(whisker, force), settings, np.random.default_rng(0),
                                  Realism().noise_uT)
        task.advance(1)
    source = PacedSource(read[:, None, :], settings.rate_hz, reading=MAGNETIC, saturated=saturated[:, None, :],
                         name="whisker")
    return LiveScenario("a whisker brushed past pegs, its direction turning", source, (), chips=1,
                        rate_hz=settings.rate_hz, baseline_frames=round(REST_S * settings.rate_hz) // 2)
