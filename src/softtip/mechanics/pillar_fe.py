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

The elements are straight-sided, so the mesh's sections are polygons: a coarse mesh is too soft in bending
(2.4 % at 40 µm elements on a 250 µm cylinder, falling as h²), and the bonded rim of the base is a stress
singularity that the root converges slowly towards. :func:`mesh_convergence` solves one problem on several
meshes and :func:`richardson` estimates the limit and the finest mesh's error from them;
:func:`bonded_root_end_effect` measures what the bonded base does to a cylinder's root, the coefficients of
the rod's ``bonded_root``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse.linalg as spla
from scipy.optimize import brentq
from numpy.typing import ArrayLike, NDArray

from softtip._core.errors import NotConverged
from softtip.design.model import Material
from softtip.mechanics.fe import BodyModel
from softtip.mechanics.linsolve import NotPositiveDefinite, SPDSolver
from softtip.mechanics.mesh import TetMesh, gmsh_session, tet_mesh_from_gmsh
from softtip.mechanics.rod import Rod, RodError

MIN_QUALITY = 1e-3  # a tetrahedron flatter than this makes the stiffness singular to round-off

def mesh_frustum(rod: Rod, size: float, slices: int = 10, substrate: float | None = None) -> TetMesh:
    """Tetrahedra of the rod's cone frustum (elements of at most ``size`` m) cut into ``slices`` equal
    slices along its axis that the mesh conforms to (no element straddles two), boundaries "base" and
    "top". With ``substrate`` (m), the pillar stands on a cylinder of that radius and depth of its own
    material, meshed coarser away from the root, whose bottom is the "base"."""
    if not (np.isfinite(size) and 0 < size <= rod.length):
        raise RodError(f"size = {size!r}: expected an element size in m, 0 < size <= the length")
    if not (isinstance(slices, int) and slices >= 1):
        raise RodError(f"slices = {slices!r}: expected a positive integer")
    if substrate is not None and not (np.isfinite(substrate) and substrate > rod.base_diameter):
        raise RodError(f"substrate = {substrate!r}: expected a radius in m wider than the pillar's base")
    heights = np.linspace(0.0, rod.length, slices + 1)
    radii = rod.diameter(heights) / 2
    with gmsh_session("frustum") as gmsh:
        occ = gmsh.model.occ
        # OpenCASCADE refuses a cone of equal radii: a uniform rod's slices are cylinders
        pieces = [(3, occ.addCone(0, 0, heights[k], 0, 0, heights[k + 1] - heights[k], radii[k], radii[k + 1])
                   if radii[k] != radii[k + 1] else occ.addCylinder(0, 0, heights[k], 0, 0, heights[k + 1] - heights[k],
                                                                    radii[k]))
                  for k in range(slices)]
        bottom = 0.0
        if substrate is not None:
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
        points = self._slice_mean(cell_mean)
        points[..., 2] += frustum_slice_centroids(self.rod, self.slices)
        # F e_z = e_z + Σ_a u_a ∂N_a/∂Z, averaged with the quadrature weights
        weighted_dz = np.einsum("eqa,eq->ea", space.grads[..., 2], space.weights)  # (ne, 10)
        volume = space.weights.sum(axis=1)
        axis = np.einsum("ea,beaj->bej", weighted_dz, solution.displacements[:, space.cell_nodes]) / volume[:, None]
        axis[..., 2] += 1.0
        tangents = self._slice_mean(axis)
        return points, tangents / np.linalg.norm(tangents, axis=-1, keepdims=True)

    def _slice_mean(self, values: NDArray[np.float64]) -> NDArray[np.float64]:
        """(B, K, 3) the volume average over each slice of the per-element ``values`` (B, ne, 3)."""
        means = np.zeros((values.shape[0], self.slices, 3))
        for b in range(values.shape[0]):
            for j in range(3):
                means[b, :, j] = np.bincount(self._slice_of, weights=self._slice_weight * values[b, :, j],
                                             minlength=self.slices)
        return means


@dataclass(frozen=True)
class MeshConvergence:
    """Quantities of one problem solved on meshes of decreasing element size, and what Richardson
    extrapolation makes of the three finest: ``sizes`` (M,) each mesh's mean element size (m), (volume /
    elements)^⅓; ``values`` (M, ...) the quantities; ``order`` the observed order p of q = q* + C hᵖ;
    ``extrapolated`` q*; ``error`` |q* − q| of the finest mesh, its estimated discretisation error;
    ``asymptotic`` whether the three finest converge monotonically at an order from 0.5 to 6 (if not,
    q* is the finest value and ``error`` the largest change over the meshes: a bound, not an estimate)."""

    sizes: NDArray[np.float64]
    values: NDArray[np.float64]
    order: NDArray[np.float64]
    extrapolated: NDArray[np.float64]
    error: NDArray[np.float64]
    asymptotic: NDArray[np.bool_]


def richardson(sizes: ArrayLike, values: ArrayLike) -> MeshConvergence:
    """Richardson extrapolation of ``values`` (M, ...) computed on meshes of ``sizes`` (M,), M ≥ 3, from
    coarse to fine, elementwise over the trailing axes (L. F. Richardson, Phil. Trans. R. Soc. A 226, 1927;
    the observed order from three unevenly refined meshes as in P. J. Roache, *Verification and Validation in
    Computational Science and Engineering*, 1998, §5.4)."""
    sizes, values = np.asarray(sizes, dtype=np.float64), np.asarray(values, dtype=np.float64)
    if sizes.ndim != 1 or sizes.size < 3 or np.any(np.diff(sizes) >= 0) or sizes[-1] <= 0:
        raise RodError(f"sizes: expected three or more decreasing positive element sizes, got {sizes!r}")
    if values.shape[:1] != sizes.shape or not np.all(np.isfinite(values)):
        raise RodError(f"values: expected finite numbers of shape ({sizes.size}, ...), got shape {values.shape}")
    h1, h2, h3 = sizes[-3:] / sizes[-1]  # relative sizes: h3 = 1
    q1, q2, q3 = values[-3:]
    flat = [np.ravel(q) for q in (q1, q2, q3)]
    order = np.zeros(flat[0].size)
    asymptotic = np.zeros(flat[0].size, dtype=bool)
    for k, (a, b, c) in enumerate(zip(*flat)):
        ratio = (a - b) / (b - c) if b != c else np.inf
        if not (np.isfinite(ratio) and ratio > 0):
            continue
        mismatch = lambda p: (h1**p - h2**p) / (h2**p - h3**p) - ratio  # noqa: E731 (rises with p)
        if mismatch(0.5) < 0 < mismatch(6.0):
            order[k], asymptotic[k] = brentq(mismatch, 0.5, 6.0, xtol=1e-10), True
    order = order.reshape(np.shape(q3))
    asymptotic = asymptotic.reshape(np.shape(q3))
    with np.errstate(divide="ignore", invalid="ignore"):
        extrapolated = np.where(asymptotic, q3 - (q2 - q3) / (h2**order - 1.0), q3)
    spread = np.max(np.abs(values - q3), axis=0)
    error = np.where(asymptotic, np.abs(extrapolated - q3), spread)
    return MeshConvergence(sizes, values, order, extrapolated, error, asymptotic)


def mesh_convergence(rod: Rod, sizes: ArrayLike, force: ArrayLike, slices: int = 10,
                     **solve_options: float) -> MeshConvergence:
    """The pillar under the tip forces ``force`` (B,) N meshed at each element size of ``sizes`` (m,
    decreasing); the quantities (B, slices + 1) are the sideways (x) positions of the slices' centroids and,
    last, of the tip. ``solve_options`` go to :meth:`PillarFE.solve`; a solve that does not converge raises."""
    sizes = np.asarray(sizes, dtype=np.float64)
    if sizes.ndim != 1 or sizes.size < 3 or np.any(np.diff(sizes) >= 0):
        raise RodError(f"sizes: expected three or more decreasing element sizes in m, got {sizes!r}")
    values, effective = [], []
    for size in sizes:
        solid = PillarFE(rod, float(size), slices)
        solution = solid.solve(force, **solve_options)
        points, _ = solid.centreline(solution)
        values.append(np.concatenate([points[..., 0], solution.tip[:, None, 0]], axis=1))
        effective.append((solid._volume / solid.mesh.tets.shape[1]) ** (1 / 3))
    return richardson(np.array(effective), np.array(values))


@dataclass(frozen=True)
class RootEndEffect:
    """What a bonded base does to a uniform cylinder's section rotations, fitted to the solid (see
    :func:`bonded_root_end_effect`): the stiffening ``c`` and decay length ``decay`` (in radii) of
    :func:`~softtip.mechanics.rod.bonded_root_flexibility`, ``faceting`` the solid's excess curvature over
    the rod's (the polygonal sections of the mesh: it falls as h²), ``misfit`` the rms residual of the fit
    over the rotation offset it describes, and the mesh's ``unknowns``."""

    c: float
    decay: float
    faceting: float
    misfit: float
    unknowns: int


def bonded_root_end_effect(poisson_ratio: float, size: float, radius: float = 125e-6, slices: int = 25,
                           youngs_modulus: float = 1e6) -> RootEndEffect:
    """The end effect of a bonded base, from the solid: a uniform cylinder of ``radius`` and length 8 radii,
    bonded at its base, under a small tip force (linear), meshed at ``size`` and cut into ``slices``. Each
    slice's mean rotation minus the clamped Timoshenko rod's is fitted (least squares, the decay length by a
    bounded scalar search) by the rod's correction, −c F (L − λ − (L − z − λ) e^(−z/λ)) / (E r³)
    averaged over the slice, plus ``faceting`` times the rod's own rotation."""
    from scipy.optimize import minimize_scalar

    from softtip.mechanics.rod import solve_tip_force

    length = 8 * radius
    rod = Rod(length=length, base_diameter=2 * radius, tip_diameter=2 * radius, youngs_modulus=youngs_modulus,
              poisson_ratio=poisson_ratio, segments=200)
    force = 1e-6 * youngs_modulus * radius**2  # a tip turned by about 1e-5 rad: linear
    solid = PillarFE(rod, size, slices)
    _, tangents = solid.centreline(solid.solve([force], steps_per_force=1))
    _, rod_tangents = solve_tip_force(rod, [[force, 0.0]]).slice_means(slices)
    rod_turn = np.arcsin(rod_tangents[0, :, 0])
    offset = np.arcsin(tangents[0, :, 0]) - rod_turn
    heights = (np.arange(slices)[:, None] + np.linspace(0, 1, 401)[None, :]) * length / slices
    unit = force / (youngs_modulus * radius**3)

    def fit(decay: float) -> tuple[float, NDArray]:
        lam = decay * radius
        profile = length - lam - (length - heights - lam) * np.exp(-heights / lam)
        design = np.stack([-unit * np.trapezoid(profile, heights, axis=1) / (length / slices), rod_turn], axis=-1)
        coefficients = np.linalg.lstsq(design, offset, rcond=None)[0]
        return float(np.sum((design @ coefficients - offset) ** 2)), coefficients

    best = minimize_scalar(lambda decay: fit(decay)[0], bounds=(0.05, 2.0), method="bounded",
                           options={"xatol": 1e-4})
    squares, (c, faceting) = fit(best.x)
    misfit = float(np.sqrt(squares / slices) / max(abs(c) * unit * length, 1e-300))
    return RootEndEffect(float(c), float(best.x), float(faceting), misfit, solid.unknowns)
