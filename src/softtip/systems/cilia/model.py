"""The sensor composed once: force → deformed pillars → field averaged over each spin valve → voltage.

Load modes (every pillar takes the same share of the force; the five are identical):

* ``paper`` (the fits' mode, as published): each pillar is loaded at its tip by force / P perpendicular to
  its undeformed axis; it bends towards the horizontal, where more force changes its shape ever less and
  goes along its length into the side wall (the voltage saturates), without ever lying flat.
* ``paper-follower``: the same load parallel to the tip face (perpendicular to the deformed axis at the
  tip), which curls the pillar over until its side touches the die; from then on it lies there and the
  rest of the force goes into its side wall (``lying``).
* balance (:meth:`CiliaModel.balance_curve`): the die lowered onto a flat plate, as the measurement was
  made: a vertical push with friction at the tips, compression, buckling, lying down, and the plate
  pressing the lying pillars' side walls and folding them further.

The field of each pillar is a chain of ``chain_count`` point dipoles at the midpoints of equal pieces of
its deformed centre line, along the local tangent, each with 1/K of its moment (as published); the
in-plane field along each sensor's axis is averaged exactly over every spin valve, which saturates on its
own. The balance test may read each pillar instead as what the composite is, a uniformly magnetised cone,
integrated over its volume in cells finest near the sensors (:func:`cone_cells`). Voltages are across a
sensor at constant current; a curve's ``change`` is relative to zero force (the reading's initial value
subtracted).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import brentq

from softtip.magnetics.dipoles import Dipoles, dipole_chain, rectangle_average_in_plane
from softtip.mechanics.rod import (
    PlateContact,
    PlatePath,
    RodError,
    RodShapes,
    lower_plate,
    solve_follower_force,
    solve_tip_force,
    touching_height,
)
from softtip.systems.cilia.layout import Die, DieError, Meander, Pillars

LoadMode = Literal["paper", "paper-follower"]
BalanceMagnet = Literal["chain", "cone"]


@dataclass(frozen=True)
class ForceCurve:
    """A sensor's voltage against the total force on the die (N): ``volts`` across the sensor, ``change``
    from zero force, ``lying`` the pillars lie on their side; ``shapes`` the pillars' deformation."""

    sensor: str
    force: NDArray[np.float64]
    volts: NDArray[np.float64]
    change: NDArray[np.float64]
    lying: NDArray[np.bool_]
    shapes: RodShapes


@dataclass(frozen=True)
class BalanceCurve(ForceCurve):
    """A balance test's curve (:meth:`CiliaModel.balance_curve`): ``shapes`` are those of the pillar nearest
    the plate's pivot, ``lying`` every pillar lies; ``gaps`` (G, P) each pillar's plate height over its base
    (m), ``rotation`` (G,) the plate's turn (rad), ``lying_count`` (G,) the pillars lying."""

    gaps: NDArray[np.float64]
    rotation: NDArray[np.float64]
    lying_count: NDArray[np.int_]


@dataclass(frozen=True)
class BalancePlate:
    """The balance's plate: ``rotation_stiffness`` (N·m/rad) of its turn about the axis across the bend under
    the die's centre (None: it does not turn under the pushes); ``seated`` (rad) the turn it rests at before
    the die comes down (a plate seated askew: every base's gap less by its lever times it)."""

    rotation_stiffness: float | None = None
    seated: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.seated) and abs(self.seated) < 0.1):
            raise DieError(f"seated = {self.seated!r}: expected a turn in rad, |turn| < 0.1")
        k = self.rotation_stiffness
        if k is not None and not (math.isfinite(k) and k > 0):
            raise DieError(f"rotation_stiffness = {k!r}: expected a positive stiffness in N·m/rad, or none")


def _push_at(path: PlatePath, gaps: NDArray) -> NDArray[np.float64]:
    """(B,) one pillar's push (N) at plate heights ``gaps`` (B,) over its base (0 above first contact)."""
    return np.interp(gaps, path.gaps[::-1], path.vertical_force[::-1])


def _shapes_at(path: PlatePath, gaps: NDArray) -> RodShapes:
    """One pillar's shapes at plate heights ``gaps`` (B,): linear between the table's rows (the table's
    first row, at first contact, above it); lying where the nearer row lies."""
    heights = path.gaps[::-1]
    upper = np.clip(np.searchsorted(heights, gaps), 1, heights.size - 1)
    weight = np.clip((gaps - heights[upper - 1]) / (heights[upper] - heights[upper - 1]), 0.0, 1.0)[:, None]
    rows_low, rows_high = path.gaps.size - upper, path.gaps.size - 1 - upper  # the table's own order

    def blend(values: NDArray) -> NDArray:
        return values[rows_low] * (1 - weight) + values[rows_high] * weight

    shapes = path.shapes
    return replace(shapes, x=blend(shapes.x), z=blend(shapes.z), angles=blend(shapes.angles),
                   force=blend(shapes.force), saturated=np.where(weight[:, 0] < 0.5, shapes.saturated[rows_low],
                                                                 shapes.saturated[rows_high]))


def _pillar_gaps(path: PlatePath, unturned: NDArray, lever: NDArray, plate: BalancePlate) -> tuple[NDArray, NDArray]:
    """Each pillar's gap (G, P) and the plate's turn (G,): ``unturned`` (G, P) the gaps of a plate that does
    not turn, ``lever`` (P,) each base's lever along the bend."""
    if plate.rotation_stiffness is None:
        return unturned, np.zeros(unturned.shape[0])
    low = path.gaps[-1]
    tips = path.shapes.x[:, -1]

    def moment_balance(turn: float, row: NDArray) -> float:
        gaps = row - lever * turn
        offsets = np.interp(gaps, path.gaps[::-1], tips[::-1])
        return plate.rotation_stiffness * turn + float(_push_at(path, gaps) @ (lever + offsets))

    turns = np.empty(unturned.shape[0])
    moving = lever != 0
    for index, row in enumerate(unturned):
        # the turns that keep every gap in the table (gaps above first contact need no bound)
        limits = (row[moving] - low) / lever[moving]
        upper = float(limits[lever[moving] > 0].min(initial=math.inf))
        lower = float(-(-limits[lever[moving] < 0]).min(initial=math.inf))
        upper, lower = min(upper, 0.5), max(lower, -0.5)
        if moment_balance(lower, row) > 0 or moment_balance(upper, row) < 0:
            raise DieError(f"plate.rotation_stiffness = {plate.rotation_stiffness:g}: the plate would turn "
                           "beyond what the pillars' table covers; expected a stiffer plate")
        turns[index] = brentq(moment_balance, lower, upper, args=(row,), xtol=1e-12, rtol=1e-10)
    return unturned - lever[None, :] * turns[:, None], turns


def pillar_dipoles(pillars: Pillars, shapes: RodShapes, count: int, shares: tuple[float, ...] | None = None) -> Dipoles:
    """(B, P·K) dipoles of every pillar bent to ``shapes`` (one shape per load, the same for all pillars):
    K = ``count`` per pillar, along the local tangents, each ``shares`` of the pillar's moment (base first;
    None: 1/K each, as published)."""
    fractions = (np.arange(count) + 0.5) / count
    points, tangents = shapes.centreline(fractions)  # (B, K, 2) in the bending plane (along, up)
    lift = np.zeros(points.shape[:-1] + (1,))

    def to_3d(plane: NDArray) -> NDArray:  # the bending plane is the pillar's x-z plane
        return np.concatenate([plane[..., :1], lift, plane[..., 1:]], axis=-1)

    return chain_dipoles(pillars, to_3d(points), to_3d(tangents), shares)


def chain_dipoles(pillars: Pillars, points: NDArray, tangents: NDArray,
                  shares: tuple[float, ...] | None = None) -> Dipoles:
    """(B, P·K) dipoles of every pillar whose centre line is at ``points`` (B, K, 3) with unit ``tangents``
    (B, K, 3), given in a pillar's own frame (base at the origin, bending towards +x), turned to the
    pillars' bend azimuth and placed at each base."""
    c, s = np.cos(pillars.bend_azimuth), np.sin(pillars.bend_azimuth)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    offsets = np.concatenate([pillars.positions, np.zeros((len(pillars.positions), 1))], axis=-1)  # (P, 3)
    positions = (points @ turn.T)[:, None, :, :] + offsets[None, :, None, :]  # (B, P, K, 3)
    axes = np.broadcast_to((tangents @ turn.T)[:, None], positions.shape)
    chain = dipole_chain(positions, axes, pillars.moment, shares)
    batch = positions.shape[0]
    return Dipoles(chain.positions.reshape(batch, -1, 3), chain.moments.reshape(batch, -1, 3))


@dataclass(frozen=True)
class ConeCells:
    """How finely :func:`cone_cells` cuts each pillar: ``slices`` along it (their lengths growing from the
    root as the ``grading`` power of the arc length), each slice's cross-section into cells about ``size``
    times the slice's height over the sensing plane at rest (Gauss–Legendre rings × equal sectors): a cell
    is a point dipole, which stands for its piece of magnet where the sensors are farther than its size."""

    slices: int = 64
    size: float = 1.0
    grading: float = 2.0

    def __post_init__(self) -> None:
        if not (isinstance(self.slices, int) and self.slices >= 1 and math.isfinite(self.size) and self.size > 0
                and math.isfinite(self.grading) and 1.0 <= self.grading <= 4.0):
            raise DieError(f"cone cells {self!r}: expected a positive integer of slices, a positive size and a "
                           "grading from 1 to 4")


def cone_cells(pillars: Pillars, shapes: RodShapes, depth: float, cells: ConeCells = ConeCells()) -> Dipoles:
    """(B, P·C) the pillars bent to ``shapes`` as uniformly magnetised cones, their volume integrated cell by
    cell: each cell of each slice's cross-section (a disc of the cone's local diameter, turned as the rod's
    sections are) a dipole along the section's axis carrying the magnetisation times its volume; the sensing plane lies
    ``depth`` (m) below the bases. A cell the bent root would carry below the die's surface (the bases'
    plane) is left out: the magnet cannot go below its base."""
    rod = pillars.rod
    edges = np.linspace(0.0, 1.0, cells.slices + 1) ** cells.grading
    middles, lengths = (edges[:-1] + edges[1:]) / 2, np.diff(edges) * rod.length
    radii = (rod.base_diameter + (rod.tip_diameter - rod.base_diameter) * middles) / 2  # (K,)
    sizes = cells.size * (middles * rod.length + depth)
    owner, across, angle, volume = [], [], [], []
    for index, (radius, size, length) in enumerate(zip(radii, sizes, lengths, strict=True)):
        rings, sectors = max(1, math.ceil(radius / size)), max(4, math.ceil(2 * math.pi * radius / size))
        nodes, weights = np.polynomial.legendre.leggauss(rings)
        rho = radius * (1 + nodes) / 2
        # each cell's volume: its ring's ∫ρ dρ by Gauss, its sector's angle, the slice's length
        ring_volume = radius / 2 * weights * rho * (2 * math.pi / sectors) * length
        phi = 2 * math.pi * (np.arange(sectors) + 0.5) / sectors
        owner.append(np.full(rings * sectors, index))
        across.append(np.repeat(rho, sectors))
        angle.append(np.tile(phi, rings))
        volume.append(np.repeat(ring_volume, sectors))
    owner, across, angle, volume = (np.concatenate(v) for v in (owner, across, angle, volume))
    points, _ = shapes.centreline(middles)  # (B, K, 2) in the bending plane (along, up)
    # each section turns with the rod's segments, interpolated between their middles; at the base by the
    # base's own turn (none when clamped: the bonded face stays flat on the die)
    segments = shapes.angles.shape[1]
    base = np.zeros(shapes.angles.shape[0]) if rod.base_stiffness is None else shapes.angles[:, 0]
    where = np.concatenate([[0.0], (np.arange(segments) + 0.5) / segments])
    turns = np.stack([np.interp(middles, where, np.concatenate([[b], row])) for b, row in zip(base, shapes.angles)])
    points, turns = points[:, owner], turns[:, owner]  # (B, C, 2), (B, C)
    tangents = np.stack([np.sin(turns), np.cos(turns)], axis=-1)
    normals = np.stack([np.cos(turns), -np.sin(turns)], axis=-1)  # in the plane, across the tangent
    in_plane = (across * np.cos(angle))[None, :, None] * normals
    positions = np.concatenate([points[..., :1] + in_plane[..., :1],
                                np.broadcast_to(across * np.sin(angle), points.shape[:-1])[..., None],
                                points[..., 1:] + in_plane[..., 1:]], axis=-1)
    directions = np.concatenate([tangents[..., :1], np.zeros_like(tangents[..., :1]), tangents[..., 1:]], axis=-1)
    kept = positions[..., 2] >= 0.0
    chain = chain_dipoles(replace(pillars, moment=1.0), positions, directions)  # the cells turned and placed
    # chain_dipoles gave each cell 1/C: each carries instead the magnetisation times its own volume
    scale = np.tile(pillars.moment * volume.size * volume / rod.volume * kept, (1, len(pillars.positions)))
    return Dipoles(chain.positions, chain.moments * scale[..., None])


def element_fields(meander: Meander, dipoles: Dipoles) -> NDArray[np.float64]:
    """(B, n) field (T) along the meander's sensing axis, averaged over each of its spin valves."""
    return rectangle_average_in_plane(meander.elements, dipoles.positions, dipoles.moments, (meander.axis,))[..., 0]


def _forces(values: ArrayLike, name: str) -> NDArray[np.float64]:
    forces = np.asarray(values, dtype=np.float64)
    if forces.ndim != 1 or forces.size == 0 or not np.all(np.isfinite(forces)) or np.any(forces < 0):
        raise DieError(f"{name}: expected a non-empty 1-D array of finite forces >= 0 N")
    return forces


@dataclass(frozen=True)
class CiliaModel:
    """The die's forward model. ``chain_count`` dipoles per pillar, carrying ``chain_shares`` of its moment
    (base first; None: equal shares, as published: a uniform magnetisation of a uniform pillar); ``mode``
    the paper's load reading; ``balance_chain_count`` the equal dipoles per pillar of the balance test (None:
    ``chain_count``), whose buckled and lying roots need more than a tip-loaded pillar; ``balance_magnet`` how
    the balance test reads the pillars: ``chain`` those dipoles, ``cone`` each pillar a uniformly magnetised
    cone integrated over its volume in ``cells`` (:func:`cone_cells`: the moment by volume, the wide root
    resolved near the sensors)."""

    die: Die
    chain_count: int = 10
    mode: LoadMode = "paper"
    chain_shares: tuple[float, ...] | None = None
    balance_chain_count: int | None = None
    balance_magnet: BalanceMagnet = "chain"
    cells: ConeCells = ConeCells()

    def __post_init__(self) -> None:
        if not isinstance(self.chain_count, int) or self.chain_count < 1:
            raise DieError(f"chain_count = {self.chain_count!r}: expected a positive integer")
        if self.balance_chain_count is not None and (not isinstance(self.balance_chain_count, int)
                                                     or self.balance_chain_count < 1):
            raise DieError(f"balance_chain_count = {self.balance_chain_count!r}: expected a positive integer or None")
        if self.chain_shares is not None and (len(self.chain_shares) != self.chain_count
                                              or min(self.chain_shares) < 0 or abs(sum(self.chain_shares) - 1) > 1e-9):
            raise DieError(f"chain_shares: expected {self.chain_count} shares >= 0 summing to 1")
        if self.balance_magnet not in ("chain", "cone"):
            raise DieError(f"balance_magnet = {self.balance_magnet!r}: expected chain or cone")
        if self.mode not in ("paper", "paper-follower"):
            raise DieError(f"mode = {self.mode!r}: expected paper or paper-follower")

    @property
    def pillar_count(self) -> int:
        return len(self.die.pillars.positions)

    def shapes(self, forces: ArrayLike) -> RodShapes:
        """The pillars' shapes under total forces ``forces`` (B,) N on the die (paper modes)."""
        per_pillar = _forces(forces, "forces") / self.pillar_count
        rod = self.die.pillars.rod
        if self.mode == "paper-follower":
            return solve_follower_force(rod, per_pillar)
        return solve_tip_force(rod, np.stack([per_pillar, np.zeros_like(per_pillar)], axis=-1))

    def unit_fields(self, shapes: RodShapes, sensor: str) -> NDArray[np.float64]:
        """(B, n) element fields of ``sensor`` per unit of the pillars' moment (T per A·m²): the field is
        linear in the moment, so a fit of the moment rescales these."""
        unit = replace(self.die.pillars, moment=float(np.sign(self.die.pillars.moment)))
        return element_fields(self.die.meander(sensor), pillar_dipoles(unit, shapes, self.chain_count, self.chain_shares))

    def volts(self, fields: ArrayLike, sensor: str) -> NDArray[np.float64]:
        """Voltage across ``sensor`` whose elements see ``fields`` (B, n)."""
        return self.die.meander(sensor).readout.voltage(fields)

    def curve(self, forces: ArrayLike, sensor: str = "X") -> ForceCurve:
        """Voltage of ``sensor`` against the total forces ``forces`` (B,) N (zero force is added for the tare
        if absent)."""
        return self.curves(forces, (sensor,))[0]

    def curves(self, forces: ArrayLike, sensors: tuple[str, ...]) -> tuple[ForceCurve, ...]:
        """:meth:`curve` of each of ``sensors``: the pillars' shapes solved once for all."""
        forces = _forces(forces, "forces")
        with_zero = forces if forces[0] == 0 else np.concatenate([[0.0], forces])
        shapes = self.shapes(with_zero)
        start = 0 if forces[0] == 0 else 1
        loaded, lying = shapes.take(slice(start, None)), shapes.saturated[start:]
        volts = [self._volts(shapes, sensor) for sensor in sensors]
        return tuple(ForceCurve(sensor, forces, v[start:], v[start:] - v[0], lying, loaded)
                     for sensor, v in zip(sensors, volts, strict=True))

    def rest_volts(self, sensor: str) -> float:
        """Voltage (V) across ``sensor`` at zero force: its tare."""
        return float(self.curve(np.array([0.0]), sensor).volts[0])

    def balance_curve(self, descent: ArrayLike, contact: PlateContact = PlateContact(), sensor: str = "X",
                      plate: BalancePlate = BalancePlate()) -> BalanceCurve:
        """The balance test: the die lowered by ``descent`` (G,) m (increasing, from 0) past the height where
        the plate first touches a pillar; the force is the balance's reading, all pillars together."""
        return self.balance_curves(descent, contact, (sensor,), plate)[0]

    def balance_curves(self, descent: ArrayLike, contact: PlateContact, sensors: tuple[str, ...],
                       plate: BalancePlate = BalancePlate()) -> tuple[BalanceCurve, ...]:
        """:meth:`balance_curve` of each of ``sensors``: the plate lowered once for all.

        Every pillar follows one rod's path under the plate (:func:`lower_plate`, in the plate's frame, the
        die's ``contact.tilt`` included), tabulated against the plate's height over its base; the pillars
        differ in that height. A die tilted by t brings the bases at a lever a along the bend nearer the
        plate by a sin t; a plate that turns by φ about the axis across the bend under the die's centre
        moves each base's gap by −a φ, and turns until its stiffness balances the pushes' moment,
        k φ = −Σ F_i (a_i + u_i) (u the tip's offset along the bend). The turn's own change of the pillars'
        inclination (φ beside the tilt) is left out of the rod: it is reported (``rotation``) to be judged."""
        descent = np.asarray(descent, dtype=np.float64)
        pillars = self.die.pillars
        rod = pillars.rod
        start = touching_height(rod, contact)
        lever = pillars.positions @ np.array([math.cos(pillars.bend_azimuth), math.sin(pillars.bend_azimuth)])
        nearer = lever * (math.sin(contact.tilt) + plate.seated)
        spread = float(nearer.max() - nearer.min())
        if (descent.ndim != 1 or descent.size == 0 or not np.all(np.isfinite(descent)) or np.any(descent < 0)
                or np.any(np.diff(descent) < 0) or descent[-1] + spread >= start):
            raise DieError(f"descent: expected a non-empty 1-D array of increasing distances from 0 to below "
                           f"{start - spread:.6g} m (the plate then touches the bases)")
        # the table: every gap a pillar may meet, the plate's turn allowed a twentieth of the height more
        lowest = max(start - descent[-1] - spread - (0.0 if plate.rotation_stiffness is None else 0.05 * rod.length),
                     0.05 * start)
        unturned = start - descent[:, None] + nearer.max() - nearer[None, :]
        # a regular grid and every gap a plate that does not turn meets (so that there the table is exact)
        grid = np.linspace(start, lowest, max(3, int(math.ceil((start - lowest) / (0.0025 * rod.length))) + 1))
        table_gaps = np.unique(np.concatenate([grid, unturned[unturned < start]]))[::-1]
        try:
            path = lower_plate(rod, table_gaps, contact)
        except RodError as problem:
            raise DieError(f"balance: {problem}") from None
        gaps, rotation = _pillar_gaps(path, unturned, lever, plate)
        shapes = [_shapes_at(path, gaps[:, p]).turned(contact.tilt) for p in range(lever.size)]
        force = np.stack([_push_at(path, gaps[:, p]) for p in range(lever.size)], axis=1).sum(axis=1)
        standing = path.standing.turned(contact.tilt)
        centre = int(np.argmin(np.abs(lever)))
        lying = np.all(np.stack([s.saturated for s in shapes], axis=1), axis=1)
        count, shares = ((self.chain_count, self.chain_shares) if self.balance_chain_count is None
                         else (self.balance_chain_count, None))

        def magnets(pillars: Pillars, shapes: RodShapes) -> Dipoles:
            if self.balance_magnet == "cone":
                return cone_cells(pillars, shapes, self.die.depth, self.cells)
            return pillar_dipoles(pillars, shapes, count, shares)

        curves = []
        for sensor in sensors:
            meander = self.die.meander(sensor)
            fields = sum(element_fields(meander, magnets(replace(pillars, positions=pillars.positions[p:p + 1]),
                                                         shapes[p]))
                         for p in range(lever.size))
            rest = element_fields(meander, magnets(pillars, standing))
            volts = self.volts(np.concatenate([rest, fields]), sensor)
            curves.append(BalanceCurve(sensor, force, volts[1:], volts[1:] - volts[0], lying, shapes[centre],
                                       gaps, rotation, np.stack([s.saturated for s in shapes], axis=1).sum(axis=1)))
        return tuple(curves)

    def _volts(self, shapes: RodShapes, sensor: str) -> NDArray[np.float64]:
        return self.volts(abs(self.die.pillars.moment) * self.unit_fields(shapes, sensor), sensor)
