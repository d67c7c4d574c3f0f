"""The smallest force the sensor resolves, and its measurement range, from the model and the readout.

* 3σ over the local slope: a force F is resolved where 3σ_V / |dV/dF| is the smallest force change whose
  voltage change stands three standard deviations of one reading above the noise (σ_V: the computed
  noise floor of the readout, quantisation included).
* the smallest distinguishable step: two readings before and after a step differ by more than their own
  noise (3√2 σ_V for a difference of two readings) and by at least one count of the meter (a step below
  one count can leave the quantised reading unchanged): max(LSB, 3√2 σ_V) / |dV/dF|.
* the measurement range: from zero force up to where the local slope has fallen to ``saturation`` (a tenth
  by default) of its value at zero force: beyond, the pillars have turned over and the voltage barely
  follows the force.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from softtip.sensors.gmr import NoiseBudget
from softtip.systems.cilia.layout import DieError
from softtip.systems.cilia.model import CiliaModel, ForceCurve


@dataclass(frozen=True)
class Resolution:
    """``force`` (N,) N, the voltage ``change`` (V) and local ``slope`` (V/N) there, the readout's
    ``noise`` budget at the sensor's voltage, ``minimum_force`` (N,) 3σ/|slope| and ``smallest_step`` (N,)
    N along the curve, and the measurement ``range`` (N)."""

    sensor: str
    force: NDArray[np.float64]
    change: NDArray[np.float64]
    slope: NDArray[np.float64]
    noise: NoiseBudget
    minimum_force: NDArray[np.float64]
    smallest_step: NDArray[np.float64]
    range: tuple[float, float]

    @property
    def sensitivity(self) -> float:
        """V/N at zero force."""
        return float(self.slope[0])

    @property
    def minimum_force_at_rest(self) -> float:
        return float(self.minimum_force[0])

    @property
    def smallest_step_at_rest(self) -> float:
        return float(self.smallest_step[0])


def resolution(model: CiliaModel, sensor: str, force_max: float, points: int = 101,
               saturation: float = 0.1) -> Resolution:
    """The resolution of ``sensor`` along ``points`` forces from 0 to ``force_max`` (N)."""
    return resolutions(model, (sensor,), force_max, points, saturation)[0]


def resolutions(model: CiliaModel, sensors: tuple[str, ...], force_max: float, points: int = 101,
                saturation: float = 0.1) -> tuple[Resolution, ...]:
    """:func:`resolution` of each of ``sensors``: the pillars' shapes solved once for all."""
    if not (math.isfinite(force_max) and force_max > 0):
        raise DieError(f"force_max = {force_max!r}: expected a positive force in N")
    if points < 5:
        raise DieError(f"points = {points!r}: expected at least 5")
    if not 0 < saturation < 1:
        raise DieError(f"saturation = {saturation!r}: expected a fraction strictly between 0 and 1")
    force = np.linspace(0.0, force_max, points)
    # the local slope by differences over 1e-4 of the range (central; one-sided second order at zero force)
    step = 1e-4 * force_max
    below = np.where(force > 0, force - step, 2 * step)
    curves = model.curves(np.concatenate([force, force + step, below]), sensors)
    return tuple(_resolution(model, curve, force, step, saturation) for curve in curves)


def _resolution(model: CiliaModel, curve: ForceCurve, force: NDArray, step: float, saturation: float) -> Resolution:
    change, above, under = np.split(curve.change, 3)
    slope = (above - under) / (2 * step)
    slope[0] = (4 * above[0] - under[0] - 3 * change[0]) / (2 * step)
    budget = model.die.meander(curve.sensor).readout.noise(float(curve.volts[0]))
    sigma = budget.total
    with np.errstate(divide="ignore"):
        minimum = np.where(slope != 0, 3 * sigma / np.abs(slope), np.inf)
        smallest = np.where(slope != 0, max(budget.resolution, 3 * math.sqrt(2) * sigma) / np.abs(slope), np.inf)
    flat = np.flatnonzero(np.abs(slope) < saturation * abs(slope[0]))
    upper = float(force[flat[0]]) if flat.size else float(force[-1])
    return Resolution(curve.sensor, force, change, slope, budget, minimum, smallest, (0.0, upper))
