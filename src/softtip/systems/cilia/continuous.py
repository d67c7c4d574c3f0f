"""The published dipole chain checked against the pillars as continuous magnets.

The model's field is the published one: ``chain_count`` point dipoles per pillar along its bent centre line,
each with an equal share of the moment. The reference is each bent cone as a stack of uniformly magnetised
magpylib cylinders (:mod:`softtip.magnetics.stack`), its moment spread by volume (the base's pieces carry
more than the tip's), at the same shapes, averaged over the same area elements of the meander and read
through the same readout. The gap is the chain's error in the voltage change.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from softtip._core.units import MN
from softtip.report.tables import Table
from softtip.magnetics.stack import cylinder_stack, stack_in_plane_average
from softtip.systems.cilia.model import CiliaModel, chain_dipoles


@dataclass(frozen=True)
class ContinuousCheck:
    """The voltage change of ``sensor`` (V) at ``force`` (N) from the model's dipole chain and from the
    stacked cylinders (``pieces`` per pillar)."""

    sensor: str
    force: NDArray[np.float64]
    chain: NDArray[np.float64]
    stack: NDArray[np.float64]
    pieces: int

    @property
    def gap(self) -> NDArray[np.float64]:
        """(N,) the chain's change over the stack's, less one."""
        return self.chain / self.stack - 1.0

    def to_dict(self) -> dict:
        return {"sensor": self.sensor, "force_mN": (self.force / MN).tolist(), "chain_uV": (self.chain * 1e6).tolist(),
                "stack_uV": (self.stack * 1e6).tolist(), "gap": self.gap.tolist(), "pieces": self.pieces}

    def figure(self) -> Figure:
        figure = Figure(figsize=(6.4, 4.0), layout="constrained")
        axes = figure.add_subplot()
        axes.plot(self.force / MN, self.stack * 1e3, "o-", label=f"continuous cones ({self.pieces} magpylib cylinders "
                                                                    "each, moment by volume)")
        axes.plot(self.force / MN, self.chain * 1e3, "s--", label="dipole chain, equal shares (as published)")
        axes.set_xlabel("force on the die (mN), paper mode")
        axes.set_ylabel(f"voltage change, sensor {self.sensor} (mV)")
        twin = axes.twinx()
        twin.plot(self.force / MN, 100 * self.gap, ":", color="k", lw=1)
        twin.set_ylabel("chain / continuous − 1 (%, dotted)")
        axes.legend(fontsize=7, loc="lower left")
        return figure


def chain_against_stack(model: CiliaModel, forces: NDArray, sensor: str = "X", pieces: int = 40,
                        nodes: int = 2) -> ContinuousCheck:
    """The voltage change of ``sensor`` at ``forces`` (N, paper mode) from the model and from its pillars as
    stacks of ``pieces`` cylinders, the field averaged over each area element by ``nodes`` × ``nodes``
    Gauss points."""
    forces = np.asarray(forces, dtype=np.float64)
    shapes = model.shapes(np.concatenate([[0.0], forces]))
    pillars = model.die.pillars
    rod = pillars.rod
    fractions = (np.arange(pieces) + 0.5) / pieces
    points, tangents = shapes.centreline(fractions)
    lift = np.zeros(points.shape[:-1] + (1,))
    placed = chain_dipoles(pillars, *(np.concatenate([v[..., :1], lift, v[..., 1:]], axis=-1) for v in (points, tangents)))
    axes = placed.moments / np.linalg.norm(placed.moments, axis=-1, keepdims=True) * math.copysign(1.0, pillars.moment)
    diameters = np.tile(rod.base_diameter + (rod.tip_diameter - rod.base_diameter) * fractions, len(pillars.positions))
    volume = math.pi * rod.length / 12 * (rod.base_diameter**2 + rod.base_diameter * rod.tip_diameter + rod.tip_diameter**2)
    magnetisation = pillars.moment / volume
    meander = model.die.meander(sensor)
    fields = np.stack([stack_in_plane_average(cylinder_stack(p, t, diameters, rod.length / pieces, magnetisation),
                                              meander.elements, meander.axis, nodes)
                       for p, t in zip(placed.positions, axes)])
    volts = meander.readout.voltage(fields)
    return ContinuousCheck(sensor, forces, model.curve(forces, sensor).change, volts[1:] - volts[0], pieces)


def continuous_table(check: ContinuousCheck) -> Table:
    """The check as a report table: the voltage change both ways at each force, and the chain's gap."""
    rows = [f"{force / MN:g} mN" for force in check.force]
    columns = ["dipole chain (µV)", "continuous cones (µV)", "chain / continuous − 1 (%)"]
    cells = {}
    for row, chain, stack, gap in zip(rows, check.chain, check.stack, check.gap):
        cells.update({(row, columns[0]): chain * 1e6, (row, columns[1]): stack * 1e6, (row, columns[2]): 100 * gap})
    return Table("The field checked as a continuous magnet", "force (paper mode)", rows, columns, cells, digits=3,
                 caption=f"Sensor {check.sensor}'s voltage change from the published chain (equal shares of the moment "
                         f"at points of the bent centre line) and from each bent cone as {check.pieces} uniformly "
                         "magnetised magpylib cylinders (the moment by volume), the same shapes, area elements and "
                         "readout. On uniform cylinders the two agree within 5.3 %, 100 µm under the bases "
                         "(tests/test_cilia_continuous.py); on the cones the equal shares put too much moment in "
                         "the tip, which moves most.")
