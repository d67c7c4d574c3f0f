"""The whisker's bench: a probe pushes the wire's tip sideways, in one direction per trial, to a set
deflection and back, while the TLV493D is read at its update rate; the probe's force is the label."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from softtip.plugin import (
    MAGNETIC,
    BenchKind,
    DatasetMetadata,
    NonNegativeNumber,
    PositiveNumber,
    TrialWriter,
    integer,
    protocol_file_schema,
    schema,
)
from softtip_whisker.tlv493d import LINEAR_RANGE_UT, TLV493DSettings, read_uT
from softtip_whisker.whisker import MM, Whisker, field_at_chip

LARGEST_TILT_RAD = 0.1  # the linear footing and beam hold for small tilts only
LABELS = {"fx_N": "N", "fy_N": "N"}


@schema(section="parameters")
class SweepParameters:
    """Trials: one push each, in evenly spread directions (calibration) or random ones (validation)."""

    calibration_trials: integer(2) = 12
    validation_trials: integer(1) = 6
    deflection_mm: PositiveNumber = 3.0
    push_s: PositiveNumber = 1.0  # to full deflection, and as long back
    rest_s: PositiveNumber = 0.2  # still before each push: the trial's baseline


@schema(section="realism")
class Realism:
    noise_uT: NonNegativeNumber = 100.0
    probe_direction_sd_deg: NonNegativeNumber = 2.0

    def to_dict(self) -> dict:
        return {"noise_uT": self.noise_uT, "probe_direction_sd_deg": self.probe_direction_sd_deg}


REALISM_SOURCES = {
    "noise_uT": "TLV493D-A1B6 data sheet: magnetic noise, typical rms",
    "probe_direction_sd_deg": "a hand-aligned probe: a guess, not measured",
}


@schema(section="viscoelastic")
class NoRelaxation:
    """The steel wire and the rubber's rocking are taken as elastic: no relaxation."""


ProtocolFile = protocol_file_schema(Realism, NoRelaxation, design=(Whisker, Whisker()),
                                    sensor=(TLV493DSettings, TLV493DSettings()))


@dataclass(frozen=True)
class Rig:
    """What a protocol file describes: the whisker and the chip's settings."""

    whisker: Whisker
    sensor: TLV493DSettings

    @property
    def name(self) -> str:
        return self.whisker.name

    @property
    def spec(self) -> dict:
        return {**self.whisker.spec, "sensor": self.sensor.to_dict()}


@dataclass(frozen=True)
class WhiskerBench:
    rig: Rig
    realism: Realism
    rng: np.random.Generator


def deflection_profile(p: SweepParameters, rate_hz: float) -> np.ndarray:
    """The tip's deflection (m) over one trial: at rest, then a linear push out and back."""
    rest = np.zeros(max(1, round(p.rest_s * rate_hz)))
    out = np.linspace(0.0, p.deflection_mm * MM, max(2, round(p.push_s * rate_hz)))
    return np.concatenate([rest, out, out[::-1][1:]])


def check_range(whisker: Whisker, deflection_mm: float) -> None:
    """Refuses a design or a push the model or the chip's linear range cannot take, before any trial."""
    if whisker.layer_mm < whisker.magnet_diameter_mm / 2:
        raise ValueError(f"design.layer_mm = {whisker.layer_mm}: expected at least the magnet's radius "
                         f"({whisker.magnet_diameter_mm / 2:g} mm), where the layer's stiffness factors hold")
    force = deflection_mm * MM / whisker.tip_compliance
    tilt = force * whisker.lever_m / whisker.rocking_stiffness
    if tilt > LARGEST_TILT_RAD:
        raise ValueError(f"parameters.deflection_mm = {deflection_mm}: tilts the magnet by {tilt:.3g} rad, "
                         f"expected at most {LARGEST_TILT_RAD} rad (the linear model's range)")
    pushed = np.vstack([np.zeros(2), force * np.eye(2)])  # at rest and fully pushed: the field's extremes
    largest = float(np.abs(field_at_chip(whisker, pushed)).max()) * 1e6
    if largest > LINEAR_RANGE_UT:
        raise ValueError(f"design: the magnet's field at the chip reaches {largest / 1e3:.4g} mT, expected at most "
                         f"{LINEAR_RANGE_UT / 1e3:g} mT (the TLV493D's linear range): a thicker layer or a "
                         "smaller magnet")


def sweep(bench: WhiskerBench, p: SweepParameters, seed: int, record: dict):
    whisker, sensor = bench.rig.whisker, bench.rig.sensor
    check_range(whisker, p.deflection_mm)
    writer = TrialWriter(dict.fromkeys(MAGNETIC.channel_names(1), MAGNETIC.unit), LABELS,
                         {"role": "1", "direction_deg": "deg"},
                         DatasetMetadata(description="a whisker pushed sideways over a TLV493D",
                                         design=whisker.spec, sensor_settings=sensor.to_dict(),
                                         protocol=record, seed=seed))
    deflection = deflection_profile(p, sensor.rate_hz)
    spread = np.arange(p.calibration_trials) * 360.0 / p.calibration_trials
    random = bench.rng.uniform(0.0, 360.0, p.validation_trials)
    for role, directions in (("calibration", spread), ("validation", random)):
        for direction in directions:
            sd = bench.realism.probe_direction_sd_deg
            pushed = np.deg2rad(direction + (bench.rng.normal(0.0, sd) if sd else 0.0))
            force = np.outer(deflection / whisker.tip_compliance, [np.cos(pushed), np.sin(pushed)])
            read, _ = read_uT(field_at_chip(whisker, force), sensor, bench.rng, bench.realism.noise_uT)
            change = (read - read[0])[:, None, :]  # from the trial's first reading, at rest
            writer.add({"time_s": np.arange(len(force)) / sensor.rate_hz, **MAGNETIC.columns(change),
                        "fx_N": force[:, 0], "fy_N": force[:, 1]},
                       {"role": role, "direction_deg": float(direction)})
    return writer.to_dataset()


def setup(protocol, progress, timings):
    return WhiskerBench(protocol.design, protocol.realism, np.random.default_rng(protocol.seed)), {}, "whisker pushes"


BENCH = BenchKind(protocol_file=ProtocolFile, parameters={"whisker-sweep": SweepParameters},
                  runners={"whisker-sweep": sweep}, device=lambda file, *_: Rig(file.design, file.sensor),
                  setup=setup, realism_sources=REALISM_SOURCES, viscoelastic_sources={})
