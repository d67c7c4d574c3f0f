"""A whisker's physics: a steel wire rising from a cylindrical magnet bonded on a silicone layer over a
TLV493D. A sideways force on the wire's tip bends the wire, rocks the magnet on the rubber and slides it
sideways; the magnet's pose changes the field at the chip, on all three axes.

The magnet is a rigid circular footing on an elastic layer over a rigid base (the chip's board): its
rocking stiffness is the half-space's (the toolkit's ``half_space_rotational_stiffness``) times
(1 + R / 6h), its sliding stiffness 8 G R / (2 - ν) times (1 + R / 2h), R its radius and h the layer's
thickness (the stratum-on-bedrock factors of Gazetas, "Foundation vibrations", Foundation Engineering
Handbook, 1991, Table 15.1; they hold for layers at least as thick as R). It rocks about the centre of its
bottom face. The wire bends as an Euler-Bernoulli cantilever clamped in the magnet. All of it is linear:
the model holds while the tilt stays small (the bench keeps it under 0.1 rad). The field is the exact
field of the posed cylinder (``softtip.magnetics``).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from softtip.magnetics import magnet_field_at_sensors
from softtip.mechanics.rod import half_space_rotational_stiffness
from softtip.plugin import PoissonRatio, PositiveNumber, schema

MM = 1e-3


@schema(section="design")
class Whisker:
    """The whisker as built (lengths in mm, moduli as named).

    Defaults: a 0.5 mm spring-steel wire (E about 200 GPa) 30 mm long, in a 3 x 1 mm N42 disc magnet
    (remanence 1.28-1.32 T, axially magnetised) bonded on a 1.5 mm layer of a silicone of 1 MPa (nearly
    incompressible) over the chip's sensitive point: about 98 mT at rest, inside the chip's linear
    ±130 mT. (The magnet's tilt and the shift of its centre move the field under it in opposite senses:
    a thicker layer or a taller magnet cancels more of the signal.)"""

    wire_length_mm: PositiveNumber = 30.0
    wire_diameter_mm: PositiveNumber = 0.5
    wire_modulus_GPa: PositiveNumber = 200.0
    magnet_diameter_mm: PositiveNumber = 3.0
    magnet_height_mm: PositiveNumber = 1.0
    polarization_T: PositiveNumber = 1.3
    rubber_modulus_MPa: PositiveNumber = 1.0
    rubber_poisson: PoissonRatio = 0.49
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
    def _radius_over_layer(self) -> float:
        return self.magnet_diameter_mm / 2.0 / self.layer_mm

    @property
    def rocking_stiffness(self) -> float:
        """The magnet's rocking stiffness on the layer (N·m/rad)."""
        half_space = half_space_rotational_stiffness(self.rubber_modulus_MPa * 1e6, self.rubber_poisson,
                                                     self.magnet_diameter_mm * MM)
        return half_space * (1.0 + self._radius_over_layer / 6.0)

    @property
    def sliding_stiffness(self) -> float:
        """The magnet's sideways stiffness on the layer (N/m)."""
        shear = self.rubber_modulus_MPa * 1e6 / (2.0 * (1.0 + self.rubber_poisson))
        half_space = 8.0 * shear * self.magnet_diameter_mm * MM / 2.0 / (2.0 - self.rubber_poisson)
        return half_space * (1.0 + self._radius_over_layer / 2.0)

    @property
    def wire_compliance(self) -> float:
        """The wire's own bending at its tip (m/N): L³ / (3 E I)."""
        second_moment = math.pi * (self.wire_diameter_mm * MM) ** 4 / 64.0
        return (self.wire_length_mm * MM) ** 3 / (3.0 * self.wire_modulus_GPa * 1e9 * second_moment)

    @property
    def tip_compliance(self) -> float:
        """The tip's sideways displacement per newton (m/N): the wire's bending, the magnet's rocking and its
        sliding."""
        return self.wire_compliance + self.lever_m ** 2 / self.rocking_stiffness + 1.0 / self.sliding_stiffness


def tilts(whisker: Whisker, tip_force_N: np.ndarray) -> np.ndarray:
    """The magnet's rotation vectors (N, 3) (rad) under sideways tip forces (N, 2) (N): the moment about
    the rocking centre over the rocking stiffness."""
    force = np.asarray(tip_force_N, dtype=np.float64)
    arm = whisker.lever_m / whisker.rocking_stiffness
    # (0, 0, lever) x (fx, fy, 0) = lever (-fy, fx, 0)
    return np.stack([-arm * force[:, 1], arm * force[:, 0], np.zeros(len(force))], axis=1)


def field_at_chip(whisker: Whisker, tip_force_N: np.ndarray) -> np.ndarray:
    """The flux density (N, 3) (T) at the chip's sensitive point (the origin) under tip forces (N, 2)."""
    force = np.asarray(tip_force_N, dtype=np.float64)
    rotvecs = tilts(whisker, force)
    pivots = np.column_stack([force / whisker.sliding_stiffness, np.full(len(force), whisker.layer_mm * MM)])
    centre_above_pivot = np.array([0.0, 0.0, whisker.magnet_height_mm * MM / 2.0])
    centres = pivots + Rotation.from_rotvec(rotvecs).apply(centre_above_pivot)
    field = magnet_field_at_sensors(np.zeros((1, 3)), centres[:, None, :], rotvecs[:, None, :],
                                    whisker.magnet_diameter_mm * MM / 2.0, whisker.magnet_height_mm * MM,
                                    whisker.polarization_T)
    return field[:, 0, :]
