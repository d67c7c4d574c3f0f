"""What every sensor model gives the twins and the live path: what it reads, and what it reports for
true values - one contract, implemented by the MLX90393 and by 3-axis force sensors.

A sensor's settings are validated once, when it is built (from a design or a bench file), and typed
from then on; :meth:`Sensor.acquire` is then a pure function of the true values (and of the noise
drawn from ``rng``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike

from softtip._core.channels import Reading


@dataclass(frozen=True)
class Acquisition:
    """What a sensor reports for true values (..., 3): ``values`` in its reading's unit, ``raw`` as
    the chip sends them (register words, or the values themselves) and where it ``saturated``."""

    values: np.ndarray
    raw: np.ndarray
    saturated: np.ndarray


@runtime_checkable
class Sensor(Protocol):
    """A 3-axis sensor model: its :class:`~softtip._core.channels.Reading` (quantity, unit, channel
    names) and its acquisition of true values in SI units (..., 3); ``rng`` draws its noise, none
    gives the noiseless output (still quantised and clipped)."""

    @property
    def reading(self) -> Reading: ...

    def acquire(self, true: ArrayLike, rng: np.random.Generator | None = None) -> Acquisition: ...

    def to_dict(self) -> dict:
        """Its settings, as a dataset's metadata records them."""
        ...
