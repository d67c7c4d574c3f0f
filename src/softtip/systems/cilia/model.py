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
own. Voltages are across a sensor at constant current; a curve's ``change`` is relative to zero force
(the reading's initial value subtracted).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from softtip.magnetics.dipoles import Dipoles, dipole_chain, rectangle_average_in_plane
from softtip.mechanics.rod import (
    PlateContact,
    RodError,
    RodShapes,
    lower_plate,
    solve_follower_force,
    solve_tip_force,
    touching_height,
)
from softtip.systems.cilia.layout import Die, DieError, Meander, Pillars

LoadMode = Literal["paper", "paper-follower"]


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


def pillar_dipoles(pillars: Pillars, shapes: RodShapes, count: int) -> Dipoles:
    """(B, P·K) dipoles of every pillar bent to ``shapes`` (one shape per load, the same for all pillars):
    K = ``count`` per pillar, along the local tangents, 1/K of the pillar's moment each."""
    fractions = (np.arange(count) + 0.5) / count
    points, tangents = shapes.centreline(fractions)  # (B, K, 2) in the bending plane (along, up)
    lift = np.zeros(points.shape[:-1] + (1,))

    def to_3d(plane: NDArray) -> NDArray:  # the bending plane is the pillar's x-z plane
        return np.concatenate([plane[..., :1], lift, plane[..., 1:]], axis=-1)

    return chain_dipoles(pillars, to_3d(points), to_3d(tangents))


def chain_dipoles(pillars: Pillars, points: NDArray, tangents: NDArray) -> Dipoles:
    """(B, P·K) dipoles of every pillar whose centre line is at ``points`` (B, K, 3) with unit ``tangents``
    (B, K, 3), given in a pillar's own frame (base at the origin, bending towards +x), turned to the
    pillars' bend azimuth and placed at each base."""
    c, s = np.cos(pillars.bend_azimuth), np.sin(pillars.bend_azimuth)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    offsets = np.concatenate([pillars.positions, np.zeros((len(pillars.positions), 1))], axis=-1)  # (P, 3)
    positions = (points @ turn.T)[:, None, :, :] + offsets[None, :, None, :]  # (B, P, K, 3)
    axes = np.broadcast_to((tangents @ turn.T)[:, None], positions.shape)
    chain = dipole_chain(positions, axes, pillars.moment)
    batch = positions.shape[0]
    return Dipoles(chain.positions.reshape(batch, -1, 3), chain.moments.reshape(batch, -1, 3))


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
    """The die's forward model. ``chain_count`` dipoles per pillar; ``mode`` the paper's load reading."""

    die: Die
    chain_count: int = 10
    mode: LoadMode = "paper"

    def __post_init__(self) -> None:
        if not isinstance(self.chain_count, int) or self.chain_count < 1:
            raise DieError(f"chain_count = {self.chain_count!r}: expected a positive integer")
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
        return element_fields(self.die.meander(sensor), pillar_dipoles(unit, shapes, self.chain_count))

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

    def balance_curve(self, descent: ArrayLike, contact: PlateContact = PlateContact(),
                      sensor: str = "X") -> ForceCurve:
        """The balance test: the die lowered by ``descent`` (G,) m (increasing, from 0) past the height where
        the plate first touches the pillars; the force is the balance's reading, all pillars together."""
        return self.balance_curves(descent, contact, (sensor,))[0]

    def balance_curves(self, descent: ArrayLike, contact: PlateContact,
                       sensors: tuple[str, ...]) -> tuple[ForceCurve, ...]:
        """:meth:`balance_curve` of each of ``sensors``: the plate lowered once for all."""
        descent = np.asarray(descent, dtype=np.float64)
        rod = self.die.pillars.rod
        start = touching_height(rod, contact)
        if (descent.ndim != 1 or descent.size == 0 or not np.all(np.isfinite(descent)) or np.any(descent < 0)
                or np.any(np.diff(descent) < 0) or descent[-1] >= start):
            raise DieError(f"descent: expected a non-empty 1-D array of increasing distances from 0 to below "
                           f"{start:.6g} m (the plate then touches the bases)")
        try:
            path = lower_plate(rod, start - descent, contact)
        except RodError as problem:
            raise DieError(f"balance: {problem}") from None
        both = path.standing.concatenate(path.shapes)  # the tare: the pillars before the plate touches them
        force = path.vertical_force * self.pillar_count
        volts = [self._volts(both, sensor) for sensor in sensors]
        return tuple(ForceCurve(sensor, force, v[1:], v[1:] - v[0], path.lying, path.shapes)
                     for sensor, v in zip(sensors, volts, strict=True))

    def _volts(self, shapes: RodShapes, sensor: str) -> NDArray[np.float64]:
        return self.volts(abs(self.die.pillars.moment) * self.unit_fields(shapes, sensor), sensor)
