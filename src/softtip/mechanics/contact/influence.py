"""Influence matrices of the fingertip's contact surface, and an exact contact solve on them.

The small-strain body is linear, so everything a contact load does is fixed by
two matrices over the surface nodes where contact can happen:

``compliance``  W (3m x 3m): displacement of every surface node's x, y, z per
                unit force on every other (the Schur complement of K^-1);
``magnets``     R (6M x 3m): each magnet's rigid translation and rotation per
                unit surface force.

Both come from one factorisation of K and 3m back-substitutions, done in
blocks. A contact problem then only involves the nodes under the indenter: a
primal-dual active-set iteration on dense blocks of W enforces the contact
conditions exactly (Lagrange multipliers, no penalty) in milliseconds.
:func:`solve_influence_contact` holds nodes, with the same load path and
friction semantics as the finite-element solver
(:func:`~softtip.mechanics.contact.nodal.solve_linear_contact`);
:meth:`SurfaceInfluence.compliance_of` serves contact on footprint cells
(:func:`~softtip.mechanics.contact.footprint.solve_footprint_contact`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from softtip._core.cache import EntryPieces
from softtip._core.progress import SILENT, Progress
from softtip.mechanics.contact.active_set import ACTIVE_SET_MEASURE, exact_contact_step
from softtip.mechanics.contact.load import LoadCase, load_path, require_nodal_friction, touch_offset
from softtip.mechanics.contact.nodal import contact_candidates
from softtip.mechanics.contact.result import ConvergenceLog, ReducedContactResult
from softtip.mechanics.fe import BodyModel
from softtip.mechanics.linsolve import SPDSolver
from softtip.mechanics.poses import MagnetPoses


@dataclass
class SurfaceInfluence:
    nodes: np.ndarray  # (m, 3) m, surface nodes where contact may happen
    node_ids: np.ndarray  # (m,) their numbers in the body
    compliance: np.ndarray  # (3m, 3m) m/N, node-major (x, y, z of node 0, then node 1, ...)
    magnets: np.ndarray  # (6M, 3m): (t, theta) of each magnet per unit nodal force
    magnet_centers: np.ndarray  # (M, 3) m

    @classmethod
    def build(cls, body: BodyModel, lowest_z: float, progress: Progress = SILENT,
              pieces: EntryPieces | None = None) -> "SurfaceInfluence":
        """Influence of unit forces on the body's outer nodes at or above ``lowest_z`` (m); ``pieces``: where
        the back-substitutions' finished blocks are kept (:meth:`BodyModel.unit_load_responses`)."""
        candidates, dofs = contact_candidates(body)
        keep = (body.space.nodes[candidates, 2] >= lowest_z) & (dofs >= 0).all(axis=1)
        solver = SPDSolver()
        solver.factorize(body.stiffness)
        compliance, magnets = body.unit_load_responses(solver, dofs[keep].ravel(), progress=progress,
                                                         pieces=pieces)
        return cls(nodes=body.space.nodes[candidates[keep]], node_ids=candidates[keep], compliance=compliance,
                   magnets=magnets, magnet_centers=body.magnet_centers.copy())

    def compliance_of(self, node_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Compliance (3n, 3n) and magnet response (6M, 3n) of body nodes ``node_ids`` (all among
        :attr:`node_ids`): the view :func:`~softtip.mechanics.contact.footprint.solve_footprint_contact` needs."""
        order = np.argsort(self.node_ids)
        local = order[np.minimum(np.searchsorted(self.node_ids, node_ids, sorter=order), len(order) - 1)]
        if not np.array_equal(self.node_ids[local], node_ids):
            raise ValueError("node_ids: expected nodes of the influence matrices' surface")
        rows = (3 * local[:, None] + np.arange(3)).ravel()
        return self.compliance[np.ix_(rows, rows)], self.magnets[:, rows]


_BULGE_MARGIN = 1e-3  # m


def solve_influence_contact(influence: SurfaceInfluence, load: LoadCase, *, normal_steps: int | None = None,
                            tangential_steps: int = 4, max_iterations: int = 50,
                            report_unconverged: bool = False) -> ReducedContactResult:
    """Exact small-strain contact on the influence matrices, along the FE solver's load path.
    ``max_iterations`` caps the active-set iterations of each load step; a step that reaches it
    raises :class:`ContactNotConverged`, or with ``report_unconverged`` the result says
    ``converged=False``. Residual: the active-set changes of each step's last iteration."""
    require_nodal_friction(load)
    touch = touch_offset(load.indenter, load.position, influence.nodes)
    stick = load.friction == "stick"
    path = load_path(load, normal_steps, tangential_steps, holds=stick)
    log = ConvergenceLog("solve_influence_contact", ACTIVE_SET_MEASURE, load, len(path), max_iterations,
                         report_unconverged)
    # only nodes the indenter can reach along its path take part: every other node stays out of contact
    # unless the surface bulges up by more than the margin, far beyond what these loads do
    reach = np.zeros(len(influence.nodes), dtype=bool)
    for travel in path:
        reach |= load.indenter.vertical_gap(influence.nodes - (touch + travel))[0] < load.depth + _BULGE_MARGIN
    local = np.flatnonzero(reach)
    x = influence.nodes[local]
    local_rows = (3 * local[:, None] + np.arange(3)).ravel()
    compliance = influence.compliance[np.ix_(local_rows, local_rows)]
    held = compliance if stick else compliance[2::3, 2::3]  # the components the constraints hold
    u = np.zeros_like(x)
    active = np.zeros(len(x), dtype=bool)
    previous_frame = touch.copy()
    states = []
    for travel in path:
        frame = touch + travel
        gap = load.indenter.vertical_gap(x - frame)[0]
        active |= gap - u[:, 2] < 0  # the linearised gap g + n.u, n = -z
        if stick:
            gap = np.where(active, load.indenter.vertical_gap(x - frame, extend=True)[0], gap)
        else:  # without friction, nodes the indenter has moved off are free
            active &= np.isfinite(gap)
        # held nodes follow the indenter tangentially from where they were (the constraints hold
        # exactly, so that is where they were held)
        target = u[:, :2] + (frame - previous_frame)[:2]
        multipliers, active, outcome = exact_contact_step(held, gap, target, stick, active, load.tolerance,
                                                          max_iterations)
        log.step(outcome)
        forces = np.zeros_like(x)  # force of the indenter on each node
        if stick:
            forces[:] = multipliers.reshape(-1, 3)
        else:
            forces[:, 2] = multipliers
        u = (compliance @ forces.ravel()).reshape(-1, 3)
        previous_frame = frame
        states.append((travel, MagnetPoses.from_rigid((influence.magnets[:, local_rows] @ forces.ravel()).reshape(-1, 6)),
                       -forces.sum(axis=0)))
    _, poses, force = states[-1]
    return ReducedContactResult(magnet_poses=poses, force=force, contact_nodes=local[active], path=states,
                                **log.record())
