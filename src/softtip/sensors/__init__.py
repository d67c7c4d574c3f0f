"""Sensor models: the MLX90393 3-axis Hall magnetometer."""

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
    "averaging_count",
    "conversion_time_s",
    "full_scale_uT",
    "lsb_uT",
    "max_output_rate_hz",
    "noise_rms_uT",
]
