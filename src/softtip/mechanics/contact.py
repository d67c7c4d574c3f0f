"""Unilateral contact of the elastomer body with a rigid indenter.

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
indenter tangentially from where they touched). The indenter is lowered until
it touches the undeformed body, then pushed ``depth`` down, then moved
``tangential`` (x, y) sideways, in load steps.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from softtip.mechanics.fe import BodyModel
from softtip.mechanics.indenters import Indenter
from softtip.mechanics.linsolve import NotPositiveDefinite, SPDSolver
from softtip.mechanics.poses import MagnetPoses

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


def require_nodal_friction(load: LoadCase) -> None:
    """Refuse friction the solvers that hold nodes do not model."""
    if load.friction not in FRICTION_MODES:
        raise ValueError(f"friction = {load.friction!r}: contact on nodes models {' or '.join(FRICTION_MODES)}; "
                         "Coulomb friction needs contact on footprint cells (softtip.mechanics.footprint)")


@dataclass
class ContactResult:
    unknowns: np.ndarray
    magnet_poses: MagnetPoses  # (M, 3)
    force: np.ndarray  # (3,) N, force of the body on the indenter (its reaction); Fz > 0 when pushing down
    contact_nodes: np.ndarray  # indices of nodes in contact at the end
    displacements: np.ndarray  # (n_nodes, 3) m
    iterations: int
    factorizations: int
    timings: dict = field(default_factory=dict)


@dataclass
class ContactSolution:
    """A contact solve on a reduced view of the body (its surface compliance)."""

    magnet_rigid: np.ndarray  # (M, 6): translation (m) and rotation vector (rad) of each magnet
    force: np.ndarray  # (3,) N, the fingertip's reaction on the indenter
    contact_nodes: np.ndarray  # nodes in contact, as the solver numbers them
    path: list[tuple[np.ndarray, np.ndarray, np.ndarray]]  # (travel (3,), magnet_rigid, force) after every step


def touch_offset(indenter: Indenter, position: tuple[float, float], points: np.ndarray) -> np.ndarray:
    """Where the indenter's frame sits when it first touches the undeformed body."""
    offset = np.array([position[0], position[1], 0.0])
    gap = indenter.vertical_gap(points - offset)[0].min()
    if not np.isfinite(gap):
        raise ValueError(f"the indenter at position {position} m does not reach the fingertip")
    offset[2] = -gap
    return offset


def load_path(load: LoadCase, normal_steps: int, tangential_steps: int) -> list[np.ndarray]:
    path = [np.array([0.0, 0.0, -load.depth * k / normal_steps]) for k in range(1, normal_steps + 1)]
    if any(load.tangential):
        path += [np.array([load.tangential[0] * k / tangential_steps, load.tangential[1] * k / tangential_steps,
                           -load.depth]) for k in range(1, tangential_steps + 1)]
    return path


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


class ActiveSetIteration:
    """The primal-dual active-set update shared by the contact solvers.

    A node in contact stays in while it is compressed; a free node enters when
    it penetrates. Corner nodes of quadratic faces carry ~zero consistent
    pressure, so only clear tension (below -1e-3 of the peak nodal pressure)
    releases a node; once an active set repeats (a cycle), nodes are only added.
    """

    def __init__(self, active: np.ndarray):
        self.active = active
        self._seen: set[bytes] = set()
        self._only_add = False

    def update(self, pressure: np.ndarray, linear_gap: np.ndarray, tolerance: float) -> bool:
        """Update ``active`` from nodal pressures and gaps; True when it did not change."""
        release = -1e-3 * max(pressure.max(initial=0.0), 0.0)
        new = np.where(self.active, pressure > release, linear_gap < -tolerance)
        if self._only_add:
            new |= self.active
        if np.array_equal(new, self.active):
            return True
        if new.tobytes() in self._seen:
            self._only_add = True
            new |= self.active
        self._seen.add(self.active.tobytes())
        self.active = new
        return False


def exact_contact_step(compliance: np.ndarray, gap: np.ndarray, target: np.ndarray, stick: bool,
                       active: np.ndarray, tolerance: float, max_iterations: int) -> tuple[np.ndarray, np.ndarray]:
    """One load step of contact enforced exactly (Lagrange multipliers) on the dense ``compliance``
    of the points it holds (surface nodes or footprint cells): with ``stick`` three components per
    point (x, y, z), the tangential ones held at ``target`` (n, 2); else only the normal one
    (``compliance`` of those alone). The gap closes: u_z = ``gap``. Returns the multipliers (the
    indenter's force on each point, per component) and the contact set, by primal-dual active sets."""
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
    return multipliers, active


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


def solve_linear_contact(body: BodyModel, load: LoadCase, penalty: float = 1e4, normal_steps: int | None = None,
                         tangential_steps: int = 4, max_iterations: int = 30,
                         solver: SPDSolver | None = None) -> ContactResult:
    """Small-strain contact; gaps are linearised about the undeformed body."""
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
    if normal_steps is None:  # sticking nodes that touch late hold where they touched
        normal_steps = 2 if stick and any(load.tangential) else 1
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
    iterations = 0
    for travel in load_path(load, normal_steps, tangential_steps):
        frame = touch + travel
        gap = load.indenter.vertical_gap(x - frame)[0]
        active |= gap + np.einsum("ij,ij->i", normal, u_candidates) < 0
        if stick:  # nodes held by the indenter travel with it, even past the edge of its footprint
            gap = np.where(active, load.indenter.vertical_gap(x - frame, extend=True)[0], gap)
        else:  # without friction, nodes the indenter has moved off are free
            active &= np.isfinite(gap)
        iteration = ActiveSetIteration(active)
        for _ in range(max_iterations):
            iterations += 1
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
            if iteration.update(pressure, linear_gap, 1e-6 * max(load.depth, 1e-6)):
                break
            active = iteration.active
        u_candidates = u_now
        if stick:
            anchors.keep_only(candidates[active])
            anchors.targets(candidates[active], x[active] + u_now[active], frame)
        previous_frame = frame
    t_total = time.perf_counter() - t0
    return ContactResult(
        unknowns=unknowns, magnet_poses=body.magnet_poses(unknowns), force=-nodal_force.sum(axis=0),
        contact_nodes=candidates[active], displacements=body.nodal_displacements(unknowns), iterations=iterations,
        factorizations=solver.factorizations - factorizations0,
        timings={"assembly_s": t_assembly, "contact_solve_s": t_total - t_assembly})


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


def solve_hyperelastic_contact(body: BodyModel, load: LoadCase, load_steps: int = 6, tangential_steps: int = 4,
                               penalty: float = 1e3, tolerance: float = 1e-7, max_newton: int = 40,
                               progress=None, monitor=None) -> ContactResult:
    """Neo-Hookean body under large deformation; contact gaps at the deformed positions."""
    require_nodal_friction(load)
    t0 = time.perf_counter()
    solver = SPDSolver()
    candidates, cand_dofs = contact_candidates(body)
    x = body.space.nodes[candidates]
    epsilon = penalty * body.stiffness.diagonal()[: body.n_free].mean()
    touch = touch_offset(load.indenter, load.position, x)
    anchors: dict[int, np.ndarray] = {}  # sticking nodes (candidate index) -> anchor in the indenter's frame
    unknowns = np.zeros(body.size)
    iterations = 0

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

    path = load_path(load, load_steps, tangential_steps)
    newton = _RegularizedNewton(solver)
    previous = unknowns
    for step, travel in enumerate(path):
        frame = touch + travel
        if step == 0:  # the small-strain solution: its approach-direction gaps suit a first deep bite
            first = LoadCase(load.indenter, -travel[2], position=load.position, friction=load.friction)
            predicted = solve_linear_contact(body, first, solver=solver).unknowns
        else:  # secant predictor along the load path
            predicted = 2 * unknowns - previous
            previous = unknowns
        if np.isfinite(total_energy(predicted, frame)):
            unknowns = predicted
        reference = None
        for _ in range(max_newton):
            iterations += 1
            elastic, gradient, tangent = body.hyperelastic(unknowns)
            c_energy, c_gradient, c_matrix, force, _, _, in_contact = contact_terms(unknowns, frame, True)
            residual = gradient + c_gradient
            norm = np.linalg.norm(residual)
            reference = reference or max(norm, 1e-30)
            if norm < tolerance * reference:
                break
            step_vector = newton.step(tangent + c_matrix, residual)
            energy0 = elastic + c_energy
            slope = residual @ step_vector
            alpha = 1.0
            while alpha > 1e-4:
                if total_energy(unknowns + alpha * step_vector, frame) <= energy0 + 1e-4 * alpha * slope:
                    break
                alpha *= 0.5
            unknowns = unknowns + alpha * step_vector
            if monitor is not None:
                monitor({"step": step + 1, "iteration": iterations, "residual": norm, "alpha": alpha,
                         "contact_nodes": int(in_contact.sum()), "shift": newton.shift})
            if alpha * np.abs(step_vector).max() < tolerance * max(load.depth, 1e-6):
                break
        if load.friction == "stick":
            update_anchors(unknowns, frame)
        if progress is not None:
            progress(step + 1, len(path))
    t_total = time.perf_counter() - t0
    return ContactResult(
        unknowns=unknowns, magnet_poses=body.magnet_poses(unknowns), force=-force.sum(axis=0),
        contact_nodes=candidates[in_contact], displacements=body.nodal_displacements(unknowns), iterations=iterations,
        factorizations=solver.factorizations, timings={"contact_solve_s": t_total})
