"""Three-axis force sensors against their datasheet figures: the Nano17 SI-12-0.12's ranges and
resolution (ATI's datasheet), and the tactile chip's class figures as the module states them."""

from __future__ import annotations

import numpy as np
import pytest

from softtip._core.config import ConfigError
from softtip.sensors.force_sensor import NANO17, ForceSensorSpec, read_forces
from softtip.systems.wearable.chip import TACTILE_CHIP


def test_the_nano17_reads_in_steps_of_1_320_N_within_12_and_17_N():
    rng = np.random.default_rng(0)
    force = rng.uniform(-20, 20, (5000, 3))
    read, saturated = read_forces(force, NANO17, rng)
    steps = read * 320
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-9)
    assert read[:, :2].min() == -12 and read[:, :2].max() == 12 and read[:, 2].min() == -17 and read[:, 2].max() == 17
    inside = np.abs(force) < np.array([12, 12, 17]) - 0.05
    outside = np.abs(force) > np.array([12, 12, 17]) + 0.05
    assert not saturated[inside].any() and saturated[outside].all()
    # within range: the force to within noise and half a step
    assert np.abs(read - force)[inside].max() < 6 / 320 + 0.5 / 320


def test_the_chip_reads_in_steps_of_5_N_over_4096_and_cannot_be_pulled():
    rng = np.random.default_rng(1)
    read, saturated = read_forces(np.array([[0.1, -3.0, -0.2], [3.0, 0.2, 6.0], [0.0, 0.0, 1.0]]), TACTILE_CHIP, rng)
    steps = read * 4096 / 5
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-9)
    assert read[0, 1] == -2.5 and read[0, 2] == 0.0 and read[1, 0] == 2.5 and read[1, 2] == 5.0
    np.testing.assert_array_equal(saturated, [[False, True, True], [True, False, True], [False, False, False]])


@pytest.mark.parametrize("spec", [NANO17, TACTILE_CHIP], ids=["nano17", "chip"])
def test_noise_is_the_stated_rms_plus_the_rounding(spec):
    rng = np.random.default_rng(2)
    held = np.tile([0.3, -0.2, 1.0], (20000, 1))
    read, _ = read_forces(held, spec, rng)
    expected = np.sqrt(np.array(spec.noise) ** 2 + np.array(spec.resolution) ** 2 / 12)
    # the standard error of a standard deviation of n samples is sd / sqrt(2 (n - 1)): 0.5 %; four of them
    np.testing.assert_allclose(read.std(axis=0), expected, rtol=4 / np.sqrt(2 * (len(held) - 1)))


def test_without_noise_the_reading_is_exact_but_still_clipped():
    read, saturated = read_forces(np.array([0.1234567, -30.0, 1.0]), NANO17)
    np.testing.assert_array_equal(read, [0.1234567, -12.0, 1.0])
    np.testing.assert_array_equal(saturated, [False, True, False])


def test_a_spec_whose_range_is_empty_is_refused_naming_the_axis():
    with pytest.raises(ConfigError, match=r"^sensor.highest\[2\] = 0: expected above sensor.lowest\[2\] = 1.0$"):
        ForceSensorSpec(name="x", lowest=(-1, -1, 1), highest=(1, 1, 0), resolution=(1, 1, 1), noise=(0, 0, 0),
                        source="test")
    with pytest.raises(ConfigError, match=r"^sensor.resolution = "):
        ForceSensorSpec(name="x", lowest=(-1, -1, -1), highest=(1, 1, 1), resolution=(0, 1, 1), noise=(0, 0, 0),
                        source="test")


def test_the_hall_chip_and_a_force_sensor_keep_one_sensor_contract():
    from softtip._core.channels import MAGNETIC
    from softtip.sensors import MLX90393, ForceSensor, MLX90393Settings, Sensor, lsb_uT
    from softtip.systems.wearable.reading import FORCE

    hall = MLX90393(MLX90393Settings(gain_sel=7))
    chip = ForceSensor(NANO17, FORCE)
    assert isinstance(hall, Sensor) and isinstance(chip, Sensor)
    assert hall.reading is MAGNETIC and chip.reading is FORCE
    field = np.array([[1.0e-3, -2.0e-3, 5.0e-3]])  # T
    step = lsb_uT(hall.settings)  # the datasheet's µT per count at GAIN_SEL 7, RES 0
    got = hall.acquire(field)
    np.testing.assert_array_equal(got.values, np.rint(field * 1e6 / step) * step)
    assert got.raw.dtype == np.uint16 and not got.saturated.any()
    pushed = chip.acquire(np.array([13.0, -1.0, 0.5]))  # beyond the Nano17's ±12 N on x
    np.testing.assert_array_equal(pushed.values, [12.0, -1.0, 0.5])
    np.testing.assert_array_equal(pushed.saturated, [True, False, False])
    with pytest.raises(ValueError, match="a force sensor's reading is in N, not uT"):
        ForceSensor(NANO17, MAGNETIC)
