"""The die: its size, its pillars and its spin-valve meanders, read from a validated TOML file.

The published work shows the layout only in figures, so softtip declares one in ``die.toml`` beside this
module (each choice is commented there) and checks any other file the same way: pillars inside the die
and apart, banks of strips inside the die with room for their strips, element counts that add up.
A file states lengths in the units its keys name (``_mm``, ``_um``); :class:`Die` holds SI values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Annotated

import numpy as np
from pydantic import Field
from scipy.constants import mu_0

from softtip._core.config import (
    ConfigError,
    Number,
    PositiveInteger,
    PositiveNumber,
    Real,
    Refusal,
    choice,
    expect,
    number,
    parse,
    read_toml,
    schema,
)
from softtip._core.units import MM, UM
from softtip.design.model import STRONGEST_NDFEB_T, ElastomerModulusMPa
from softtip.magnetics.dipoles import Rectangles
from softtip.mechanics.rod import Rod, half_space_rotational_stiffness
from softtip.sensors.gmr import ConstantCurrentReadout, SpinValveSensor, published_spin_valve

MEMU = 1e-6  # A·m² per milli-emu (1 emu = 1e-3 A·m²)
SHIPPED_DIE = Path(__file__).with_name("die.toml")


class DieError(ConfigError):
    """A die file or layout that cannot describe a buildable die."""


Pair = Annotated[list[Real], Field(min_length=2, max_length=2), expect("a pair of numbers")]
PositivePair = Annotated[list[Annotated[Real, Field(gt=0)]], Field(min_length=2, max_length=2),
                         expect("a pair of positive numbers")]
Points = Annotated[list[Pair], Field(min_length=1), expect("a non-empty list of [x, y] pairs")]


def _interval(pair: list[float], key: str) -> None:
    if pair[1] <= pair[0]:
        raise Refusal(key, "expected [low, high] with low < high")


@schema
class DieTable:
    size_mm: PositivePair
    active_area_mm: PositivePair
    sensing_depth_um: PositiveNumber

    def __post_init__(self) -> None:
        if any(a > s for a, s in zip(self.active_area_mm, self.size_mm)):
            raise Refusal("active_area_mm", f"expected an area within the die ({self.size_mm} mm)")


@schema
class PillarsTable:
    positions_mm: Points
    height_mm: PositiveNumber
    tip_diameter_um: PositiveNumber
    base_diameter_um: PositiveNumber
    youngs_modulus_MPa: ElastomerModulusMPa  # PDMS and its NdFeB-filled blends lie within 0.1-10 MPa
    poisson_ratio: number("a number from 0 to 0.5", ge=0.0, le=0.5)
    moment_memu: PositiveNumber
    magnetisation: choice("up", "down")
    base: choice("half-space", "clamped")
    bend_azimuth_deg: Number = 0.0

    def __post_init__(self) -> None:
        problem = pillar_problem(self.height_mm * MM, self.tip_diameter_um * UM, self.base_diameter_um * UM,
                                 self.moment_memu * MEMU)
        if problem:
            raise Refusal(*problem)


def pillar_problem(height: float, tip: float, base: float, moment: float) -> tuple[str, str] | None:
    """What keeps a pillar (height, tip and base diameters in m, moment in A·m²) from being one softtip
    models: (the die file's key at fault, why), or None."""
    if tip > base:
        return "tip_diameter_um", (f"a tip wider than its base ({base / UM:g} um): expected pillars that narrow from "
                                   "base to tip, as moulded ones do")
    if base > height:
        return "base_diameter_um", (f"pillars wider than they are high ({height / UM:g} um): expected a base no "
                                    "wider than the height (a pillar bends as a rod)")
    # the moment of a pillar made wholly of the strongest NdFeB: no composite holds more
    most = STRONGEST_NDFEB_T / mu_0 * math.pi * height * (tip**2 + tip * base + base**2) / 12
    if abs(moment) > most:
        return "moment_memu", (f"more than a pillar of solid NdFeB holds ({most / MEMU:.3g} memu at "
                               f"{STRONGEST_NDFEB_T} T): expected a moment within that")
    return None


@schema
class BankTable:
    x_mm: Pair
    y_mm: Pair
    elements: PositiveInteger

    def __post_init__(self) -> None:
        _interval(self.x_mm, "x_mm")
        _interval(self.y_mm, "y_mm")


@schema
class SensorTable:
    elements: PositiveInteger
    magnetoresistance: number("a fraction between 0 and 1 (exclusive)", gt=0.0, lt=1.0)
    sensitivity_ohm_per_Oe: PositiveNumber
    linear_range_Oe: Pair
    axis: choice("x", "y")
    element_width_um: PositiveNumber
    banks: Annotated[list[BankTable], Field(min_length=1), expect("a non-empty list of banks")]
    area_element_um: PositiveNumber = 50.0  # the pieces of a bank that saturate on their own: about this wide, at most this long

    def __post_init__(self) -> None:
        _interval(self.linear_range_Oe, "linear_range_Oe")
        if sum(bank.elements for bank in self.banks) != self.elements:
            raise Refusal("banks", f"expected banks holding {self.elements} elements in all")
        for index, bank in enumerate(self.banks):
            across = bank.x_mm if self.axis == "x" else bank.y_mm
            if bank.elements * self.element_width_um * UM > (across[1] - across[0]) * MM:
                raise Refusal(("banks", index), f"{bank.elements} strips of {self.element_width_um} um do not fit")


@schema
class ReadoutTable:
    current_uA: PositiveNumber = 100.0
    thermal_resistance_K_per_W: number("a number >= 0", ge=0.0) = 450.0
    offset_V: Number = 0.0


@schema
class DieFile:
    die: DieTable
    pillars: PillarsTable
    sensors: Annotated[dict[str, SensorTable], Field(min_length=1)]
    readout: ReadoutTable = ReadoutTable()


# ---------------------------------------------------------------------------------------------- SI model


@dataclass(frozen=True)
class Pillars:
    """Identical magnetised pillars (SI): base positions (P, 2) on the die, the rod they are, their
    moment (A·m², signed along the axis: up is away from the die) and the azimuth they bend towards."""

    positions: np.ndarray
    rod: Rod
    moment: float
    bend_azimuth: float

    @property
    def compliant_base(self) -> bool:
        """The pillars are rooted in an elastic substrate (their rod has a base stiffness)."""
        return self.rod.base_stiffness is not None

    def with_diameter(self, tip_diameter: float) -> Pillars:
        """The same pillars with tip diameter ``tip_diameter`` (m), the taper ratio kept."""
        ratio = self.rod.base_diameter / self.rod.tip_diameter
        return replace(self, rod=pillar_rod(self.rod, tip_diameter, ratio * tip_diameter))


def uniform_clamped(die: Die) -> Die:
    """``die`` with the publication's model of its pillars: uniform cylinders of the tip diameter (the fit's
    free diameter) bonded to a rigid die, as its FE clamps them; height, modulus and moment kept."""
    pillars = die.pillars
    rod = replace(pillars.rod, base_diameter=pillars.rod.tip_diameter, base_stiffness=None, bonded_root=True)
    return die.with_pillars(replace(pillars, rod=rod))


def pillar_rod(template: Rod, tip_diameter: float, base_diameter: float) -> Rod:
    """``template`` with new diameters; a compliant base's stiffness follows the base
    (a half-space of the rod's material)."""
    return replace(template, tip_diameter=tip_diameter, base_diameter=base_diameter,
                   base_stiffness=_half_space_stiffness(template, base_diameter)
                   if template.base_stiffness is not None else None)


def _half_space_stiffness(rod: Rod, base_diameter: float) -> float:
    """The rotational stiffness (N·m/rad) of a base of ``base_diameter`` (m) rooted in a half-space of the
    ``rod``'s material."""
    return half_space_rotational_stiffness(rod.youngs_modulus, rod.poisson_ratio, base_diameter)


@dataclass(frozen=True)
class Meander:
    """One sensor: its spin valves' rectangles in the sensing plane (``strips``, one per spin valve), the
    area elements its banks are divided into (``elements``: each saturates on its own; the readout's sensor
    holds the spin valves' area in each), the in-plane axis each senses (0: x, 1: y) and its
    constant-current readout."""

    name: str
    axis: int
    strips: Rectangles
    elements: Rectangles
    readout: ConstantCurrentReadout


@dataclass(frozen=True)
class Die:
    """A die (SI): its size (2,) and active area (2,), sensing-plane depth below the pillar bases, the
    pillars and the meanders."""

    size: np.ndarray
    active_area: np.ndarray
    depth: float
    pillars: Pillars
    meanders: tuple[Meander, ...]
    source: str

    def meander(self, name: str) -> Meander:
        for meander in self.meanders:
            if meander.name == name:
                return meander
        raise DieError(f"{self.source}: no sensor {name!r} (it has {', '.join(m.name for m in self.meanders)})")

    def with_pillars(self, pillars: Pillars) -> Die:
        return Die(self.size, self.active_area, self.depth, pillars, self.meanders, self.source)

    def with_depth(self, depth: float) -> Die:
        """The same die with its sensing plane ``depth`` (m) below the pillar bases."""
        return self._with_elements(depth, 1.0)

    def with_meanders_scaled(self, scale: float) -> Die:
        """The same die with every strip's edges moved ``scale`` times as far from the die's centre (the
        meanders grown or shrunk under the pillars, which stay)."""
        return self._with_elements(self.depth, scale)

    def _with_elements(self, depth: float, scale: float) -> Die:
        if not (math.isfinite(depth) and depth > 0 and math.isfinite(scale) and scale > 0):
            raise DieError(f"{self.source}: expected a depth and a scale > 0, got {depth!r} and {scale!r}")
        meanders = tuple(Meander(m.name, m.axis, Rectangles(scale * m.strips.x, scale * m.strips.y, -depth),
                                 Rectangles(scale * m.elements.x, scale * m.elements.y, -depth), m.readout)
                         for m in self.meanders)
        return Die(self.size, self.active_area, depth, self.pillars, meanders, self.source)


def _strips(bank: BankTable, axis: str, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Rectangles (x, y) of a bank's strips: evenly spread across the sensing axis, each spanning the
    bank along the other."""
    x, y = np.array(bank.x_mm) * MM, np.array(bank.y_mm) * MM
    across = x if axis == "x" else y
    pitch = (across[1] - across[0]) / bank.elements
    centres = across[0] + (np.arange(bank.elements) + 0.5) * pitch
    narrow = np.column_stack([centres - width / 2, centres + width / 2])
    wide = np.tile(y if axis == "x" else x, (bank.elements, 1))
    return (narrow, wide) if axis == "x" else (wide, narrow)


def area_elements(x: np.ndarray, y: np.ndarray, axis: str, size: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The area elements of one bank of strips (``x``, ``y`` (n, 2), evenly spread across the sensing
    ``axis``, each spanning the bank along the other): runs of neighbouring strips about ``size`` (m) wide,
    each cut into pieces at most ``size`` long. Their rectangles (x, y) and the strips' area in each.

    A run spans its strips' pitch, gaps included, so neighbouring runs share their edges: the field's exact
    average then takes half the corners (:func:`softtip.magnetics.dipoles.rectangle_average_in_plane`),
    and over ~25 µm the field's average over the gaps' few µm differs from the strips' by far less than the
    element's own size does (the point-by-point test)."""
    across, along = (x, y) if axis == "x" else (y, x)
    count = across.shape[0]
    pitch = (across[-1, 0] - across[0, 0]) / (count - 1) if count > 1 else across[0, 1] - across[0, 0]
    per_cell = max(1, round(size / pitch))
    starts = np.arange(0, count, per_cell)
    # one array of run edges, so that a run's upper edge is its neighbour's lower edge to the last bit
    edges = across[0].mean() + pitch * (np.append(starts, count) - 0.5)
    runs = np.column_stack([edges[:-1], edges[1:]])
    strips_in = np.minimum(starts + per_cell, count) - starts
    length = along[0, 1] - along[0, 0]
    pieces = max(1, math.ceil(length / size - 1e-9))
    cuts = along[0, 0] + length * np.linspace(0.0, 1.0, pieces + 1)
    spans = np.column_stack([cuts[:-1], cuts[1:]])
    cell_across = np.repeat(runs, pieces, axis=0)
    cell_along = np.tile(spans, (len(starts), 1))
    area = np.repeat(strips_in * (across[0, 1] - across[0, 0]) * length / pieces, pieces)
    return (cell_across, cell_along, area) if axis == "x" else (cell_along, cell_across, area)


def placement_problem(positions: np.ndarray, base_diameter: float, size: np.ndarray) -> str:
    """What keeps pillars of base ``base_diameter`` (m) at ``positions`` (P, 2) m off a die of ``size`` (2,)
    m centred on the origin: a base leaving the die, or two bases overlapping; '' when they fit."""
    radius = base_diameter / 2
    for index, (x, y) in enumerate(positions):
        if abs(x) + radius > size[0] / 2 or abs(y) + radius > size[1] / 2:
            shown = [round(float(v) / MM, 6) for v in (x, y)]
            return f"pillars.positions_mm[{index}] = {shown}: the pillar's base leaves the die"
    gaps = np.linalg.norm(positions[:, None] - positions[None], axis=-1)
    np.fill_diagonal(gaps, np.inf)
    if np.any(gaps < base_diameter):
        first, second = np.argwhere(gaps < base_diameter)[0]
        return f"pillars.positions_mm[{first}] and [{second}]: the pillars' bases overlap"
    return ""


def build_die(table: DieFile, source: str) -> Die:
    """The SI die of a validated file, after the checks between its tables."""
    die, pillars = table.die, table.pillars
    size, area = np.array(die.size_mm) * MM, np.array(die.active_area_mm) * MM
    positions = np.array(pillars.positions_mm) * MM
    base = pillars.base_diameter_um * UM
    problem = placement_problem(positions, base, size)
    if problem:
        raise DieError(f"{source}: {problem}")
    rigid = Rod(length=pillars.height_mm * MM, base_diameter=base, tip_diameter=pillars.tip_diameter_um * UM,
                youngs_modulus=pillars.youngs_modulus_MPa * 1e6, poisson_ratio=pillars.poisson_ratio)
    rod = (replace(rigid, base_stiffness=_half_space_stiffness(rigid, base)) if pillars.base == "half-space"
           else rigid)
    sign = 1.0 if pillars.magnetisation == "up" else -1.0
    column = Pillars(positions, rod, sign * pillars.moment_memu * MEMU, math.radians(pillars.bend_azimuth_deg))
    meanders = []
    for name, sensor in table.sensors.items():
        width = sensor.element_width_um * UM
        banks = [_strips(bank, sensor.axis, width) for bank in sensor.banks]
        x, y = (np.concatenate(parts) for parts in zip(*banks))
        cells = [area_elements(bx, by, sensor.axis, sensor.area_element_um * UM) for bx, by in banks]
        cell_x, cell_y, weights = (np.concatenate(parts) for parts in zip(*cells))
        if np.any(np.abs(x) > size[0] / 2) or np.any(np.abs(y) > size[1] / 2):
            raise DieError(f"{source}: sensors.{name}.banks: a bank leaves the die")
        length = float(np.mean(x[:, 1] - x[:, 0]) if sensor.axis == "y" else np.mean(y[:, 1] - y[:, 0]))
        valve: SpinValveSensor = published_spin_valve(
            name, sensor.elements, sensor.magnetoresistance, sensor.sensitivity_ohm_per_Oe,
            *sensor.linear_range_Oe, element_length=length, element_width=width, area_weights=weights.tolist())
        readout = ConstantCurrentReadout(sensor=valve, current=table.readout.current_uA * UM,
                                         thermal_resistance=table.readout.thermal_resistance_K_per_W,
                                         offset=table.readout.offset_V)
        depth = -die.sensing_depth_um * UM
        meanders.append(Meander(name, 0 if sensor.axis == "x" else 1, Rectangles(x, y, depth),
                                Rectangles(cell_x, cell_y, depth), readout))
    return Die(size, area, die.sensing_depth_um * UM, column, tuple(meanders), source)


def read_die(path: str | Path = SHIPPED_DIE) -> Die:
    """The die described by the TOML file ``path`` (default: the shipped, declared layout)."""
    source = str(path)
    return build_die(parse(DieFile, read_toml(path, "die", DieError), source, error=DieError), source)
