"""Sensor models: the MLX90393 3-axis Hall magnetometer, and 3-axis force sensors (range, output
step, noise, saturation; the Nano17 reference among them)."""

from softtip.sensors.contract import Acquisition, Sensor
from softtip.sensors.force_sensor import NANO17, ForceSensor, ForceSensorSpec, read_forces
from softtip.sensors.mlx90393 import (
    MLX90393,
    MLX90393Settings,
    averaging_count,
    conversion_time_s,
    full_scale_uT,
    lsb_uT,
    max_output_rate_hz,
    noise_rms_uT,
)

__all__ = [
    "MLX90393",
    "MLX90393Settings",
    "NANO17",
    "Acquisition",
    "ForceSensor",
    "Sensor",
    "ForceSensorSpec",
    "averaging_count",
    "conversion_time_s",
    "full_scale_uT",
    "lsb_uT",
    "max_output_rate_hz",
    "noise_rms_uT",
    "read_forces",
]
