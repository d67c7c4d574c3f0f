"""Finite elements and contact against analytic elasticity.

References: the exact homogeneous solution of uniaxial compression (linear and
neo-Hookean), Hertz's sphere-on-half-space solution with the finite-thickness
correction of a bonded incompressible layer (Dimitriadis et al., Biophys. J.
82, 2002), static equilibrium, and a mesh-convergence study.
"""

from __future__ import annotations

import math

import gmsh
import numpy as np
import pytest
from scipy.optimize import brentq

from softtip._core.units import MM
from softtip.design.model import Material, load_design
from softtip.mechanics.contact import LoadCase, solve_hyperelastic_contact, solve_linear_contact
from softtip.mechanics.fe import BodyModel
from softtip.mechanics.indenters import Board, Plate, Sphere
from softtip.mechanics.mesh import mesh_design, tet_mesh_from_gmsh

RUBBER = Material(youngs_modulus=0.59e6, poisson_ratio=0.48, density=1120.0)
SYMMETRIC_SUPPORTS = {"sym_x": (0,), "sym_y": (1,), "base": (2,)}


def _classified_mesh(build, size_setup, key: str):
    """Mesh a gmsh OCC model made by ``build`` with boundaries named by plane:
    x = 0 -> sym_x, y = 0 -> sym_y, z = 0 -> base, anything else -> outer."""
    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        build(gmsh.model.occ)
        gmsh.model.occ.synchronize()
        groups = {"sym_x": [], "sym_y": [], "base": [], "outer": []}
        for _, tag in gmsh.model.getEntities(2):
            x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, tag)
            name = ("sym_x" if x1 < 1e-6 else "sym_y" if y1 < 1e-6 else "base" if z1 < 1e-6 else "outer")
            groups[name].append(tag)
        size_setup()
        gmsh.model.mesh.generate(3)
        return tet_mesh_from_gmsh(groups, key)
    finally:
        gmsh.finalize()


def quarter_block(side: float, height: float, size: float):
    def sizes():
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)

    return _classified_mesh(lambda occ: occ.addBox(0, 0, 0, side, side, height), sizes, "block")


def quarter_layer(radius: float, height: float, fine: float, fine_radius: float, coarse: float):
    """A quarter of a thick cylindrical layer, refined around the top of its axis."""

    def build(occ):
        occ.addCylinder(0, 0, 0, 0, 0, height, radius, angle=math.pi / 2)

    def sizes():
        point = gmsh.model.occ.addPoint(0, 0, height)
        gmsh.model.occ.synchronize()
        distance = gmsh.model.mesh.field.add("Distance")
        gmsh.model.mesh.field.setNumbers(distance, "PointsList", [point])
        threshold = gmsh.model.mesh.field.add("Threshold")
        gmsh.model.mesh.field.setNumber(threshold, "InField", distance)
        gmsh.model.mesh.field.setNumber(threshold, "SizeMin", fine)
        gmsh.model.mesh.field.setNumber(threshold, "SizeMax", coarse)
        gmsh.model.mesh.field.setNumber(threshold, "DistMin", fine_radius)
        gmsh.model.mesh.field.setNumber(threshold, "DistMax", radius)
        gmsh.model.mesh.field.setAsBackgroundMesh(threshold)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)

    return _classified_mesh(build, sizes, "layer")


@pytest.fixture(scope="module")
def block_body():
    mesh = quarter_block(5 * MM, 5 * MM, 2.5 * MM)
    return BodyModel(mesh, RUBBER, np.zeros((0, 3)), SYMMETRIC_SUPPORTS)


def test_uniaxial_compression_by_a_frictionless_plate_is_exact(block_body):
    side, height, depth = 5 * MM, 5 * MM, 0.1 * MM
    result = solve_linear_contact(block_body, LoadCase(Plate(), depth, friction="none"))
    # exact: uniform stress E * strain over the (quarter) top face, lateral expansion nu * strain
    expected_force = RUBBER.youngs_modulus * depth / height * side**2
    assert result.force[2] == pytest.approx(expected_force, rel=1e-5)
    corner = np.argmin(np.linalg.norm(block_body.space.nodes - [side, side, height], axis=1))
    u = result.displacements[corner]
    assert u[2] == pytest.approx(-depth, rel=1e-5)
    assert u[0] == pytest.approx(RUBBER.poisson_ratio * depth / height * side, rel=1e-5)
    # the contact area is the whole top face: every top node is in contact
    top = np.flatnonzero(np.isclose(block_body.space.nodes[:, 2], height))
    assert set(top) <= set(result.contact_nodes)


def test_uniaxial_compression_neo_hookean_matches_the_exact_large_strain_solution(block_body):
    side, height, depth = 5 * MM, 5 * MM, 1.0 * MM  # 20 % compression
    lam, mu = RUBBER.lame
    stretch = 1 - depth / height

    def lateral_stress(lateral):  # nominal lateral stress of the homogeneous state, zero on free faces
        log_j = math.log(stretch * lateral**2)
        return mu * (lateral - 1 / lateral) + lam * log_j / lateral

    lateral = brentq(lateral_stress, 1.0, 1.5)
    log_j = math.log(stretch * lateral**2)
    nominal = mu * (stretch - 1 / stretch) + lam * log_j / stretch  # first Piola-Kirchhoff, axial
    result = solve_hyperelastic_contact(block_body, LoadCase(Plate(), depth, friction="none"), normal_steps=4)
    assert -result.force[2] == pytest.approx(nominal * side**2, rel=1e-4)
    corner = np.argmin(np.linalg.norm(block_body.space.nodes - [side, side, height], axis=1))
    assert result.displacements[corner][0] == pytest.approx((lateral - 1) * side, rel=1e-4)


def test_base_reaction_balances_the_contact_force():
    design = load_design("cylindrical-A")
    body = BodyModel.for_design(design, mesh_design(design, 2.0 * MM))
    result = solve_linear_contact(body, LoadCase(Board(1.6e-3, math.radians(30)), 0.8e-3, friction="stick"))
    base_reaction = -body.nodal_forces(result.displacements)[body.space.boundary_nodes["base"]].sum(axis=0)
    # the force on the indenter equals minus the force the base must supply
    np.testing.assert_allclose(result.force, -base_reaction, atol=1e-3 * abs(result.force[2]))


@pytest.mark.slow
def test_hertz_sphere_on_a_thick_bonded_layer():
    radius_sphere, depth = 5 * MM, 0.05 * MM
    layer_radius = layer_height = 20 * MM
    mesh = quarter_layer(layer_radius, layer_height, fine=0.09 * MM, fine_radius=0.9 * MM, coarse=4 * MM)
    body = BodyModel(mesh, RUBBER, np.zeros((0, 3)), SYMMETRIC_SUPPORTS)
    result = solve_linear_contact(body, LoadCase(Sphere(radius_sphere), depth, friction="none"))
    contact_radius = math.sqrt(radius_sphere * depth)
    e_star = RUBBER.youngs_modulus / (1 - RUBBER.poisson_ratio**2)
    hertz = 4 / 3 * e_star * math.sqrt(radius_sphere) * depth**1.5
    chi = contact_radius / layer_height
    thick_layer = hertz * (1 + 1.133 * chi + 1.283 * chi**2 + 0.769 * chi**3 + 0.0975 * chi**4)
    quarter_force = result.force[2] * 4
    assert quarter_force == pytest.approx(thick_layer, rel=0.05)
    # the contact area is found, not prescribed: its radius is Hertz's a = sqrt(R d)
    r_contact = np.hypot(*body.space.nodes[result.contact_nodes, :2].T).max()
    assert r_contact == pytest.approx(contact_radius, abs=0.1 * MM)


def test_neo_hookean_agrees_with_linear_at_small_depth():
    design = load_design("cylindrical-D")
    body = BodyModel.for_design(design, mesh_design(design, 2.0 * MM))
    load = LoadCase(Board(1.6e-3, 0.0), 0.05e-3, friction="none")
    linear = solve_linear_contact(body, load)
    large = solve_hyperelastic_contact(body, load, normal_steps=1)
    # the small-strain solution is the limit of the neo-Hookean one as the depth vanishes: they differ
    # by the geometric nonlinearity, first order in depth. Measured at 0.05 mm: 0.33 % of the force and
    # 0.046 % of the largest magnet translation (half that at 0.025 mm; the two solvers' penalties
    # account for 0.001 %); the bounds allow 2.5 times that
    assert large.force[2] == pytest.approx(linear.force[2], rel=0.008)
    for a, b in zip(linear.magnet_poses.translation, large.magnet_poses.translation):
        assert np.linalg.norm(b - a) < 0.0012 * np.linalg.norm(a)


@pytest.mark.slow
def test_mesh_convergence_of_the_fingertip_board_push():
    design = load_design("cylindrical-D")
    sizes = (1.5, 1.0, 0.75)  # the last is the reference
    feature, force = [], []
    for size in sizes:
        body = BodyModel.for_design(design, mesh_design(design, size * MM))
        result = solve_linear_contact(body, LoadCase(Board(1.6e-3, 0.0), 1e-3, friction="none"))
        arms = np.array([m.top_center for m in design.magnets]) - np.array([m.center for m in design.magnets])
        # the magnet beside the board, most sensitive to the mesh
        feature.append(result.magnet_poses.displacement_of(arms)[1, 2])
        force.append(result.force[2])
    for values in (feature, force):
        coarse_error, default_error = abs(values[0] - values[2]), abs(values[1] - values[2])
        assert default_error < coarse_error  # refinement converges towards the reference
        assert default_error < 0.01 * abs(values[2])  # the default 1.0 mm mesh is within 1 %


def test_a_contact_layer_refines_the_top_of_the_body_only(tmp_path, monkeypatch):
    monkeypatch.setenv("SOFTTIP_CACHE_DIR", str(tmp_path))
    design = load_design("cylindrical-A")
    plain = mesh_design(design, 2.5 * MM)
    layered = mesh_design(design, 2.5 * MM, contact_layer=(1.5 * MM, 1.0 * MM))
    assert layered.key != plain.key

    def edges(mesh, low, high):
        """Mean length of the tetrahedra's edges with both ends in low <= z <= high."""
        ends = [(a, b) for a in range(4) for b in range(a + 1, 4)]
        lengths = []
        for a, b in ends:
            p, q = mesh.points[mesh.tets[a]], mesh.points[mesh.tets[b]]
            inside = (np.minimum(p[:, 2], q[:, 2]) >= low) & (np.maximum(p[:, 2], q[:, 2]) <= high)
            lengths.append(np.linalg.norm(p - q, axis=1)[inside])
        return np.concatenate(lengths).mean()

    top = (design.height - 1.0 * MM, design.height)
    bottom = (0.0, 2.0 * MM)
    assert edges(layered, *top) < 1.2 * MM < edges(plain, *top)
    assert edges(layered, *bottom) == pytest.approx(edges(plain, *bottom), rel=0.25)
    with pytest.raises(ValueError, match="contact_layer"):
        mesh_design(design, 2.5 * MM, contact_layer=(1.5 * MM, 0.0))
