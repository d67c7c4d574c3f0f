"""Quadratic-tetrahedron finite elements of the elastomer body.

Quadratic (P2) displacement elements avoid the volumetric locking that linear
tetrahedra show at Poisson's ratio 0.48. Stiffness integrands of P2 elasticity
are quadratic polynomials on an affine tetrahedron, so the 4-point rule
(``intorder=2``) integrates the linear model exactly; the same rule is used for
the neo-Hookean model so residual and tangent stay consistent.

Kernels are pure functions of arrays (gradients, weights, nodal displacements);
:class:`BodyModel` wraps them with the mesh, the material and the constraints:
the base face is bonded and each magnet's hole surface moves as a rigid body
(translation t and small rotation theta: u = t + theta x (x - c)).
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
import scipy.sparse as sp

from softtip.design.model import Design, Material
from softtip._core.cache import EntryPieces
from softtip._core.forked import shared_zeros, solve_in_processes
from softtip._core.progress import SILENT, Progress
from softtip.mechanics.mesh import TetMesh
from softtip.mechanics.poses import MagnetPoses

# --------------------------------------------------------------------------- kernels


def linear_elastic_matrices(grads: np.ndarray, weights: np.ndarray, lam: float, mu: float) -> np.ndarray:
    """Element stiffness matrices (ne, 3k, 3k) of isotropic linear elasticity.

    ``grads`` (ne, nq, k, 3) are shape-function gradients at the quadrature
    points and ``weights`` (ne, nq) the quadrature weights times |J|. Local dof
    3a + i is component i of node a.
    """
    ne, _, k, _ = grads.shape
    weighted = grads * weights[:, :, None, None]
    outer = np.einsum("eqai,eqbj->eaibj", weighted, grads, optimize=True)
    dots = np.einsum("eqak,eqbk->eab", weighted, grads, optimize=True)
    matrices = lam * outer + mu * outer.transpose(0, 3, 2, 1, 4)
    matrices += mu * np.einsum("eab,ij->eaibj", dots, np.eye(3))
    return matrices.reshape(ne, 3 * k, 3 * k)


def neo_hookean_element(grads: np.ndarray, weights: np.ndarray, lam: float, mu: float,
                        element_displacements: np.ndarray, with_tangent: bool = True, with_forces: bool = True):
    """Energy, internal forces and tangents of a compressible neo-Hookean solid.

    W = mu/2 (tr C - 3) - mu ln J + lam/2 (ln J)^2, which reduces to linear
    elasticity with the same Lamé parameters at small strain.
    ``element_displacements`` is (ne, k, 3). Returns (energy per element (ne,),
    forces (ne, 3k) or None, tangents (ne, 3k, 3k) or None). Elements inverted by a
    trial displacement get infinite energy so a line search backs off.
    """
    ne, nq, k, _ = grads.shape
    F = np.eye(3) + np.einsum("eai,eqaj->eqij", element_displacements, grads, optimize=True)
    J = np.linalg.det(F)
    bad = J <= 0
    J_safe = np.where(bad, 1.0, J)
    log_j = np.log(J_safe)
    F_inv_t = np.linalg.inv(np.where(bad[..., None, None], np.eye(3), F)).transpose(0, 1, 3, 2)
    density = 0.5 * mu * (np.einsum("eqij,eqij->eq", F, F) - 3) - mu * log_j + 0.5 * lam * log_j**2
    energy = np.einsum("eq,eq->e", density, weights)
    energy[bad.any(axis=1)] = np.inf
    if not with_forces:
        return energy, None, None
    P = mu * (F - F_inv_t) + (lam * log_j)[..., None, None] * F_inv_t
    weighted = grads * weights[:, :, None, None]
    forces = np.einsum("eqiJ,eqaJ->eai", P, weighted, optimize=True).reshape(ne, 3 * k)
    if not with_tangent:
        return energy, forces, None
    # dP_iJ/dF_kL = mu d_ik d_JL + (mu - lam ln J) Finv_Li Finv_Jk + lam Finv_Ji Finv_Lk (written with F^-T)
    coef = (mu - lam * log_j)[..., None, None, None, None]
    A = coef * np.einsum("eqiL,eqkJ->eqiJkL", F_inv_t, F_inv_t, optimize=True)
    A += lam * np.einsum("eqiJ,eqkL->eqiJkL", F_inv_t, F_inv_t, optimize=True)
    half = np.einsum("eqiJkL,eqaJ->eqaikL", A, weighted, optimize=True)
    tangents = np.einsum("eqaikL,eqbL->eaibk", half, grads, optimize=True)
    dots = np.einsum("eqaJ,eqbJ->eab", weighted, grads, optimize=True)
    tangents += mu * np.einsum("eab,ik->eaibk", dots, np.eye(3))
    return energy, forces, tangents.reshape(ne, 3 * k, 3 * k)


class SparseAssembler:
    """Scatter element matrices into CSR matrices.

    The first assembly goes through SciPy's duplicate summation; repeated
    assemblies (Newton iterations) use a scatter map computed on first need.
    """

    def __init__(self, cell_dofs: np.ndarray, size: int):
        self.cell_dofs, self.size = cell_dofs, size
        self._scatter: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def _rows_cols(self) -> tuple[np.ndarray, np.ndarray]:
        per = self.cell_dofs.shape[1]
        return np.repeat(self.cell_dofs, per, axis=1).ravel(), np.tile(self.cell_dofs, (1, per)).ravel()

    def assemble(self, element_matrices: np.ndarray) -> sp.csr_matrix:
        return sp.coo_matrix((element_matrices.ravel(), self._rows_cols()), shape=(self.size, self.size)).tocsr()

    def assemble_repeatedly(self, element_matrices: np.ndarray) -> sp.csr_matrix:
        if self._scatter is None:
            rows, cols = self._rows_cols()
            unique, slot = np.unique(rows.astype(np.int64) * self.size + cols, return_inverse=True)
            indptr = np.searchsorted(unique // self.size, np.arange(self.size + 1)).astype(np.int32)
            self._scatter = (slot, (unique % self.size).astype(np.int32), indptr)
        slot, indices, indptr = self._scatter
        data = np.bincount(slot, weights=element_matrices.ravel(), minlength=len(indices))
        return sp.csr_matrix((data, indices, indptr), shape=(self.size, self.size))


# --------------------------------------------------------------------------- the P2 space


class P2Space:
    """Quadratic Lagrange nodes (vertices and edge midpoints) of a tetrahedral mesh."""

    def __init__(self, mesh: TetMesh):
        import skfem

        # contiguous, as scikit-fem keeps them (it would copy them and log a warning)
        skmesh = skfem.MeshTet(np.ascontiguousarray(mesh.points.T), mesh.tets)
        basis = skfem.CellBasis(skmesh, skfem.ElementTetP2(), intorder=2)
        self.nodes = basis.doflocs.T.copy()  # (n, 3): vertices first, then edges
        self.cell_nodes = basis.element_dofs.T.copy()  # (ne, 10)
        grads = np.stack([basis.basis[a][0].grad for a in range(10)])  # (10, 3, ne, nq)
        self.grads = np.ascontiguousarray(grads.transpose(2, 3, 0, 1))  # (ne, nq, 10, 3)
        self.weights = np.asarray(basis.dx)  # (ne, nq)
        edges = np.sort(skmesh.edges, axis=0)
        self._edge_keys = edges[0].astype(np.int64) * mesh.points.shape[0] + edges[1]
        self._edge_order = np.argsort(self._edge_keys)
        self.mesh = mesh
        self.boundary_nodes = {name: np.unique(self.boundary_facets(name)) for name in mesh.boundaries}

    @property
    def node_count(self) -> int:
        return self.nodes.shape[0]

    def boundary_facets(self, name: str) -> np.ndarray:
        """(k, 6) nodes of the quadratic triangles of boundary ``name``: corners 0, 1, 2, then the
        midpoints of edges 01, 12, 20."""
        tris = self.mesh.boundaries[name]
        n_vertices = self.mesh.points.shape[0]
        pairs = np.sort(np.hstack([tris[[0, 1]], tris[[1, 2]], tris[[2, 0]]]), axis=0)
        keys = pairs[0].astype(np.int64) * n_vertices + pairs[1]
        edge_index = self._edge_order[np.searchsorted(self._edge_keys, keys, sorter=self._edge_order)]
        return np.column_stack([tris.T, (n_vertices + edge_index).reshape(3, -1).T])

    def cell_dofs(self) -> np.ndarray:
        """(ne, 30) global dofs, 3 * node + component."""
        return (3 * self.cell_nodes[:, :, None] + np.arange(3)).reshape(len(self.cell_nodes), 30)


# --------------------------------------------------------------------------- constrained body


class BodyModel:
    """The elastomer body: P2 space, material, supports and rigid magnets.

    ``supports`` maps boundary names to the displacement components held at
    zero there: the fingertip's base is bonded ({"base": (0, 1, 2)}); a
    symmetry plane x = 0 is {"...": (0,)}. Unknowns are the free nodal
    displacement components followed by 6 rigid-body coordinates (t, theta)
    per magnet; ``transform`` maps them to all nodal displacements.
    """

    def __init__(self, mesh: TetMesh, material: Material, magnet_centers: np.ndarray,
                 supports: dict[str, tuple[int, ...]] | None = None):
        self.space = P2Space(mesh)
        self.lam, self.mu = material.lame
        n = self.space.node_count
        held = np.zeros((n, 3), dtype=bool)
        for name, components in (supports or {"base": (0, 1, 2)}).items():
            held[np.ix_(self.space.boundary_nodes[name], list(components))] = True
        self.magnet_centers = np.asarray(magnet_centers, dtype=float).reshape(-1, 3)
        magnet_of = np.full(n, -1)
        for i in range(len(self.magnet_centers)):
            nodes = self.space.boundary_nodes[f"magnet{i}"]
            if held[nodes].any():
                raise ValueError(f"magnet {i} touches a supported boundary")
            magnet_of[nodes] = i
        self.magnet_nodes = [np.flatnonzero(magnet_of == i) for i in range(len(self.magnet_centers))]
        free = ~held & (magnet_of < 0)[:, None]
        self.free_dofs = np.flatnonzero(free.ravel())
        self.n_free = len(self.free_dofs)
        self.size = self.n_free + 6 * len(self.magnet_centers)
        # where each node's x, y, z live among the unknowns (-1: held or on a magnet)
        self.node_dofs = np.full(3 * n, -1)
        self.node_dofs[self.free_dofs] = np.arange(self.n_free)
        self.node_dofs = self.node_dofs.reshape(n, 3)
        self.transform = self._transform(n)
        self._assembler = SparseAssembler(self.space.cell_dofs(), 3 * n)

    @classmethod
    def for_design(cls, design: Design, mesh: TetMesh) -> "BodyModel":
        """The fingertip: base bonded to the rigid base, magnets rigid and tied in."""
        return cls(mesh, design.material, np.array([m.center for m in design.magnets]), {"base": (0, 1, 2)})

    def _transform(self, n: int) -> sp.csr_matrix:
        rows, cols, vals = [], [], []
        rows.append(self.free_dofs)
        cols.append(np.arange(self.n_free))
        vals.append(np.ones(self.n_free))
        for i, nodes in enumerate(self.magnet_nodes):
            base = self.n_free + 6 * i
            arm = self.space.nodes[nodes] - self.magnet_centers[i]
            for comp in range(3):
                # u_comp = t_comp + (theta x r)_comp
                rows.append(3 * nodes + comp)
                cols.append(np.full(len(nodes), base + comp))
                vals.append(np.ones(len(nodes)))
                for axis in range(3):
                    coef = np.cross(np.eye(3)[axis], arm)[:, comp]
                    keep = coef != 0
                    rows.append(3 * nodes[keep] + comp)
                    cols.append(np.full(keep.sum(), base + 3 + axis))
                    vals.append(coef[keep])
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                             shape=(3 * n, self.size))

    def reduce(self, full_matrix: sp.spmatrix) -> sp.csr_matrix:
        return (self.transform.T @ full_matrix @ self.transform).tocsr()

    @cached_property
    def full_stiffness(self) -> sp.csr_matrix:
        """Small-strain stiffness matrix over all nodal displacements (N/m), before constraints."""
        element = linear_elastic_matrices(self.space.grads, self.space.weights, self.lam, self.mu)
        return self._assembler.assemble(element)

    @cached_property
    def stiffness(self) -> sp.csr_matrix:
        """Reduced small-strain stiffness matrix (N/m) over the unknowns."""
        return self.reduce(self.full_stiffness)

    def nodal_forces(self, displacements: np.ndarray) -> np.ndarray:
        """Small-strain internal forces (n_nodes, 3) of nodal ``displacements``: at supported
        nodes, minus the reactions the supports provide."""
        return (self.full_stiffness @ displacements.ravel()).reshape(-1, 3)

    def nodal_displacements(self, unknowns: np.ndarray) -> np.ndarray:
        return (self.transform @ unknowns).reshape(-1, 3)

    def magnet_poses(self, unknowns: np.ndarray) -> MagnetPoses:
        return MagnetPoses.from_rigid(unknowns[self.n_free:].reshape(-1, 6).copy())

    def unit_load_responses(self, solver, columns: np.ndarray, block: int = 240, progress: Progress = SILENT,
                            pieces: EntryPieces | None = None,
                            processes: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Responses to a unit force on each of the unknowns ``columns``, by back-substitution in
        blocks with ``solver`` (an :class:`~softtip.mechanics.linsolve.SPDSolver` holding the
        factorised stiffness): at the same unknowns (len, len) - a compliance - and at the magnets'
        rigid coordinates (6M, len). ``pieces``: where each finished block is kept, and read back
        instead of solved again (a run stopped part way resumes). The blocks are independent: ``processes``
        (default one per core) forked after the factorisation share its factor and solve them side by side."""
        rigid = np.arange(self.n_free, self.size)
        blocks = [slice(start, min(start + block, len(columns))) for start in range(0, len(columns), block)]
        at_columns = shared_zeros((len(columns), len(columns)))
        at_magnets = shared_zeros((len(rigid), len(columns)))

        def keep(index: int, arrays: dict[str, np.ndarray]) -> None:
            at_columns[:, blocks[index]] = arrays["at_columns"]
            at_magnets[:, blocks[index]] = arrays["at_magnets"]

        def solve(index: int) -> None:  # in this process or a forked one: the arrays are shared
            chunk = columns[blocks[index]]
            unit = np.zeros((self.size, len(chunk)))
            unit[chunk, np.arange(len(chunk))] = 1.0
            solved = solver.solve(unit)
            arrays = {"at_columns": solved[columns], "at_magnets": solved[rigid]}
            if pieces is not None:
                pieces.write(index, arrays)
            keep(index, arrays)

        with progress.task("unit load responses", total=len(columns)) as task:
            to_solve = []
            for index, columns_of_block in enumerate(blocks):
                kept = pieces.read(index) if pieces is not None else None
                if kept is None:
                    to_solve.append(index)
                else:
                    keep(index, kept)
                    task.advance(columns_of_block.stop - columns_of_block.start)
            solve_in_processes(solve, to_solve, lambda index: task.advance(blocks[index].stop - blocks[index].start),
                               processes)
        return 0.5 * (at_columns + at_columns.T), np.array(at_magnets)  # symmetric up to round-off

    def hyperelastic_energy(self, unknowns: np.ndarray) -> float:
        """Neo-Hookean strain energy at ``unknowns`` (inf if an element inverts)."""
        u = self.nodal_displacements(unknowns)
        energy = neo_hookean_element(self.space.grads, self.space.weights, self.lam, self.mu,
                                     u[self.space.cell_nodes], with_tangent=False, with_forces=False)[0]
        return float(energy.sum())

    def hyperelastic(self, unknowns: np.ndarray, with_tangent: bool = True):
        """Neo-Hookean energy, reduced gradient and (optionally) reduced tangent at ``unknowns``."""
        u = self.nodal_displacements(unknowns)
        energy, forces, tangents = neo_hookean_element(self.space.grads, self.space.weights, self.lam, self.mu,
                                                       u[self.space.cell_nodes], with_tangent)
        total = float(energy.sum())
        gradient = np.bincount(self.space.cell_dofs().ravel(), weights=forces.ravel(),
                               minlength=self.transform.shape[0])
        gradient = self.transform.T @ gradient
        tangent = self.reduce(self._assembler.assemble_repeatedly(tangents)) if with_tangent else None
        return total, gradient, tangent
