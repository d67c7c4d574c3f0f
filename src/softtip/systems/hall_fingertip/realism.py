"""What makes a virtual experiment look like a real one, with the source of every number.

On by default; each effect can be switched off (set to 0) in a protocol's ``[realism]`` table.
:data:`REALISM_SOURCES` gives, for each, where its default comes from (the reports print it).
:class:`Realism` is the Hall fingertip's table; :class:`FabricatedUnit` one fingertip as it came out of
fabrication.

Nothing here is tuned to make a result look better: the numbers are the sources' and are the same
for every experiment and design.
"""

from __future__ import annotations

import numpy as np

from softtip._core.config import Flag, NonNegativeNumber, schema
from softtip._core.units import MM, UT_PER_T
from softtip.design.model import Design
from softtip.lab.bench import RealismTable
from softtip.mechanics.poses import MagnetPoses
from softtip.twin import Readout

BR_TEMPERATURE_COEFFICIENT = -0.0012  # 1/K, sintered NdFeB, reversible


REALISM_SOURCES = {
    "noise": "MLX90393 datasheet noise at the design's GAIN/OSR/DIG_FILT (softtip.sensors.mlx90393.noise_rms_uT), "
             "quantised to the register's LSB, clipped at full scale",
    "magnet_position_sd_mm": "per magnet and axis, per fabricated unit: cast or printed pockets hold a magnet to "
                             "about ±0.1 mm",
    "magnetisation_sd": "per magnet: NdFeB grades specify Br within about ±2-3 %",
    "sensor_position_sd_mm": "per chip and axis: reflow and pick-and-place tolerance",
    "position_sd_mm": "per trial and axis: a hand-set or fixture-set contact",
    "angle_sd_deg": "per trial: a rotary stage set by hand",
    "speed_sd": "per trial: the robot's speed is exact, its start is not",
    "drift_K_per_sqrt_s": "temperature random walk of the magnets during a trial; the field follows Br's reversible "
                          "coefficient, -0.12 %/K for sintered NdFeB",
}


@schema(section="realism")
class Realism(RealismTable):
    """The ``[realism]`` table of a protocol."""

    noise: Flag = True
    magnet_position_sd_mm: NonNegativeNumber = 0.10
    magnetisation_sd: NonNegativeNumber = 0.02
    sensor_position_sd_mm: NonNegativeNumber = 0.10
    position_sd_mm: NonNegativeNumber = 0.20
    angle_sd_deg: NonNegativeNumber = 0.5
    speed_sd: NonNegativeNumber = 0.02
    drift_K_per_sqrt_s: NonNegativeNumber = 0.02


class FabricatedUnit(Readout):
    """One physical fingertip: the design's magnets and chips as they came out of fabrication."""

    def __init__(self, design: Design, realism: Realism, rng: np.random.Generator):
        self.realism = realism
        magnets, sensors = len(design.magnets), len(design.sensor_positions)
        self.magnet_offsets = rng.normal(0, realism.magnet_position_sd_mm * MM, (magnets, 3))
        polarizations = np.array([m.polarization for m in design.magnets]) * (
            1 + rng.normal(0, realism.magnetisation_sd, magnets))
        sensor_positions = design.sensor_positions + rng.normal(0, realism.sensor_position_sd_mm * MM, (sensors, 3))
        super().__init__(design, magnet_centers=np.array([m.center for m in design.magnets]) + self.magnet_offsets,
                         polarizations=polarizations, sensor_positions=sensor_positions)

    def record(self, poses: MagnetPoses, times: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """What the chips report over one trial, initial value subtracted: (N, S, 3) µT.

        The first sample is taken before contact (the protocol starts every trial in the air), so
        subtracting it is the papers' "reading before contact" - with its noise."""
        field = self.field(poses)
        if self.realism.drift_K_per_sqrt_s > 0:
            steps = rng.normal(0, self.realism.drift_K_per_sqrt_s, len(times)) * np.sqrt(
                np.diff(times, prepend=times[0]))
            field = field * (1 + BR_TEMPERATURE_COEFFICIENT * np.cumsum(steps))[:, None, None]
        if self.realism.noise:
            read = self.sensor.acquire(field, rng).values
        else:
            read = field * UT_PER_T
        return read - read[:1]
