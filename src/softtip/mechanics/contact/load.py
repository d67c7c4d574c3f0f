"""A contact load: the indenter, where it touches, how far it travels, and friction.

The indenter is lowered until it touches the undeformed body, then pushed
``depth`` down, then moved ``tangential`` (x, y) sideways, in load steps.
Friction is ``"none"``, ``"stick"`` (contact points move with the indenter
tangentially from where they touched) or, for contact on footprint cells only,
``"coulomb"``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from softtip.mechanics.indenters import Indenter

FRICTION_MODES = ("none", "stick")  # of the solvers that hold nodes
FOOTPRINT_FRICTION_MODES = (*FRICTION_MODES, "coulomb")  # contact on footprint cells adds Coulomb's law


@dataclass(frozen=True)
class LoadCase:
    indenter: Indenter
    depth: float  # m, normal travel after first touch
    tangential: tuple[float, float] = (0.0, 0.0)  # m, travel along x and y after the normal push
    position: tuple[float, float] = (0.0, 0.0)  # m, (x, y) of the indenter's axis on the fingertip
    friction: str = "none"
    mu: float = 0.7  # Coulomb's coefficient, with friction = "coulomb" (soft body on a board, S1)

    def __post_init__(self):
        if not self.depth >= 0:
            raise ValueError(f"depth = {self.depth}: expected a non-negative length in metres")
        if self.friction not in FOOTPRINT_FRICTION_MODES:
            raise ValueError(f"friction = {self.friction!r}: expected one of {', '.join(FOOTPRINT_FRICTION_MODES)}")
        if not 0 <= self.mu <= 2:  # where the semi-smooth Newton is checked; friction="stick" never slips
            raise ValueError(f"mu = {self.mu}: expected a friction coefficient from 0 to 2")

    @property
    def tolerance(self) -> float:
        """m, how far a point may penetrate before it joins the contact set."""
        return 1e-6 * max(self.depth, 1e-6)


def require_nodal_friction(load: LoadCase) -> None:
    """Refuse friction the solvers that hold nodes do not model."""
    if load.friction not in FRICTION_MODES:
        raise ValueError(f"friction = {load.friction!r}: contact on nodes models {' or '.join(FRICTION_MODES)}; "
                         "Coulomb friction needs contact on footprint cells (solve_footprint_contact)")


def touch_offset(indenter: Indenter, position: tuple[float, float], points: np.ndarray) -> np.ndarray:
    """Where the indenter's frame sits when it first touches the undeformed body."""
    offset = np.array([position[0], position[1], 0.0])
    gap = indenter.vertical_gap(points - offset)[0].min()
    if not np.isfinite(gap):
        raise ValueError(f"the indenter at position {position} m does not reach the fingertip")
    offset[2] = -gap
    return offset


def load_path(load: LoadCase, normal_steps: int | None, tangential_steps: int, holds: bool = False
              ) -> list[np.ndarray]:
    """The indenter's travel from first touch after each load step: ``normal_steps`` down to
    ``depth``, then, if there is tangential travel, ``tangential_steps`` sideways. Without
    ``normal_steps``, one, or two with friction that ``holds`` and a tangential travel (points that
    touch late in the push then hold where they touched)."""
    if normal_steps is None:
        normal_steps = 2 if holds and any(load.tangential) else 1
    path = [np.array([0.0, 0.0, -load.depth * k / normal_steps]) for k in range(1, normal_steps + 1)]
    if any(load.tangential):
        path += [np.array([load.tangential[0] * k / tangential_steps, load.tangential[1] * k / tangential_steps,
                           -load.depth]) for k in range(1, tangential_steps + 1)]
    return path
