"""Dipoles and dipole chains against magpylib (its Dipole, and stacks of its Cylinder), and the exact
rectangle averages against adaptive quadrature and very fine grids."""

from __future__ import annotations

import magpylib as magpy
import numpy as np
import pytest
from scipy.integrate import dblquad, quad
from scipy.spatial.transform import Rotation

from softtip.magnetics.dipoles import (
    DipoleError,
    Dipoles,
    Rectangles,
    dipole_chain,
    dipole_field,
    frustum_shares,
    rectangle_average_in_plane,
)

RNG = np.random.default_rng(7)
POSITIONS = np.column_stack([RNG.normal(0, 1e-4, 5), RNG.normal(0, 1e-4, 5), RNG.uniform(2e-5, 4e-4, 5)])
MOMENTS = RNG.normal(0, 1e-7, (5, 3))
RECTANGLES = Rectangles(x=np.array([[-2e-4, 1e-4], [0.0, 3e-6], [-1e-3, 1e-3]]),
                        y=np.array([[-1e-4, 2e-4], [-5e-4, 5e-4], [3e-4, 4e-4]]), z=-1e-5)


def test_dipole_field_matches_magpylib():
    points = np.column_stack([RNG.normal(0, 5e-4, 50), RNG.normal(0, 5e-4, 50), RNG.normal(0, 5e-4, 50)])
    ours = dipole_field(points, POSITIONS, MOMENTS)
    theirs = sum(magpy.misc.Dipole(moment=m, position=p).getB(points) for p, m in zip(POSITIONS, MOMENTS))
    # measured: 5e-16 of the largest field
    assert np.abs(ours - theirs).max() <= 1e-13 * np.abs(theirs).max()
    # batches broadcast: two sets of dipoles at once
    both = dipole_field(points, np.stack([POSITIONS, POSITIONS]), np.stack([MOMENTS, 2 * MOMENTS]))
    assert np.allclose(both[1], 2 * ours, rtol=1e-14, atol=0)


def test_rectangle_average_is_exact_against_adaptive_quadrature():
    average = rectangle_average_in_plane(RECTANGLES, POSITIONS, MOMENTS)
    for r in range(len(RECTANGLES)):
        for axis in range(2):
            integral, _ = dblquad(
                lambda y, x: dipole_field(np.array([[x, y, RECTANGLES.z]]), POSITIONS, MOMENTS)[0, axis],
                RECTANGLES.x[r, 0], RECTANGLES.x[r, 1], RECTANGLES.y[r, 0], RECTANGLES.y[r, 1],
                epsabs=0, epsrel=1e-11)
            # measured: 6e-15 relative at worst
            assert average[r, axis] == pytest.approx(integral / RECTANGLES.area[r], rel=1e-10)


def test_rectangles_sharing_their_edges_are_exact_against_adaptive_quadrature():
    """Strips' runs cut along their length (a meander's area elements: 3 x 4 cells with gaps between the runs,
    30 distinct corners for 12 cells) take the kernel's shared-corner path; each cell against quadrature."""
    runs = np.array([[-3e-4, -1.2e-4], [-1e-4, 8e-5], [1e-4, 2.8e-4]])
    cuts = np.linspace(-2e-4, 2e-4, 5)
    x = np.repeat(runs, 4, axis=0)
    y = np.tile(np.column_stack([cuts[:-1], cuts[1:]]), (3, 1))
    cells = Rectangles(x=x, y=y, z=-1e-5)
    average = rectangle_average_in_plane(cells, POSITIONS, MOMENTS)
    for r in range(len(cells)):
        for axis in range(2):
            integral, _ = dblquad(
                lambda y, x: dipole_field(np.array([[x, y, cells.z]]), POSITIONS, MOMENTS)[0, axis],
                cells.x[r, 0], cells.x[r, 1], cells.y[r, 0], cells.y[r, 1], epsabs=0, epsrel=1e-11)
            assert average[r, axis] == pytest.approx(integral / cells.area[r], rel=1e-9)


def test_a_fine_grid_converges_to_the_exact_average_at_second_order():
    rectangle = Rectangles(x=np.array([[-3e-4, 2e-4]]), y=np.array([[-2e-4, 3e-4]]), z=-1e-5)
    exact = rectangle_average_in_plane(rectangle, POSITIONS, MOMENTS)[0]
    errors = []
    for cells in (100, 200, 400, 800):
        x = np.linspace(*rectangle.x[0], cells + 1)
        y = np.linspace(*rectangle.y[0], cells + 1)
        xm, ym = np.meshgrid(0.5 * (x[1:] + x[:-1]), 0.5 * (y[1:] + y[:-1]), indexing="ij")
        points = np.column_stack([xm.ravel(), ym.ravel(), np.full(xm.size, rectangle.z)])
        grid = dipole_field(points, POSITIONS, MOMENTS)[:, :2].mean(axis=0)
        errors.append(np.abs(grid - exact).max() / np.abs(exact).max())
    errors = np.array(errors)
    # midpoint rule: error ∝ h²; measured ratios 3.6 .. 4.0 per halving, 2.7e-5 at 800 × 800
    assert np.all(errors[:-1] / errors[1:] > 3.4)
    assert errors[-1] < 5e-5


def arc_centreline(bend: float, count: int, length: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """Points and unit tangents at the midpoints of ``count`` equal pieces of a circular arc standing
    on the origin along +z and bending by ``bend`` rad towards +x."""
    s = (np.arange(count) + 0.5) / count * length
    if bend == 0:
        return np.column_stack([0 * s, 0 * s, s]), np.tile([0.0, 0.0, 1.0], (count, 1))
    radius = length / bend
    angle = s / radius
    points = np.column_stack([radius * (1 - np.cos(angle)), 0 * s, radius * np.sin(angle)])
    return points, np.column_stack([np.sin(angle), 0 * s, np.cos(angle)])


BASE, TIP, MOMENT, DEPTH = 320e-6, 200e-6, 2.8e-6, 10e-6


def pillar_chain(bend: float, count: int, volume_shares: bool) -> Dipoles:
    points, tangents = arc_centreline(bend, count)
    return dipole_chain(points, tangents, MOMENT, frustum_shares(BASE, TIP, count) if volume_shares else None)


def test_frustum_shares_are_each_pieces_volume_by_quadrature():
    # each piece's volume ∫ π d(z)²/4 dz over its height, by adaptive quadrature, over the whole frustum's
    count = 7
    edges = np.linspace(0.0, 1e-3, count + 1)

    def area(z: float) -> float:
        return np.pi / 4 * (BASE + (TIP - BASE) * z / 1e-3) ** 2

    pieces = np.array([quad(area, a, b, epsabs=0, epsrel=1e-13)[0] for a, b in zip(edges[:-1], edges[1:])])
    np.testing.assert_allclose(frustum_shares(BASE, TIP, count), pieces / pieces.sum(), rtol=1e-12)
    # a cylinder's pieces share alike; the shares of pieces add up to the share of their union
    np.testing.assert_allclose(frustum_shares(TIP, TIP, 5), np.full(5, 0.2), rtol=1e-14)
    np.testing.assert_allclose(frustum_shares(BASE, TIP, 2), frustum_shares(BASE, TIP, 4).reshape(2, 2).sum(axis=1),
                               rtol=1e-14)


def cylinder_stack(bend: float, count: int = 120) -> magpy.Collection:
    """The conical pillar as ``count`` uniformly magnetised magpylib cylinders along the arc."""
    points, tangents = arc_centreline(bend, count)
    fractions = (np.arange(count) + 0.5) / count
    diameters = BASE + (TIP - BASE) * fractions
    height = 1e-3 / count
    # uniform magnetisation: the frustum's moment over its volume π h (D² + Dd + d²)/12, each cylinder its share
    # by its own volume (the reference does not use frustum_shares)
    magnetisation = MOMENT / (np.pi * 1e-3 / 12 * (BASE**2 + BASE * TIP + TIP**2))
    moments = magnetisation * np.pi * diameters**2 / 4 * (1e-3 / count)
    stack = magpy.Collection()
    for point, tangent, diameter, moment in zip(points, tangents, diameters, moments):
        polarisation = 4e-7 * np.pi * moment / (np.pi * diameter**2 / 4 * height)  # J = μ₀ m / V
        turn = Rotation.align_vectors([tangent], [[0.0, 0.0, 1.0]])[0]
        stack.add(magpy.magnet.Cylinder(polarization=(0, 0, polarisation), dimension=(diameter, height),
                                        position=point, orientation=turn))
    return stack


def stack_average(stack: magpy.Collection, rectangles: Rectangles, nodes: int = 48) -> np.ndarray:
    """Mean in-plane field of magpylib's magnets over each rectangle, by Gauss–Legendre quadrature."""
    g, w = np.polynomial.legendre.leggauss(nodes)
    out = []
    for (x0, x1), (y0, y1) in zip(rectangles.x, rectangles.y):
        xs, ys = np.meshgrid((x0 + x1) / 2 + (x1 - x0) / 2 * g, (y0 + y1) / 2 + (y1 - y0) / 2 * g, indexing="ij")
        field = stack.getB(np.column_stack([xs.ravel(), ys.ravel(), np.full(xs.size, rectangles.z)]))[:, :2]
        out.append((np.outer(w, w).ravel()[:, None] * field).sum(axis=0) / 4)
    return np.array(out)


# sensing areas beside the pillar's root, in the plane 10 µm below it
NEAR_DIE = Rectangles(x=np.array([[-1e-3, -0.2e-3], [0.2e-3, 1e-3], [-1e-3, 1e-3]]),
                      y=np.array([[-0.5e-3, 0.5e-3], [-0.5e-3, 0.5e-3], [0.2e-3, 1e-3]]), z=-DEPTH)


@pytest.mark.parametrize("bend", [0.0, 1.0])
def test_ten_dipoles_are_close_to_a_converged_chain(bend):
    converged = pillar_chain(bend, 2000, volume_shares=False).in_plane_average(NEAR_DIE)
    ten = pillar_chain(bend, 10, volume_shares=False).in_plane_average(NEAR_DIE)
    error = np.abs(ten - converged).max() / np.abs(converged).max()
    # measured: 1.0 % (straight) and 1.1 % (bent by 1 rad) of the largest average
    assert error < 0.015


@pytest.mark.parametrize("bend", [0.0, 1.0])
def test_a_chain_near_the_die_against_a_stack_of_magpylib_cylinders(bend):
    """The centre-line chain is a thin magnet: 10 µm under a 320 µm root its averages miss the thick
    magnet's by 8.7 / 11.1 % (straight / bent) with volume shares and 19.3 / 18.7 % with the published
    equal shares (measured, of the largest average); far away the two agree."""
    stack = cylinder_stack(bend)
    reference = stack_average(stack, NEAR_DIE)
    scale = np.abs(reference).max()
    volume = np.abs(pillar_chain(bend, 10, volume_shares=True).in_plane_average(NEAR_DIE) - reference).max() / scale
    equal = np.abs(pillar_chain(bend, 10, volume_shares=False).in_plane_average(NEAR_DIE) - reference).max() / scale
    assert volume < 0.13
    assert equal < 0.22
    assert volume < equal
    for distance, bound in ((3.3e-3, 3e-3), (33e-3, 3e-5)):
        far = np.array([[3.0, 1.0, -1.0], [-2.0, -2.0, 1.5]]) * distance / 3.3
        chain = pillar_chain(bend, 200, volume_shares=True).field(far)
        error = np.abs(chain - stack.getB(far)).max() / np.abs(chain).max()
        # the thick magnet's higher multipoles fade as (radius/distance)²: measured 2.4e-3 and 1.3e-3 at
        # 3.3 mm, 2.1e-5 and 1.6e-5 at 33 mm (straight, bent)
        assert error < bound


def test_bad_input_is_refused_in_one_line():
    with pytest.raises(DipoleError, match="points: a point coincides with a dipole"):
        dipole_field(POSITIONS[:1], POSITIONS, MOMENTS)
    with pytest.raises(DipoleError, match=r"positions: expected an array of shape \(..., 3\)"):
        dipole_field(POSITIONS, POSITIONS[:, :2], MOMENTS)
    with pytest.raises(DipoleError, match="moments: expected the shape of positions"):
        dipole_field(POSITIONS, POSITIONS, MOMENTS[:2])
    with pytest.raises(DipoleError, match="upper edge must lie above"):
        Rectangles(x=np.array([[1.0, 0.0]]), y=np.array([[0.0, 1.0]]), z=0.0)
    with pytest.raises(DipoleError, match="a dipole lies in the rectangles' plane"):
        rectangle_average_in_plane(Rectangles(np.array([[0.0, 1.0]]), np.array([[0.0, 1.0]]), POSITIONS[0, 2]),
                                   POSITIONS, MOMENTS)
    points, tangents = arc_centreline(0.5, 4)
    with pytest.raises(DipoleError, match="shares: expected 4 numbers >= 0 summing to 1"):
        dipole_chain(points, tangents, 1e-6, [0.5, 0.5, 0.5, -0.5])
    with pytest.raises(DipoleError, match="tangents: expected unit vectors"):
        dipole_chain(points, 2 * tangents, 1e-6)
    with pytest.raises(DipoleError, match="moment = nan"):
        dipole_chain(points, tangents, float("nan"))
