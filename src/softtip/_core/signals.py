"""Signal kernels: pure numpy functions of sampled series that both the physics
(:mod:`softtip.mechanics.viscoelastic`) and the calibration metrics
(:mod:`softtip.metrics`) compute.

The hysteresis of a load/unload cycle is defined in S1 §2: |Z_up − Z_down| /
(Z_max − Z_min) × 100, with Z_up and Z_down the sensor output on the loading and
unloading branches at the force midway between the cycle's minimum and maximum.
"""

from __future__ import annotations

import numpy as np


def _mean_crossing(force: np.ndarray, sensor_z: np.ndarray, level: float, branch: str) -> float:
    """The sensor output where a branch's force crosses ``level``: linear
    interpolation between the two samples either side of each crossing, averaged
    over all crossings (a noisy branch may cross the level several times)."""
    above = force - level
    hits = list(sensor_z[above == 0])
    for i in np.flatnonzero(above[:-1] * above[1:] < 0):
        fraction = above[i] / (above[i] - above[i + 1])
        hits.append(sensor_z[i] + fraction * (sensor_z[i + 1] - sensor_z[i]))
    if not hits:
        raise ValueError(f"force: the {branch} branch never reaches the mid force {level:g} N: not a load/unload cycle")
    return float(np.mean(hits))


def hysteresis_percent(sensor_z: np.ndarray, force: np.ndarray) -> float:
    """Hysteresis (%) of one load/unload cycle, |Z_up − Z_down| / (Z_max − Z_min) × 100.

    Z_up and Z_down are the sensor's z output on the loading branch (start to the
    maximum force) and the unloading branch (maximum force to end) at the force
    midway between the cycle's minimum and maximum. On each branch Z is
    interpolated linearly between the samples either side of the mid force;
    where noise makes a branch cross it more than once, the crossings are averaged.
    """
    sensor_z = np.asarray(sensor_z, dtype=float)
    force = np.asarray(force, dtype=float)
    if sensor_z.ndim != 1 or sensor_z.shape != force.shape or len(force) < 3:
        raise ValueError(f"sensor_z {sensor_z.shape} and force {force.shape}: expected two 1-D arrays of one cycle, same length ≥ 3")
    if not (np.all(np.isfinite(sensor_z)) and np.all(np.isfinite(force))):
        raise ValueError("sensor_z and force: expected finite values")
    z_range = np.ptp(sensor_z)
    if not np.ptp(force) > 0 or not z_range > 0:
        raise ValueError("sensor_z and force: expected a cycle along which both vary")
    peak = int(np.argmax(force))
    mid = (force.min() + force.max()) / 2
    z_up = _mean_crossing(force[: peak + 1], sensor_z[: peak + 1], mid, "loading")
    z_down = _mean_crossing(force[peak:], sensor_z[peak:], mid, "unloading")
    return float(abs(z_up - z_down) / z_range * 100)
