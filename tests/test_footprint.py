"""Contact on cells of the indenter's footprint: the cell operator, the two routes to the same
solve, and the smoothness it exists for."""

from __future__ import annotations

import math

import numpy as np
import pytest

from softtip._core.units import MM
from softtip.design.model import load_design
from softtip.mechanics.contact import (FootprintBody, LoadCase, SurfaceInfluence, SurfacePatch, solve_footprint_contact,
                                      solve_influence_contact, solve_linear_contact, stiffness_compliance)
from softtip.mechanics.contact.footprint import footprint_cells, quadratic_triangle_shapes
from softtip.mechanics.fe import BodyModel
from softtip.mechanics.indenters import Board, Sphere
from softtip.mechanics.mesh import mesh_design

LOWEST_Z = 5 * MM


@pytest.fixture(scope="module")
def coarse():
    design = load_design("cylindrical-A")
    body = BodyModel.for_design(design, mesh_design(design, 2.5 * MM))
    influence = SurfaceInfluence.build(body, LOWEST_Z)
    # the surface seen through its influence matrices
    return body, influence, FootprintBody(SurfacePatch(body, LOWEST_Z), influence.compliance_of)


def test_quadratic_shapes_at_corners_and_midpoints():
    # hand-computed: each shape is 1 at its own node and 0 at the other five
    nodes = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [0.5, 0.5, 0], [0, 0.5, 0.5], [0.5, 0, 0.5]])
    np.testing.assert_allclose(quadratic_triangle_shapes(nodes), np.eye(6), atol=1e-15)


def test_cell_averages_reproduce_quadratic_fields_and_sum_to_one(coarse):
    body, _, reduced = coarse
    patch = reduced.patch
    board = Board(1.6e-3, 0.7)
    cells = footprint_cells(patch, board, np.array([1e-3, -2e-3, 9e-3]), patch.radius)
    np.testing.assert_allclose(cells.average.sum(axis=1), 1.0, atol=1e-12)

    def field(x):  # quadratic in plan view: the surface interpolation holds it exactly on flat facets
        return 3.0 + 2e2 * x[:, 0] - 5e2 * x[:, 1] + 4e4 * x[:, 0] * x[:, 1] + 7e4 * x[:, 1] ** 2

    direct = np.bincount(cells.cell_of_point, weights=field(cells.points)) / np.bincount(cells.cell_of_point)
    np.testing.assert_allclose(cells.average @ field(body.space.nodes[cells.nodes]), direct, rtol=1e-10)
    # a board's cells tile its thickness: every point lies within it, in the cells' plan-view area
    across = np.array([-math.sin(board.angle), math.cos(board.angle)])
    assert np.abs((cells.points[:, :2] - [1e-3, -2e-3]) @ across).max() < board.thickness / 2


@pytest.mark.parametrize(
    "load",
    [
        LoadCase(Board(1.6e-3, 0.3), 2e-3, tangential=(1e-3, -0.5e-3), position=(1e-3, 0.0), friction="stick"),
        LoadCase(Board(1.6e-3, 1.1), 1.5e-3, tangential=(0.6e-3, 0.4e-3), friction="none"),
        LoadCase(Sphere(5e-3), 1e-3, position=(2e-3, 0.0), friction="none"),
        LoadCase(Board(1.6e-3, 0.8), 1.5e-3, tangential=(1.2e-3, 0.3e-3), position=(0.0, 2e-3), friction="coulomb"),
    ],
)
def test_influence_matrices_and_the_factorised_stiffness_give_the_same_solve(coarse, load):
    body, _, reduced = coarse
    fe = solve_footprint_contact(FootprintBody(reduced.patch, stiffness_compliance(body)), load)
    exact = solve_footprint_contact(reduced, load)
    np.testing.assert_allclose(exact.force, fe.force, rtol=1e-8, atol=1e-9)
    scale = np.abs(fe.magnet_poses.rigid).max()
    np.testing.assert_allclose(exact.magnet_poses.rigid, fe.magnet_poses.rigid, rtol=1e-8, atol=1e-8 * scale)
    assert fe.force[2] > 0


def test_a_wide_board_pushes_as_hard_as_with_nodal_contact(coarse):
    # two discretisations of one problem: they converge to each other once the footprint spans
    # several elements
    body, _, reduced = coarse
    load = LoadCase(Board(8e-3, 0.2), 1e-3, friction="none")
    nodal = solve_linear_contact(body, load)
    cells = solve_footprint_contact(FootprintBody(reduced.patch, stiffness_compliance(body)), load)
    assert cells.force[2] == pytest.approx(nodal.force[2], rel=0.05)


def test_a_board_shifted_along_itself_or_turned_half_a_turn_is_the_same_load(coarse):
    _, _, reduced = coarse
    angle = 0.6
    along = np.array([math.cos(angle), math.sin(angle)])
    start = np.array([0.5e-3, -0.3e-3])
    loads = [LoadCase(Board(1.6e-3, a), 1.2e-3, tangential=(0.4e-3, 0.2e-3), position=tuple(p), friction="stick")
             for a, p in ((angle, start), (angle, start + 2e-3 * along), (angle + math.pi, start))]
    results = [solve_footprint_contact(reduced, load) for load in loads]
    for other in results[1:]:
        np.testing.assert_allclose(other.force, results[0].force, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(other.magnet_poses.rigid, results[0].magnet_poses.rigid, rtol=1e-9, atol=1e-15)


def test_the_response_is_smooth_across_a_narrow_board_where_nodal_contact_steps(coarse):
    _, influence, reduced = coarse
    angle = 0.4
    across = np.array([-math.sin(angle), math.cos(angle)])
    offsets = np.linspace(-1.25e-3, 1.25e-3, 26)  # one element across, in 0.1 mm steps
    loads = [LoadCase(Board(1.6e-3, angle), 2e-3, position=tuple(s * across), friction="stick") for s in offsets]

    def roughness(solve) -> float:
        fz = np.array([solve(load).force[2] for load in loads])
        return np.abs(fz - np.polyval(np.polyfit(offsets, fz, 3), offsets)).max() / fz.mean()

    cells = roughness(lambda load: solve_footprint_contact(reduced, load))
    nodes = roughness(lambda load: solve_influence_contact(influence, load))
    assert cells < 0.01
    assert nodes > 5 * cells


def test_nodes_off_the_influence_surface_are_refused(coarse):
    _, influence, _ = coarse
    with pytest.raises(ValueError, match="node_ids"):
        influence.compliance_of(np.array([0, 10**9]))


def _drag(friction: str, mu: float = 0.5) -> LoadCase:
    """A shallow push dragged far along the board."""
    angle = 0.3
    return LoadCase(Board(1.6e-3, angle), 0.2e-3, tangential=(1.5e-3 * math.cos(angle), 1.5e-3 * math.sin(angle)),
                    friction=friction, mu=mu)


def test_coulomb_friction_slides_at_mu_times_the_normal_force_where_stick_holds_more(coarse):
    _, _, reduced = coarse
    stuck = solve_footprint_contact(reduced, _drag("stick"))
    sliding = solve_footprint_contact(reduced, _drag("coulomb", mu=0.5))
    assert np.hypot(*stuck.force[:2]) > 2 * stuck.force[2]  # no board holds the skin like that
    shear = np.hypot(*sliding.force[:2])
    assert shear == pytest.approx(0.5 * sliding.force[2], rel=1e-3)  # Amontons, in gross sliding
    travel = np.array(_drag("coulomb").tangential)
    assert sliding.force[:2] @ travel / (shear * np.linalg.norm(travel)) < -0.95  # against the travel


def test_coulomb_friction_never_exceeds_its_cone_and_holds_like_stick_when_ample(coarse):
    _, _, reduced = coarse
    rng = np.random.default_rng(3)
    for _ in range(8):
        angle, depth = rng.uniform(0, math.pi), rng.uniform(0.3e-3, 2e-3)
        load = LoadCase(Board(1.6e-3, angle), depth, tangential=tuple(rng.uniform(-1.5e-3, 1.5e-3, 2)),
                        position=tuple(rng.uniform(-3e-3, 3e-3, 2)), friction="coulomb", mu=0.4)
        force = solve_footprint_contact(reduced, load).force
        assert np.hypot(*force[:2]) <= 0.4 * force[2] * (1 + 1e-3)
    # a deep push with a short travel needs little friction: as mu grows, Coulomb's law tends to
    # stick (stick follows its path exactly, Coulomb's law in steps: fine ones)
    def push(friction: str, mu: float = 0.7) -> np.ndarray:
        load = LoadCase(Board(1.6e-3, 0.5), 2e-3, tangential=(0.2e-3, 0.1e-3), friction=friction, mu=mu)
        return solve_footprint_contact(reduced, load, normal_steps=8, tangential_steps=8).force

    stick = push("stick")
    gaps = [np.abs(push("coulomb", mu) - stick).max() / stick[2] for mu in (0.2, 0.7, 2.0)]
    assert gaps[0] > gaps[1] > gaps[2] and gaps[2] < 0.02


def test_sticking_cells_follow_the_load_path_exactly_whatever_its_steps(coarse):
    # with a board's flat face the path is linear between changes of the contact set, and it is
    # followed from one change to the next: one step and 8 + 16 steps give the same state (up to
    # cells touching with no pressure, which hold on from the end of a step). A stepped path, which
    # joins cells only at its steps, differed here by 0.4-0.6 % of the force
    _, _, reduced = coarse
    rng = np.random.default_rng(4)
    for _ in range(6):
        load = LoadCase(Board(1.6e-3, rng.uniform(0, math.pi)), rng.uniform(0.3e-3, 2e-3),
                        tangential=tuple(rng.uniform(-1.5e-3, 1.5e-3, 2)), position=tuple(rng.uniform(-3e-3, 3e-3, 2)),
                        friction="stick")
        coarse_path = solve_footprint_contact(reduced, load, normal_steps=1, tangential_steps=1)
        fine_path = solve_footprint_contact(reduced, load, normal_steps=8, tangential_steps=16)
        assert np.abs(coarse_path.force - fine_path.force).max() < 2e-3 * np.linalg.norm(fine_path.force)


def test_solvers_that_hold_nodes_refuse_coulomb_friction(coarse):
    body, influence, _ = coarse
    load = LoadCase(Board(), 1e-3, friction="coulomb")
    for solve in (lambda: solve_influence_contact(influence, load), lambda: solve_linear_contact(body, load)):
        with pytest.raises(ValueError, match="footprint cells"):
            solve()
    for mu in (-0.1, 5.0):
        with pytest.raises(ValueError, match=f"mu = {mu}"):
            LoadCase(Board(), 1e-3, friction="coulomb", mu=mu)
