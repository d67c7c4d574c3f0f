"""Spin-valve (giant magnetoresistance) sensors read at constant current by a voltmeter.

A sensor is a meander of ``elements`` spin valves in series. Each element's free layer turns with the
local in-plane field along the sensing axis; pinned across its easy axis, it answers as a Stoner–Wohlfarth
particle along its hard axis: linearly between two saturation fields and flat beyond (E. C. Stoner,
E. P. Wohlfarth, Phil. Trans. R. Soc. A 240, 1948). Its linear range is set by anisotropy and interlayer
(Néel) coupling, which shifts it off zero. The field is given averaged over area elements of the meander
(each element, or pieces of the meander small beside the field's variation), each saturating on its own
before the meander's resistance averages them by the spin valves' area in each (a strip whose end sits in
a saturating field near a magnet is not the clipped mean of its field):

    R = R_min [1 + MR · Σ_k a_k clip((B_k − B_low) / (B_high − B_low), 0, 1) / Σ_k a_k],

so a sensor whose area elements all see B has the sensitivity S = R_min MR / (B_high − B_low) (Ω/T) and
R_min = S (B_high − B_low) / MR. The published figures (S4: MR 5 % and 4.4 %, 146.6 and 118.8 Ω/Oe,
−25 .. +37.5 Oe) give R_min ≈ 183 kΩ and 169 kΩ. In air B = μ₀H, so 1 Oe of H is 1e-4 T of B
(:data:`TESLA_PER_OERSTED`); the library works in tesla.

Driven at a constant current I, the sensor dissipates I²R and warms by ΔT = I²R R_th; its resistance
follows R(T) = R(T₀)(1 + TCR ΔT) and its magnetoresistance MR(T) = MR(T₀)(1 + TC_MR ΔT) (Infineon GMR S6
data sheet, 1999: TCR₀ +0.09..+0.12 %/K, TC of ΔR −0.12..−0.09 %/K, thermal conductance > 2.2 mW/K).

Noise at the voltmeter, over the bandwidth of one reading (a reading integrates for T_int: an equivalent
noise bandwidth of 1/(2 T_int)):
* Johnson noise of the sensor, 4 k_B T R per Hz at the warmed temperature;
* 1/f noise after Hooge, S_V(f) = α_H V² / (N_c f), N_c the free carriers in the meander's metal, integrated
  from 1/(record length) to the bandwidth;
* the voltmeter's own noise and its resolution (the reading is quantised to it: LSB²/12), both in ppm of
  the range the voltage needs, set by the integration time. The default meter is the publication's, the HP
  34401A on DC volts (ranges 0.1–1000 V, 20 % overrange; HP 34401A User's Guide, "Integration Time":
  resolution 100, 10, 3, 1 and 0.3 ppm of full scale at 0.02, 0.2, 1, 10 and 100 power-line cycles; its
  operating characteristics: 1000, 300, 50, 5 and 0.5 readings/s at 50 Hz, and an additional noise error of
  0.01 %, 0.001 %, 0.001 %, 0 and 0 % of range plus 20 µV on DC volts below 10 cycles, as HP specifies the
  6½-digit multi-slope III converter in its E1412A data sheet). softtip reads that noise error, a bound, as
  the rms of one reading: the pessimistic reading of the datasheet. On the ~18 V a meander reads the meter is
  on its 100 V range: 100 µV steps at 10 cycles, 300 µV at 1 cycle (50 readings/s). An offset voltage
  subtracted before the meter (a bridge with a matched reference resistor; softtip's addition, off unless
  asked) lets it read the change on a low range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.constants import Boltzmann

from softtip._core.config import (
    NonNegativeNumber,
    Number,
    Numbers,
    PositiveInteger,
    PositiveNumber,
    Refusal,
    Text,
    choice,
    number,
    schema,
)
from softtip._core.errors import NotConverged

TESLA_PER_OERSTED = 1e-4  # B = μ₀H in air: 1 Oe of H ↔ 1 G = 1e-4 T of B


class SensorError(ValueError):
    """Settings or inputs a sensor model cannot take."""


@schema(section="spin_valve", error=SensorError)
class SpinValveSensor:
    """A meander of spin valves in series (SI; the published Ω/Oe and Oe are converted where they enter).

    ``sensitivity``: Ω/T of the whole sensor; ``field_low``/``field_high``: the linear range, T;
    ``element_length``/``element_width``/``thickness``: one element's strip and its metal stack (m), for
    the carriers of 1/f noise; ``hooge``: the Hooge parameter; ``carrier_density``: free carriers per m³;
    ``area_weights``: the spin valves' area in each area element the field is given over (:meth:`resistance`).
    """

    name: Text
    elements: PositiveInteger
    magnetoresistance: number("a fraction between 0 and 1 (exclusive)", gt=0.0, lt=1.0)
    sensitivity: PositiveNumber
    field_low: Number
    field_high: Number
    temperature_coefficient: Number = 1.0e-3  # 1/K, Infineon GMR S6: +0.09 .. +0.12 %/K
    magnetoresistance_temperature_coefficient: Number = -1.0e-3  # 1/K, GMR S6: −0.12 .. −0.09 %/K
    element_length: PositiveNumber = 1.0e-3
    element_width: PositiveNumber = 2.0e-6
    thickness: PositiveNumber = 40e-9
    hooge: NonNegativeNumber = 2e-3
    carrier_density: PositiveNumber = 8.5e28  # copper's, the spin valve's spacer and most of its metal
    area_weights: Numbers | None = None  # the spin valves' area in each area element; None: one per element

    def __post_init__(self) -> None:
        if self.field_high <= self.field_low:
            raise Refusal("field_high", f"expected a field above field_low ({self.field_low} T)")
        if self.area_weights is not None and any(w <= 0 for w in self.area_weights):
            raise Refusal("area_weights", "expected positive areas")

    @property
    def minimum_resistance(self) -> float:
        """R_min (Ω) at the reference temperature: S (B_high − B_low) / MR."""
        return self.sensitivity * (self.field_high - self.field_low) / self.magnetoresistance

    @property
    def carriers(self) -> float:
        return self.carrier_density * self.elements * self.element_length * self.element_width * self.thickness

    @property
    def area_elements(self) -> int:
        return self.elements if self.area_weights is None else len(self.area_weights)

    def resistance(self, field: ArrayLike, warming: ArrayLike = 0.0) -> NDArray[np.float64]:
        """(...) resistance (Ω) of the meander whose area elements see the in-plane fields ``field`` (..., m)
        along the sensing axis (T, each averaged over its element; m = :attr:`area_elements`), ``warming`` K
        above the reference. Each area element's free layers turn with its own field and saturate on their
        own before the meander's resistance averages them by area: a strip half in a saturating field is not
        read as the clipped mean of its field."""
        field = np.asarray(field, dtype=np.float64)
        if field.shape[-1:] != (self.area_elements,):
            raise SensorError(f"field: expected the field of {self.area_elements} area elements on the last axis, "
                              f"got shape {field.shape}")
        if not np.all(np.isfinite(field)):
            raise SensorError("field: expected finite numbers")
        warming = np.asarray(warming, dtype=np.float64)
        turned = np.clip((field - self.field_low) / (self.field_high - self.field_low), 0.0, 1.0)
        share = (turned.mean(axis=-1) if self.area_weights is None else
                 turned @ np.asarray(self.area_weights) / math.fsum(self.area_weights))
        mr = self.magnetoresistance * (1.0 + self.magnetoresistance_temperature_coefficient * warming)
        base = self.minimum_resistance * (1.0 + self.temperature_coefficient * warming)
        return base * (1.0 + mr * share)


def published_spin_valve(name: str, elements: int, magnetoresistance: float, ohm_per_oersted: float,
                         low_oersted: float, high_oersted: float, **options: float) -> SpinValveSensor:
    """A sensor from figures as published: sensitivity in Ω/Oe, linear range in Oe."""
    return SpinValveSensor(name=name, elements=elements, magnetoresistance=magnetoresistance,
                           sensitivity=ohm_per_oersted / TESLA_PER_OERSTED, field_low=low_oersted * TESLA_PER_OERSTED,
                           field_high=high_oersted * TESLA_PER_OERSTED, **options)


# HP 34401A on DC volts, by integration time in power-line cycles: (resolution, ppm of range; readings per
# second at 50 Hz mains; additional noise, ppm of range) - the module notes give the sources
HP34401A_INTEGRATIONS = {0.02: (100.0, 1000.0, 100.0), 0.2: (10.0, 300.0, 10.0), 1.0: (3.0, 50.0, 10.0),
                         10.0: (1.0, 5.0, 0.0), 100.0: (0.3, 0.5, 0.0)}
HP34401A_FAST_NOISE = 20e-6  # V, added below 10 power-line cycles on DC volts


@schema(section="voltmeter", error=SensorError)
class Voltmeter:
    """The HP 34401A on DC volts (module notes) at ``cycles`` power-line cycles of integration (one of
    :data:`HP34401A_INTEGRATIONS`; its power-on 10 by default) on ``line_hz`` mains: its ranges (V,
    ascending; each reads to ``overrange`` × itself)."""

    ranges: Numbers = (0.1, 1.0, 10.0, 100.0, 1000.0)
    overrange: number("a number >= 1", ge=1.0) = 1.2
    cycles: PositiveNumber = 10.0
    line_hz: choice(50.0, 60.0, expected="50 or 60 (Hz)") = 50.0

    def __post_init__(self) -> None:
        if any(r <= 0 for r in self.ranges) or list(self.ranges) != sorted(self.ranges):
            raise Refusal("ranges", "expected positive ranges in ascending order")
        if self.cycles not in HP34401A_INTEGRATIONS:
            raise Refusal("cycles", f"expected one of the meter's integration times: "
                                    f"{', '.join(f'{c:g}' for c in sorted(HP34401A_INTEGRATIONS))} power-line cycles")

    def range_for(self, volts: float) -> float:
        """The smallest range that reads ``volts``; a voltage beyond the largest is refused."""
        for candidate in self.ranges:
            if abs(volts) <= self.overrange * candidate:
                return float(candidate)
        raise SensorError(f"voltage {volts:.6g} V: beyond the voltmeter's largest range ({self.ranges[-1]:g} V)")

    @property
    def resolution_ppm(self) -> float:
        return HP34401A_INTEGRATIONS[self.cycles][0]

    @property
    def readings_per_second(self) -> float:
        """Readings/s: one per integration from one cycle up, the datasheet's figure below."""
        return self.line_hz / self.cycles if self.cycles >= 1 else HP34401A_INTEGRATIONS[self.cycles][1]

    @property
    def noise_ppm(self) -> float:
        return HP34401A_INTEGRATIONS[self.cycles][2]

    @property
    def added_noise(self) -> float:
        """V rms added to every reading whatever the range (below 10 cycles)."""
        return HP34401A_FAST_NOISE if self.cycles < 10 else 0.0

    @property
    def integration_time(self) -> float:
        """Seconds one reading integrates over."""
        return self.cycles / self.line_hz

    @property
    def bandwidth(self) -> float:
        """Equivalent noise bandwidth (Hz) of one reading: 1/(2 T_int) for a boxcar integration."""
        return 1.0 / (2.0 * self.integration_time)

    def at_rate(self, rate: float) -> Voltmeter:
        """The meter set to the longest integration that still gives ``rate`` readings per second; a rate
        beyond its fastest is refused."""
        settings = [replace(self, cycles=cycles) for cycles in HP34401A_INTEGRATIONS]
        fitting = [meter for meter in settings if meter.readings_per_second >= rate * (1 - 1e-9)]
        if not (math.isfinite(rate) and rate > 0) or not fitting:
            raise SensorError(f"rate = {rate!r}: expected a positive number of readings/s up to the meter's "
                              f"{max(meter.readings_per_second for meter in settings):g}")
        return max(fitting, key=lambda meter: meter.cycles)


@dataclass(frozen=True)
class NoiseBudget:
    """rms noise (V) of one reading, by source, and their root sum of squares."""

    johnson: float
    flicker: float
    meter: float
    quantisation: float
    range_volts: float
    resolution: float

    @property
    def total(self) -> float:
        return math.sqrt(self.johnson**2 + self.flicker**2 + self.meter**2 + self.quantisation**2)


@schema(section="readout", error=SensorError)
class ConstantCurrentReadout:
    """A sensor driven at ``current`` (A) and read by ``voltmeter`` after subtracting ``offset`` (V);
    ``thermal_resistance`` (K/W) from the die to ambient at ``temperature`` (K); readings over
    ``record_length`` (s), the lowest frequency of 1/f noise."""

    sensor: SpinValveSensor
    voltmeter: Voltmeter = Voltmeter()
    current: PositiveNumber = 100e-6
    offset: Number = 0.0
    thermal_resistance: NonNegativeNumber = 450.0  # Infineon GMR S6: conductance > 2.2 mW/K
    temperature: PositiveNumber = 296.15
    record_length: PositiveNumber = 60.0

    def warming(self, field: ArrayLike) -> NDArray[np.float64]:
        """(...) the self-heating (K): the fixed point of ΔT = I² R(ΔT) R_th, iterated to round-off (the
        map contracts by I² R_th dR/dT, ~1e-3 here; a runaway, where it does not contract, is refused)."""
        heat = self.current**2 * self.thermal_resistance
        warming = np.zeros(np.shape(field)[:-1])
        for _ in range(60):
            updated = heat * self.sensor.resistance(field, warming)
            if np.all(np.abs(updated - warming) <= 1e-13 * np.maximum(np.abs(updated), 1e-300)):
                return updated
            warming = updated
        raise NotConverged(f"readout: the self-heating runs away at {self.current:g} A and {self.thermal_resistance:g} K/W")

    def voltage(self, field: ArrayLike) -> NDArray[np.float64]:
        """(...) the voltage (V) across the sensor at constant current, self-heating included, before
        the offset is subtracted."""
        return self.current * self.sensor.resistance(field, self.warming(field))

    def noise(self, volts: float) -> NoiseBudget:
        """The noise of one reading of the sensor at ``volts`` (across it; the meter sees volts − offset)."""
        if not math.isfinite(volts) or volts <= 0:
            raise SensorError(f"volts = {volts!r}: expected the positive voltage across the sensor")
        resistance = volts / self.current
        warmed = self.temperature + self.current**2 * resistance * self.thermal_resistance
        band = self.voltmeter.bandwidth
        johnson = math.sqrt(4.0 * Boltzmann * warmed * resistance * band)
        lowest = 1.0 / self.record_length
        flicker2 = self.sensor.hooge * volts**2 / self.sensor.carriers * math.log(max(band / lowest, 1.0))
        meter_range = self.voltmeter.range_for(volts - self.offset)
        resolution = self.voltmeter.resolution_ppm * 1e-6 * meter_range
        meter = math.hypot(self.voltmeter.noise_ppm * 1e-6 * meter_range, self.voltmeter.added_noise)
        return NoiseBudget(johnson=johnson, flicker=math.sqrt(flicker2), meter=meter,
                           quantisation=resolution / math.sqrt(12.0), range_volts=meter_range, resolution=resolution)

    def read(self, volts: ArrayLike, rng: np.random.Generator) -> NDArray[np.float64]:
        """Readings (V, after the offset) of the sensor at ``volts``: Johnson, 1/f (drawn white at its
        rms over one reading: readings far apart in time) and meter noise, quantised to the resolution."""
        volts = np.asarray(volts, dtype=np.float64)
        if volts.size == 0 or not np.all(np.isfinite(volts)):
            raise SensorError("volts: expected a non-empty array of finite voltages")
        budget = self.noise(float(np.max(volts)))
        analog = math.sqrt(budget.johnson**2 + budget.flicker**2 + budget.meter**2)
        noisy = volts - self.offset + rng.normal(0.0, analog, volts.shape)
        return np.round(noisy / budget.resolution) * budget.resolution
