"""The spin-valve sensor and its constant-current readout against the published figures of S4 and
hand-computed noise."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from softtip.sensors.gmr import (
    TESLA_PER_OERSTED,
    ConstantCurrentReadout,
    SensorError,
    SpinValveSensor,
    Voltmeter,
    published_spin_valve,
)

X = published_spin_valve("X", 444, 0.05, 146.6, -25.0, 37.5)
Y = published_spin_valve("Y", 416, 0.044, 118.8, -25.0, 37.5)


def test_published_figures_give_the_resistances_the_spec_derives():
    # S4 spec: "the bridge-free resistances are about 183 kΩ (X) and 169 kΩ (Y)"
    assert X.minimum_resistance == pytest.approx(146.6 * 62.5 / 0.05)  # 183.25 kΩ
    assert Y.minimum_resistance == pytest.approx(118.8 * 62.5 / 0.044)  # 168.75 kΩ
    # at 100 µA the X sensor sits near 18 V (18.33 V at R_min, 18.69 V at zero field, 40 % up its range)
    readout = ConstantCurrentReadout(sensor=X, thermal_resistance=0.0)
    assert readout.voltage(np.zeros(444)) == pytest.approx(100e-6 * 183250 * (1 + 0.05 * 25 / 62.5))


def test_sensitivity_linear_range_and_saturation_per_element():
    field = 5 * TESLA_PER_OERSTED
    step = 1e-3 * TESLA_PER_OERSTED
    slope = (X.resistance(np.full(444, field + step)) - X.resistance(np.full(444, field))) / (step / TESLA_PER_OERSTED)
    assert slope == pytest.approx(146.6, rel=1e-9)  # Ω per Oe, inside the linear range
    # flat beyond the range's ends, which are not centred on zero
    assert X.resistance(np.full(444, -30 * TESLA_PER_OERSTED)) == pytest.approx(X.minimum_resistance)
    assert X.resistance(np.full(444, 1.0)) == pytest.approx(X.minimum_resistance * 1.05)
    # each element saturates on its own: half the meander in a huge field, half at the low end
    mixed = np.where(np.arange(444) < 222, 1.0, -1.0)
    assert X.resistance(mixed) == pytest.approx(X.minimum_resistance * 1.025)


def test_each_area_element_saturates_before_the_meander_averages_them_by_area():
    # two area elements, 1 and 3 units of spin-valve area: the first far above the range, the other far below
    sensor = replace(X, area_weights=[1.0, 3.0])
    assert sensor.area_elements == 2
    assert sensor.resistance(np.array([1.0, -1.0])) == pytest.approx(X.minimum_resistance * (1 + 0.05 * 1 / 4))
    # the area-weighted mean field, -0.5 T, saturated after averaging would read the bottom of the range
    assert X.resistance(np.full(444, -0.5)) == pytest.approx(X.minimum_resistance)
    with pytest.raises(SensorError, match=r"spin_valve.area_weights = .*: expected positive areas"):
        replace(X, area_weights=[1.0, 0.0])


def test_self_heating_is_the_fixed_point_of_the_power_balance():
    readout = ConstantCurrentReadout(sensor=X, thermal_resistance=450.0)
    field = np.zeros(444)
    warming = float(readout.warming(field))
    resistance = float(X.resistance(field, warming))
    assert warming == pytest.approx(100e-6**2 * resistance * 450.0, rel=1e-12)
    assert 0.8 < warming < 0.9  # 1.87 mW into 450 K/W


def test_noise_floor_is_johnson_flicker_and_meter_from_hand_computed_values():
    readout = ConstantCurrentReadout(sensor=X, thermal_resistance=0.0, temperature=300.0)
    volts = 18.0
    budget = readout.noise(volts)
    # Johnson: √(4 k T R B) with R = 180 kΩ, T = 300 K, B = 1/(2 × 0.2 s) = 2.5 Hz (10 cycles of 50 Hz)
    assert budget.johnson == pytest.approx(math.sqrt(4 * 1.380649e-23 * 300 * 180e3 * 2.5), rel=1e-9)
    assert budget.johnson == pytest.approx(86.3e-9, rel=1e-3)
    # Hooge: α V² ln(f_hi/f_lo)/N, N = n × 444 × 1 mm × 2 µm × 40 nm
    carriers = 8.5e28 * 444 * 1e-3 * 2e-6 * 40e-9
    assert budget.flicker == pytest.approx(math.sqrt(2e-3 * 18.0**2 * math.log(2.5 * 60) / carriers), rel=1e-9)
    # the HP 34401A at its power-on 10 cycles: the 100 V range (18 V > 1.2 × 10 V), resolution 0.000001 ×
    # full scale = 100 µV, no additional noise at 10 cycles
    assert budget.range_volts == 100.0
    assert budget.resolution == pytest.approx(100e-6)
    assert budget.meter == 0.0
    assert budget.quantisation == pytest.approx(100e-6 / math.sqrt(12))
    assert budget.total == pytest.approx(math.sqrt(budget.johnson**2 + budget.flicker**2 + (100e-6) ** 2 / 12))
    # a matched offset subtracted before the meter puts it on its 0.1 V range: 0.1 µV resolution
    nulled = ConstantCurrentReadout(sensor=X, thermal_resistance=0.0, temperature=300.0, offset=17.95)
    assert nulled.noise(volts).resolution == pytest.approx(0.1e-6)
    assert nulled.noise(volts).total < budget.total / 50


def test_the_34401a_at_a_sampling_rate_takes_the_longest_integration_its_datasheet_allows():
    meter = Voltmeter()
    # User's Guide: 0.02 / 0.2 / 1 / 10 / 100 PLC give 0.0001 / 0.00001 / 0.000003 / 0.000001 / 0.0000003 x
    # full scale; datasheet: 50 readings/s at 1 PLC and 5 at 10 PLC on 50 Hz mains, 300 at 0.2 PLC
    assert [meter.at_rate(r).cycles for r in (0.5, 2.0, 5.0, 20.0, 50.0, 100.0, 300.0, 1000.0)] == [
        100.0, 10.0, 10.0, 1.0, 1.0, 0.2, 0.2, 0.02]
    fifty = meter.at_rate(50.0)
    assert fifty.integration_time == pytest.approx(0.02)
    readout = ConstantCurrentReadout(sensor=X, voltmeter=fifty, thermal_resistance=0.0, temperature=300.0)
    budget = readout.noise(18.7)
    assert budget.resolution == pytest.approx(3e-6 * 100.0)  # 300 µV steps on the 100 V range
    # the additional noise error at 1 PLC, 0.001 % of range, plus 20 µV on DC volts (taken as rms)
    assert budget.meter == pytest.approx(math.hypot(1e-5 * 100.0, 20e-6))
    # on 60 Hz mains one cycle is 16.7 ms, 60 readings/s
    assert Voltmeter(line_hz=60.0).at_rate(60.0).cycles == 1.0
    assert Voltmeter(line_hz=60.0).at_rate(60.0).integration_time == pytest.approx(1 / 60)
    with pytest.raises(SensorError, match="up to the meter's 1000"):
        meter.at_rate(2000.0)
    with pytest.raises(SensorError, match=r"voltmeter.cycles = 3.0: expected one of the meter's integration times"):
        Voltmeter(cycles=3.0)


def test_readings_are_quantised_and_scatter_by_the_budget():
    readout = ConstantCurrentReadout(sensor=X, offset=18.0, voltmeter=Voltmeter(cycles=0.02))
    rng = np.random.default_rng(1)
    volts = np.full(20000, 18.01234)
    readings = readout.read(volts, rng)
    budget = readout.noise(18.01234)
    assert budget.range_volts == 0.1 and budget.meter == pytest.approx(math.hypot(1e-4 * 0.1, 20e-6))
    assert np.allclose(readings / budget.resolution, np.round(readings / budget.resolution))
    assert readings.std() == pytest.approx(budget.total, rel=0.03)  # 20000 draws: 1 % standard error
    assert readings.mean() == pytest.approx(0.01234, abs=3 * budget.total / math.sqrt(20000) + budget.resolution)


def test_bad_input_is_refused_in_one_line():
    with pytest.raises(SensorError, match=r"spin_valve.field_high = .*expected a field above field_low"):
        published_spin_valve("X", 444, 0.05, 146.6, 37.5, -25.0)
    with pytest.raises(SensorError, match=r"spin_valve.magnetoresistance = 1.5"):
        published_spin_valve("X", 444, 1.5, 146.6, -25.0, 37.5)
    with pytest.raises(SensorError, match=r"field: expected the field of 444 area elements"):
        X.resistance(np.zeros(10))
    with pytest.raises(SensorError, match="field: expected finite numbers"):
        X.resistance(np.full(444, np.nan))
    with pytest.raises(SensorError, match=r"readout.current = 0: expected a positive number"):
        ConstantCurrentReadout(sensor=X, current=0)
    with pytest.raises(SensorError, match="beyond the voltmeter's largest range"):
        ConstantCurrentReadout(sensor=X).noise(5000.0)
    with pytest.raises(SensorError, match="voltmeter.ranges"):
        Voltmeter(ranges=[10.0, 1.0])
    with pytest.raises(SensorError, match="spin_valve.elements"):
        SpinValveSensor(name="X", elements=0, magnetoresistance=0.05, sensitivity=1.0, field_low=0.0, field_high=1.0)
