"""The primal-dual active-set iteration every contact solver shares, and one load step of
contact enforced exactly with it on a dense compliance."""

from __future__ import annotations

import numpy as np

from softtip.mechanics.contact.result import StepOutcome

ACTIVE_SET_MEASURE = "points whose contact state the last active-set iteration changed"


class ActiveSetIteration:
    """The primal-dual active-set update of one load step.

    A node in contact stays in while it is compressed; a free node enters when
    it penetrates. Corner nodes of quadratic faces carry ~zero consistent
    pressure, so only clear tension (below -1e-3 of the peak nodal pressure)
    releases a node; once an active set repeats (a cycle), nodes are only added.
    """

    def __init__(self, active: np.ndarray):
        self.active = active
        self.iterations = 0
        self.changes = len(active)  # points the last update changed: 0 once the set has settled
        self._seen: set[bytes] = set()
        self._only_add = False

    def update(self, pressure: np.ndarray, linear_gap: np.ndarray, tolerance: float) -> bool:
        """Update ``active`` from nodal pressures and gaps; True when it did not change."""
        self.iterations += 1
        release = -1e-3 * max(pressure.max(initial=0.0), 0.0)
        new = np.where(self.active, pressure > release, linear_gap < -tolerance)
        if self._only_add:
            new |= self.active
        if np.array_equal(new, self.active):
            self.changes = 0
            return True
        if new.tobytes() in self._seen:
            self._only_add = True
            new |= self.active
        self._seen.add(self.active.tobytes())
        self.changes = int(np.count_nonzero(new != self.active))
        self.active = new
        return False

    @property
    def outcome(self) -> StepOutcome:
        return StepOutcome(self.changes == 0, self.iterations, self.changes)


def exact_contact_step(compliance: np.ndarray, gap: np.ndarray, target: np.ndarray, stick: bool,
                       active: np.ndarray, tolerance: float, max_iterations: int
                       ) -> tuple[np.ndarray, np.ndarray, StepOutcome]:
    """One load step of contact enforced exactly (Lagrange multipliers) on the dense ``compliance``
    of the points it holds (surface nodes or footprint cells): with ``stick`` three components per
    point (x, y, z), the tangential ones held at ``target`` (n, 2); else only the normal one
    (``compliance`` of those alone). The gap closes: u_z = ``gap``. Returns the multipliers (the
    indenter's force on each point, per component), the contact set, by primal-dual active sets,
    and how the iteration ended (its residual: :data:`ACTIVE_SET_MEASURE`)."""
    components = 3 if stick else 1
    iteration = ActiveSetIteration(active)
    for _ in range(max_iterations):
        index = np.flatnonzero(active)
        if stick:
            rows = (3 * index[:, None] + np.arange(3)).ravel()
            values = np.column_stack([target[index], gap[index]]).ravel()
        else:
            rows, values = index, gap[index]
        multipliers = np.zeros(len(compliance))
        if len(rows):
            multipliers[rows] = np.linalg.solve(compliance[np.ix_(rows, rows)], values)
        normal_u = (compliance @ multipliers).reshape(-1, components)[:, -1]
        pressure = -multipliers.reshape(-1, components)[:, -1]  # the indenter pushes down
        if iteration.update(pressure, gap - normal_u, tolerance):
            break
        active = iteration.active
    return multipliers, active, iteration.outcome
