"""Contact enforced on cells of the indenter's footprint: smooth in where the indenter is.

Nodal contact (:mod:`softtip.mechanics.contact.nodal`) holds surface *nodes* to the
indenter. An indenter narrower than a few elements - a 1.6 mm board on a
1.5 mm mesh - then covers one or two rows of nodes, and the response steps as
rows enter and leave its footprint as it moves across them (Bz by up to
3.7 % of full scale at a 2.8 mm push).

Here the rigid indenter is the mortar side: the contact pressure is constant
on each cell of a grid fixed to the indenter, and each cell holds the body's
displacement *averaged over the cell* (the quadratic surface interpolation,
integrated at points every ``_POINT_SPACING``). The constraints move
continuously with the indenter, so does the response. Cells are about as
large as the surface's node spacing, so the constraints never outnumber the
nodes they act on (the discrete inf-sup condition).

A board's footprint is a strip: its cells tile the board's thickness exactly
and lie along the board from the foot of its centre line, so a board shifted
along itself meets the same cells. Other indenters get a square grid on the
part of it over which they have a lower surface.

Friction semantics follow the nodal solvers, with one difference that makes
them physical: with ``"stick"`` the material under a cell holds on to it, so
the cells stay attached to the material they first touched, and tangential
travel brings no new material under the indenter (the nodal solvers let nodes
the moved footprint covers in the *undeformed* configuration join). Cells also
model Coulomb's law (``"coulomb"``), which the nodal solvers do not.

The contact problem needs only the surface and the compliance of the nodes
under the cells (a :class:`FootprintBody`), from any source: influence
matrices (:meth:`SurfaceInfluence.compliance_of
<softtip.mechanics.contact.influence.SurfaceInfluence.compliance_of>`) or
back-substitutions with a factorised stiffness (:func:`stiffness_compliance`),
which is the finite-element solve of the same problem.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from softtip.mechanics.contact.active_set import ACTIVE_SET_MEASURE, ActiveSetIteration, exact_contact_step
from softtip.mechanics.contact.load import LoadCase, load_path, touch_offset
from softtip.mechanics.contact.result import ConvergenceLog, ReducedContactResult, StepOutcome
from softtip.mechanics.fe import BodyModel
from softtip.mechanics.indenters import Board, Indenter
from softtip.mechanics.linsolve import SPDSolver
from softtip.mechanics.poses import MagnetPoses

_POINT_SPACING = 0.2e-3  # m, integration points in each cell
CELL_SIZE = 1.0e-3  # m, about the surface node spacing of a 1.5 mm quadratic mesh

# (nodes (n,) -> (compliance (3n, 3n) m/N, magnet response (6M, 3n))): the body seen from its surface
Compliance = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


class SurfacePatch:
    """The upward-facing outer surface of a body above ``lowest_z``, as quadratic triangles whose
    nodes are all free; one-to-one with its plan view, where points are located."""

    def __init__(self, body: BodyModel, lowest_z: float):
        from scipy.spatial import cKDTree

        facets = body.space.boundary_facets("outer")
        nodes = body.space.nodes
        corners = nodes[facets[:, :3]]
        normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        keep = ((normal[:, 2] > 1e-3 * np.linalg.norm(normal, axis=1))
                & (nodes[facets, 2] >= lowest_z).all(axis=1)
                & (body.node_dofs[facets] >= 0).all(axis=(1, 2)))
        self.facets = facets[keep]  # (k, 6) node ids
        self.corners = nodes[self.facets[:, :3]]  # (k, 3, 3) m
        self.radius = float(np.hypot(self.corners[..., 0], self.corners[..., 1]).max())
        self._tree = cKDTree(self.corners.mean(axis=1)[:, :2])
        # a point lies in one of the facets whose centroids are nearest; 12 covers any graded mesh
        self._candidates = min(12, len(self.facets))

    def locate(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Facet under each plan-view point (-1 where none) and the point's barycentric coordinates."""
        _, near = self._tree.query(xy, k=self._candidates)
        facet = np.full(len(xy), -1)
        bary = np.zeros((len(xy), 3))
        for j in range(self._candidates):
            f = near[:, j]
            a, b, c = (self.corners[f, k, :2] for k in range(3))
            e1, e2, r = b - a, c - a, xy - a
            det = e1[:, 0] * e2[:, 1] - e2[:, 0] * e1[:, 1]
            l1 = (r[:, 0] * e2[:, 1] - e2[:, 0] * r[:, 1]) / det
            l2 = (e1[:, 0] * r[:, 1] - r[:, 0] * e1[:, 1]) / det
            inside = (facet < 0) & (np.minimum(np.minimum(1 - l1 - l2, l1), l2) >= -1e-9)
            facet[inside] = f[inside]
            bary[inside] = np.column_stack([1 - l1 - l2, l1, l2])[inside]
        return facet, bary


def quadratic_triangle_shapes(bary: np.ndarray) -> np.ndarray:
    """(n, 6) quadratic Lagrange shape values: corners 0, 1, 2, then edges 01, 12, 20."""
    l0, l1, l2 = bary.T
    return np.column_stack([l0 * (2 * l0 - 1), l1 * (2 * l1 - 1), l2 * (2 * l2 - 1),
                            4 * l0 * l1, 4 * l1 * l2, 4 * l2 * l0])


@dataclass
class FootprintCells:
    nodes: np.ndarray  # (n,) body nodes under the cells
    average: np.ndarray  # (c, n): a cell's mean of each node's shape function
    points: np.ndarray  # (p, 3) m, integration points on the undeformed surface, evenly spaced
    cell_of_point: np.ndarray  # (p,)
    points_per_cell: np.ndarray  # (c,)

    def gaps(self, indenter: Indenter, frame: np.ndarray, extend: bool = False) -> np.ndarray:
        """Each cell's mean vertical gap to the indenter at ``frame`` (inf where a point has none;
        with ``extend``, the indenter's lower surface continued beyond its edge)."""
        gap = indenter.vertical_gap(self.points - frame, extend=extend)[0]
        return np.bincount(self.cell_of_point, weights=gap) / self.points_per_cell


def _grid(indenter: Indenter, frame: np.ndarray, reach: float, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Plan-view integration points of the footprint cells at ``frame`` and the cell of each. Cells
    have the size ``cell`` and sit at fixed places relative to the indenter, whatever ``reach``: a
    longer reach only adds cells at the far ends, so the response is continuous in the tangential
    travel that sets it."""
    cells_out = math.ceil(reach / cell)  # on each side of the indenter's axis
    if isinstance(indenter, Board):
        along = np.array([math.cos(indenter.angle), math.sin(indenter.angle)])
        across = np.array([-along[1], along[0]])
        origin = (frame[:2] @ across) * across  # the foot of the centre line
        half = (cells_out * cell, indenter.thickness / 2)
        counts = (2 * cells_out, max(1, round(indenter.thickness / cell)))
    else:
        along, across, origin = np.array([1.0, 0.0]), np.array([0.0, 1.0]), frame[:2]
        half = (cells_out * cell,) * 2
        counts = (2 * cells_out,) * 2
    per_cell = [max(2, math.ceil(2 * h / n / _POINT_SPACING)) for h, n in zip(half, counts)]
    u = ((np.arange(counts[0] * per_cell[0]) + 0.5) / (counts[0] * per_cell[0]) * 2 - 1) * half[0]
    v = ((np.arange(counts[1] * per_cell[1]) + 0.5) / (counts[1] * per_cell[1]) * 2 - 1) * half[1]
    cell_u = np.arange(len(u)) // per_cell[0]
    cell_v = np.arange(len(v)) // per_cell[1]
    xy = origin + u[:, None, None] * along + v[None, :, None] * across
    cells = cell_u[:, None] * counts[1] + cell_v[None, :]
    return xy.reshape(-1, 2), cells.ravel()


def footprint_cells(patch: SurfacePatch, indenter: Indenter, frame: np.ndarray, reach: float,
                    cell: float = CELL_SIZE) -> FootprintCells:
    """Cells of the indenter's footprint at ``frame`` over ``patch``, out to ``reach`` (m) from the
    indenter's axis (a board's centre line); cells with no point over the patch are left out."""
    xy, cell_of_point = _grid(indenter, frame, reach, cell)
    facet, bary = patch.locate(xy)
    keep = facet >= 0
    z = np.einsum("pk,pk->p", bary[keep], patch.corners[facet[keep], :, 2])
    points = np.column_stack([xy[keep], z])
    if not isinstance(indenter, Board):  # only where the indenter has a lower surface
        under = np.isfinite(indenter.vertical_gap(points - np.array([*frame[:2], 0.0]))[0])
        points, keep = points[under], np.flatnonzero(keep)[under]
    facet, bary, cell_of_point = facet[keep], bary[keep], cell_of_point[keep]
    _, cell_of_point = np.unique(cell_of_point, return_inverse=True)
    count = np.bincount(cell_of_point)  # the points are evenly spaced: means are plain averages
    nodes, node_of = np.unique(patch.facets[facet], return_inverse=True)
    average = np.zeros((len(count), len(nodes)))
    np.add.at(average, (np.repeat(cell_of_point, 6), node_of.ravel()), quadratic_triangle_shapes(bary).ravel())
    return FootprintCells(nodes=nodes, average=average / count[:, None], points=points,
                          cell_of_point=cell_of_point, points_per_cell=count)


def stiffness_compliance(body: BodyModel) -> Compliance:
    """Compliance of surface nodes by back-substitution with the factorised stiffness: with it,
    :func:`solve_footprint_contact` is a finite-element solve."""
    solver = SPDSolver()
    solver.factorize(body.stiffness)

    def compliance(nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        columns = body.node_dofs[nodes].ravel()
        return body.unit_load_responses(solver, columns)

    return compliance


@dataclass(frozen=True)
class FootprintBody:
    """The body as contact on footprint cells sees it: its upward surface, and the compliance of
    any nodes on it."""

    patch: SurfacePatch
    compliance: Compliance


FOOTPRINT_MEASURES = {
    "none": ACTIVE_SET_MEASURE,
    "stick": "share of the load step's path not followed",
    "coulomb": "relative size of the last semi-smooth Newton update (the contact set must also settle)",
}


def solve_footprint_contact(body: FootprintBody, load: LoadCase, *, normal_steps: int | None = None,
                            tangential_steps: int = 4, cell: float = CELL_SIZE, max_iterations: int | None = None,
                            report_unconverged: bool = False) -> ReducedContactResult:
    """Small-strain contact with tractions constant on footprint cells (Lagrange multipliers, exact),
    along the nodal solvers' load path; ``contact_nodes`` are the body nodes under cells in contact.

    Friction: ``"none"``, ``"stick"`` (the path followed exactly between its steps, from one change
    of the contact set to the next), or ``"coulomb"`` with ``load.mu``: a cell in contact sticks
    while its tangential traction is below mu times its pressure and otherwise slips, with that
    traction, against its slip (incremental over the load steps; semi-smooth Newton).

    ``max_iterations`` caps each load step: its active-set (``"none"``) or semi-smooth Newton
    (``"coulomb"``) iterations, 50 by default, or with ``"stick"`` the changes of the contact set
    along it, by default 20 per cell and 50 more (a cell touches and lets go a few times at most).
    A step that reaches it raises :class:`ContactNotConverged`, or with ``report_unconverged`` the
    result says ``converged=False``. Residual: see :data:`FOOTPRINT_MEASURES`."""
    patch = body.patch
    holds = load.friction in ("stick", "coulomb")  # cells hold on to the material they touch
    path = load_path(load, normal_steps, tangential_steps, holds=holds)
    reach = patch.radius + float(np.hypot(*load.tangential))
    # cells depend on the plan view of the frame only: those where the indenter starts find the touch
    cells = footprint_cells(patch, load.indenter, np.array([*load.position, 0.0]), reach, cell)
    touch = touch_offset(load.indenter, load.position, cells.points)
    steps, plan = [], np.zeros(2)  # the cells of every load step; the sideways travel they are at
    for travel in path:
        # held cells stay with the material they hold; others travel with the indenter
        if not holds and not np.array_equal(travel[:2], plan):
            cells, plan = footprint_cells(patch, load.indenter, touch + travel, reach, cell), travel[:2]
        steps.append(cells)
    if max_iterations is None:
        max_iterations = 20 * len(cells.average) + 50 if load.friction == "stick" else 50
    log = ConvergenceLog("solve_footprint_contact", FOOTPRINT_MEASURES[load.friction], load, len(path),
                         max_iterations, report_unconverged)
    nodes = np.unique(np.concatenate([c.nodes for c in steps]))
    body_compliance, magnet_response = body.compliance(nodes)
    u = np.zeros(3 * len(nodes))  # surface displacements after the last step
    previous_frame = touch.copy()
    tolerance = load.tolerance
    if load.friction == "stick":  # the cells never change: a step starts at the gaps the last ended at
        previous_gap = cells.gaps(load.indenter, touch)
    states = []
    for k, travel in enumerate(path):
        frame = touch + travel
        cells = steps[k]
        if k == 0 or cells is not steps[k - 1]:
            spread = np.zeros((len(cells.average), len(nodes)))
            spread[:, np.searchsorted(nodes, cells.nodes)] = cells.average
            spread = np.kron(spread, np.eye(3))  # every cell's mean displacement (x, y, z)
            operator = spread if holds else spread[2::3]  # the components the constraints hold
            schur = operator @ body_compliance @ operator.T
            active = np.zeros(len(cells.average), dtype=bool)
            multipliers = np.zeros(operator.shape[0])
        gap = cells.gaps(load.indenter, frame)
        if load.friction == "stick":
            multipliers, active, outcome = _stick_segment(schur, multipliers, active, previous_gap,
                                                          (gap, cells.gaps(load.indenter, frame, extend=True)),
                                                          (frame - previous_frame)[:2], tolerance, max_iterations)
            previous_gap = gap
        else:
            cell_u = (spread @ u).reshape(-1, 3)
            active |= gap - cell_u[:, 2] < 0
            if holds:  # held cells travel with the indenter, even past the edge of its footprint
                gap = np.where(active, cells.gaps(load.indenter, frame, extend=True), gap)
            else:  # without friction, cells the indenter has moved off are free
                active &= np.isfinite(gap)
            # held cells follow the indenter tangentially from where they were
            target = cell_u[:, :2] + (frame - previous_frame)[:2]
            if load.friction == "coulomb":
                multipliers, active, outcome = _coulomb_step(schur, gap, target, load.mu, active, multipliers,
                                                             tolerance, max_iterations)
            else:
                multipliers, active, outcome = exact_contact_step(schur, gap, target, holds, active, tolerance,
                                                                  max_iterations)
        log.step(outcome)
        force_on_nodes = operator.T @ multipliers
        u = body_compliance @ force_on_nodes
        previous_frame = frame
        states.append((travel, MagnetPoses.from_rigid((magnet_response @ force_on_nodes).reshape(-1, 6)),
                       -force_on_nodes.reshape(-1, 3).sum(axis=0)))
    _, poses, force = states[-1]
    touched = cells.nodes[(cells.average[active] != 0).any(axis=0)]
    return ReducedContactResult(magnet_poses=poses, force=force, contact_nodes=touched, path=states, **log.record())


def _stick_segment(schur: np.ndarray, multipliers: np.ndarray, active: np.ndarray, start: np.ndarray,
                   end: tuple[np.ndarray, np.ndarray], shift: np.ndarray, tolerance: float, max_events: int
                   ) -> tuple[np.ndarray, np.ndarray, StepOutcome]:
    """One segment of the load path with sticking cells, followed exactly: with a fixed contact set
    the response is linear along the segment, so the path is solved from one change of the contact
    set to the next (a cell touches: its gap closes; a cell lets go: its pressure vanishes). A cell
    holds on where it touched, wherever that falls in the segment, so the end state is continuous in
    the load, where a stepped path joins cells only at its steps.

    ``start``: each cell's mean gap to the indenter's surface (inf where it has none) where the
    segment starts; ``end``: the same where it ends, and to that surface extended (for the cells in
    contact). The gaps are taken linear along the segment (exact for flat faces), over which the
    indenter moves ``shift`` tangentially. Cells that change at one point of the path change
    together, whatever their order. A cell that touches with no pressure may be unable to be held
    (it would pull) or left free (it would penetrate): friction needs pressure, so it stays in
    contact without holding on until the segment ends, and holds on from there.

    Stops after ``max_events`` changes of the contact set, where it has got to (the outcome's
    residual: the share of the segment not followed)."""
    cells = len(active)
    reachable = np.isfinite(start) & np.isfinite(end[0])
    free_start, free_end = np.where(reachable, start, 0.0), np.where(reachable, end[0], 0.0)
    active = active.copy()
    held = active.copy()  # cells also held tangentially: those in contact, but for touches with no pressure
    flips = np.zeros(cells, dtype=int)  # changes of each cell at the present point of the path
    moved = schur @ multipliers
    done = 0.0  # fraction of the segment travelled
    for count in range(1, max_events + 1):
        left = 1.0 - done
        rows = np.flatnonzero(np.column_stack([held, held, active]))  # the components held, cell-major
        target = np.column_stack([moved.reshape(-1, 3)[:, :2] + left * shift, end[1]]).ravel()[rows]
        final = np.zeros_like(multipliers)
        if len(rows):
            final[rows] = np.linalg.solve(schur[np.ix_(rows, rows)], target)
        change = final - multipliers
        moved_change = schur @ change
        # where, as a fraction of what is left, a cell's pressure or a free cell's gap reaches zero
        pressure, pressure_change = -multipliers[2::3], -change[2::3]
        gap_now = free_start + done * (free_end - free_start) - moved[2::3]
        gap_end = free_end - moved[2::3] - moved_change[2::3]
        lets_go = active & (pressure + pressure_change < 0)
        touches = ~active & reachable & (gap_end < -tolerance)
        when = np.full(cells, np.inf)
        when[lets_go] = np.clip(pressure[lets_go], 0, None) / -pressure_change[lets_go]
        when[touches] = np.clip(gap_now[touches], 0, None) / (gap_now[touches] - gap_end[touches])
        when[(flips >= 4) & (when <= 1e-12)] = np.inf  # a cell that cannot settle waits for the path to move on
        first = when.min()
        if not np.isfinite(first):
            return final, active, StepOutcome(True, count, 0.0)
        changing = np.flatnonzero(when <= first + 1e-12)
        if first > 1e-12:
            flips[:] = 0
        multipliers = multipliers + first * change
        moved = moved + first * moved_change
        done += first * left
        flips[changing] += 1
        active[changing] = ~active[changing]
        held[changing] = active[changing] & (flips[changing] < 2)
    return multipliers, active, StepOutcome(False, max_events, 1.0 - done)


def _coulomb_step(schur: np.ndarray, gap: np.ndarray, target: np.ndarray, mu: float, active: np.ndarray,
                  multipliers: np.ndarray, tolerance: float, max_iterations: int
                  ) -> tuple[np.ndarray, np.ndarray, StepOutcome]:
    """One load step with Coulomb friction: semi-smooth Newton on the contact conditions and on
    Alart and Curnier's friction condition  max(b, |z|) t - b z = 0,  z = t - c s,  b = mu p
    (t tangential traction on the body, s its slip relative to the indenter, p pressure), with
    the damped tangent of Hueber, Stadler and Wohlmuth; contact sets by primal-dual active sets.
    Starts from the last step's multipliers; converged once the contact set has settled and the
    update is below 1e-9 of the multipliers (the outcome's residual: that relative update)."""
    cells = len(gap)
    augment = 1.0 / np.mean(np.diag(schur))  # c: makes traction and slip commensurate
    rows = schur.reshape(cells, 3, -1)
    iteration = ActiveSetIteration(active)
    for _ in range(max_iterations):
        traction = multipliers.reshape(-1, 3)
        moved = (schur @ multipliers).reshape(-1, 3)
        pressure = -traction[:, 2]
        slip = moved[:, :2] - target
        z = traction[:, :2] - augment * slip
        bound = mu * np.maximum(pressure, 0.0)
        size = np.linalg.norm(z, axis=1)
        slipping = active & (size > bound)
        # residuals and their generalised Jacobian, three rows per cell
        residual = np.concatenate([slip, (moved[:, 2] - gap)[:, None]], axis=1)
        jacobian = rows.copy()
        k = np.flatnonzero(slipping)
        if len(k):
            n = np.arange(len(k))
            dz = -augment * rows[k, :2]  # d z / d multipliers
            dz[n, 0, 3 * k] += 1.0
            dz[n, 1, 3 * k + 1] += 1.0
            tangential = traction[k, :2]
            damped = bound[k, None] * tangential / np.maximum(
                np.maximum(bound[k], np.linalg.norm(tangential, axis=1)), 1e-300)[:, None]
            direction = z[k] / size[k, None]
            jac = (damped[:, :, None] * np.einsum("ki,kij->kj", direction, dz)[:, None, :]
                   - bound[k, None, None] * dz)
            jac[n, 0, 3 * k] += size[k]
            jac[n, 1, 3 * k + 1] += size[k]
            jac[n[:, None], np.arange(2), (3 * k + 2)[:, None]] += mu * z[k]  # b = mu p = -mu (normal multiplier)
            jacobian[k, :2] = jac
            residual[k, :2] = size[k, None] * tangential - bound[k, None] * z[k]
        free = np.flatnonzero(~active)  # out of contact: no traction
        jacobian[free] = 0.0
        jacobian[free[:, None], np.arange(3), 3 * free[:, None] + np.arange(3)] = 1.0
        residual[free] = traction[free]
        step = np.linalg.solve(jacobian.reshape(3 * cells, -1), -residual.ravel())
        multipliers = multipliers + step
        settled = iteration.update(-multipliers[2::3], gap - (schur @ multipliers)[2::3], tolerance)
        scale = max(np.abs(multipliers).max(), 1e-12)
        update = np.abs(step).max() / scale
        if settled and np.abs(step).max() <= 1e-9 * scale:
            return multipliers, active, StepOutcome(True, iteration.iterations, update)
        active = iteration.active
    return multipliers, active, StepOutcome(False, iteration.iterations, update)
