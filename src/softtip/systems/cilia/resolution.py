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

from softtip.sensors.gmr import ConstantCurrentReadout, NoiseBudget
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
    # the local slope by forward differences over 1e-4 of the range: 2 curves where central ones take 3, and
    # their O(step) error (the curve bends over milli-newtons) is about 1e-4 of the slope
    step = 1e-4 * force_max
    curves = model.curves(np.concatenate([force, force + step]), sensors)
    return tuple(_resolution(model, curve, force, step, saturation) for curve in curves)


def _resolution(model: CiliaModel, curve: ForceCurve, force: NDArray, step: float, saturation: float) -> Resolution:
    change, above = np.split(curve.change, 2)
    slope = (above - change) / step
    budget = model.die.meander(curve.sensor).readout.noise(float(curve.volts[0]))
    sigma = budget.total
    with np.errstate(divide="ignore"):
        minimum = np.where(slope != 0, 3 * sigma / np.abs(slope), np.inf)
        smallest = np.where(slope != 0, max(budget.resolution, 3 * math.sqrt(2) * sigma) / np.abs(slope), np.inf)
    flat = np.flatnonzero(np.abs(slope) < saturation * abs(slope[0]))
    upper = float(force[flat[0]]) if flat.size else float(force[-1])
    return Resolution(curve.sensor, force, change, slope, budget, minimum, smallest, (0.0, upper))


# ------------------------------------------------------------------------------ the balance test's floor

BUDGET_PARTS = ("balance", "plate", "meter", "drift")
GRAM_FORCE = 9.80665e-3  # N per gram on a balance (standard gravity)
# the die's heat capacity for the spin valves' warming: a 3 × 3 mm silicon die (ρc = 2329 kg/m³ × 700 J/(kg K)),
# thickness chosen as a standard wafer's 0.5 mm; in its package the real time constant is longer
SILICON_HEAT_CAPACITY = 2329.0 * 700.0  # J/(m³ K)
DIE_THICKNESS = 0.5e-3  # m


@dataclass(frozen=True)
class ForceBudget:
    """The force the balance test resolves, by cause: each a standard deviation of the force (N) along the
    balance curve's ``force`` (G,), where the voltage's ``slope`` (V/N) turns a voltage into a force.

    * ``balance``: the balance's readability d, read as quantisation (d/√12);
    * ``plate``: the plate's seating turn scattering by σ_φ between steps, at a given force (∂V/∂φ σ_φ/|slope|);
    * ``meter``: one reading's noise at the sensor's voltage (Johnson, 1/f, the meter's noise and count);
    * ``drift``: the spin valves' self-heating still settling during a step (V TCR ΔT e^(−t_w/τ)(1 − e^(−t_s/τ))
      over |slope|, τ = R_th C_th of the die).

    ``parts`` names those switched on; ``minimum_force`` is 3 × their root sum of squares."""

    force: NDArray[np.float64]
    slope: NDArray[np.float64]
    balance: NDArray[np.float64]
    plate: NDArray[np.float64]
    meter: NDArray[np.float64]
    drift: NDArray[np.float64]
    parts: tuple[str, ...]
    plate_per_radian: NDArray[np.float64]  # (G,) N of force-equivalent per rad of seating turn
    warming: float  # K: the spin valves' steady self-heating
    time_constant: float  # s: the die's thermal time constant R_th C_th
    drift_per_kelvin: float  # V per K of warming still settling within a step (V × TCR)
    dwell: float  # s per step

    def part(self, name: str) -> NDArray[np.float64]:
        return {"balance": self.balance, "plate": self.plate, "meter": self.meter, "drift": self.drift}[name]

    @property
    def minimum_force(self) -> NDArray[np.float64]:
        return 3.0 * np.sqrt(sum((self.part(name) ** 2 for name in self.parts), np.zeros_like(self.force)))

    @property
    def best(self) -> int:
        """The index of the force the test resolves best (the smallest minimum force along the curve)."""
        return int(np.argmin(self.minimum_force))

    def shares(self, index: int) -> dict[str, float]:
        """Each switched-on cause's share of the variance at the curve's point ``index``."""
        variances = {name: float(self.part(name)[index]) ** 2 for name in self.parts}
        total = sum(variances.values())
        return {name: v / total for name, v in variances.items()}


def balance_force_budget(force: NDArray, change: NDArray, rest_volts: float, readout: ConstantCurrentReadout,
                         seated_change: tuple[NDArray, NDArray, float], readability: float, seating: float,
                         warm_up: float, dwell: float, die_area: float, parts: tuple[str, ...] = BUDGET_PARTS) -> ForceBudget:
    """The budget of :class:`ForceBudget` along a balance curve (``force`` (G,) N increasing from 0,
    ``change`` (G,) V from the tare at ``rest_volts``). ``seated_change``: the curve's change with the plate
    seated at −δ and +δ (each at the same forces, interpolated) and δ (rad); ``readability`` (N) the
    balance's; ``seating`` (rad) the scatter of the plate's turn; ``warm_up`` (s) the current on before the
    test, ``dwell`` (s) per step; ``die_area`` (m²) for the die's heat capacity."""
    unknown = [name for name in parts if name not in BUDGET_PARTS]
    if unknown or not parts:
        raise DieError(f"parts: expected some of {', '.join(BUDGET_PARTS)}, got {list(parts)!r}")
    for name, value in (("readability", readability), ("seating", seating), ("warm_up", warm_up),
                        ("dwell", dwell)):
        if not (math.isfinite(value) and value >= 0):
            raise DieError(f"{name} = {value!r}: expected a number >= 0")
    if force.size < 3 or np.any(np.diff(force) <= 0):
        raise DieError("force: expected at least 3 increasing forces (the curve's steps)")
    slope = np.gradient(change, force)
    low, high, delta = seated_change
    per_radian = (high - low) / (2 * delta)
    with np.errstate(divide="ignore"):
        inverse = np.where(slope != 0, 1.0 / np.abs(slope), np.inf)
    noise = readout.noise(rest_volts)
    resistance = rest_volts / readout.current
    warming = readout.current**2 * resistance * readout.thermal_resistance
    time_constant = readout.thermal_resistance * SILICON_HEAT_CAPACITY * die_area * DIE_THICKNESS
    settling = warming * math.exp(-warm_up / time_constant) * -math.expm1(-dwell / time_constant)
    drift_volts = rest_volts * readout.sensor.temperature_coefficient * settling
    balance = np.full_like(force, readability / math.sqrt(12.0))
    return ForceBudget(force=force, slope=slope, balance=balance, plate=np.abs(per_radian) * seating * inverse,
                       meter=noise.total * inverse, drift=abs(drift_volts) * inverse, parts=tuple(parts),
                       plate_per_radian=np.abs(per_radian) * inverse, warming=warming, time_constant=time_constant,
                       drift_per_kelvin=abs(rest_volts * readout.sensor.temperature_coefficient), dwell=dwell)
