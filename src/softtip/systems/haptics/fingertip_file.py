"""A researcher's own fingertip from a TOML file: its shape, size, stiffness, core and mounting.

The file holds one ``[fingertip]`` table, lengths in mm (every key but ``name`` and ``radius_mm``
has the default shown)::

    [fingertip]
    name = "my index finger"
    radius_mm = 9.0              # the cap's radius under the pad
    shape = "sphere"             # sphere, ellipsoid (1.6 r along the finger) or pad (1.3 r across and along)
    law = "cast"                 # cast: rubber over the FS's rigid core, the FE-calibrated bonded layer (6.5-11 mm)
                                 # hertz: a homogeneous elastic cap; exponential: living finger pulp (Pawluk and Howe)
    youngs_modulus_MPa = 1.14    # cast and hertz: the rubber's modulus (VytaFlex 30 by default)
    stiffness_N_per_m = 330.0    # exponential: F = (b/m)(exp(m δ) - 1) under a flat plate, b this stiffness
    stiffening_per_m = 1700.0    # and m this stiffening, for this finger's radius
    core_offset_mm = [0.0, 0.0, 0.0]   # the core's sensor origin from the cap's centre (+z towards the nail)
    mounting = "centre"          # centre: at the device's finger centre; nail: the device resting on the nail

Each mistake is refused in one line naming the file and the key (:func:`load_fingertip`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from softtip._core.config import (ConfigError, PositiveNumber, Real, Refusal, Text, choice, expect, from_numpy, number,
                                  parse, read_toml, schema)
from softtip._core.units import MM
from softtip.design.model import ElastomerModulusMPa
from softtip.mechanics.plate_contact import PlateContactLaw
from softtip.systems.haptics.fingertips import (CALIBRATED_RADII, SHAPE_AXES, VYTAFLEX_30_MODULUS, Fingertip,
                                                layer_thickness)

MPA = 1e6  # Pa per MPa
_EXPONENTIAL = PlateContactLaw(law="exponential")
OffsetMm = Annotated[tuple[Real, Real, Real], from_numpy, expect("3 coordinates (mm)")]


class FingertipFileError(ConfigError):
    """A fingertip file that cannot describe a fingertip."""


@schema(section="fingertip", error=FingertipFileError)
class FingertipFile:
    """A fingertip file's ``[fingertip]`` table (see the module's notes)."""

    name: Text
    radius_mm: number("a radius from 3 to 20 mm", ge=3, le=20)
    shape: choice(*SHAPE_AXES) = "sphere"
    law: choice("cast", "hertz", "exponential") = "cast"
    youngs_modulus_MPa: ElastomerModulusMPa = VYTAFLEX_30_MODULUS / MPA
    stiffness_N_per_m: PositiveNumber = _EXPONENTIAL.stiffness
    stiffening_per_m: PositiveNumber = _EXPONENTIAL.stiffening
    core_offset_mm: OffsetMm = (0.0, 0.0, 0.0)
    mounting: choice("centre", "nail") = "centre"

    def __post_init__(self) -> None:
        low, high = CALIBRATED_RADII
        if self.law == "cast" and not low / MM <= self.radius_mm <= high / MM:
            raise Refusal("radius_mm", f"expected {low / MM:g} to {high / MM:g} mm for a cast, the range of its FE "
                                       "calibration (or law = \"hertz\" or \"exponential\")")

    def fingertip(self) -> Fingertip:
        radius = self.radius_mm * MM
        if self.law == "cast":
            contact = PlateContactLaw(law="bonded-layer", youngs_modulus=self.youngs_modulus_MPa * MPA,
                                      layer_thickness=layer_thickness(radius))
        elif self.law == "hertz":
            contact = PlateContactLaw(law="hertz", youngs_modulus=self.youngs_modulus_MPa * MPA)
        else:
            contact = PlateContactLaw(law="exponential", stiffness=self.stiffness_N_per_m,
                                      stiffening=self.stiffening_per_m, reference_radius=radius)
        return Fingertip(name=self.name, radius=radius, shape=self.shape, contact=contact,
                         core_offset=tuple(v * MM for v in self.core_offset_mm), mounting=self.mounting)


def load_fingertip(path: str | Path) -> Fingertip:
    """The fingertip a TOML file describes, refused in one line naming the file and key."""
    table = read_toml(path, "fingertip", FingertipFileError)
    if set(table) != {"fingertip"}:
        extra = sorted(set(table) - {"fingertip"})
        problem = (f"unknown table or key {extra[0]!r}, expected only [fingertip]" if extra
                   else "expected a [fingertip] table")
        raise FingertipFileError(f"fingertip file {path}: {problem}")
    return parse(FingertipFile, table["fingertip"], str(path), "fingertip", error=FingertipFileError).fingertip()
