"""A whisker's physics: a steel wire rising from a cylindrical magnet that rests on a silicone layer over
a TLV493D. A sideways force on the wire's tip bends the wire and rocks the magnet on the rubber; the
magnet's tilt changes the field at the chip, on all three axes.

The magnet rocks as a rigid circular footing on an elastic half-space (the toolkit's
``half_space_rotational_stiffness``, Gazetas 1991), about the centre of its bottom face; the wire bends as
an Euler-Bernoulli cantilever clamped in the magnet. Both are linear: the model holds while the tilt stays
small (the protocol keeps it under 0.1 rad). The field is the exact field of the posed cylinder
(``softtip.magnetics``).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from softtip.magnetics import magnet_field_at_sensors
from softtip.mechanics.rod import half_space_rotational_stiffness
from softtip.plugin import PositiveNumber, schema

MM = 1e-3


@schema(section="design")
class Whisker:
    """The whisker as built (lengths in mm, moduli as named).

    Defaults: a 0.5 mm spring-steel wire (E about 200 GPa) 30 mm long, in a 4 x 1 mm N42 disc magnet
    (remanence 1.28-1.32 T, axially magnetised) resting on a 1.5 mm layer of a silicone of 1 MPa
    (nearly incompressible) above the chip's sensitive point: about 118 mT at rest, inside the chip's
    linear ±130 mT. (The magnet's tilt and the shift of its centre move the field under it in opposite
    senses: a thicker layer or a taller magnet cancels more of the signal.)"""

    wire_length_mm: PositiveNumber = 30.0
    wire_diameter_mm: PositiveNumber = 0.5
    wire_modulus_GPa: PositiveNumber = 200.0
    magnet_diameter_mm: PositiveNumber = 4.0
    magnet_height_mm: PositiveNumber = 1.0
    polarization_T: PositiveNumber = 1.3
    rubber_modulus_MPa: PositiveNumber = 1.0
    rubber_poisson: PositiveNumber = 0.49
    layer_mm: PositiveNumber = 1.5

    @property
    def name(self) -> str:
        return f"whisker {self.wire_diameter_mm:g} x {self.wire_length_mm:g} mm"

    @property
    def spec(self) -> dict:
        return {key: getattr(self, key) for key in self.__dataclass_fields__}

    @property
    def lever_m(self) -> float:
        """From the rocking centre (the magnet's bottom face) to the wire's tip."""
        return (self.magnet_height_mm + self.wire_length_mm) * MM

    @property
    def rocking_stiffness(self) -> float:
        """The magnet's rocking stiffness on the rubber (N·m/rad)."""
        return half_space_rotational_stiffness(self.rubber_modulus_MPa * 1e6, self.rubber_poisson,
                                               self.magnet_diameter_mm * MM)

    @property
    def wire_compliance(self) -> float:
        """The wire's own bending at its tip (m/N): L³ / (3 E I)."""
        second_moment = math.pi * (self.wire_diameter_mm * MM) ** 4 / 64.0
        return (self.wire_length_mm * MM) ** 3 / (3.0 * self.wire_modulus_GPa * 1e9 * second_moment)

    @property
    def tip_compliance(self) -> float:
        """The tip's sideways displacement per newton (m/N): the wire's bending and the magnet's rocking."""
        return self.wire_compliance + self.lever_m ** 2 / self.rocking_stiffness


def tilts(whisker: Whisker, tip_force_N: np.ndarray) -> np.ndarray:
    """The magnet's rotation vectors (N, 3) (rad) under sideways tip forces (N, 2) (N): the moment about
    the rocking centre over the rocking stiffness."""
    force = np.asarray(tip_force_N, dtype=np.float64)
    arm = whisker.lever_m / whisker.rocking_stiffness
    # (0, 0, lever) x (fx, fy, 0) = lever (-fy, fx, 0)
    return np.stack([-arm * force[:, 1], arm * force[:, 0], np.zeros(len(force))], axis=1)


def field_at_chip(whisker: Whisker, tip_force_N: np.ndarray) -> np.ndarray:
    """The flux density (N, 3) (T) at the chip's sensitive point (the origin) under tip forces (N, 2)."""
    rotvecs = tilts(whisker, tip_force_N)
    centre_above_pivot = np.array([0.0, 0.0, whisker.magnet_height_mm * MM / 2.0])
    centres = np.array([0.0, 0.0, whisker.layer_mm * MM]) + Rotation.from_rotvec(rotvecs).apply(centre_above_pivot)
    field = magnet_field_at_sensors(np.zeros((1, 3)), centres[:, None, :], rotvecs[:, None, :],
                                    whisker.magnet_diameter_mm * MM / 2.0, whisker.magnet_height_mm * MM,
                                    whisker.polarization_T)
    return field[:, 0, :]
