"""Three-axis force sensors read at a chosen instant: range, resolution, noise and saturation.

A reading is the force plus the sensor's white noise, rounded to its resolution (one output step)
and held within its range; a value outside the range reads as the range's end and is flagged.
Vectorised over arrays (..., 3) of x, y, z forces in N.

:data:`NANO17` is the common reference sensor: ATI Industrial Automation's Nano17 with its SI-12-0.12
  calibration (datasheet: sensing ranges Fx, Fy ±12 N and Fz ±17 N, resolution 1/320 N on each
  force axis). ATI's resolution is the smallest change its data acquisition resolves; we take the
  noise as one resolution step RMS (an assumption: ATI gives no separate noise figure).

The sampling instant and rate are the caller's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np
from numpy.typing import ArrayLike

from softtip._core.channels import Reading
from softtip._core.config import NonNegativeNumber, PositiveNumber, Real, Refusal, Text, expect, from_numpy, schema
from softtip.sensors.contract import Acquisition

Triple = Annotated[tuple[Real, Real, Real], from_numpy, expect("3 numbers (x, y, z)")]
PositiveTriple = Annotated[tuple[PositiveNumber, PositiveNumber, PositiveNumber], from_numpy,
                           expect("3 positive numbers (x, y, z)")]
NonNegativeTriple = Annotated[tuple[NonNegativeNumber, NonNegativeNumber, NonNegativeNumber], from_numpy,
                              expect("3 numbers >= 0 (x, y, z)")]


@schema(section="sensor")
class ForceSensorSpec:
    """A 3-axis force sensor: its range per axis (N), its output step (N) and its RMS noise (N)."""

    name: Text
    lowest: Triple
    highest: Triple
    resolution: PositiveTriple
    noise: NonNegativeTriple
    source: Text  # where the numbers come from

    def __post_init__(self) -> None:
        for axis, (low, high) in enumerate(zip(self.lowest, self.highest, strict=True)):
            if not low < high:
                raise Refusal(("highest", axis), f"expected above sensor.lowest[{axis}] = {low}")

    def to_dict(self) -> dict:
        return {"name": self.name, "lowest_N": list(self.lowest), "highest_N": list(self.highest),
                "resolution_N": list(self.resolution), "noise_N": list(self.noise), "source": self.source}


NANO17 = ForceSensorSpec(
    name="ATI Nano17 SI-12-0.12", lowest=(-12.0, -12.0, -17.0), highest=(12.0, 12.0, 17.0),
    resolution=(1 / 320,) * 3, noise=(1 / 320,) * 3,
    source="ATI Nano17 datasheet (SI-12-0.12 ranges and resolution); noise taken as one resolution step")


@dataclass(frozen=True)
class ForceSensor:
    """A 3-axis force sensor of ``spec`` whose channels are named by ``reading`` (a force reading in N):
    the sensor contract (:class:`~softtip.sensors.contract.Sensor`) over :func:`read_forces`."""

    spec: ForceSensorSpec
    reading: Reading

    def __post_init__(self) -> None:
        if self.reading.units.get("N") != 1.0:
            raise ValueError(f"reading {self.reading.quantity!r}: a force sensor's reading is in N, "
                             f"not {self.reading.unit}")

    def acquire(self, force: ArrayLike, rng: np.random.Generator | None = None) -> Acquisition:
        values, saturated = read_forces(np.asarray(force, dtype=float), self.spec, rng)
        return Acquisition(values=values, raw=values, saturated=saturated)

    def to_dict(self) -> dict:
        return self.spec.to_dict()


def read_forces(force: np.ndarray, spec: ForceSensorSpec,
                rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
    """What the sensor reports for ``force`` (..., 3) in N, and where it saturates (..., 3).

    With ``rng`` the reading carries the sensor's noise and is rounded to its resolution; without,
    it is exact (the range still clips it)."""
    force = np.asarray(force, dtype=float)
    if force.shape[-1:] != (3,):
        raise ValueError(f"force has shape {force.shape}: expected (..., 3)")
    lowest, highest = np.array(spec.lowest), np.array(spec.highest)
    if rng is not None:
        step = np.array(spec.resolution)
        force = np.round((force + rng.normal(0.0, 1.0, force.shape) * np.array(spec.noise)) / step) * step
    saturated = (force < lowest) | (force > highest)
    return np.clip(force, lowest, highest), saturated
