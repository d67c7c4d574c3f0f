"""Contact of the finite-element body's outer nodes with a rigid indenter.

Both solvers enforce non-penetration of the body's outer nodes with a penalty
that is stiff compared to the body (``penalty`` times the mean diagonal of the
stiffness, so penetration is ~1/penalty of the local displacement) and find
the contact set by a semi-smooth Newton (primal-dual active-set) iteration:
the contact area is an outcome, not an input.

* :func:`solve_linear_contact` - small strain, gaps measured along the
  approach direction (see :mod:`softtip.mechanics.indenters`). The first
  active set is the indenter's geometric overlap with the body, which is
  nearly the converged one; later ones are low-rank updates of that one
  factorisation (see :class:`_ActiveSetSystem`).
* :func:`solve_hyperelastic_contact` - neo-Hookean, large deformation; Newton's
  method with load steps and a backtracking line search on the total energy.

Friction is either ``"none"`` or ``"stick"`` (contact nodes move with the
indenter tangentially from where they touched); load paths are those of
:mod:`softtip.mechanics.contact.load`.
"""

from __future__ import annotations

import math
import time

import numpy as np
import scipy.sparse as sp

from softtip._core.progress import SILENT, Progress
from softtip.mechanics.contact.active_set import ACTIVE_SET_MEASURE, ActiveSetIteration
from softtip.mechanics.contact.load import LoadCase, load_path, require_nodal_friction, touch_offset
from softtip.mechanics.contact.result import ContactResult, ConvergenceLog, StepOutcome
from softtip.mechanics.fe import BodyModel
from softtip.mechanics.linsolve import NotPositiveDefinite, SPDSolver


def contact_candidates(body: BodyModel) -> tuple[np.ndarray, np.ndarray]:
    """Outer nodes with a free displacement component, and their unknowns (-1 where held)."""
    outer = body.space.boundary_nodes["outer"]
    outer = outer[(body.node_dofs[outer] >= 0).any(axis=1)]
    return outer, body.node_dofs[outer]


def _gather(vector: np.ndarray, dofs: np.ndarray) -> np.ndarray:
    """Nodal vectors (k, 3) from the unknowns; held components are zero."""
    return np.where(dofs >= 0, vector[np.maximum(dofs, 0)], 0.0)


def _scatter(size: int, dofs: np.ndarray, nodal: np.ndarray) -> np.ndarray:
    out = np.zeros(size)
    keep = dofs >= 0
    np.add.at(out, dofs[keep], nodal[keep])
    return out


def penalty_blocks(body: BodyModel, dofs: np.ndarray, blocks: np.ndarray) -> sp.csr_matrix:
    """A block-diagonal matrix over the unknowns with 3x3 ``blocks`` on nodes' ``dofs`` (k, 3)."""
    rows = np.repeat(dofs, 3, axis=1).ravel()
    cols = np.tile(dofs, (1, 3)).ravel()
    keep = (rows >= 0) & (cols >= 0)
    return sp.csr_matrix((blocks.ravel()[keep], (rows[keep], cols[keep])), shape=(body.size, body.size))


class StickAnchors:
    """Where each sticking node holds on to the indenter, in the indenter's frame
    (stored as the node's position, or displacement, minus the frame's when it was held)."""

    def __init__(self):
        self.points: dict[int, np.ndarray] = {}

    def targets(self, nodes: np.ndarray, current: np.ndarray, frame: np.ndarray) -> np.ndarray:
        """Target positions of ``nodes``; nodes without an anchor anchor at ``current`` now."""
        out = np.empty((len(nodes), 3))
        for k, node in enumerate(nodes):
            anchor = self.points.setdefault(int(node), current[k] - frame)
            out[k] = anchor + frame
        return out

    def keep_only(self, nodes: np.ndarray) -> None:
        keep = set(int(n) for n in nodes)
        self.points = {n: p for n, p in self.points.items() if n in keep}


class _ActiveSetSystem:
    """Solves (K + sum of penalty blocks of the active nodes) u = f for changing active sets.

    One Cholesky factorisation serves many active sets: the blocks of nodes that
    joined or left the set since the factorisation form a low-rank correction
    applied with the Woodbury identity, using K0^-1 columns cached per node.
    When solving for the missing columns would take longer than a new
    factorisation (both timed as they happen), it refactorises instead.
    """

    def __init__(self, body: BodyModel, stiffness: sp.csr_matrix, dofs: np.ndarray, blocks: np.ndarray,
                 solver: SPDSolver):
        self.body, self.stiffness, self.dofs, self.solver = body, stiffness, dofs, solver
        self.blocks = np.where((dofs >= 0)[:, :, None] & (dofs >= 0)[:, None, :], blocks, 0.0)
        self.factorize_seconds = np.inf
        self.column_seconds = 0.0
        # each 3x3 block as a sum of rank-one terms: coefficient * v v^T
        values, vectors = np.linalg.eigh(self.blocks)
        self.rank_terms = [[(values[i, k], vectors[i, :, k]) for k in range(3) if values[i, k] > 1e-12 * values[i].max()]
                           for i in range(len(dofs))]
        self.base: np.ndarray | None = None
        self.columns: dict[int, np.ndarray] = {}

    def _factorize(self, active: np.ndarray) -> None:
        start = time.perf_counter()
        penalty = penalty_blocks(self.body, self.dofs[active], self.blocks[active])
        self.solver.factorize(self.stiffness + penalty)
        self.base, self.columns = active.copy(), {}
        self.factorize_seconds = time.perf_counter() - start

    def solve(self, active: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        if self.base is None:
            self._factorize(active)
            return self.solver.solve(rhs)
        changed = np.flatnonzero(active != self.base)
        if len(changed) == 0:
            return self.solver.solve(rhs)
        missing = [i for i in changed if i not in self.columns]
        new_columns = sum(len(self.rank_terms[i]) for i in missing)
        changed_columns = sum(len(self.rank_terms[i]) for i in changed)
        # before any column was timed, guess 1/50 of a factorisation (measured: 1/60 to 1/80)
        per_column = self.column_seconds or self.factorize_seconds / 50
        if new_columns * per_column > self.factorize_seconds or changed_columns > 600:
            self._factorize(active)
            return self.solver.solve(rhs)
        if missing:
            vectors = [self._vectors(i) for i in missing]
            start = time.perf_counter()
            solved = self.solver.solve(np.hstack(vectors))
            self.column_seconds = (time.perf_counter() - start) / new_columns
            start = 0
            for i, v in zip(missing, vectors):
                self.columns[i] = solved[:, start:start + v.shape[1]]
                start += v.shape[1]
        update = np.hstack([self._vectors(i) for i in changed])
        inverse_update = np.hstack([self.columns[i] for i in changed])
        signs = np.concatenate([[1.0 if active[i] else -1.0] * len(self.rank_terms[i]) for i in changed])
        coefficients = signs * np.concatenate([[c for c, _ in self.rank_terms[i]] for i in changed])
        y = self.solver.solve(rhs)
        capacitance = np.diag(1 / coefficients) + update.T @ inverse_update
        return y - inverse_update @ np.linalg.solve(capacitance, update.T @ y)

    def _vectors(self, i: int) -> np.ndarray:
        out = np.zeros((self.body.size, len(self.rank_terms[i])))
        keep = self.dofs[i] >= 0
        for k, (_, v) in enumerate(self.rank_terms[i]):
            out[self.dofs[i][keep], k] = v[keep]
        return out


def solve_linear_contact(body: BodyModel, load: LoadCase, *, penalty: float = 1e4, normal_steps: int | None = None,
                         tangential_steps: int = 4, max_iterations: int = 30, solver: SPDSolver | None = None,
                         report_unconverged: bool = False, progress: Progress = SILENT) -> ContactResult:
    """Small-strain contact; gaps are linearised about the undeformed body. ``max_iterations``
    caps the active-set iterations of each load step; a step that reaches it raises
    :class:`ContactNotConverged`, or with ``report_unconverged`` the result says
    ``converged=False``. Residual: the active-set changes of each step's last iteration."""
    require_nodal_friction(load)
    t0 = time.perf_counter()
    stiffness = body.stiffness
    t_assembly = time.perf_counter() - t0
    solver = solver or SPDSolver()
    factorizations0 = solver.factorizations
    candidates, cand_dofs = contact_candidates(body)
    x = body.space.nodes[candidates]
    epsilon = penalty * stiffness.diagonal()[: body.n_free].mean()
    touch = touch_offset(load.indenter, load.position, x)
    stick = load.friction == "stick"
    path = load_path(load, normal_steps, tangential_steps, holds=stick)
    log = ConvergenceLog("solve_linear_contact", ACTIVE_SET_MEASURE, load, len(path), max_iterations,
                         report_unconverged)
    # approach-direction gaps share one normal per node for the whole load path
    normal = load.indenter.vertical_gap(x - touch)[1]
    blocks = epsilon * (np.broadcast_to(np.eye(3), (len(x), 3, 3)) if stick
                        else np.einsum("ni,nj->nij", normal, normal))
    system = _ActiveSetSystem(body, stiffness, cand_dofs, blocks, solver)
    blocks = system.blocks  # held components carry no penalty
    anchors = StickAnchors()
    unknowns = np.zeros(body.size)
    u_candidates = np.zeros_like(x)
    nodal_force = np.zeros_like(x)
    previous_frame = touch.copy()
    active = np.zeros(len(candidates), dtype=bool)
    with progress.task("contact load steps", total=len(path)) as task:
        for travel in path:
            frame = touch + travel
            gap = load.indenter.vertical_gap(x - frame)[0]
            active |= gap + np.einsum("ij,ij->i", normal, u_candidates) < 0
            if stick:  # nodes held by the indenter travel with it, even past the edge of its footprint
                gap = np.where(active, load.indenter.vertical_gap(x - frame, extend=True)[0], gap)
            else:  # without friction, nodes the indenter has moved off are free
                active &= np.isfinite(gap)
            iteration = ActiveSetIteration(active)
            for _ in range(max_iterations):
                if stick:
                    # contact nodes follow the indenter tangentially; the normal gap closes
                    held = anchors.targets(candidates[active], x[active] + u_candidates[active], previous_frame)
                    target = held + (frame - previous_frame) - x[active]
                    target -= np.einsum("ij,ij->i", target, normal[active])[:, None] * normal[active]
                    target -= gap[active, None] * normal[active]
                    rhs_nodal = epsilon * target
                else:
                    rhs_nodal = -epsilon * gap[active, None] * normal[active]
                rhs_nodal = np.where(cand_dofs[active] >= 0, rhs_nodal, 0.0)
                unknowns = system.solve(active, _scatter(body.size, cand_dofs[active], rhs_nodal))
                u_now = _gather(unknowns, cand_dofs)
                nodal_force = np.zeros_like(x)  # force of the indenter on each candidate node
                nodal_force[active] = rhs_nodal - np.einsum("nij,nj->ni", blocks[active], u_now[active])
                pressure = np.einsum("ij,ij->i", nodal_force, normal)
                linear_gap = gap + np.einsum("ij,ij->i", normal, u_now)
                if iteration.update(pressure, linear_gap, load.tolerance):
                    break
                active = iteration.active
            log.step(iteration.outcome)
            u_candidates = u_now
            if stick:
                anchors.keep_only(candidates[active])
                anchors.targets(candidates[active], x[active] + u_now[active], frame)
            previous_frame = frame
            task.advance(note=f"{iteration.iterations} active-set iterations")
    t_total = time.perf_counter() - t0
    return ContactResult(
        unknowns=unknowns, magnet_poses=body.magnet_poses(unknowns), force=-nodal_force.sum(axis=0),
        contact_nodes=candidates[active], displacements=body.nodal_displacements(unknowns),
        factorizations=solver.factorizations - factorizations0,
        timings={"assembly_s": t_assembly, "contact_solve_s": t_total - t_assembly}, **log.record())


class _RegularizedNewton:
    """Newton steps with the tangent shifted towards its diagonal where it is indefinite
    (near snap-through of the roof), so each step stays a descent direction for the
    line search. The last shift that worked is remembered and relaxed tenfold per step."""

    def __init__(self, solver: SPDSolver):
        self.solver, self.shift = solver, 0.0

    def step(self, matrix: sp.csr_matrix, residual: np.ndarray) -> np.ndarray:
        diagonal = sp.diags(matrix.diagonal())
        shift = self.shift / 10 if self.shift > 1e-4 else 0.0
        while True:
            try:
                self.solver.factorize(matrix + shift * diagonal if shift else matrix)
                self.shift = shift
                return -self.solver.solve(residual)
            except NotPositiveDefinite:
                shift = 1e-3 if shift == 0 else shift * 10
                if shift > 1e3:
                    raise


def solve_hyperelastic_contact(body: BodyModel, load: LoadCase, *, normal_steps: int = 6, tangential_steps: int = 4,
                               penalty: float = 1e3, tolerance: float = 1e-7, max_iterations: int = 40,
                               report_unconverged: bool = False, progress: Progress = SILENT,
                               monitor=None) -> ContactResult:
    """Neo-Hookean body under large deformation; contact gaps at the deformed positions.

    A load step has converged when the Newton residual has fallen below ``tolerance`` times its
    first value in the step, or when a Newton update moves no unknown by more than ``tolerance``
    times the depth with the residual below ``sqrt(tolerance)`` times its first.
    ``max_iterations`` caps the Newton iterations of each load step; a step that reaches it, or
    ends otherwise unconverged, raises :class:`ContactNotConverged`, or with
    ``report_unconverged`` the result says ``converged=False``. Residual: the Newton residual norm
    of each step's last iteration relative to its first."""
    require_nodal_friction(load)
    t0 = time.perf_counter()
    solver = SPDSolver()
    candidates, cand_dofs = contact_candidates(body)
    x = body.space.nodes[candidates]
    epsilon = penalty * body.stiffness.diagonal()[: body.n_free].mean()
    touch = touch_offset(load.indenter, load.position, x)
    anchors: dict[int, np.ndarray] = {}  # sticking nodes (candidate index) -> anchor in the indenter's frame
    unknowns = np.zeros(body.size)

    def contact_terms(q: np.ndarray, frame: np.ndarray, with_matrix: bool):
        """Penalty energy, gradient, matrix and nodal forces at ``q``. Nodes held since an earlier
        load step stick to their anchor; others only may not penetrate (smooth within a step)."""
        p = x + _gather(q, cand_dofs)
        gap, normal = load.indenter.signed_distance(p - frame)
        held = np.zeros(len(candidates), dtype=bool)
        held[list(anchors)] = True
        touching = (gap < 0) & ~held
        stuck_offset = p[held] - (np.array([anchors[i] for i in np.flatnonzero(held)]).reshape(-1, 3) + frame)
        energy = 0.5 * epsilon * (np.sum(stuck_offset**2) + np.sum(gap[touching] ** 2))
        force = np.zeros_like(p)  # force of the indenter on each candidate node
        force[held] = -epsilon * stuck_offset
        force[touching] = -epsilon * gap[touching, None] * normal[touching]
        force = np.where(cand_dofs < 0, 0.0, force)  # supports take the held components
        gradient = -_scatter(body.size, cand_dofs, force)
        matrix = None
        if with_matrix:
            blocks = np.zeros((len(p), 3, 3))
            blocks[held] = epsilon * np.eye(3)
            blocks[touching] = epsilon * np.einsum("ni,nj->nij", normal[touching], normal[touching])
            in_contact = held | touching
            matrix = penalty_blocks(body, cand_dofs[in_contact], blocks[in_contact])
        return energy, gradient, matrix, force, gap, normal, held | touching

    def total_energy(q: np.ndarray, frame: np.ndarray) -> float:
        elastic = body.hyperelastic_energy(q)
        return elastic + contact_terms(q, frame, False)[0] if np.isfinite(elastic) else np.inf

    def update_anchors(q: np.ndarray, frame: np.ndarray) -> None:
        """After a converged step: release held nodes under tension, anchor new contacts where they touch."""
        _, _, _, force, gap, normal, in_contact = contact_terms(q, frame, False)
        p = x + _gather(q, cand_dofs)
        for i in list(anchors):
            if force[i] @ normal[i] <= 0:
                del anchors[i]
        for i in np.flatnonzero(in_contact & (gap < 0)):
            anchors.setdefault(int(i), p[i] - gap[i] * normal[i] - frame)

    path = load_path(load, normal_steps, tangential_steps)
    log = ConvergenceLog("solve_hyperelastic_contact", "Newton residual norm relative to the load step's first",
                         load, len(path), max_iterations, report_unconverged)
    newton = _RegularizedNewton(solver)
    previous = unknowns
    with progress.task("Newton load steps", total=len(path)) as task:
        for step, travel in enumerate(path):
            frame = touch + travel
            if step == 0:  # the small-strain solution: its approach-direction gaps suit a first deep bite
                first = LoadCase(load.indenter, -travel[2], position=load.position, friction=load.friction)
                # a predictor: the Newton iteration judges convergence
                predicted = solve_linear_contact(body, first, solver=solver, report_unconverged=True).unknowns
            else:  # secant predictor along the load path
                predicted = 2 * unknowns - previous
                previous = unknowns
            if np.isfinite(total_energy(predicted, frame)):
                unknowns = predicted
            reference = None
            converged = False
            for count in range(1, max_iterations + 1):
                elastic, gradient, tangent = body.hyperelastic(unknowns)
                c_energy, c_gradient, c_matrix, force, _, _, in_contact = contact_terms(unknowns, frame, True)
                residual = gradient + c_gradient
                norm = np.linalg.norm(residual)
                reference = reference or max(norm, 1e-30)
                if norm < tolerance * reference:
                    converged = True
                    break
                try:
                    step_vector = newton.step(tangent + c_matrix, residual)
                except NotPositiveDefinite:  # no shift makes the tangent definite: the step cannot go on
                    break
                energy0 = elastic + c_energy
                slope = residual @ step_vector
                alpha = 1.0
                while alpha > 1e-4:
                    if total_energy(unknowns + alpha * step_vector, frame) <= energy0 + 1e-4 * alpha * slope:
                        break
                    alpha *= 0.5
                unknowns = unknowns + alpha * step_vector
                if monitor is not None:
                    monitor({"step": step + 1, "iteration": log.iterations + count, "residual": norm, "alpha": alpha,
                             "contact_nodes": int(in_contact.sum()), "shift": newton.shift})
                if alpha * np.abs(step_vector).max() < tolerance * max(load.depth, 1e-6):
                    # near the solution the energy's round-off stalls the line search; far from it, a
                    # stalled line search is no convergence
                    converged = norm < math.sqrt(tolerance) * reference
                    break
            log.step(StepOutcome(converged, count, norm / reference))
            if load.friction == "stick":
                update_anchors(unknowns, frame)
            task.advance()
    t_total = time.perf_counter() - t0
    return ContactResult(
        unknowns=unknowns, magnet_poses=body.magnet_poses(unknowns), force=-force.sum(axis=0),
        contact_nodes=candidates[in_contact], displacements=body.nodal_displacements(unknowns),
        factorizations=solver.factorizations, timings={"contact_solve_s": t_total}, **log.record())
