"""Sensor channels: the change of flux density of one axis of one 3-axis sensor, in µT.

Channel ``s{k}_b{x|y|z}_uT`` is axis x, y or z of sensor k; channels are stored sensor by sensor,
x, y, z within each (the order of a reading of shape (sensors, 3) flattened).
"""

from __future__ import annotations

import numbers
import re
from typing import Any

import numpy as np

CHANNEL_UNIT = "uT"
AXES = ("x", "y", "z")
CHANNEL_PATTERN = re.compile(r"s(0|[1-9][0-9]*)_b([xyz])_uT")


def channel_name(sensor: int, axis: str) -> str:
    """The column of one axis (``"x"``, ``"y"`` or ``"z"``) of sensor ``sensor``."""
    if axis not in AXES or isinstance(sensor, bool) or not isinstance(sensor, numbers.Integral) or sensor < 0:
        raise ValueError(f"channel: expected a sensor index >= 0 and an axis in x, y, z, got {sensor!r}, {axis!r}")
    return f"s{int(sensor)}_b{axis}_uT"


def channel_names(n_sensors: int) -> tuple[str, ...]:
    """Every channel of ``n_sensors`` 3-axis sensors, in storage order."""
    if isinstance(n_sensors, bool) or not isinstance(n_sensors, numbers.Integral) or n_sensors < 1:
        raise ValueError(f"n_sensors: expected an integer >= 1, got {n_sensors!r}")
    return tuple(channel_name(k, axis) for k in range(n_sensors) for axis in AXES)


def is_channel(name: str) -> bool:
    return CHANNEL_PATTERN.fullmatch(name) is not None


def channel_order(name: str) -> tuple[int, int]:
    """(sensor, axis index) of a channel: sorting by it gives the storage order."""
    match = CHANNEL_PATTERN.fullmatch(name)
    return int(match[1]), AXES.index(match[2])


def channel_columns(field_uT: Any) -> dict[str, np.ndarray]:
    """Named channel columns from readings of shape (n_samples, n_sensors, 3) in µT."""
    values = np.asarray(field_uT, dtype=np.float64)
    if values.ndim != 3 or values.shape[2] != 3 or values.shape[1] < 1:
        raise ValueError(f"field_uT: expected shape (n_samples, n_sensors, 3), got {values.shape}")
    return {channel_name(k, axis): values[:, k, a] for k in range(values.shape[1]) for a, axis in enumerate(AXES)}


def channel_index(name: str) -> int:
    """Position of channel ``s{k}_b{axis}_uT`` in a flattened (sensors, 3) reading."""
    match = CHANNEL_PATTERN.fullmatch(name) if isinstance(name, str) else None
    if match is None:
        raise ValueError(f"input channel {name!r}: expected a channel name like s0_bx_uT")
    return 3 * int(match[1]) + AXES.index(match[2])
