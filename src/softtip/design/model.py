"""Parametric fingertip designs: validated, immutable, in SI units.

A design is written in TOML with millimetre keys (``*_mm``) because that is how
fingertips are drawn; :func:`design_from_dict` converts it into SI dataclasses
and refuses anything that cannot be built, with one line naming the parameter
and the limit it breaks.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from softtip.tomlfile import read_toml

MM = 1e-3


class DesignError(ValueError):
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
    sensor_readout: dict  # MLX90393 register settings; validated by the sensor model when the twin is built

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


# ---------------------------------------------------------------- parsing helpers


_TOP_KEYS = {"kind", "name", "description", "body", "cavity", "magnets", "sensor"}
_SECTION_KEYS = {
    "cylindrical": {
        "body": {"diameter_mm", "height_mm", "fillet_mm", "youngs_modulus_Pa", "poisson_ratio", "density_kg_m3"},
        "cavity": {"radius_mm", "height_mm"},
        "magnets": {"count", "circle_radius_mm", "diameter_mm", "height_mm", "depth_mm", "polarization_T",
                    "surface_field_T", "first_angle_deg"},
    },
    "rectangular": {
        "body": {"width_mm", "length_mm", "height_mm", "fillet_mm", "youngs_modulus_Pa", "poisson_ratio",
                 "density_kg_m3"},
        "cavity": {"width_mm", "length_mm", "height_mm"},
        "magnets": {"pitch_x_mm", "pitch_y_mm", "diameter_mm", "height_mm", "depth_mm", "polarization_T",
                    "surface_field_T"},
    },
}


class _Reader:
    """Pulls typed values out of a TOML table, naming the dotted key in every error."""

    def __init__(self, source: str, table: dict, section: str, allowed: set[str]):
        if not isinstance(table, dict):
            raise DesignError(f"{source}: [{section}] must be a table")
        unknown = sorted(set(table) - allowed)
        if unknown:
            raise DesignError(f"{source}: unknown key {section}.{unknown[0]} (expected one of {', '.join(sorted(allowed))})")
        self.source, self.table, self.section = source, table, section

    def where(self, key: str) -> str:
        return f"{self.source}: {self.section}.{key}"

    def number(self, key: str, default: float | None = None, positive: bool = True) -> float:
        if key not in self.table:
            if default is None:
                raise DesignError(f"{self.where(key)} is missing")
            return default
        value = self.table[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise DesignError(f"{self.where(key)} = {value!r}: expected a number")
        if positive and value <= 0:
            raise DesignError(f"{self.where(key)} = {value}: expected a positive number")
        return float(value)

    def fail(self, key: str, message: str) -> DesignError:
        return DesignError(f"{self.where(key)} = {self.table.get(key)}: {message}")


def _material(body: _Reader) -> Material:
    nu = body.number("poisson_ratio", 0.48)
    if not 0 < nu < 0.5:
        raise body.fail("poisson_ratio", "expected 0 < nu < 0.5 (a compressible elastic solid)")
    return Material(body.number("youngs_modulus_Pa", 0.59e6), nu, body.number("density_kg_m3", 1120.0))


def polarization_from_surface_field(surface_field: float, diameter: float, height: float) -> float:
    """Polarisation J (T) of an axial cylinder whose field at the centre of a face is ``surface_field``.

    Magnet vendors quote this "surface flux density"; the exact on-axis field of a
    cylinder at its face is J/2 * L / sqrt(R^2 + L^2). A Ø4 x 2 mm magnet with
    330 mT at its face therefore has J = 0.933 T.
    """
    radius = diameter / 2
    return 2 * surface_field * math.hypot(radius, height) / height


def _polarization(mag: _Reader, diameter: float, height: float) -> float:
    if "polarization_T" in mag.table and "surface_field_T" in mag.table:
        raise DesignError(f"{mag.source}: give magnets.polarization_T or magnets.surface_field_T, not both")
    if "surface_field_T" in mag.table:
        return float(polarization_from_surface_field(mag.number("surface_field_T"), diameter, height))
    pol = mag.number("polarization_T", 1.2, positive=False)
    if pol == 0 or abs(pol) > 1.6:
        raise mag.fail("polarization_T", "expected 0 < |J| <= 1.6 T (NdFeB remanence)")
    return pol


def _sensors(source: str, table: dict, default_positions: list, check_inside) -> tuple[np.ndarray, dict]:
    if not isinstance(table, dict):
        raise DesignError(f"{source}: [sensor] must be a table")
    positions = table.get("positions_mm", default_positions)
    array = np.asarray(positions, dtype=float) if _is_point_list(positions) else None
    if array is None:
        raise DesignError(f"{source}: sensor.positions_mm = {positions!r}: expected a list of [x, y, z] in mm")
    for index, point in enumerate(array):
        problem = check_inside(point)
        if problem:
            raise DesignError(f"{source}: sensor.positions_mm[{index}] = {point.tolist()}: {problem}")
    return array * MM, {k: v for k, v in table.items() if k != "positions_mm"}


def _is_point_list(value: Any) -> bool:
    return (isinstance(value, list) and len(value) > 0
            and all(isinstance(p, list) and len(p) == 3 and all(isinstance(c, (int, float)) and not isinstance(c, bool)
                                                               for c in p) for p in value))


# ---------------------------------------------------------------- the two families


def _cylindrical(spec: dict, source: str) -> Design:
    keys = _SECTION_KEYS["cylindrical"]
    body = _Reader(source, spec.get("body", {}), "body", keys["body"])
    cav = _Reader(source, spec.get("cavity", {}), "cavity", keys["cavity"])
    mag = _Reader(source, spec.get("magnets", {}), "magnets", keys["magnets"])

    radius = body.number("diameter_mm") / 2
    height = body.number("height_mm")
    fillet = body.number("fillet_mm", 0.0, positive=False)
    if fillet < 0 or fillet >= min(radius, height):
        raise body.fail("fillet_mm", f"expected 0 <= fillet < min(body radius {radius}, body height {height}) mm")
    cavity_radius = cav.number("radius_mm")
    cavity_height = cav.number("height_mm")
    if cavity_radius >= radius:
        raise cav.fail("radius_mm", f"the cavity must be narrower than the body (radius < {radius} mm)")
    if cavity_height >= height:
        raise cav.fail("height_mm", f"the cavity must be lower than the body (height < {height} mm)")

    count = mag.table.get("count", 4)
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise mag.fail("count", "expected a positive integer")
    circle = mag.number("circle_radius_mm")
    m_diameter, m_height = mag.number("diameter_mm"), mag.number("height_mm")
    depth = mag.number("depth_mm")
    m_radius = m_diameter / 2
    if count > 1 and 2 * circle * math.sin(math.pi / count) <= m_diameter:
        raise mag.fail("circle_radius_mm", f"the {count} magnets overlap (centre spacing "
                       f"{2 * circle * math.sin(math.pi / count):.3g} mm <= diameter {m_diameter} mm)")
    top, bottom = height - depth, height - depth - m_height
    outer = circle + m_radius
    if bottom <= 0:
        raise mag.fail("depth_mm", f"the magnets reach the base (depth + height must be < {height} mm)")
    if outer >= radius:
        raise mag.fail("circle_radius_mm", f"the magnets cross the side surface (circle radius + magnet radius "
                       f"must be < {radius} mm)")
    if fillet > 0 and outer > radius - fillet and top > height - fillet:
        # the magnet's outer top edge must stay inside the rounded edge of the body
        if math.hypot(outer - (radius - fillet), top - (height - fillet)) >= fillet:
            raise mag.fail("circle_radius_mm", f"with magnets.depth_mm = {depth}, the magnets cross the filleted top "
                           f"edge of the body (move them inwards or deeper)")
    if bottom <= cavity_height and circle - m_radius < cavity_radius:
        raise mag.fail("depth_mm", f"the magnets cut into the cavity (magnet bottom at z = {bottom:.3g} mm must be "
                       f"above the cavity top at {cavity_height} mm)")

    def inside_cavity(point: np.ndarray) -> str:
        if math.hypot(point[0], point[1]) >= cavity_radius or not 0 <= point[2] < cavity_height:
            return f"the sensor must sit inside the cavity (r < {cavity_radius} mm, 0 <= z < {cavity_height} mm)"
        return ""

    sensor_positions, settings = _sensors(source, spec.get("sensor", {}), [[0.0, 0.0, 0.8]], inside_cavity)
    first = math.radians(mag.number("first_angle_deg", 0.0, positive=False))
    polarization = _polarization(mag, m_diameter * MM, m_height * MM)
    center_z = (top + bottom) / 2
    magnets = tuple(
        Magnet(center=(circle * MM * math.cos(first + 2 * math.pi * i / count),
                       circle * MM * math.sin(first + 2 * math.pi * i / count), center_z * MM),
               diameter=m_diameter * MM, height=m_height * MM, polarization=polarization)
        for i in range(count))
    return Design(name=spec.get("name", source), kind="cylindrical", spec=spec, material=_material(body),
                  height=height * MM, magnets=magnets, sensor_positions=sensor_positions, sensor_readout=settings)


def _rectangular(spec: dict, source: str) -> Design:
    keys = _SECTION_KEYS["rectangular"]
    body = _Reader(source, spec.get("body", {}), "body", keys["body"])
    cav = _Reader(source, spec.get("cavity", {}), "cavity", keys["cavity"])
    mag = _Reader(source, spec.get("magnets", {}), "magnets", keys["magnets"])

    width, length, height = body.number("width_mm"), body.number("length_mm"), body.number("height_mm")
    fillet = body.number("fillet_mm", 0.0, positive=False)
    if fillet < 0 or fillet >= min(width / 2, length / 2, height):
        raise body.fail("fillet_mm", "expected 0 <= fillet < min(half width, half length, height)")
    c_width, c_length, c_height = cav.number("width_mm"), cav.number("length_mm"), cav.number("height_mm")
    for key, inner, outer in (("width_mm", c_width, width), ("length_mm", c_length, length),
                              ("height_mm", c_height, height)):
        if inner >= outer:
            raise cav.fail(key, f"the cavity must be smaller than the body (< {outer} mm)")

    pitch_x, pitch_y = mag.number("pitch_x_mm"), mag.number("pitch_y_mm")
    m_diameter, m_height, depth = mag.number("diameter_mm"), mag.number("height_mm"), mag.number("depth_mm")
    m_radius = m_diameter / 2
    if min(pitch_x, pitch_y) <= m_diameter:
        key = "pitch_x_mm" if pitch_x <= pitch_y else "pitch_y_mm"
        raise mag.fail(key, f"neighbouring magnets overlap (pitch must exceed the diameter {m_diameter} mm)")
    top, bottom = height - depth, height - depth - m_height
    if bottom <= 0:
        raise mag.fail("depth_mm", f"the magnets reach the base (depth + height must be < {height} mm)")
    for key, half_pitch, half_side in (("pitch_x_mm", pitch_x / 2, width / 2), ("pitch_y_mm", pitch_y / 2, length / 2)):
        outer = half_pitch + m_radius
        if outer >= half_side:
            raise mag.fail(key, f"the magnets cross the side surface (half pitch + magnet radius must be < {half_side} mm)")
        if fillet > 0 and outer > half_side - fillet and top > height - fillet:
            if math.hypot(outer - (half_side - fillet), top - (height - fillet)) >= fillet:
                raise mag.fail(key, f"with magnets.depth_mm = {depth}, the magnets cross the filleted top edge "
                               f"of the body (move them inwards or deeper)")
    over_cavity = (pitch_x / 2 - m_radius < c_width / 2) and (pitch_y / 2 - m_radius < c_length / 2)
    if over_cavity and bottom <= c_height:
        raise mag.fail("depth_mm", f"the magnets cut into the cavity (magnet bottom at z = {bottom:.3g} mm must be "
                       f"above the cavity top at {c_height} mm)")

    def inside_cavity(point: np.ndarray) -> str:
        if abs(point[0]) >= c_width / 2 or abs(point[1]) >= c_length / 2 or not 0 <= point[2] < c_height:
            return "the sensor must sit inside the cavity"
        return ""

    sensor_positions, settings = _sensors(source, spec.get("sensor", {}),
                                          [[-pitch_x / 2, 0.0, 0.8], [pitch_x / 2, 0.0, 0.8]], inside_cavity)
    polarization = _polarization(mag, m_diameter * MM, m_height * MM)
    center_z = (top + bottom) / 2 * MM
    magnets = tuple(
        Magnet(center=(sx * pitch_x / 2 * MM, sy * pitch_y / 2 * MM, center_z), diameter=m_diameter * MM,
               height=m_height * MM, polarization=polarization)
        for sy in (-1, 1) for sx in (-1, 1))
    return Design(name=spec.get("name", source), kind="rectangular", spec=spec, material=_material(body),
                  height=height * MM, magnets=magnets, sensor_positions=sensor_positions, sensor_readout=settings)


_BUILDERS = {"cylindrical": _cylindrical, "rectangular": _rectangular}


def design_from_dict(spec: dict, source: str = "design") -> Design:
    """Validate a TOML-level description and build the design."""
    if not isinstance(spec, dict):
        raise DesignError(f"{source}: expected a table of design parameters")
    unknown = sorted(set(spec) - _TOP_KEYS)
    if unknown:
        raise DesignError(f"{source}: unknown key {unknown[0]!r} (expected one of {', '.join(sorted(_TOP_KEYS))})")
    kind = spec.get("kind")
    if kind not in _BUILDERS:
        raise DesignError(f"{source}: kind = {kind!r}: expected one of {', '.join(sorted(_BUILDERS))}")
    return _BUILDERS[kind](copy.deepcopy(spec), source)


SHIPPED_DIR = Path(__file__).with_name("shipped")


def shipped_designs() -> list[str]:
    return sorted(p.stem for p in SHIPPED_DIR.glob("*.toml"))


def load_design(name_or_path: str | Path) -> Design:
    """A shipped design by name (``cylindrical-A``) or a TOML file by path."""
    path = Path(name_or_path)
    if not path.suffix:
        shipped = SHIPPED_DIR / f"{name_or_path}.toml"
        if not shipped.exists():
            raise DesignError(f"design {name_or_path!r} is neither a file nor a shipped design "
                              f"({', '.join(shipped_designs())})")
        path = shipped
    spec = read_toml(path, "design", DesignError)
    spec.setdefault("name", path.stem)
    return design_from_dict(spec, source=str(path.name if path.parent == SHIPPED_DIR else path))
