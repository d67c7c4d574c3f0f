"""Sensor channels: one axis of one sensor of one to three axes, named after what the sensor reads.

A :class:`Reading` is what a stream's sensors read, on which axes (x, y, z or some of them), in one
unit, and how their channels are named. The toolkit's own is :data:`MAGNETIC`: the change of flux
density of a Hall chip, in µT; channel ``s{k}_b{x|y|z}_uT`` is axis x, y or z of sensor k. Systems register their own
(:class:`softtip._core.systems.System`), e.g. a force chip's in N; the registry knows every reading
(``known_readings``, ``reading_of``), this module none but its own.

Channels are stored sensor by sensor, the reading's axes in x, y, z order within each (the order of a
reading of shape (sensors, axes) flattened). The module-level functions name magnetic channels, the datasets' default.
"""

from __future__ import annotations

import numbers
import re
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

AXES = ("x", "y", "z")


def _checked_sensor(sensor: Any, axis: str, axes: tuple[str, ...]) -> int:
    if axis not in axes or isinstance(sensor, bool) or not isinstance(sensor, numbers.Integral) or sensor < 0:
        raise ValueError(f"channel: expected a sensor index >= 0 and an axis in {', '.join(axes)}, "
                         f"got {sensor!r}, {axis!r}")
    return int(sensor)


@dataclass(frozen=True)
class Reading:
    """What a stream's sensors read (``quantity``, in ``unit``, on ``axes``: one to three of x, y, z, in
    that order) and how its channels are named: a one-axis chip's reading has one channel per sensor.

    ``symbol``: the quantity's symbol in displays (ΔBx, ΔFx), ``shown_unit`` its unit there;
    ``units``: the units values of this quantity may come in (a CSV column, a model's inputs), each as
    how many ``unit`` one of it is (1 mT = 1000 µT);
    ``topic`` and ``message``: how a chip's readings go out (softtip.realtime.recording.format);
    ``drift_threshold``: the default change (in ``unit``) below which a free sensor's baseline may
    follow slow drift; ``baseline_step``: the default change of that filtered baseline that replaces
    the one in use (:class:`softtip.realtime.Baseline`); ``decimals``: the decimals a display shows.
    """

    quantity: str
    unit: str
    symbol: str
    shown_unit: str
    prefix: str  # channel name before the sensor number
    infix: str  # between the sensor number and the axis
    units: dict[str, float] = field(compare=False)
    drift_threshold: float
    baseline_step: float
    decimals: int  # shown in live displays: a tenth of a µT, a mN
    topic: str  # a chip's topic leaf in recordings and live views (/fingertip/chip0/field)
    message: str  # the ROS 2 message type it is recorded and published as, in its SI unit
    first_numbered: bool = True  # the first sensor's number is written (s0_...), or not (side_...)
    axes: tuple[str, ...] = AXES
    pattern: re.Pattern = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.axes, tuple) or not self.axes or list(self.axes) != [a for a in AXES if a in self.axes]:
            raise ValueError(f"reading {self.quantity!r}: axes = {self.axes!r}: expected one to three of x, y, z, "
                             "in that order")
        object.__setattr__(self, "pattern", re.compile(
            rf"{self.prefix}(|0|[1-9][0-9]*)_{self.infix}([{''.join(self.axes)}])_{re.escape(self.unit)}"))

    @property
    def positions(self) -> tuple[int, ...]:
        """Where its axes sit in an x, y, z vector (a message's): (2,) for a z-only reading."""
        return tuple(AXES.index(axis) for axis in self.axes)

    def channel_name(self, sensor: int, axis: str) -> str:
        """The column of one of its axes (``"x"``, ``"y"`` or ``"z"``) of sensor ``sensor``."""
        sensor = _checked_sensor(sensor, axis, self.axes)
        number = "" if sensor == 0 and not self.first_numbered else str(sensor)
        return f"{self.prefix}{number}_{self.infix}{axis}_{self.unit}"

    def channel_names(self, n_sensors: int) -> tuple[str, ...]:
        """Every channel of ``n_sensors`` sensors, in storage order."""
        if isinstance(n_sensors, bool) or not isinstance(n_sensors, numbers.Integral) or n_sensors < 1:
            raise ValueError(f"n_sensors: expected an integer >= 1, got {n_sensors!r}")
        return tuple(self.channel_name(k, axis) for k in range(n_sensors) for axis in self.axes)

    def is_channel(self, name: str) -> bool:
        match = self.pattern.fullmatch(name) if isinstance(name, str) else None
        return match is not None and self.channel_name(int(match[1] or 0), match[2]) == name

    def channel_order(self, name: str) -> tuple[int, int]:
        """(sensor, axis index) of a channel: sorting by it gives the storage order."""
        if not self.is_channel(name):
            raise ValueError(f"channel {name!r}: expected a {self.quantity} channel like "
                             f"{self.channel_name(0, self.axes[0])}")
        match = self.pattern.fullmatch(name)
        return int(match[1] or 0), self.axes.index(match[2])

    def columns(self, values: Any) -> dict[str, np.ndarray]:
        """Named channel columns from readings of shape (n_samples, n_sensors, axes) in this unit."""
        import numpy as np  # here, not at the top: the command line lists the readings without numpy

        values = np.asarray(values, dtype=np.float64)
        if values.ndim != 3 or values.shape[2] != len(self.axes) or values.shape[1] < 1:
            raise ValueError(f"readings: expected shape (n_samples, n_sensors, {len(self.axes)}), got {values.shape}")
        return {self.channel_name(k, axis): values[:, k, a] for k in range(values.shape[1])
                for a, axis in enumerate(self.axes)}

    def channel_index(self, name: str) -> int:
        """Position of a channel in a flattened (sensors, axes) reading."""
        sensor, axis = self.channel_order(name)
        return len(self.axes) * sensor + axis


MAGNETIC = Reading("flux density", "uT", "B", "µT", prefix="s", infix="b",  # 1 G = 1e-4 T
                   units={"uT": 1.0, "µT": 1.0, "μT": 1.0, "mT": 1e3, "G": 1e2, "T": 1e6}, drift_threshold=20.0,
                   baseline_step=0.01, decimals=1, topic="field",
                   message="sensor_msgs/msg/MagneticField")
CHANNEL_UNIT = MAGNETIC.unit
channel_name = MAGNETIC.channel_name
channel_names = MAGNETIC.channel_names
is_channel = MAGNETIC.is_channel
channel_order = MAGNETIC.channel_order
channel_columns = MAGNETIC.columns
