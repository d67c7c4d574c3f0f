"""The wearable fingertip-force twin (S2), composed once: a person's finger pad
(:mod:`softtip.systems.wearable.fingerpad`) pressed on an object on a table force sensor, the tactile chip
the ring holds against the side of the nail, and both sensors (:mod:`softtip.sensors.force_sensor`)
sampling the continuous response at their own instants.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from softtip.systems.wearable.fingerpad import ChipMount, FingerPad, PadResponse, chip_forces, pad_response
from softtip.sensors import Sensor
from softtip.systems.wearable.chip import CHIP, TABLE_SENSOR


@dataclass(frozen=True)
class WearableResponse:
    """The continuous response over a history (N samples, any batch ...)."""

    pad: PadResponse
    chip: np.ndarray  # (N, ..., 3) forces on the chip: distal shear, dorsal shear, pressure (N)


@dataclass(frozen=True)
class WearableReadings:
    """What the two sensors report at their sample instants (S samples, any batch ...)."""

    chip: np.ndarray  # (S, ..., 3) N, the chip's (x: distal shear, y: dorsal shear, z: pressure)
    chip_saturated: np.ndarray  # (S, ..., 3)
    table: np.ndarray  # (S, ..., 3) N, the force on the object in the table sensor's axes
    table_saturated: np.ndarray  # (S, ..., 3)
    centre: np.ndarray  # (S, ..., 2) m, the true centre of force on the pad (NaN without contact)
    sliding: np.ndarray  # (S, ...) the finger slides on the object


@dataclass(frozen=True)
class WearableTwin:
    pad: FingerPad
    mount: ChipMount
    chip: Sensor = CHIP
    table: Sensor = TABLE_SENSOR

    def respond(self, times: np.ndarray, intended: np.ndarray, object_radii=(np.inf, np.inf),
                rest_centre=(0.0, 0.0), lean: float = 0.0) -> WearableResponse:
        """The finger pressed with the ``intended`` force (N, ..., 3, finger frame) at ``times`` (N,);
        see :func:`softtip.systems.wearable.fingerpad.pad_response` for the other arguments."""
        pad = pad_response(times, intended, self.pad, self.mount, object_radii, rest_centre, lean)
        return WearableResponse(pad=pad, chip=chip_forces(times, pad.skin, self.pad, self.mount))

    def read(self, times: np.ndarray, response: WearableResponse, instants: np.ndarray,
             rng: np.random.Generator | None = None, chip_delay: float = 0.0, table_yaw=0.0) -> WearableReadings:
        """Both sensors sampled at ``instants`` (S,) (the chip ``chip_delay`` s later), unfiltered;
        ``rng`` adds their noise and output steps (none: exact readings). The finger lies rotated by
        ``table_yaw`` (rad, ..., about z) in the table sensor's axes."""
        chip = self.chip.acquire(_at(times, response.chip, instants + chip_delay), rng)
        force = _at(times, response.pad.force, instants)
        cos, sin = np.cos(table_yaw), np.sin(table_yaw)
        turned = np.stack([cos * force[..., 0] - sin * force[..., 1], sin * force[..., 0] + cos * force[..., 1],
                           force[..., 2]], axis=-1)
        table = self.table.acquire(turned, rng)
        nearest = np.clip(np.searchsorted(times, instants), 0, len(times) - 1)
        return WearableReadings(chip=chip.values, chip_saturated=chip.saturated, table=table.values,
                                table_saturated=table.saturated, centre=_at(times, response.pad.centre, instants),
                                sliding=response.pad.sliding[nearest])


def _at(times: np.ndarray, values: np.ndarray, instants: np.ndarray) -> np.ndarray:
    """``values`` (N, ...) sampled at ``times`` (N,), linearly interpolated at ``instants`` (S,)."""
    right = np.clip(np.searchsorted(times, instants), 1, len(times) - 1)
    share = np.clip((instants - times[right - 1]) / (times[right] - times[right - 1]), 0.0, 1.0)
    share = share.reshape(-1, *(1,) * (values.ndim - 1))
    return (1 - share) * values[right - 1] + share * values[right]
