"""A 3-D neo-Hookean finite-element reference of a conical pillar under a tip load: what the rod model
(:mod:`softtip.mechanics.rod`) is held against where it matters most, near the root.

The pillar (a cone frustum standing on z = 0 along +z, the shape and material of a
:class:`~softtip.mechanics.rod.Rod`) is meshed with gmsh into tetrahedra and solved with softtip's P2
elements and compressible neo-Hookean energy (:class:`~softtip.mechanics.fe.BodyModel`): its base bonded
(clamped), or standing on a substrate of its own material bonded beneath (the root free to tilt), a dead force along +x spread uniformly over its top face (the consistent nodal loads of a P2
triangle under uniform traction: a third of its area on each mid-side node, none on the corners). Newton's
method on the total energy with a backtracking line search follows the forces in order, each from the
last, in load steps; a step that does not converge raises :class:`~softtip._core.errors.NotConverged`.

Its centre line is read slice by slice: the pillar is meshed as ``slices`` equal slices along its axis (the
pieces a dipole chain gives one dipole each), and each slice's current centroid and mean material axis
(F e_z) are exact volume averages of the P2 solution.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike, NDArray

from softtip._core.errors import NotConverged
from softtip.design.model import Material
from softtip.mechanics.fe import BodyModel
from softtip.mechanics.linsolve import NotPositiveDefinite, SPDSolver
from softtip.mechanics.mesh import TetMesh, tet_mesh_from_gmsh
from softtip.mechanics.rod import Rod, RodError

MIN_QUALITY = 1e-3  # a tetrahedron flatter than this makes the stiffness singular to round-off

def mesh_frustum(rod: Rod, size: float, slices: int = 10, substrate: float | None = None) -> TetMesh:
    """Tetrahedra of the rod's cone frustum (elements of at most ``size`` m) cut into ``slices`` equal
    slices along its axis that the mesh conforms to (no element straddles two), boundaries "base" and
    "top". With ``substrate`` (m), the pillar stands on a cylinder of that radius and depth of its own
    material, meshed coarser away from the root, whose bottom is the "base"."""
    import gmsh

    if not (np.isfinite(size) and 0 < size <= rod.length):
        raise RodError(f"size = {size!r}: expected an element size in m, 0 < size <= the length")
    if not (isinstance(slices, int) and slices >= 1):
        raise RodError(f"slices = {slices!r}: expected a positive integer")
    heights = np.linspace(0.0, rod.length, slices + 1)
    radii = rod.diameter(heights) / 2
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("frustum")
        occ = gmsh.model.occ
        # OpenCASCADE refuses a cone of equal radii: a uniform rod's slices are cylinders
        pieces = [(3, occ.addCone(0, 0, heights[k], 0, 0, heights[k + 1] - heights[k], radii[k], radii[k + 1])
                   if radii[k] != radii[k + 1] else occ.addCylinder(0, 0, heights[k], 0, 0, heights[k + 1] - heights[k],
                                                                    radii[k]))
                  for k in range(slices)]
        bottom = 0.0
        if substrate is not None:
            if not (np.isfinite(substrate) and substrate > rod.base_diameter):
                raise RodError(f"substrate = {substrate!r}: expected a radius in m wider than the pillar's base")
            bottom = -substrate
            pieces.append((3, occ.addCylinder(0, 0, bottom, 0, 0, substrate, substrate)))
        if len(pieces) > 1:
            occ.fragment(pieces[:1], pieces[1:])
        occ.synchronize()
        groups: dict[str, list[int]] = {"base": [], "top": []}
        for _, tag in gmsh.model.getEntities(2):
            z = occ.getCenterOfMass(2, tag)[2]  # only the end discs sit at the ends (the walls lie between)
            if abs(z - bottom) < 1e-6 * rod.length:
                groups["base"].append(tag)
            elif abs(z - rod.length) < 1e-6 * rod.length:
                groups["top"].append(tag)
        if substrate is not None:  # fine in and around the pillar, four times coarser far in the substrate
            near = gmsh.model.mesh.field.add("Box")
            reach = 1.5 * rod.base_diameter
            for key, value in (("VIn", size), ("VOut", 4 * size), ("XMin", -reach), ("XMax", reach),
                               ("YMin", -reach), ("YMax", reach), ("ZMin", -reach), ("ZMax", rod.length),
                               ("Thickness", reach)):
                gmsh.model.mesh.field.setNumber(near, key, value)
            gmsh.model.mesh.field.setAsBackgroundMesh(near)
            gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
            gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
            gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.option.setNumber("Mesh.MeshSizeMax", size if substrate is None else 4 * size)
        gmsh.option.setNumber("Mesh.MeshSizeMin", size / 4)
        # MeshAdapt on the surfaces: the default Frontal-Delaunay puts three collinear nodes on a cone's
        # straight seam at some sizes (28 µm here), and the tetrahedron over them has no volume
        gmsh.option.setNumber("Mesh.Algorithm", 1)
        gmsh.model.mesh.generate(3)
        mesh = tet_mesh_from_gmsh(groups, key=f"frustum-{rod.length}-{rod.base_diameter}-{rod.tip_diameter}-{size}-"
                                              f"{slices}-{substrate}")
    finally:
        gmsh.finalize()
    worst = float(tetrahedron_quality(mesh.points, mesh.tets).min())
    if worst < MIN_QUALITY:
        raise NotConverged(f"pillar mesh of {size:.3g} m elements: a degenerate tetrahedron (quality {worst:.2e}, "
                           f"below {MIN_QUALITY}); try another element size")
    return mesh


def tetrahedron_quality(points: NDArray, tets: NDArray) -> NDArray[np.float64]:
    """(nt,) volume of each tetrahedron over that of the regular one on its longest edge: 1 regular,
    0 flat; ``tets`` (4, nt) vertex indices."""
    corners = points[tets.T]
    volume = np.abs(np.einsum("ij,ij->i", np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]),
                              corners[:, 3] - corners[:, 0])) / 6.0
    longest = np.max([np.linalg.norm(corners[:, a] - corners[:, b], axis=1)
                      for a in range(4) for b in range(a + 1, 4)], axis=0)
    return volume / (longest**3 / (6.0 * np.sqrt(2.0)))


def frustum_slice_centroids(rod: Rod, slices: int) -> NDArray[np.float64]:
    """(K,) heights (m) of the centroids of the rod's cone frustum cut into ``slices`` equal slices: a
    frustum of height h and end radii R (below), r (above) has its centroid h (R² + 2Rr + 3r²) /
    (4 (R² + Rr + r²)) above its lower face."""
    heights = np.linspace(0.0, rod.length, slices + 1)
    lower, upper = rod.diameter(heights[:-1]) / 2, rod.diameter(heights[1:]) / 2
    step = rod.length / slices
    return heights[:-1] + step * (lower**2 + 2 * lower * upper + 3 * upper**2) / (
        4 * (lower**2 + lower * upper + upper**2))


@dataclass(frozen=True)
class PillarSolution:
    """The pillar under tip forces ``force`` (B,) N along +x: ``tip`` (B, 3) the top face's mean position,
    ``displacements`` (B, nodes, 3), Newton's ``iterations`` and the largest final relative residual."""

    force: NDArray[np.float64]
    tip: NDArray[np.float64]
    displacements: NDArray[np.float64]
    iterations: int
    residual: float


class PillarFE:
    """The meshed pillar: ``rod`` gives shape and material (its shear and base options do not apply: the
    solid has its own shear, and its base is bonded, or it stands on a ``substrate`` of its own material
    whose bottom is bonded — the solid counterpart of the rod's compliant base)."""

    def __init__(self, rod: Rod, size: float, slices: int = 10, substrate: float | None = None):
        self.rod, self.slices = rod, slices
        self.mesh = mesh_frustum(rod, size, slices, substrate)
        material = Material(youngs_modulus=rod.youngs_modulus, poisson_ratio=rod.poisson_ratio, density=1.0)
        self.body = BodyModel(self.mesh, material, np.zeros((0, 3)), {"base": (0, 1, 2)})
        space = self.body.space
        facets = space.boundary_facets("top")  # (k, 6): corners, then mid-side nodes
        corners = space.nodes[facets[:, :3]]
        areas = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
        share = np.zeros(space.node_count)
        np.add.at(share, facets[:, 3:], np.repeat(areas[:, None] / 3, 3, axis=1))
        self._top_share = share / share.sum()  # of the total force, per node
        self._volume = float(space.weights.sum())
        # each element's slice (elements do not straddle slices) and its share of its slice's volume
        centres = space.nodes[space.cell_nodes[:, :4]].mean(axis=1)
        in_pillar = centres[:, 2] > 0  # the substrate's elements belong to no slice
        self._slice_of = np.where(in_pillar, np.minimum((centres[:, 2] / rod.length * slices).astype(int), slices - 1), 0)
        volume = np.where(in_pillar, space.weights.sum(axis=1), 0.0)
        self._slice_weight = volume / np.bincount(self._slice_of, weights=volume, minlength=slices)[self._slice_of]

    @property
    def unknowns(self) -> int:
        return self.body.size

    def _load(self, force: float) -> NDArray[np.float64]:
        nodal = np.zeros((self.body.space.node_count, 3))
        nodal[:, 0] = force * self._top_share
        return self.body.transform.T @ nodal.ravel()

    def solve(self, force: ArrayLike, steps_per_force: int = 4, tolerance: float = 1e-8,
              max_iterations: int = 30) -> PillarSolution:
        """The pillar under each tip force in ``force`` (B,) N, ascending, each reached from the last in
        ``steps_per_force`` load steps."""
        force = np.asarray(force, dtype=np.float64)
        if force.ndim != 1 or force.size == 0 or not np.all(np.isfinite(force)) or np.any(np.diff(force) < 0) \
                or force[0] < 0:
            raise RodError("force: expected a non-empty 1-D array of ascending finite forces >= 0 N")
        unknowns = np.zeros(self.body.size)
        solver = SPDSolver()
        total_iterations, worst = 0, 0.0
        states, previous = [], 0.0
        for target in force:
            for level in np.linspace(previous, target, steps_per_force + 1)[1:]:
                unknowns, used, residual = self._newton(unknowns, self._load(level), solver, tolerance, max_iterations)
                total_iterations += used
                worst = max(worst, residual)
            previous = target
            states.append(self.body.nodal_displacements(unknowns))
        displacements = np.stack(states)
        # the top face's area-mean displacement (the P2 shares integrate it exactly) from its exact centre:
        # the faceted mesh's own centroid sits off the axis by a fraction of a micrometre
        tips = np.array([0.0, 0.0, self.rod.length]) + np.einsum("n,bnj->bj", self._top_share, displacements)
        return PillarSolution(force, tips, displacements, total_iterations, worst)

    def _newton(self, unknowns: NDArray, load: NDArray, solver: SPDSolver, tolerance: float,
                max_iterations: int) -> tuple[NDArray, int, float]:
        scale = max(np.linalg.norm(load), self.rod.youngs_modulus * self.rod.tip_diameter**2 * 1e-6)
        for iteration in range(1, max_iterations + 1):
            energy, gradient, tangent = self.body.hyperelastic(unknowns)
            residual = gradient - load
            size = float(np.linalg.norm(residual) / scale)
            if size <= tolerance:
                return unknowns, iteration, size
            try:
                solver.factorize(tangent)
                step = -solver.solve(residual)
            except NotPositiveDefinite:  # a stiffness made indefinite by a too long step: solve it as it is
                step = -spla.spsolve(tangent.tocsc(), residual)
            total = energy - load @ unknowns
            slope = residual @ step
            if slope >= 0:  # not a descent direction (an indefinite tangent): go down the gradient instead
                step = -residual * (np.linalg.norm(step) / max(np.linalg.norm(residual), 1e-300))
                slope = residual @ step
            length = 1.0
            # near the solution the energy's change is below its round-off: the full step is taken, and
            # the residual, not the energy, decides convergence (Newton's cap still raises). Each
            # quadrature point's energy is a difference of order-one invariants (I₁ − 3, ln J), so the
            # round-off is relative to μ × volume, not to the (small) total
            round_off = max(1e-12 * abs(total), 16 * np.finfo(float).eps * self.body.mu * self._volume)

            def energy_at(length: float) -> float:
                trial = unknowns + length * step
                return self.body.hyperelastic_energy(trial) - load @ trial

            while (trial := energy_at(length)) > total + 1e-4 * length * slope \
                    and not (length == 1.0 and abs(trial - total) <= round_off):
                length /= 2  # backtracking (Armijo); inverted elements give inf
                if length < 1e-8:
                    raise NotConverged("pillar FE: the line search found no lower energy "
                                       f"(relative residual {size:.2e})")
            unknowns = unknowns + length * step
        raise NotConverged(f"pillar FE: Newton did not converge in {max_iterations} iterations "
                           f"(relative residual {size:.2e})")

    def centreline(self, solution: PillarSolution) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Per slice (K = ``slices``, base first): its current centroid (B, K, 3) and the unit direction of
        its mean material axis F e_z (B, K, 3). Both are exact volume averages over the slice of the P2
        field: a quadratic tetrahedron's mean displacement weighs its vertices −1/20 and its mid-edge
        nodes 1/5. The centroid is the exact frustum slice's plus that mean displacement: the faceted
        mesh's own slices have their centroids up to 0.3 µm off the axis (at 60 µm elements), as much as
        the lowest slice moves under a small load."""
        space = self.body.space
        per_node = np.array([-0.05] * 4 + [0.2] * 6)
        cell_mean = np.einsum("a,bcaj->bcj", per_node, solution.displacements[:, space.cell_nodes])  # (B, ne, 3)
        points = np.zeros((len(solution.force), self.slices, 3))
        for b in range(len(solution.force)):
            for j in range(3):
                points[b, :, j] = np.bincount(self._slice_of, weights=self._slice_weight * cell_mean[b, :, j],
                                              minlength=self.slices)
        points[..., 2] += frustum_slice_centroids(self.rod, self.slices)
        # F e_z = e_z + Σ_a u_a ∂N_a/∂Z, averaged with the quadrature weights
        weighted_dz = np.einsum("eqa,eq->ea", space.grads[..., 2], space.weights)  # (ne, 10)
        volume = space.weights.sum(axis=1)
        axis = np.einsum("ea,beaj->bej", weighted_dz, solution.displacements[:, space.cell_nodes]) / volume[:, None]
        axis[..., 2] += 1.0
        tangents = np.zeros_like(points)
        for b in range(len(solution.force)):
            for j in range(3):
                tangents[b, :, j] = np.bincount(self._slice_of, weights=self._slice_weight * axis[b, :, j],
                                                minlength=self.slices)
        return points, tangents / np.linalg.norm(tangents, axis=-1, keepdims=True)
