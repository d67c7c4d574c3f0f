"""Parametric fingertip designs: validated, immutable, in SI units.

A design is written in TOML with millimetre keys (``*_mm``) because that is how
fingertips are drawn; :func:`design_from_dict` converts it into SI dataclasses
and refuses anything that cannot be built, with one line naming the parameter
and the limit it breaks.

Its ``kind`` names a :class:`BodyKind`: softtip's own are ``cylindrical`` and ``rectangular``; a
system registers another (``System.bodies``: name -> ``"module:attribute"`` of a :class:`BodyKind`),
which ``simulate``, ``optimize`` and the twin then build and mesh as they do softtip's own.

Its ``[sensor]`` table names its chips (``chip``: a registered :class:`~softtip.sensors.registry.SensorKind`
reading the flux density on x, y and z with an acquisition model, softtip's own MLX90393 when not given)
and states their settings in that sensor's own schema, beside ``positions_mm``.
"""

from __future__ import annotations

import copy
import math
import os
from collections.abc import Callable
from dataclasses import KW_ONLY, dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import AfterValidator, Field, model_validator

from softtip._core.channels import MAGNETIC
from softtip._core.systems import NotRegistered, beside_own, own_or_declared, systems
from softtip._core.config import (
    ConfigError,
    NonNegativeNumber,
    Number,
    PositiveInteger,
    PositiveNumber,
    Real,
    Refusal,
    Text,
    expect,
    number,
    parse,
    read_toml,
    refused,
    schema,
)
from softtip._core.units import MM
from softtip.sensors.mlx90393 import SENSOR as MLX90393_SENSOR
from softtip.sensors.registry import ChipSettings, SensorKind

# the chips a design without ``sensor.chip`` has: softtip's own, which every shipped design uses
OWN_CHIPS = {MLX90393_SENSOR.name: MLX90393_SENSOR}
DEFAULT_CHIP = MLX90393_SENSOR.name


class DesignError(ConfigError):
    """A design file or parameter that cannot describe a buildable fingertip."""


@dataclass(frozen=True)
class Material:
    youngs_modulus: float  # Pa
    poisson_ratio: float
    density: float  # kg/m^3

    @property
    def lame(self) -> tuple[float, float]:
        """Lamé parameters (lambda, mu) in Pa."""
        e, nu = self.youngs_modulus, self.poisson_ratio
        return e * nu / ((1 + nu) * (1 - 2 * nu)), e / (2 * (1 + nu))


@dataclass(frozen=True)
class Magnet:
    """A cylindrical magnet at rest; polarisation along its own axis (+z when positive)."""

    center: tuple[float, float, float]  # m
    diameter: float  # m
    height: float  # m
    polarization: float  # T

    @property
    def top_center(self) -> np.ndarray:
        """The feature point: the centre of the magnet's top face."""
        return np.asarray(self.center) + np.array([0.0, 0.0, self.height / 2])


@dataclass(frozen=True)
class Design:
    """Common interface of every fingertip body the twin can simulate."""

    name: str
    kind: str
    spec: dict  # the validated TOML-level description (mm keys), for hashing and re-editing
    material: Material
    height: float  # m, the top surface is the plane z = height (before the fillet)
    magnets: tuple[Magnet, ...]
    sensor_positions: np.ndarray  # (S, 3) m, the Hall sensors' sensitive points
    chip_settings: ChipSettings  # its chips: a registered sensor at its settings, validated when the design is read

    @property
    def geometry_key(self) -> dict:
        """What determines the mesh: shapes and sizes, not materials, magnetisation or sensors."""
        physics = {"youngs_modulus_Pa", "poisson_ratio", "density_kg_m3", "polarization_T", "surface_field_T"}
        return {"kind": self.spec["kind"],
                **{section: {k: v for k, v in self.spec[section].items() if k not in physics}
                   for section in ("body", "cavity", "magnets")}}

    def with_params(self, **overrides: float) -> "Design":
        """A copy with TOML-level parameters replaced, e.g. ``{"cavity.radius_mm": 8.5}``
        passed as ``with_params(**{"cavity.radius_mm": 8.5})``; validated again."""
        spec = copy.deepcopy(self.spec)
        for dotted, value in overrides.items():
            section, _, key = dotted.partition(".")
            if section not in spec or not isinstance(spec[section], dict) or key not in spec[section]:
                raise DesignError(f"{self.name}: unknown design parameter {dotted!r}")
            spec[section][key] = value
        return design_from_dict(spec, source=self.name)


# ---------------------------------------------------------------- the tables of a design file


def _not_zero(value: float) -> float:
    if value == 0:
        raise ValueError("zero polarisation")
    return value


PoissonRatio = number("0 < nu < 0.5 (a compressible elastic solid)", gt=0, lt=0.5)
# A soft body's modulus: from the softest gels (a few kPa) to the hardest rubbers (Shore 90A, tens of MPa). Beyond
# either end the body is no soft fingertip: the contact laws and the FE's load steps are made for the range between.
ElastomerModulus = number("1e3 <= E <= 1e8 Pa (a soft elastomer: from gels to the hardest rubbers)", ge=1e3, le=1e8)
ElastomerModulusMPa = number("0.001 <= E <= 100 MPa (a soft elastomer)", ge=1e-3, le=100.0)  # the same, in MPa
# From foams to the densest filled silicones and beyond (tungsten-filled rubbers reach 11,000 kg/m3).
Density = number("100 <= rho <= 20000 kg/m3 (a solid: from foams to metal-filled rubbers)", ge=100, le=2e4)
STRONGEST_NDFEB_T = 1.6  # the remanence of the strongest sintered NdFeB: no magnet is polarised more
_REMANENCE = f"0 < |J| <= {STRONGEST_NDFEB_T} T (NdFeB remanence)"
Polarization = Annotated[number(_REMANENCE, ge=-STRONGEST_NDFEB_T, le=STRONGEST_NDFEB_T), AfterValidator(_not_zero), expect(_REMANENCE)]
Points = Annotated[list[tuple[Real, Real, Real]], Field(min_length=1), expect("a list of [x, y, z] in mm")]


@schema
class BodyMaterial:
    """A body table's fillet and elastomer (a body kind's ``[body]`` schema extends it)."""

    _: KW_ONLY
    fillet_mm: NonNegativeNumber = 0.0
    youngs_modulus_Pa: ElastomerModulus = 0.59e6
    poisson_ratio: PoissonRatio = 0.48
    density_kg_m3: Density = 1120.0

    @property
    def material(self) -> Material:
        return Material(self.youngs_modulus_Pa, self.poisson_ratio, self.density_kg_m3)


@schema
class MagnetSizes:
    """A magnets table's sizes, depth below the top and polarisation (a kind's ``[magnets]`` extends it)."""

    _: KW_ONLY
    diameter_mm: PositiveNumber
    height_mm: PositiveNumber
    depth_mm: PositiveNumber
    polarization_T: Polarization | None = None
    surface_field_T: PositiveNumber | None = None

    def __post_init__(self):
        if self.polarization_T is not None and self.surface_field_T is not None:
            raise Refusal("surface_field_T", "give magnets.polarization_T or magnets.surface_field_T, not both")
        if self.surface_field_T is not None and self.polarization > STRONGEST_NDFEB_T:
            raise Refusal("surface_field_T", f"a field at the face of {self.diameter_mm} x {self.height_mm} mm magnets "
                          f"that needs a polarisation of {self.polarization:.3g} T: expected at most {STRONGEST_NDFEB_T} T "
                          "(NdFeB remanence)")

    @property
    def polarization(self) -> float:
        """J in T, given or from the surface field."""
        if self.surface_field_T is not None:
            return float(polarization_from_surface_field(self.surface_field_T, self.diameter_mm * MM,
                                                         self.height_mm * MM))
        return 1.2 if self.polarization_T is None else self.polarization_T


@schema
class _Sensor:
    """Where the sensors sit and what chip they are; the other keys are the chip's settings, which its
    registered sensor's schema checks when the design is built."""

    positions_mm: Points | None = None
    chip: Text = DEFAULT_CHIP
    readout: dict[str, Any] = field(default_factory=dict)

    @model_validator(mode="before")
    @classmethod
    def _split(cls, table: Any) -> Any:
        if not isinstance(table, dict):
            return table
        named = ("positions_mm", "chip")
        return {**{key: table[key] for key in named if key in table},
                "readout": {k: v for k, v in table.items() if k not in named}}


def design_chip(name: str, source: str) -> SensorKind:
    """The chip ``sensor.chip = name`` of the design ``source``: softtip's own or a registered sensor
    that a twin can read the field with (the flux density on x, y and z, an acquisition model)."""
    try:
        kind = own_or_declared("sensor", name, OWN_CHIPS, SensorKind, "sensor")
    except NotRegistered:
        raise refused(f"expected a registered sensor ({', '.join(beside_own('sensor', OWN_CHIPS))})", source,
                      "sensor", "chip", value=name, error=DesignError) from None
    if kind.reading != MAGNETIC or kind.model is None:
        raise refused(f"the {kind.title or kind.name} has no model of its reading of {MAGNETIC.quantity} on x, y "
                      "and z: expected a sensor with one (SensorKind.model)", source, "sensor", "chip", value=name,
                      error=DesignError)
    return kind


def _check_sensors_inside(positions: list, inside, problem: str) -> None:
    for index, point in enumerate(positions):
        if not inside(*point):
            raise Refusal(("sensor", "positions_mm", index), problem)


def _below_the_top(magnets: MagnetSizes, body_height: float) -> tuple[float, float]:
    """z of the magnets' top and bottom faces (mm)."""
    top, bottom = body_height - magnets.depth_mm, body_height - magnets.depth_mm - magnets.height_mm
    if bottom <= 0:
        raise Refusal(("magnets", "depth_mm"),
                      f"the magnets reach the base (depth + height must be < {body_height} mm)")
    return top, bottom


def _check_fillet_edge(key: str, outer: float, top: float, half_side: float, height: float, fillet: float,
                       depth: float) -> None:
    """The magnet's outer top edge must stay inside the rounded edge of the body."""
    if fillet > 0 and outer > half_side - fillet and top > height - fillet:
        if math.hypot(outer - (half_side - fillet), top - (height - fillet)) >= fillet:
            raise Refusal(("magnets", key), f"with magnets.depth_mm = {depth}, the magnets cross the filleted top "
                          f"edge of the body (move them inwards or deeper)")


def _cut_into_cavity(bottom: float, cavity_height: float) -> Refusal:
    return Refusal(("magnets", "depth_mm"), f"the magnets cut into the cavity (magnet bottom at z = {bottom:.3g} mm "
                   f"must be above the cavity top at {cavity_height} mm)")


@schema
class DesignSpec:
    """What every kind of design has besides its body, cavity and magnets."""

    _: KW_ONLY
    sensor: _Sensor = _Sensor()
    name: Text | None = None
    description: str = ""


@schema
class CylindricalBody(BodyMaterial):
    diameter_mm: PositiveNumber
    height_mm: PositiveNumber

    def __post_init__(self):
        radius = self.diameter_mm / 2
        if self.fillet_mm >= min(radius, self.height_mm):
            raise Refusal("fillet_mm", f"expected 0 <= fillet < min(body radius {radius}, body height "
                          f"{self.height_mm}) mm")


@schema
class CylindricalCavity:
    radius_mm: PositiveNumber
    height_mm: PositiveNumber


@schema
class CylindricalMagnets(MagnetSizes):
    circle_radius_mm: PositiveNumber
    count: PositiveInteger = 4
    first_angle_deg: Number = 0.0

    def __post_init__(self):
        super().__post_init__()
        spacing = 2 * self.circle_radius_mm * math.sin(math.pi / self.count)
        if self.count > 1 and spacing <= self.diameter_mm:
            raise Refusal("circle_radius_mm", f"the {self.count} magnets overlap (centre spacing {spacing:.3g} mm "
                          f"<= diameter {self.diameter_mm} mm)")


@schema
class CylindricalSpec(DesignSpec):
    kind: Literal["cylindrical"]
    body: CylindricalBody
    cavity: CylindricalCavity
    magnets: CylindricalMagnets

    def __post_init__(self):
        body, cavity, magnets = self.body, self.cavity, self.magnets
        radius, height = body.diameter_mm / 2, body.height_mm
        if cavity.radius_mm >= radius:
            raise Refusal(("cavity", "radius_mm"), f"the cavity must be narrower than the body (radius < {radius} mm)")
        if cavity.height_mm >= height:
            raise Refusal(("cavity", "height_mm"), f"the cavity must be lower than the body (height < {height} mm)")
        top, bottom = _below_the_top(magnets, height)
        outer = magnets.circle_radius_mm + magnets.diameter_mm / 2
        if outer >= radius:
            raise Refusal(("magnets", "circle_radius_mm"), f"the magnets cross the side surface (circle radius + "
                          f"magnet radius must be < {radius} mm)")
        _check_fillet_edge("circle_radius_mm", outer, top, radius, height, body.fillet_mm, magnets.depth_mm)
        if bottom <= cavity.height_mm and magnets.circle_radius_mm - magnets.diameter_mm / 2 < cavity.radius_mm:
            raise _cut_into_cavity(bottom, cavity.height_mm)
        _check_sensors_inside(self.sensor_positions_mm,
                              lambda x, y, z: math.hypot(x, y) < cavity.radius_mm and 0 <= z < cavity.height_mm,
                              f"the sensor must sit inside the cavity (r < {cavity.radius_mm} mm, "
                              f"0 <= z < {cavity.height_mm} mm)")

    @property
    def sensor_positions_mm(self) -> list:
        return self.sensor.positions_mm or [(0.0, 0.0, 0.8)]


@schema
class RectangularBody(BodyMaterial):
    width_mm: PositiveNumber
    length_mm: PositiveNumber
    height_mm: PositiveNumber

    def __post_init__(self):
        if self.fillet_mm >= min(self.width_mm / 2, self.length_mm / 2, self.height_mm):
            raise Refusal("fillet_mm", "expected 0 <= fillet < min(half width, half length, height)")


@schema
class RectangularCavity:
    width_mm: PositiveNumber
    length_mm: PositiveNumber
    height_mm: PositiveNumber


@schema
class RectangularMagnets(MagnetSizes):
    pitch_x_mm: PositiveNumber
    pitch_y_mm: PositiveNumber

    def __post_init__(self):
        super().__post_init__()
        if min(self.pitch_x_mm, self.pitch_y_mm) <= self.diameter_mm:
            key = "pitch_x_mm" if self.pitch_x_mm <= self.pitch_y_mm else "pitch_y_mm"
            raise Refusal(key, f"neighbouring magnets overlap (pitch must exceed the diameter {self.diameter_mm} mm)")


@schema
class RectangularSpec(DesignSpec):
    kind: Literal["rectangular"]
    body: RectangularBody
    cavity: RectangularCavity
    magnets: RectangularMagnets

    def __post_init__(self):
        body, cavity, magnets = self.body, self.cavity, self.magnets
        for key in ("width_mm", "length_mm", "height_mm"):
            if getattr(cavity, key) >= getattr(body, key):
                raise Refusal(("cavity", key), f"the cavity must be smaller than the body (< {getattr(body, key)} mm)")
        top, bottom = _below_the_top(magnets, body.height_mm)
        radius = magnets.diameter_mm / 2
        for key, half_pitch, half_side in (("pitch_x_mm", magnets.pitch_x_mm / 2, body.width_mm / 2),
                                           ("pitch_y_mm", magnets.pitch_y_mm / 2, body.length_mm / 2)):
            outer = half_pitch + radius
            if outer >= half_side:
                raise Refusal(("magnets", key), f"the magnets cross the side surface (half pitch + magnet radius "
                              f"must be < {half_side} mm)")
            _check_fillet_edge(key, outer, top, half_side, body.height_mm, body.fillet_mm, magnets.depth_mm)
        over_cavity = (magnets.pitch_x_mm / 2 - radius < cavity.width_mm / 2
                       and magnets.pitch_y_mm / 2 - radius < cavity.length_mm / 2)
        if over_cavity and bottom <= cavity.height_mm:
            raise _cut_into_cavity(bottom, cavity.height_mm)
        _check_sensors_inside(self.sensor_positions_mm,
                              lambda x, y, z: abs(x) < cavity.width_mm / 2 and abs(y) < cavity.length_mm / 2
                              and 0 <= z < cavity.height_mm, "the sensor must sit inside the cavity")

    @property
    def sensor_positions_mm(self) -> list:
        half = self.magnets.pitch_x_mm / 2
        return self.sensor.positions_mm or [(-half, 0.0, 0.8), (half, 0.0, 0.8)]


def polarization_from_surface_field(surface_field: float, diameter: float, height: float) -> float:
    """Polarisation J (T) of an axial cylinder whose field at the centre of a face is ``surface_field``.

    Magnet vendors quote this "surface flux density"; the exact on-axis field of a
    cylinder at its face is J/2 * L / sqrt(R^2 + L^2). A Ø4 x 2 mm magnet with
    330 mT at its face therefore has J = 0.933 T.
    """
    radius = diameter / 2
    return 2 * surface_field * math.hypot(radius, height) / height


# ---------------------------------------------------------------- the kinds of body


def magnets_at(spec: DesignSpec, raw: dict, source: str, magnets_xy: list) -> Design:
    """The design of a validated ``spec`` (its file's ``raw`` table) whose magnets' centres are at
    ``magnets_xy`` (m), at the depth its magnets table states: what every kind's builder returns."""
    magnets = spec.magnets
    top, bottom = _below_the_top(magnets, spec.body.height_mm)
    center_z = (top + bottom) / 2 * MM
    polarization = magnets.polarization
    chip = design_chip(spec.sensor.chip, source)
    return Design(
        name=spec.name or source, kind=spec.kind, spec=raw, material=spec.body.material,
        height=spec.body.height_mm * MM,
        magnets=tuple(Magnet(center=(x, y, center_z), diameter=magnets.diameter_mm * MM,
                             height=magnets.height_mm * MM, polarization=polarization) for x, y in magnets_xy),
        sensor_positions=np.asarray(spec.sensor_positions_mm, dtype=float) * MM,
        chip_settings=chip.at(_chip_settings(chip, spec.sensor.readout, source)))


def _chip_settings(chip: SensorKind, table: dict, source: str) -> Any:
    """The design's chip settings in its sensor's schema: located key by key when the schema is softtip's."""
    if hasattr(chip.settings, "__pydantic_validator__"):
        return parse(chip.settings, table, source, "sensor", error=DesignError)
    try:
        return chip.settings_from(table)
    except (TypeError, ValueError) as problem:
        raise DesignError(f"{source}: sensor: {problem}") from None


def ring_of_magnets(spec: DesignSpec, raw: dict, source: str) -> Design:
    """A kind's builder for magnets on a circle (a ``[magnets]`` table of :class:`CylindricalMagnets`)."""
    magnets = spec.magnets
    circle, first = magnets.circle_radius_mm * MM, math.radians(magnets.first_angle_deg)
    angles = [first + 2 * math.pi * i / magnets.count for i in range(magnets.count)]
    return magnets_at(spec, raw, source, [(circle * math.cos(a), circle * math.sin(a)) for a in angles])


def _rectangular(spec: RectangularSpec, raw: dict, source: str) -> Design:
    pitch_x, pitch_y = spec.magnets.pitch_x_mm, spec.magnets.pitch_y_mm
    return magnets_at(spec, raw, source, [(sx * pitch_x / 2 * MM, sy * pitch_y / 2 * MM)
                                          for sy in (-1, 1) for sx in (-1, 1)])


@dataclass(frozen=True)
class BodyKind:
    """A kind of body: ``spec``, its design file's schema (a :class:`DesignSpec` with ``kind`` its name,
    ``body`` (a :class:`BodyMaterial` with ``height_mm``), ``cavity`` and ``magnets`` (a
    :class:`MagnetSizes`) tables and ``sensor_positions_mm``, validated when the file is read);
    ``build(spec, raw, source) -> Design`` (:func:`magnets_at` places its magnets); ``solid``: the
    ``"module:function"`` of its gmsh solid, ``solid(design, occ) -> softtip.mechanics.mesh.BodySolid``,
    imported by the mesher (whose cache key holds that module's code)."""

    name: str
    spec: type
    build: Callable[[Any, dict, str], Design]
    solid: str


OWN_BODY_KINDS = {kind.name: kind for kind in (
    BodyKind("cylindrical", CylindricalSpec, ring_of_magnets, "softtip.mechanics.mesh:cylindrical_solid"),
    BodyKind("rectangular", RectangularSpec, _rectangular, "softtip.mechanics.mesh:rectangular_solid"))}


def body_kind_names() -> list[str]:
    """softtip's own kinds, then every registered system's not named as one of them."""
    return beside_own("body", OWN_BODY_KINDS)


def body_kind(name: str) -> BodyKind:
    """The kind of body ``name``: softtip's own or a registered system's (imported now)."""
    return own_or_declared("body", name, OWN_BODY_KINDS, BodyKind, "body kind")


def design_from_dict(spec: dict, source: str = "design") -> Design:
    """Validate a TOML-level description and build the design."""
    if not isinstance(spec, dict):
        raise DesignError(f"{source}: expected a table of design parameters")
    kind = spec.get("kind")
    if not isinstance(kind, str) or kind not in body_kind_names():
        raise refused(f"expected one of {', '.join(body_kind_names())}", source, "kind", value=kind,
                      error=DesignError)
    body = body_kind(kind)
    raw = copy.deepcopy(spec)
    return body.build(parse(body.spec, raw, source, error=DesignError), raw, source)


def _shipped() -> dict[str, Path]:
    """The registered systems' shipped designs, by name."""
    return {name: Path(str(entry)) for system in systems().values() for name, entry in system.designs().items()}


def shipped_designs() -> list[str]:
    return sorted(_shipped())


def shipped_design_path(name: str) -> Path:
    """The file of shipped design ``name``."""
    designs = _shipped()
    if name not in designs:
        raise DesignError(f"design {name!r} is neither a file nor a shipped design ({', '.join(sorted(designs))})")
    return designs[name]


def load_design(name_or_path: str | Path) -> Design:
    """A shipped design by name (a registered system's ``designs/NAME.toml``) or a TOML file by path."""
    path = Path(name_or_path)
    shipped = not path.suffix and not os.path.lexists(path)  # a device or FIFO is named like a design
    if shipped:
        path = shipped_design_path(str(name_or_path))
    spec = read_toml(path, "design", DesignError)
    spec.setdefault("name", path.stem)
    return design_from_dict(spec, source=str(path.name if shipped else path))
