"""The chips a dataset, a rig's log or a live stream may come from, each registered by name: what it
reads and on how many axes, its range and output step at its settings, when a value is saturated, its
settings schema and how its raw output words decode.

The toolkit names no chip: a system declares the sensors it uses (``System.sensors``: name ->
``"module:attribute"`` of a :class:`SensorKind`, imported when a check needs it), and every range and
saturation check asks the registered sensor at the settings a dataset or a log declares.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from softtip._core.channels import Reading
from softtip._core.systems import declared, known_readings, systems
from softtip.sensors.contract import Sensor

_NAME = re.compile(r"[a-z][a-z0-9_-]*")


@dataclass(frozen=True)
class SensorKind:
    """One chip as the toolkit checks its output.

    ``settings``: its settings schema (``settings.from_dict(table)`` refuses what is not its settings in
    one line, ``.to_dict()`` records them); ``widest``: the settings of its widest range, what values
    without declared settings are checked against; ``full_scale(settings)``: the largest magnitude per
    axis it outputs unclipped, ``step(settings)``: its output step per axis, both in the reading's unit;
    ``decode(settings, words)``: its raw output words (..., axes) as (values in the reading's unit,
    saturated), with ``raw_unit`` what a log calls those words ("counts") and ``raw_bits`` their width
    (a word is an integer 0 .. 2^raw_bits - 1); a chip that outputs values has none of the three;
    ``title``: how messages name it (its name when not given); ``noise(settings)``: its RMS noise per
    axis in the reading's unit, when its datasheet states it (a recording's covariance, estimation bounds);
    ``model(settings)``: its acquisition at the settings, a :class:`~softtip.sensors.contract.Sensor`
    whose ``acquire(true, rng)`` turns true values in SI units (..., axes) into what the chip reports
    (noise, output step, clip), what a design's twin reads its field with; ``conversion_time(settings)``:
    the seconds one reading of all its axes takes, when its datasheet states it.
    """

    name: str
    reading: Reading
    axes: int
    settings: type
    widest: Any
    full_scale: Callable[[Any], np.ndarray]
    step: Callable[[Any], np.ndarray]
    decode: Callable[[Any, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None
    raw_unit: str | None = None
    title: str | None = None
    noise: Callable[[Any], np.ndarray] | None = None
    raw_bits: int | None = None
    model: Callable[[Any], Sensor] | None = None
    conversion_time: Callable[[Any], float] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME.fullmatch(self.name):
            raise ValueError(f"sensor name {self.name!r}: expected a lower-case name (letters, digits, - or _)")
        if isinstance(self.axes, bool) or self.axes not in (1, 2, 3):
            raise ValueError(f"sensor {self.name!r}: axes = {self.axes!r}: expected 1, 2 or 3")
        if self.axes != len(self.reading.axes):
            raise ValueError(f"sensor {self.name!r}: axes = {self.axes}: its reading {self.reading.quantity!r} "
                             f"has {len(self.reading.axes)} ({', '.join(self.reading.axes)})")
        if len({self.decode is None, self.raw_unit is None, self.raw_bits is None}) > 1:
            raise ValueError(f"sensor {self.name!r}: give decode, raw_unit and raw_bits together, or none")
        if self.raw_bits is not None and (isinstance(self.raw_bits, bool) or self.raw_bits not in range(1, 64)):
            raise ValueError(f"sensor {self.name!r}: raw_bits = {self.raw_bits!r}: expected an integer 1..63")
        if not isinstance(self.widest, self.settings):
            raise ValueError(f"sensor {self.name!r}: widest: expected {self.settings.__name__} settings")

    def at(self, settings: Any) -> ChipSettings:
        """This sensor at ``settings`` (an instance of its schema), as a live stream states its chips."""
        return ChipSettings(self, settings)

    def settings_from(self, table: Mapping[str, Any]) -> Any:
        """Its settings from a recorded mapping; anything else is refused in one line."""
        return self.settings.from_dict(table)

    def saturated(self, values: np.ndarray, settings: Any) -> np.ndarray:
        """Where values (..., axes) in the reading's unit are at its clip: within half a step of the full
        scale (a host's conversion rounds to the step)."""
        return np.abs(values) >= self.full_scale(settings) - self.step(settings) / 2

    def beyond(self, values: np.ndarray, settings: Any) -> np.ndarray:
        """Where values (..., axes) are more than a step beyond what it outputs: not its readings."""
        return np.abs(values) > self.full_scale(settings) + self.step(settings)


@dataclass(frozen=True)
class ChipSettings:
    """A stream's chips: one registered sensor (``kind``) at ``values``, an instance of its settings
    schema - what a live scenario, session and pipeline carry instead of one chip's settings type."""

    kind: SensorKind
    values: Any

    def __post_init__(self) -> None:
        if not isinstance(self.kind, SensorKind):
            raise ValueError(f"kind = {self.kind!r}: expected a SensorKind")
        if not isinstance(self.values, self.kind.settings):
            raise ValueError(f"settings of sensor {self.kind.name!r}: expected {self.kind.settings.__name__}, "
                             f"got {type(self.values).__name__}")

    def to_dict(self) -> dict:
        """The settings as a dataset's and a recording's metadata record them."""
        return self.values.to_dict()

    def variance(self) -> np.ndarray | None:
        """Per-axis variance of a reading in the reading's unit squared: the noise plus the uniform
        quantisation of the output step (step^2 / 12); None when the sensor declares no noise."""
        if self.kind.noise is None:
            return None
        return self.kind.noise(self.values) ** 2 + self.kind.step(self.values) ** 2 / 12.0


def stream_settings(settings: ChipSettings | None, reading: Reading) -> ChipSettings | None:
    """``settings`` of a stream's chips, refused in one line unless they are None or a registered
    sensor of the stream's ``reading`` at its settings."""
    if settings is not None and (not isinstance(settings, ChipSettings) or settings.kind.reading != reading):
        raise ValueError(f"settings: expected a registered sensor of {reading.quantity} at its settings, "
                         f"got {settings!r}")
    return settings


def sensor_kinds() -> dict[str, SensorKind]:
    """Every sensor the registered systems declare, by name (their modules imported now)."""
    return {name: declared("sensor", name, SensorKind) for system in systems().values() for name in system.sensors}


def sensor_kind(name: str) -> SensorKind:
    """The registered sensor ``name``; another name is refused with the registered ones."""
    return declared("sensor", name, SensorKind)


def check_changes(columns: Mapping[str, np.ndarray], stated: Mapping[str, Any] | None, source: str) -> None:
    """Refuses changes from a baseline that no registered sensor of their reading can output: a change
    between two readings in range is at most twice the range, at the ``stated`` settings (a sensor
    whose schema refuses them is not the one that made the data) or, without them, at its widest. A
    reading no registered sensor reads is not checked."""
    kinds = sensor_kinds().values()
    for reading in known_readings():
        channels = [name for name in columns if reading.is_channel(name)]
        candidates = [kind for kind in kinds if kind.reading == reading]
        if not channels or not candidates:
            continue
        ranges, refusals = [], []
        for kind in candidates:
            try:
                settings = kind.widest if not stated else kind.settings_from(stated)
            except ValueError as refusal:
                refusals.append(f"{kind.name}: {refusal}")
                continue
            ranges.append((kind, settings, kind.full_scale(settings)))
        if not ranges:
            raise ValueError(f"{source}: its sensor settings are not those of a sensor reading "
                             f"{reading.quantity} ({'; '.join(refusals)})")
        where = "the dataset's sensor settings" if stated else "its widest setting"
        for channel in channels:
            axis = reading.channel_order(channel)[1]
            kind, _, full_scale = max(ranges, key=lambda candidate: candidate[2][axis])
            values = np.asarray(columns[channel], dtype=float)
            largest = float(np.nanmax(np.abs(values))) if len(values) else 0.0
            if not largest <= 2 * full_scale[axis]:
                raise ValueError(f"{source}: channel {channel} reaches {largest:.4g} {reading.unit}, beyond twice "
                                 f"the {kind.title or kind.name}'s {full_scale[axis]:.4g} {reading.unit} range at {where}")
