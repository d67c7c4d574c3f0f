"""Six-axis force/torque sensors: a wrench read at 1 kHz, and held configurations averaged over a window.

A wrench is (Fx, Fy, Fz, Tx, Ty, Tz) in N and N·m, arrays (..., 6). Each axis is read as
:mod:`softtip.sensors.force_sensor` reads a force: white noise, rounded to the axis's resolution,
held within its range (a value beyond the range reads as its end and is flagged). The force axes
and the torque axes are each described by a :class:`~softtip.sensors.force_sensor.ForceSensorSpec`
(the torque one's values in N·m).

:data:`NANO17_WRENCH` is ATI's Nano17 with the SI-12-0.12 calibration (ATI Nano17 datasheet:
Fx, Fy ±12 N, Fz ±17 N, Tx, Ty, Tz ±120 N·mm; resolution 1/320 N and 1/64 N·mm), read at 1 kHz
(the sampling rate is the acquisition's, a choice). Its noise is one resolution step RMS per axis,
an assumption as for :data:`~softtip.sensors.force_sensor.NANO17` (ATI gives no separate figure).

A measurement of a configuration held still (a lookup table's entry) is the mean of the readings
over the last ``window_s`` of the hold: :func:`held_wrench`.
"""

from __future__ import annotations

import numpy as np

from softtip._core.config import PositiveNumber, Text, instance, schema
from softtip.sensors.force_sensor import NANO17, ForceSensorSpec, read_forces


@schema(section="sensor")
class WrenchSensorSpec:
    """A 6-axis force/torque sensor: its force axes (N), its torque axes (N·m) and its sampling rate (Hz)."""

    name: Text
    force: instance(ForceSensorSpec)
    torque: instance(ForceSensorSpec)
    rate_hz: PositiveNumber
    source: Text

    def to_dict(self) -> dict:
        return {"name": self.name, "force": self.force.to_dict(),
                "torque_N_m": {key.replace("_N", ""): value for key, value in self.torque.to_dict().items()},
                "rate_hz": self.rate_hz, "source": self.source}


_NANO17_TORQUE_STEP = 1 / 64 * 1e-3  # N·m: 1/64 N·mm
NANO17_WRENCH = WrenchSensorSpec(
    name="ATI Nano17 SI-12-0.12 (6-axis)", force=NANO17,
    torque=ForceSensorSpec(name="ATI Nano17 SI-12-0.12 torque axes (N·m)", lowest=(-0.12,) * 3, highest=(0.12,) * 3,
                           resolution=(_NANO17_TORQUE_STEP,) * 3, noise=(_NANO17_TORQUE_STEP,) * 3,
                           source="ATI Nano17 datasheet: ±120 N·mm, resolution 1/64 N·mm; noise one step"),
    rate_hz=1000.0,
    source="ATI Nano17 datasheet (SI-12-0.12 ranges and resolutions); 1 kHz acquisition and noise of one step assumed")


def read_wrenches(wrench: np.ndarray, spec: WrenchSensorSpec,
                  rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
    """What the sensor reports for ``wrench`` (..., 6) in N and N·m, and where it saturates (..., 6).

    With ``rng`` each reading carries the sensor's noise and is rounded to its resolution; without,
    it is exact (the ranges still clip it)."""
    wrench = np.asarray(wrench, dtype=float)
    if wrench.shape[-1:] != (6,):
        raise ValueError(f"wrench has shape {wrench.shape}: expected (..., 6) (Fx, Fy, Fz, Tx, Ty, Tz)")
    force, force_saturated = read_forces(wrench[..., :3], spec.force, rng)
    torque, torque_saturated = read_forces(wrench[..., 3:], spec.torque, rng)
    return (np.concatenate([force, torque], axis=-1),
            np.concatenate([force_saturated, torque_saturated], axis=-1))


def samples_in_window(window_s: float, spec: WrenchSensorSpec) -> int:
    """How many readings the sensor takes in ``window_s`` seconds (at least one)."""
    if not window_s > 0:
        raise ValueError(f"window_s = {window_s!r}: expected a positive number of seconds")
    return max(1, int(round(window_s * spec.rate_hz)))


def held_wrench(wrench: np.ndarray, spec: WrenchSensorSpec, window_s: float,
                rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The mean reading (..., 6) of a wrench held still, over ``window_s`` of samples at the sensor's
    rate, and whether any sample saturated (..., 6). Without ``rng`` the readings are exact."""
    wrench = np.asarray(wrench, dtype=float)
    count = samples_in_window(window_s, spec)
    if rng is None:
        return read_wrenches(wrench, spec)
    samples = np.broadcast_to(wrench[..., None, :], (*wrench.shape[:-1], count, 6))
    readings, saturated = read_wrenches(samples, spec, rng)
    return readings.mean(axis=-2), saturated.any(axis=-2)


def shift_wrench(wrench: np.ndarray, origin: np.ndarray, new_origin: np.ndarray) -> np.ndarray:
    """The same wrench (..., 6) taken about ``new_origin`` instead of ``origin`` (m, (..., 3)):
    τ' = τ + (origin − new_origin) × F."""
    wrench = np.asarray(wrench, dtype=float)
    arm = np.asarray(origin, dtype=float) - np.asarray(new_origin, dtype=float)
    return np.concatenate([wrench[..., :3], wrench[..., 3:] + np.cross(arm, wrench[..., :3])], axis=-1)


def wrench_in_frame(wrench: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """A wrench (..., 6) given in the world's axes, expressed in a frame whose axes are the columns of
    ``rotation`` (..., 3, 3)."""
    wrench = np.asarray(wrench, dtype=float)
    rotation = np.asarray(rotation, dtype=float)
    return np.concatenate([np.einsum("...ji,...j->...i", rotation, wrench[..., :3]),
                           np.einsum("...ji,...j->...i", rotation, wrench[..., 3:])], axis=-1)
