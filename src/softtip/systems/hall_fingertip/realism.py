"""What makes a virtual experiment look like a real one, with the source of every number.

On by default; each effect can be switched off (set to 0) in a protocol's ``[realism]`` table. The
pushing test's bench geometry is one of them: a fingertip centred on a rotary stage and a board centred
on the stage's axis make the unit four-fold symmetric about the board, so that a board at a and at
a + 90° load the chip alike, which the published bench evidently was not (its Sx and Sy changed
strongly and smoothly with the board's angle); ``stage_axis_offset_mm`` and ``board_edge_offset_mm``
break that symmetry as an unaligned bench does.
The causes of drift between sessions are off by default (a protocol is one session); set them to
run a later session of the same unit (same seed): the session's temperature (the magnets' remanence,
and with ``chip_temperature_drift`` each chip's offset and sensitivity), the elastomer's aging
(``modulus_change``) and creep (``compression_set_mm``), and a soft-iron plate near the chips
(``iron_plate_gap_mm``, its field by the method of images).
:data:`REALISM_SOURCES` gives, for each, where its default comes from (the reports print it).
:class:`Realism` is the Hall fingertip's table; :class:`FabricatedUnit` one fingertip as it came out of
fabrication.

Nothing here is tuned to make a result look better: the numbers are the sources' and are the same
for every experiment and design.
"""

from __future__ import annotations

import numpy as np

from softtip._core.config import Flag, NonNegativeNumber, Number, number, schema
from softtip._core.units import MM, UT_PER_T
from softtip.design.model import Design
from softtip.lab.bench import RealismTable
from softtip.magnetics import magnet_field_at_sensors
from softtip.mechanics.poses import MagnetPoses
from softtip.sensors.mlx90393 import MLX90393Settings, lsb_uT
from softtip.twin import Readout

BR_TEMPERATURE_COEFFICIENT = -0.0012  # 1/K, sintered NdFeB, reversible
# MLX90393 datasheet, magnetic specification: the offset drifts within +-1000 LSB at the highest gain
# (GAIN_SEL 7) and the sensitivity within +-3 % (TCMP_EN = 0) over the operating range; taken here
# over its upper half, 25 -> 85 degC, as per-kelvin bounds of each chip's and axis's coefficient.
CHIP_OFFSET_DRIFT_LSB = 1000.0
CHIP_SENSITIVITY_DRIFT = 0.03
CHIP_DRIFT_SPAN_K = 60.0


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
    "stage_axis_offset_mm": "pushing test: the rotary stage's axis off the fingertip's axis, along x (through magnet "
                            "0); not published: a 25 mm fingertip centred over a stage by eye sits about 1 mm off. "
                            "With it Sx and Sy change strongly and smoothly with the board's angle, as on the "
                            "published bench (the pushing report's table of causes)",
    "board_edge_offset_mm": "pushing test: the board's mid-plane off the stage's axis, across the board; not "
                            "published: 0, a board centred on the axis (clamped by one face on the axis it would be "
                            "half its 1.6 mm thickness off: the pushing report measures that too)",
    "session_temperature_K": "the session's temperature minus the calibration session's (off: 0); Br follows "
                             "-0.12 %/K (sintered NdFeB's reversible coefficient, e.g. the Magnet Materials Producers "
                             "Association's MMPA 0100 tables, Arnold's and VAC's datasheets give -0.11 to -0.13)",
    "chip_temperature_drift": "per chip and axis, per unit: an offset coefficient drawn within +-1000 LSB at GAIN_SEL 7 "
                              "per 60 K and a sensitivity coefficient within +-3 % per 60 K (MLX90393 datasheet, "
                              "magnetic specification: offset and sensitivity drift over temperature, TCMP_EN = 0); "
                              "applied with the session's temperature and the trial's random walk",
    "modulus_change": "relative change of the elastomer's modulus since calibration (aging: silicones stiffen "
                      "by some 5-20 % over months); the magnets move 1 / (1 + change) as far under the same load",
    "compression_set_mm": "creep that did not recover (compression set): the magnets rest this much lower",
    "iron_plate_gap_mm": "a soft-iron plate (a steel gripper part) parallel to the base this far below the chips' "
                         "Hall plates (off: 0); its field is the magnets' images in it (infinite permeability)",
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
    stage_axis_offset_mm: Number = 1.0
    board_edge_offset_mm: Number = 0.0
    session_temperature_K: Number = 0.0
    chip_temperature_drift: Flag = False
    modulus_change: number("a number above -1", gt=-1) = 0.0
    compression_set_mm: NonNegativeNumber = 0.0
    iron_plate_gap_mm: NonNegativeNumber = 0.0


def mirrored_magnets(centres: np.ndarray, rotvecs: np.ndarray, polarizations: np.ndarray,
                     plane_z: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The images of posed cylinders (centres and rotation vectors (..., M, 3), polarisations (M,)) in a
    soft-iron half-space below ``plane_z`` (infinite permeability): above the plane, the magnets and
    their images give the field the iron shapes. A magnetic charge's image there has the opposite
    sign, so a moment m images to (-m_x, -m_y, m_z) at the mirrored centre (a magnet over steel sees
    its image aligned, and is pulled down): the rotation conjugated by the mirror (rotation vector
    (-w_x, -w_y, w_z)) with the same polarisation along the cylinder's own axis."""
    mirror = np.array([1.0, 1.0, -1.0])
    image_centres = centres * mirror + np.array([0.0, 0.0, 2 * plane_z])
    return image_centres, -rotvecs * mirror, polarizations


class FabricatedUnit(Readout):
    """One physical fingertip: the design's magnets and chips as they came out of fabrication, in
    the session its realism describes (module notes)."""

    def __init__(self, design: Design, realism: Realism, rng: np.random.Generator):
        self.realism = realism
        magnets, sensors = len(design.magnets), len(design.sensor_positions)
        self.magnet_offsets = rng.normal(0, realism.magnet_position_sd_mm * MM, (magnets, 3))
        polarizations = np.array([m.polarization for m in design.magnets]) * (
            1 + rng.normal(0, realism.magnetisation_sd, magnets))
        sensor_positions = design.sensor_positions + rng.normal(0, realism.sensor_position_sd_mm * MM, (sensors, 3))
        # From a stream spawned off the bench's, which draws nothing from it: the unit and its trials
        # are the same with the chips' drift on or off, so sessions differ by their drift alone.
        self.chip_offset_T_per_K = self.chip_sensitivity_per_K = np.zeros((sensors, 3))
        if realism.chip_temperature_drift:
            chips = rng.spawn(1)[0]
            highest_gain_lsb_T = lsb_uT(MLX90393Settings(gain_sel=7)) / UT_PER_T
            self.chip_offset_T_per_K = chips.uniform(-1, 1, (sensors, 3)) * (
                CHIP_OFFSET_DRIFT_LSB * highest_gain_lsb_T / CHIP_DRIFT_SPAN_K)
            self.chip_sensitivity_per_K = chips.uniform(-1, 1, (sensors, 3)) * (
                CHIP_SENSITIVITY_DRIFT / CHIP_DRIFT_SPAN_K)
        self.plane_z = (None if realism.iron_plate_gap_mm == 0
                        else float(np.min(sensor_positions[:, 2])) - realism.iron_plate_gap_mm * MM)
        centres = np.array([m.center for m in design.magnets]) + self.magnet_offsets
        centres[:, 2] -= realism.compression_set_mm * MM
        polarizations = polarizations * (1 + BR_TEMPERATURE_COEFFICIENT * realism.session_temperature_K)
        super().__init__(design, magnet_centers=centres, polarizations=polarizations,
                         sensor_positions=sensor_positions)

    def field(self, poses: MagnetPoses) -> np.ndarray:
        """The field at the chips (N, S, 3) in T: the magnets moved 1 / (1 + modulus change) as far as
        ``poses`` (the engine's, for the calibration session's elastomer), and their images in the
        iron plate if there is one."""
        stiffer = 1.0 / (1.0 + self.realism.modulus_change)
        poses = MagnetPoses(poses.translation * stiffer, poses.rotvec * stiffer)
        field = super().field(poses)
        if self.plane_z is not None:
            centres, rotvecs, polarizations = mirrored_magnets(self.rest_positions + poses.translation, poses.rotvec,
                                                               self.polarizations, self.plane_z)
            field = field + magnet_field_at_sensors(self.sensor_positions, centres, rotvecs, self._radii,
                                                    self._heights, polarizations)
        return field

    def record(self, poses: MagnetPoses, times: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """What the chips report over one trial, initial value subtracted: (N, S, 3) µT.

        The first sample is taken before contact (the protocol starts every trial in the air), so
        subtracting it is the papers' "reading before contact" - with its noise."""
        field = self.field(poses)
        walk = np.zeros(len(times))
        if self.realism.drift_K_per_sqrt_s > 0:
            steps = rng.normal(0, self.realism.drift_K_per_sqrt_s, len(times)) * np.sqrt(
                np.diff(times, prepend=times[0]))
            walk = np.cumsum(steps)
            field = field * (1 + BR_TEMPERATURE_COEFFICIENT * walk)[:, None, None]
        if self.realism.chip_temperature_drift:  # the chips at the session's temperature and the trial's walk
            warmer = (self.realism.session_temperature_K + walk)[:, None, None]
            field = field * (1 + self.chip_sensitivity_per_K * warmer) + self.chip_offset_T_per_K * warmer
        if self.realism.noise:
            read = self.sensor.acquire(field, rng).values
        else:
            read = field * UT_PER_T
        return read - read[:1]
