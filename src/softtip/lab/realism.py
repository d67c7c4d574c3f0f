"""What makes a virtual experiment look like a real one, with the source of every number.

On by default; each effect can be switched off (set to 0) in a protocol's ``[realism]`` table.
:data:`REALISM_SOURCES` gives, for each, where its default comes from (the reports print it).
Each bench has its own table: :class:`Realism` for the magnetic fingertip (S1), and
:class:`WearableRealism` (:data:`WEARABLE_REALISM_SOURCES`) for the wearable sensor on the side of
the nail (S2: a person's fingertip on a table force sensor, a tactile chip held against the side of
the nail by a ring; :mod:`softtip.mechanics.fingerpad`, :mod:`softtip.lab.human_force`).

Nothing here is tuned to make a result look better: the numbers are the sources' and are the same
for every experiment and design.
"""

from __future__ import annotations

from dataclasses import asdict, fields

import numpy as np

from softtip._core.config import Flag, NonNegativeNumber, schema
from softtip._core.units import MM, UT_PER_T
from softtip.design.model import Design
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
class Realism:
    """The ``[realism]`` table of a protocol."""

    noise: Flag = True
    magnet_position_sd_mm: NonNegativeNumber = 0.10
    magnetisation_sd: NonNegativeNumber = 0.02
    sensor_position_sd_mm: NonNegativeNumber = 0.10
    position_sd_mm: NonNegativeNumber = 0.20
    angle_sd_deg: NonNegativeNumber = 0.5
    speed_sd: NonNegativeNumber = 0.02
    drift_K_per_sqrt_s: NonNegativeNumber = 0.02

    @classmethod
    def off(cls) -> "Realism":
        return cls(noise=False, magnet_position_sd_mm=0, magnetisation_sd=0, sensor_position_sd_mm=0,
                   position_sd_mm=0, angle_sd_deg=0, speed_sd=0, drift_K_per_sqrt_s=0)

    def to_dict(self) -> dict:
        return asdict(self)


WEARABLE_REALISM_SOURCES = {
    "noise": "each sensor's noise and output step (softtip.sensors.force_sensor: the Nano17's datasheet; the "
             "chip's class figures, assumed)",
    "finger_width_sd_mm": "per participant, around the protocol's breadth; every length of the pad scales with it: "
                          "adult distal index breadths spread by about 1 mm (hand anthropometry)",
    "pad_stiffness_sd": "per participant, log-normal factor on b: in-vivo fingerpad responses vary widely between "
                        "people (Gulati & Srinivasan, MIT RLE TR 605, 1997: five subjects)",
    "friction_sd": "per participant, added to the protocol's coefficient (kept >= 0.3): skin friction varies with "
                   "moisture and person (Dzidek et al., J. R. Soc. Interface 14, 2017)",
    "ring_preload_sd": "per run (the ring is re-seated), on the clamping force: a ring closed by hand",
    "sensor_position_sd_mm": "per run, the chip's place along the nail: re-seating",
    "placement_sd_mm": "per trial, where the pad first meets the object (x, y)",
    "finger_yaw_sd_deg": "per trial, the finger's axis against the table sensor's axes, aligned by eye",
    "force_tremor": "coefficient of variation of the held force, 1-12 Hz (Galganski et al., J. Neurophysiol. 69, "
                    "1993)",
    "cross_talk": "per press, the direction error on each other axis: a person aiming a force along one axis errs "
                  "by several degrees",
    "stream_skew_ms": "per run, at most, between the chip's and the table's samples: two 10 Hz streams aligned to "
                      "the nearest sample are off by up to half a period",
}


@schema(section="realism")
class WearableRealism:
    """The ``[realism]`` table of the wearable protocol."""

    noise: Flag = True
    finger_width_sd_mm: NonNegativeNumber = 1.0
    pad_stiffness_sd: NonNegativeNumber = 0.3
    friction_sd: NonNegativeNumber = 0.2
    ring_preload_sd: NonNegativeNumber = 0.3
    sensor_position_sd_mm: NonNegativeNumber = 1.0
    placement_sd_mm: NonNegativeNumber = 1.0
    finger_yaw_sd_deg: NonNegativeNumber = 5.0
    force_tremor: NonNegativeNumber = 0.02
    cross_talk: NonNegativeNumber = 0.1
    stream_skew_ms: NonNegativeNumber = 50.0

    @classmethod
    def off(cls) -> "WearableRealism":
        return cls(noise=False, **{item.name: 0.0 for item in fields(cls) if item.name != "noise"})

    def to_dict(self) -> dict:
        return asdict(self)


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
            read = self.sensor.counts_to_uT(self.sensor.to_counts(field, rng=rng))
        else:
            read = field * UT_PER_T
        return read - read[:1]
