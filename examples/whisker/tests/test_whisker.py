"""The whisker plug-in against independent references: magpylib for the posed magnet's field, softtip's
large-deflection rod solver for the wire's bending, hand-computed words of the TLV493D and the moment
balance of the rocking magnet; and softtip's checker of a registered system."""

from __future__ import annotations

import math

import magpylib
import numpy as np
import pytest

from softtip.lab.protocols import load_protocol
from softtip.mechanics.rod import Rod, solve_tip_force
from softtip.plugin import SILENT, check_system
from softtip.sensors.registry import check_changes, sensor_kind
from softtip_whisker.bench import SweepParameters, check_range, deflection_profile
from softtip_whisker.live import whisker_scenario
from softtip_whisker.study import output_step, rest_noise
from softtip_whisker.study import whisker as whisker_study
from softtip_whisker.tlv493d import SENSOR, TLV493DSettings, decode, read_uT
from softtip_whisker.whisker import Whisker, field_at_chip, tilts

MM = 1e-3


def test_the_field_at_the_chip_is_magpylibs_of_the_magnet_slid_and_rocked_about_its_bottom_face():
    whisker = Whisker()
    forces = np.array([[0.0, 0.0], [0.02, 0.0], [-0.01, 0.015], [0.012, -0.01]])
    expected = []
    for force, rotvec in zip(forces, tilts(whisker, forces)):
        magnet = magpylib.magnet.Cylinder(polarization=(0, 0, whisker.polarization_T),
                                          dimension=(whisker.magnet_diameter_mm * MM, whisker.magnet_height_mm * MM),
                                          position=(0, 0, (whisker.layer_mm + whisker.magnet_height_mm / 2) * MM))
        slid = (*force / whisker.sliding_stiffness, 0.0)
        magnet.move(slid)
        magnet.rotate_from_rotvec(rotvec, anchor=np.add(slid, (0, 0, whisker.layer_mm * MM)), degrees=False)
        expected.append(magnet.getB((0, 0, 0)))
    np.testing.assert_allclose(field_at_chip(whisker, forces), expected, rtol=1e-9, atol=1e-12)


def test_the_magnets_stiffnesses_and_tilt_by_hand():
    # a rigid disc of radius R = 1.5 mm on a layer h = 1.5 mm thick, E = 1 MPa, ν = 0.49 (G = E / 2.98):
    # rocking 8 G R³ / (3 (1 - ν)) (1 + R / 6h), sliding 8 G R / (2 - ν) (1 + R / 2h)
    whisker, shear = Whisker(), 1e6 / 2.98
    rocking = 8 * shear * 1.5e-3 ** 3 / (3 * 0.51) * (1 + 1 / 6)
    assert whisker.rocking_stiffness == pytest.approx(rocking, rel=1e-12)
    assert whisker.sliding_stiffness == pytest.approx(8 * shear * 1.5e-3 / 1.51 * 1.5, rel=1e-12)
    # 10 mN along +y at the tip, 31 mm above the rocking centre, turns the magnet about -x
    assert tilts(whisker, np.array([[0.0, 0.01]]))[0] == pytest.approx([-0.01 * 0.031 / rocking, 0.0, 0.0])


def test_the_wires_bending_is_the_rod_solvers_at_a_small_force():
    whisker = Whisker()
    rod = Rod(length=whisker.wire_length_mm * MM, base_diameter=whisker.wire_diameter_mm * MM,
              tip_diameter=whisker.wire_diameter_mm * MM, youngs_modulus=whisker.wire_modulus_GPa * 1e9,
              poisson_ratio=0.3, shear_and_stretch=False, segments=200)
    force = 1e-3  # about 0.08 mm at the tip: the linear beam's range
    tip = solve_tip_force(rod, [[force, 0.0]]).tip[0]
    assert tip[0] / force == pytest.approx(whisker.wire_compliance, rel=5e-5)  # measured 1.2e-5: 200 segments


@pytest.mark.parametrize(("bits", "words", "values_uT", "saturated"), [
    (12, [0x001, 0xFFF, 0x000], [98.0, -98.0, 0.0], [False, False, False]),
    (12, [0x7FF, 0x800, 0x400], [2047 * 98.0, -2048 * 98.0, 1024 * 98.0], [True, True, False]),
    (8, [0x7F, 0x80, 0x01], [127 * 1568.0, -128 * 1568.0, 1568.0], [True, True, False]),
])
def test_the_words_decode_as_the_data_sheet_counts_them(bits, words, values_uT, saturated):
    values, clipped = decode(TLV493DSettings(bits=bits), np.array([words]))
    np.testing.assert_array_equal(values[0], values_uT)
    np.testing.assert_array_equal(clipped[0], saturated)


def test_the_host_reads_the_field_rounded_to_the_step_and_clipped_at_the_words():
    settings = TLV493DSettings()
    field_T = np.array([[0.049e-3, -0.05e-3, 0.2e-3], [0.3, -0.3, 0.1302]])
    values, saturated = read_uT(field_T, settings, np.random.default_rng(0), noise_uT=0.0)
    np.testing.assert_array_equal(values, [[0.0, -98.0, 196.0], [2047 * 98.0, -2048 * 98.0, 1329 * 98.0]])
    np.testing.assert_array_equal(saturated, [[False] * 3, [True, True, False]])


def test_the_chips_model_gives_the_registers_words_and_the_data_sheets_noise():
    chip = SENSOR.model(TLV493DSettings(mode="fast"))
    field_T = np.array([[0.049e-3, -0.05e-3, 0.2e-3], [0.3, -0.3, 0.1302]])
    read = chip.acquire(field_T)  # no noise without a random stream
    # 0.5, -0.51 and 2.04 steps round to 0, -1 and 2; the words hold -1 as 4096 - 1 and clip at 2047 and -2048
    np.testing.assert_array_equal(read.raw, [[0, 4095, 2], [2047, 2048, 1329]])
    np.testing.assert_array_equal(read.values, [[0.0, -98.0, 196.0], [2047 * 98.0, -2048 * 98.0, 1329 * 98.0]])
    np.testing.assert_array_equal(read.saturated, [[False] * 3, [True, True, False]])
    steady = chip.acquire(np.full((40000, 3), 5e-3), np.random.default_rng(1)).values
    # 0.1 mT rms noise, rounded to 98 µT steps: a spread of sqrt(100^2 + 98^2 / 12) = 104 µT, known to 0.35 %
    np.testing.assert_allclose(steady.std(axis=0), np.hypot(100.0, 98.0 / np.sqrt(12)), rtol=5 / np.sqrt(80000))
    assert SENSOR.conversion_time(TLV493DSettings(mode="fast")) == pytest.approx(1 / 3300.0)


def test_the_settings_refuse_what_the_chip_has_not_in_one_line():
    with pytest.raises(ValueError, match=r"^sensor\.mode = 'turbo': .*fast.*low-power.*ultra-low-power"):
        TLV493DSettings.from_dict({"mode": "turbo"})
    with pytest.raises(ValueError, match=r"sensor\.gain_sel"):
        TLV493DSettings.from_dict({"gain_sel": 7})
    assert TLV493DSettings.from_dict({"mode": "fast"}).rate_hz == 3300.0


def test_the_study_measures_a_known_step_and_noise_back():
    rng = np.random.default_rng(4)
    sigma, step = 100.0, 98.0
    rest = np.rint(rng.normal(0.0, sigma, (400, 6)) / step) * step
    assert output_step(rest[:, 0]) == step
    # the spread of a standard deviation over 6 columns of 399 degrees of freedom is about 1.2 %: 2.5 of it
    assert rest_noise(rest, step) == pytest.approx(sigma, rel=0.03)


def test_a_push_rests_first_then_goes_out_and_back():
    profile = deflection_profile(SweepParameters(deflection_mm=3.0, push_s=0.05, rest_s=0.03), 100.0)
    np.testing.assert_allclose(profile / MM, [0, 0, 0, 0, 0.75, 1.5, 2.25, 3.0, 2.25, 1.5, 0.75, 0])


def test_the_live_scenario_asks_first_and_streams_the_chip_at_its_rate():
    asked = []
    scenario = whisker_scenario(progress=SILENT, check=lambda chips, rate: asked.append((chips, rate)))
    assert asked == [(1, 100.0)] and scenario.rate_hz == 100.0 and scenario.chips == 1
    readings = scenario.source.readings[:, 0, :]
    assert not scenario.source.saturated.any()
    at_rest = readings[:scenario.baseline_frames]
    # at rest: the magnet's field on its axis; the noise (about a step) dithers the rounding, so the mean of
    # the frames is within three standard errors (3 x 100 µT / 5)
    np.testing.assert_allclose(at_rest.mean(axis=0), field_at_chip(Whisker(), np.zeros((1, 2)))[0] * 1e6, atol=60.0)


def test_the_sensor_is_registered_and_the_system_holds_every_rule():
    assert sensor_kind("tlv493d") is SENSOR
    assert check_system("whisker") == []


def test_a_push_beyond_the_linear_model_or_a_field_beyond_the_chips_range_is_refused():
    with pytest.raises(ValueError, match=r"^parameters\.deflection_mm = 4\.0: tilts the magnet by 0\.117 rad"):
        check_range(Whisker(), 4.0)
    # a 2 mm tall magnet at rest, on its axis: J / 2 (3.5 / sqrt(3.5² + 1.5²) - 1.5 / sqrt(1.5² + 1.5²)) = 137.8 mT
    with pytest.raises(ValueError, match=r"^design: the magnet's field at the chip reaches 137\.8 mT"):
        check_range(Whisker(magnet_height_mm=2.0), 0.01)
    with pytest.raises(ValueError, match=r"^design\.layer_mm = 1\.2: expected at least the magnet's radius \(1\.5 mm\)"):
        check_range(Whisker(layer_mm=1.2), 3.0)
    check_range(Whisker(), 3.0)  # the shipped protocol's: 0.087 rad, 98 mT


def test_calibrate_checks_a_dataset_against_the_registered_chip_at_its_stated_settings():
    stated = {"mode": "low-power", "bits": 12}
    check_changes({"s0_bx_uT": np.array([-401.2e3, 401.2e3])}, stated, "sweep.parquet")  # twice 2047 x 98 µT
    with pytest.raises(ValueError, match=r"^sweep\.parquet: channel s0_bx_uT reaches 4\.013e\+05 uT, beyond twice "
                                         r"the TLV493D's 2\.006e\+05 uT range at the dataset's sensor settings$"):
        check_changes({"s0_bx_uT": np.array([401.3e3])}, stated, "sweep.parquet")


def test_the_study_reads_the_chips_step_and_noise_back_from_the_shipped_protocol():
    protocol = load_protocol("whisker-sweep").changed(calibration_trials=4, validation_trials=2)
    outcome = whisker_study(protocol, 7, SILENT)
    assert outcome.results["output_step_uT"] == 98.0
    # 6 trials x 20 readings at rest x 3 axes: a standard deviation's standard error is 100 / sqrt(2 x 360) µT,
    # 3.7 µT; three of them
    assert outcome.results["rms_noise_uT"] == pytest.approx(100.0, abs=11.0)
