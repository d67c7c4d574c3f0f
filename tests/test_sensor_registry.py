"""Sensors registered by name, as the toolkit's range checks know them: a system declares the chips it
reads, and a dataset's readings are checked against the registered sensor at the settings it states
(the MLX90393's figures against its datasheet, rev. 006, tables 17 and 21, computed by hand)."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from softtip._core.channels import Reading
from softtip._core.systems import NotRegistered, owner
from softtip.realtime.baseline import Baseline
from softtip.sensors.registry import SensorKind, check_changes, sensor_kind

# GAIN_SEL 0, RES 3 (the widest): 6.009 µT/LSB on x, y and 9.680 on z, ±11000 counts (RES 3's span)
WIDEST_UT = np.array([6.009, 6.009, 9.680]) * 11000
# GAIN_SEL 7, RES 0: 0.150 and 0.242 µT/LSB, a signed 16-bit word (largest 32767)
FINEST_SETTINGS = {"gain_sel": 7, "res_xyz": [0, 0, 0]}
FINEST_UT = np.array([0.150, 0.150, 0.242]) * 32767


def test_the_fingertip_declares_the_hall_chip_the_checks_ask():
    hall = sensor_kind("mlx90393")
    assert owner("sensor", "mlx90393").name == "hall-fingertip"
    assert (hall.axes, hall.raw_unit, hall.raw_bits, hall.reading.unit) == (3, "counts", 16, "uT")
    np.testing.assert_allclose(hall.full_scale(hall.widest), WIDEST_UT, rtol=1e-12)
    np.testing.assert_allclose(hall.full_scale(hall.settings_from(FINEST_SETTINGS)), FINEST_UT, rtol=1e-12)
    # the decoder: RES 0 words are two's complement, 0xFFFF is -1 count
    values, saturated = hall.decode(hall.settings_from(FINEST_SETTINGS), np.array([[1, 0xFFFF, 32767]], np.uint16))
    np.testing.assert_allclose(values, [[0.150, -0.150, FINEST_UT[2]]], rtol=1e-12)
    assert saturated.tolist() == [[False, False, True]]
    with pytest.raises(NotRegistered, match=r"^sensor 'tmag5273': expected one of mlx90393$"):
        sensor_kind("tmag5273")


def test_a_streams_chips_are_a_registered_sensor_at_its_settings_and_give_its_recorded_covariance():
    """The default settings (GAIN_SEL 7, RES 0, OSR 0, DIG_FILT 2): 0.150 / 0.242 µT per LSB; noise 0.25 µT
    on x, y at 2^3 (2 + 2^7) = 1040 samples averaged, scaled by sqrt(1040 / 6) at 2^0 (2 + 2^2) = 6, and by
    0.242 / 0.150 on z; plus the step's uniform quantisation, step^2 / 12."""
    from softtip.realtime.recording.format import magnetic_covariance_T2

    hall = sensor_kind("mlx90393")
    chips = hall.at(hall.settings())
    noise_xy_uT2 = 0.25**2 * 1040 / 6
    expected_uT2 = [noise_xy_uT2 + 0.150**2 / 12] * 2 + [noise_xy_uT2 * (0.242 / 0.150) ** 2 + 0.242**2 / 12]
    np.testing.assert_allclose(magnetic_covariance_T2(chips), np.diag(expected_uT2).ravel() * 1e-12, rtol=1e-12)
    assert chips.to_dict() == hall.settings().to_dict()
    silent = dataclasses.replace(hall, noise=None)  # a sensor whose datasheet states no noise: ROS's "unknown"
    np.testing.assert_array_equal(magnetic_covariance_T2(silent.at(hall.settings())), np.zeros(9))
    with pytest.raises(ValueError, match=r"^settings of sensor 'mlx90393': expected MLX90393Settings, got dict$"):
        hall.at(FINEST_SETTINGS)


def test_a_stream_refuses_settings_of_a_sensor_of_another_reading():
    from softtip.hardware import PacedSource
    from softtip.realtime.pipeline import Pipeline

    force = Reading("force", "N", "F", "N", prefix="f", infix="f", units={"N": 1.0}, drift_threshold=0.05,
                    baseline_step=1e-4, decimals=3, topic="force", message="geometry_msgs/msg/WrenchStamped")
    hall = sensor_kind("mlx90393").at(sensor_kind("mlx90393").settings())
    refusal = r"^settings: expected a registered sensor of force at its settings, got ChipSettings\(kind=Sensor"
    with pytest.raises(ValueError, match=refusal):
        PacedSource(np.zeros((2, 1, 3)), 10.0, reading=force, settings=hall)
    with pytest.raises(ValueError, match=refusal):
        Pipeline(1, reading=force, baseline=Baseline(reading=force), settings=hall)


def test_a_reading_of_fewer_axes_names_and_places_only_its_own():
    """A chip reading x and z (an in-plane and a normal axis): two channels per sensor, stored x, z."""
    shear = Reading("shear", "mm", "u", "mm", prefix="u", infix="", units={"mm": 1.0}, drift_threshold=0.01,
                    baseline_step=1e-4, decimals=3, topic="shear", message="geometry_msgs/msg/Vector3Stamped",
                    axes=("x", "z"))
    assert shear.channel_names(2) == ("u0_x_mm", "u0_z_mm", "u1_x_mm", "u1_z_mm") and shear.positions == (0, 2)
    assert [shear.channel_index(name) for name in ("u1_z_mm", "u0_x_mm", "u1_x_mm")] == [3, 0, 2]
    assert not shear.is_channel("u0_y_mm")
    columns = shear.columns(np.arange(8.0).reshape(2, 2, 2))
    assert {name: list(values) for name, values in columns.items()} == {
        "u0_x_mm": [0.0, 4.0], "u0_z_mm": [1.0, 5.0], "u1_x_mm": [2.0, 6.0], "u1_z_mm": [3.0, 7.0]}
    with pytest.raises(ValueError, match=r"^readings: expected shape \(n_samples, n_sensors, 2\), got \(2, 2, 3\)$"):
        shear.columns(np.zeros((2, 2, 3)))
    with pytest.raises(ValueError, match=r"expected a sensor index >= 0 and an axis in x, z, got 0, 'y'"):
        shear.channel_name(0, "y")
    for axes in ((), ("z", "x"), ("x", "x"), ("w",), ["z"]):
        with pytest.raises(ValueError, match=r"^reading 'shear': axes = .*: expected one to three of x, y, z"):
            dataclasses.replace(shear, axes=axes)
    hall = sensor_kind("mlx90393")
    with pytest.raises(ValueError, match=r"^sensor 'shear-chip': axes = 3: its reading 'shear' has 2 \(x, z\)$"):
        dataclasses.replace(hall, name="shear-chip", reading=shear)


def test_a_sensor_record_refuses_what_it_cannot_be():
    hall = sensor_kind("mlx90393")
    fields = dict(reading=hall.reading, settings=hall.settings, widest=hall.widest, full_scale=hall.full_scale,
                  step=hall.step)
    with pytest.raises(ValueError, match=r"sensor 'flat': axes = 4: expected 1, 2 or 3"):
        SensorKind("flat", axes=4, **fields)
    with pytest.raises(ValueError, match=r"sensor 'half': give decode, raw_unit and raw_bits together, or none"):
        SensorKind("half", axes=3, raw_unit="counts", **fields)
    with pytest.raises(ValueError, match=r"sensor 'wide': raw_bits = 64: expected an integer 1..63"):
        SensorKind("wide", axes=3, decode=hall.decode, raw_unit="counts", raw_bits=64, **fields)
    with pytest.raises(ValueError, match=r"sensor name 'Hall chip': expected a lower-case name"):
        SensorKind("Hall chip", axes=3, **fields)


@pytest.mark.parametrize(("stated", "full_scale", "where"), [(None, WIDEST_UT, "its widest setting"),
                                                              (FINEST_SETTINGS, FINEST_UT, "the dataset's sensor settings")])
def test_changes_beyond_twice_the_registered_range_are_refused(stated, full_scale, where):
    inside = {"s0_bx_uT": np.array([0.0, 1.999 * full_scale[0]]), "s0_bz_uT": np.array([-1.999 * full_scale[2]])}
    check_changes(inside, stated, "d.parquet")
    beyond = {**inside, "s1_bz_uT": np.array([0.0, 2.001 * full_scale[2]])}
    with pytest.raises(ValueError, match="^" + re.escape(
            f"d.parquet: channel s1_bz_uT reaches {2.001 * full_scale[2]:.4g} uT, beyond twice the MLX90393's "
            f"{full_scale[2]:.4g} uT range at {where}") + "$"):
        check_changes(beyond, stated, "d.parquet")


def test_another_chip_s_settings_are_not_read_as_the_hall_chip_s():
    """Issue 37: a force chip's settings beside force channels are no Hall chip's to check; beside Hall
    channels they are refused, naming the sensor whose settings they are not."""
    wearable_settings = {"chip": {"range_N": 5.0}, "table": {"range_N": 50.0}}
    check_changes({"side_fz_N": np.array([0.0, 4.0])}, wearable_settings, "force.parquet")
    with pytest.raises(ValueError, match=r"^hall.parquet: its sensor settings are not those of a sensor reading "
                                         r"flux density \(mlx90393: sensor.chip: unknown key"):
        check_changes({"s0_bx_uT": np.array([1.0])}, wearable_settings, "hall.parquet")


@pytest.mark.slow  # two commands in fresh interpreters, the protocol's trials: about 20 s on 2 busy cores
def test_a_wearable_dataset_from_lab_run_is_calibrated(tmp_path):
    """Issue 37 end to end: lab run of the wearable's protocol, then calibrate."""
    protocol = tmp_path / "wearable.toml"
    protocol.write_text('protocol = "wearable"\nseed = 2\n[parameters]\nparticipants = 2\nruns = 2\n')
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}

    def softtip(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "softtip", *args], cwd=tmp_path, env=environment,
                              capture_output=True, text=True, timeout=300)

    ran = softtip("lab", "run", str(protocol), "-o", "wearable.parquet", "--json")
    assert ran.returncode == 0, ran.stderr
    calibrated = softtip("calibrate", "wearable.parquet", "-t", "fz_N", "--model", "polynomial", "-o", "force.npz",
                         "--json")
    assert calibrated.returncode == 0, calibrated.stderr
    assert json.loads(calibrated.stdout)["model"] == "force.npz" and (tmp_path / "force.npz").is_file()
