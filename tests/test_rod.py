"""The static rod solver against closed forms: Euler's elastica (elliptic integrals) for large deflection,
linear Timoshenko theory with taper, shear and base compliance for small deflection, Euler's buckling loads
under a plate, and bad input."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq
from scipy.special import ellipe, ellipeinc, ellipk, ellipkinc

from softtip.mechanics.rod import (
    BONDED_ROOT_TABLE,
    PlateContact,
    Rod,
    RodError,
    bonded_root_flexibility,
    half_space_rotational_stiffness,
    lower_plate,
    side_clearance,
    solve_follower_force,
    solve_tip_force,
    touching_height,
)

E, L = 1.0e6, 1.0e-3


def elastica_tip(load: float, length: float, bending_stiffness: float) -> tuple[float, float]:
    """Tip (x, z) of a uniform inextensible cantilever standing along +z under a horizontal dead tip force.

    With λ² = P/EI the angle θ from the vertical obeys θ'² = 2λ²(sin θ_L − sin θ); substituting
    1 + sin θ = 2k² sin²φ gives λL = K(k) − F(φ₀, k), sin φ₀ = 1/(√2 k), and
    x = L − 2(E(k) − E(φ₀, k))/λ, z = √(2(2k² − 1))/λ (Bisshopp & Drucker, Q. Appl. Math. 3, 1945)."""
    lam = math.sqrt(load / bending_stiffness)

    def mismatch(k: float) -> float:
        return ellipk(k * k) - ellipkinc(math.asin(1 / (math.sqrt(2) * k)), k * k) - lam * length

    k = brentq(mismatch, 1 / math.sqrt(2) + 1e-15, 1 - 1e-15, xtol=1e-15)
    phi0 = math.asin(1 / (math.sqrt(2) * k))
    return length - 2 / lam * (ellipe(k * k) - ellipeinc(phi0, k * k)), math.sqrt(2 * (2 * k * k - 1)) / lam


def uniform(diameter: float = 200e-6, **options) -> Rod:
    return Rod(length=L, base_diameter=diameter, tip_diameter=diameter, youngs_modulus=E, **options)


LOADS = np.array([0.1, 1.0, 3.0, 10.0])  # P L²/EI: from nearly linear to a tip turned 70° over


def elastica_errors(segments: int) -> np.ndarray:
    rod = uniform(segments=segments, shear_and_stretch=False)
    bending = E * math.pi * rod.base_diameter**4 / 64
    loads = LOADS * bending / L**2
    shapes = solve_tip_force(rod, np.stack([loads, np.zeros_like(loads)], axis=-1))
    exact = np.array([elastica_tip(load, L, bending) for load in loads])
    return np.linalg.norm(shapes.tip - exact, axis=1) / L


def test_large_deflection_matches_the_elastica():
    errors = elastica_errors(60)
    # measured: 0.4e-5 .. 1.3e-4 of the length over P L²/EI = 0.1 .. 10 (60 segments)
    assert errors.max() < 2e-4
    # second order in the segment length: halving it divides the error by 4 (measured 3.99 .. 4.01)
    ratio = elastica_errors(30) / errors
    assert np.all((ratio > 3.8) & (ratio < 4.2))


def test_small_deflection_matches_tapered_timoshenko_beam_on_a_compliant_base():
    """Unit-load method: δ = F [∫ (L − s)²/EI ds + ∫ ds/(κGA) + L²/k_base] for a conical rod."""
    base, tip = 320e-6, 200e-6
    stiffness = half_space_rotational_stiffness(E, 0.5, base)
    rod = Rod(length=L, base_diameter=base, tip_diameter=tip, youngs_modulus=E, base_stiffness=stiffness,
              segments=120)
    inertia = lambda s: math.pi * rod.diameter(s) ** 4 / 64  # noqa: E731
    area = lambda s: math.pi * rod.diameter(s) ** 2 / 4  # noqa: E731
    compliance = (quad(lambda s: (L - s) ** 2 / (E * inertia(s)), 0, L, epsabs=0, epsrel=1e-12)[0]
                  + quad(lambda s: 1 / (rod.kappa * rod.shear_modulus * area(s)), 0, L, epsabs=0, epsrel=1e-12)[0]
                  + L**2 / stiffness)
    force = 1e-4 * E * inertia(L) / L**2  # deflection ~1e-4 L: geometric nonlinearity ~1e-8
    shapes = solve_tip_force(rod, [[force, 0.0]])
    # measured: 1.4e-5 relative (the discretisation, 120 segments)
    assert shapes.tip[0, 0] / (force * compliance) == pytest.approx(1.0, abs=3e-5)
    # axial stretch: a pull along the axis lengthens the rod by ∫ F/(EA) ds exactly (straight rod)
    pull = 1e-3
    stretched = solve_tip_force(rod, [[0.0, pull]])
    assert stretched.tip[0, 1] - L == pytest.approx(quad(lambda s: pull / (E * area(s)), 0, L)[0], rel=2e-4)
    assert stretched.tip[0, 0] == 0.0


def test_a_follower_force_agrees_with_a_dead_force_when_small_and_curls_the_rod_onto_its_side():
    rod = Rod(length=L, base_diameter=320e-6, tip_diameter=200e-6, youngs_modulus=E)
    small = 1e-7
    follower = solve_follower_force(rod, [small])
    dead = solve_tip_force(rod, [[small, 0.0]])
    # the follower turns with the tip (by 3e-4 rad here): the deflections differ at second order only
    assert follower.tip[0, 0] == pytest.approx(dead.tip[0, 0], rel=1e-3)
    sizes = np.linspace(0.0, 8e-3, 17)
    shapes = solve_follower_force(rod, sizes)
    clearance = side_clearance(shapes)
    assert shapes.saturated.any() and not shapes.saturated.all()
    onset = shapes.saturated.argmax()
    # the lying shape is the one at the onset, where the side just touches the base plane
    assert clearance[onset] == pytest.approx(0.0, abs=2e-8 * L)  # measured 8e-9 L (onset to 1e-6 in force)
    assert np.array_equal(shapes.angles[onset], shapes.angles[-1])
    assert np.all(clearance[:onset] > 0)


def test_a_dead_perpendicular_force_never_lays_the_rod_down():
    rod = uniform()
    shapes = solve_tip_force(rod, [[0.16, 0.0]])  # 2000 EI/L²
    assert not shapes.saturated.any()
    assert 0 < shapes.tip_angle[0] < math.pi / 2 and shapes.tip[0, 1] > 0


@pytest.mark.parametrize(("friction", "euler"), [(0.0, math.pi**2 / 4), (5.0, 20.1907)])
def test_a_plate_buckles_the_column_at_eulers_load(friction, euler):
    """Frictionless, the tip slides: a clamped-free column (π²/4 EI/L²); with ample friction it sticks:
    clamped-pinned (20.19 EI/L², Timoshenko & Gere, Theory of Elastic Stability, §2.5). Both corrected for
    shear (Engesser: P/(1 + P/κGA)) and followed a little past the bifurcation of a 1e-4 rad bow."""
    rod = uniform(diameter=50e-6)
    bending = E * math.pi * rod.base_diameter**4 / 64
    shear = rod.kappa * rod.shear_modulus * math.pi * rod.base_diameter**2 / 4
    critical = euler * bending / L**2
    critical /= 1 + critical / shear
    gaps = L * (1 - 1e-8) - np.linspace(0, 0.01, 6) * L
    path = lower_plate(rod, gaps, PlateContact(friction=friction, imperfection=1e-4))
    assert np.all(path.sliding[1:] == (friction == 0.0))
    # measured: 1.0011 (free) and 1.0020 (pinned) of the critical load 0.4 % past the bifurcation, rising
    # with the post-buckling stiffness
    assert path.vertical_force[2] / critical == pytest.approx(1.0, abs=4e-3)
    assert np.all(np.diff(path.vertical_force[2:]) > 0)
    if friction:  # stuck, the column bulges further the way of its bow
        assert path.shapes.x[2:, rod.segments // 2].min() > 0
    else:  # free, it leans the other way: its top half slopes back, and the flagpole's mode weighs the top
        assert path.shapes.x[2:, -1].max() < 0


def test_a_pillar_under_the_plate_buckles_then_lies_on_its_side():
    rod = Rod(length=L, base_diameter=320e-6, tip_diameter=200e-6, youngs_modulus=E,
              base_stiffness=half_space_rotational_stiffness(E, 0.5, 320e-6))
    gaps = np.linspace(0.9999 * L, 0.4 * L, 15)
    path = lower_plate(rod, gaps, PlateContact(friction=0.5, imperfection=0.01))
    assert path.lying.any() and not path.lying[0]
    onset = path.lying.argmax()
    # lying, the last section stands across the plate and the push keeps rising as the plate folds it further
    assert np.all(np.abs(path.shapes.tip_angle[onset:]) == pytest.approx(math.pi / 2, abs=1e-6))
    assert np.all(np.diff(path.vertical_force[onset:]) > 0)


def test_a_rod_lying_under_the_plate_folds_as_eulers_elastica():
    """Frictionless, the free part of a lying rod is a clamped elastica loaded along its base's axis whose
    end has turned 90°: P ℓ²/EI = K(k)², height (2E(k) − K(k))/λ with k² = 1/2 (Timoshenko & Gere, §2.7),
    so the push times the plate's height squared is (2E − K)² EI = 0.7178 EI whatever the free length."""
    rod = uniform(diameter=20e-6)
    bending = E * math.pi * rod.base_diameter**4 / 64
    contact = PlateContact(friction=0.0, imperfection=1e-3)
    gaps = np.linspace(0.999 * touching_height(rod, contact), 0.3 * L, 30)
    path = lower_plate(rod, gaps, contact)
    assert path.lying.sum() >= 5
    exact = (2 * ellipe(0.5) - ellipk(0.5)) ** 2
    # measured: within 4.5e-4 (shear and stretch of a 50:1 rod, the 1e-3 bow), the free part from 0.98 to 0.42 mm
    assert path.vertical_force[path.lying] * gaps[path.lying] ** 2 / bending == pytest.approx(exact, rel=1e-3)


def test_a_lying_rod_held_by_friction_leaves_what_has_come_down_where_it_landed():
    rod = uniform(diameter=100e-6)
    contact = PlateContact(friction=5.0, imperfection=0.01)
    path = lower_plate(rod, np.linspace(0.999 * touching_height(rod, contact), 0.3 * L, 30), contact)
    lying = path.lying
    assert lying.sum() >= 5 and not path.sliding[lying].any()
    # the rod's end lies on the plate where the tip first came down, while the free part shortens under it
    assert np.allclose(path.shapes.x[lying, -1], path.shapes.x[lying, -1][0], atol=1e-12)
    assert np.allclose(path.shapes.z[lying, -1], path.gaps[lying], atol=1e-12)


def test_bad_input_is_refused_in_one_line():
    with pytest.raises(RodError, match=r"rod.length = -0.001: expected a positive number"):
        Rod(length=-1e-3, base_diameter=1e-4, tip_diameter=1e-4, youngs_modulus=E)
    with pytest.raises(RodError, match="wider than long"):
        Rod(length=1e-4, base_diameter=2e-4, tip_diameter=1e-4, youngs_modulus=E)
    with pytest.raises(RodError, match="force: expected a non-empty array of finite numbers"):
        solve_tip_force(uniform(), [[np.nan, 0.0]])
    with pytest.raises(RodError, match=r"force: expected an array of shape \(B, 2\)"):
        solve_tip_force(uniform(), [1.0, 0.0])
    with pytest.raises(RodError, match="size: expected forces >= 0"):
        solve_follower_force(uniform(), [-1e-3])
    with pytest.raises(RodError, match="gaps: expected plate heights decreasing"):
        lower_plate(uniform(), [0.5 * L, 0.9 * L])
    with pytest.raises(RodError, match="shear_and_stretch = False"):
        lower_plate(uniform(shear_and_stretch=False), [0.9 * L])
    with pytest.raises(RodError, match="imperfection"):
        PlateContact(imperfection=0.0)


def test_slice_centroids_are_the_area_weighted_means_of_the_bent_centre_line():
    """A small tip load on an unshearable, inextensible uniform rod: the linear cantilever's deflection
    x(s) = F s² (3L − s) / (6 EI), so a slice's centroid (equal areas) is x's mean over the slice, in closed
    form; the chord tangents average to the mean slope's direction."""
    rod = uniform(segments=200, shear_and_stretch=False)
    bending = E * math.pi * rod.base_diameter**4 / 64
    force = 1e-4 * bending / L**2  # P L²/EI = 1e-4: linear to 1e-4
    shapes = solve_tip_force(rod, [[force, 0.0]])
    points, tangents = shapes.slice_means(4)

    def deflection_integral(s: float) -> float:  # ∫ x ds
        return force * (L * s**3 - s**4 / 4) / (6 * bending)

    edges = np.linspace(0, L, 5)
    exact = np.diff([deflection_integral(s) for s in edges]) / np.diff(edges)
    slopes = np.diff([force * s**2 * (3 * L - s) / (6 * bending) for s in edges]) / np.diff(edges)
    # measured: within 2.4e-4 (the root slice: second-order discretisation and the 1e-4 nonlinearity)
    assert points[0, :, 0] == pytest.approx(exact, rel=4e-4)
    assert points[0, :, 1] == pytest.approx(edges[:-1] + np.diff(edges) / 2, rel=1e-8)
    assert tangents[0, :, 0] == pytest.approx(slopes, rel=2e-4)


def test_slice_centroids_of_a_taper_sit_below_the_slices_middles():
    """Unloaded, a cone's slices have their centroids where a frustum's is: h (R² + 2Rr + 3r²) /
    (4 (R² + Rr + r²)) above the lower face, here checked against scipy's quadrature of ∫ z A dz / ∫ A dz."""
    rod = Rod(length=L, base_diameter=320e-6, tip_diameter=200e-6, youngs_modulus=E, segments=60)
    points, _ = solve_tip_force(rod, [[0.0, 0.0]]).slice_means(10)
    edges = np.linspace(0, L, 11)
    area = lambda z: float(rod.diameter(z)) ** 2  # noqa: E731
    exact = [quad(lambda z: z * area(z), a, b)[0] / quad(area, a, b)[0] for a, b in zip(edges[:-1], edges[1:])]
    assert points[0, :, 1] == pytest.approx(exact, rel=1e-10)
    with pytest.raises(RodError, match="count = 0"):
        solve_tip_force(rod, [[0.0, 0.0]]).slice_means(0)


def test_a_bonded_root_turns_the_rod_less_by_its_flexibility_times_the_moment():
    """Linear bending: a flexibility g(s) taken away near the root turns every section above it back by
    ∫ g M ds and moves the tip back by ∫ g M (L − s) ds, M = F (L − s): scipy's quadrature of the
    exponential profile against the rod's tip rotation and deflection under a small load."""
    plain = uniform(diameter=250e-6, segments=200, shear_and_stretch=False, poisson_ratio=0.49)
    bonded = uniform(diameter=250e-6, segments=200, shear_and_stretch=False, poisson_ratio=0.49, bonded_root=True)
    bending = E * math.pi * plain.base_diameter**4 / 64
    force = 1e-5 * bending / L**2  # linear to 1e-5
    shapes = solve_tip_force(plain, [[force, 0.0]]), solve_tip_force(bonded, [[force, 0.0]])

    def density(s: float) -> float:  # −d/ds of the flexibility taken away below s
        step = 1e-9
        return float(bonded_root_flexibility(bonded, s, s + step)) / step

    turn = quad(lambda s: density(s) * force * (L - s), 0, L, points=[1e-5, 1e-4], limit=200)[0]
    shift = quad(lambda s: density(s) * force * (L - s) ** 2, 0, L, points=[1e-5, 1e-4], limit=200)[0]
    # measured: 4e-5 and 8e-5 apart (the 200 segments, the 1e-5 nonlinearity)
    assert shapes[0].tip_angle[0] - shapes[1].tip_angle[0] == pytest.approx(turn, rel=3e-4)
    assert shapes[0].tip[0, 0] - shapes[1].tip[0, 0] == pytest.approx(shift, rel=3e-4)
    # the table's c: a turn of c M / (E r³) for a moment M constant over the root zone, here M falls by λ F
    _, c, decay = BONDED_ROOT_TABLE[-1]
    decay *= 125e-6
    assert turn == pytest.approx(c * force * (L - decay * (1 - math.exp(-L / decay))) / (E * 125e-6**3), rel=1e-4)
    with pytest.raises(RodError, match="bonded_root"):
        uniform(base_stiffness=1e-6, bonded_root=True)
    with pytest.raises(RodError, match="poisson_ratio"):
        uniform(poisson_ratio=0.1, bonded_root=True)


def test_under_a_plate_the_push_scales_with_youngs_modulus_at_the_same_shapes():
    """The rod's equations are homogeneous in E at a given geometry (friction is a ratio of forces): a
    stiffer material of the same shape takes proportionally more push at every gap, lying down included.
    This is why the lying load, and so the range read on a balance, scales with E."""
    soft = Rod(length=L, base_diameter=320e-6, tip_diameter=200e-6, youngs_modulus=E,
               base_stiffness=half_space_rotational_stiffness(E, 0.49, 320e-6), poisson_ratio=0.49)
    stiff = replace(soft, youngs_modulus=1.5 * E, base_stiffness=1.5 * soft.base_stiffness)
    contact = PlateContact(friction=0.5, imperfection=0.01)
    gaps = touching_height(soft, contact) - np.linspace(0.0, 0.5 * L, 41)
    one, other = lower_plate(soft, gaps, contact), lower_plate(stiff, gaps, contact)
    assert one.lying.any() and np.array_equal(one.lying, other.lying)
    assert np.allclose(other.vertical_force, 1.5 * one.vertical_force, rtol=1e-6, atol=1e-12)
    assert np.allclose(other.shapes.x, one.shapes.x, atol=1e-9 * L)


def test_a_tilted_base_stands_the_rod_askew_and_turning_the_frame_back_stands_it_straight():
    rod = uniform(diameter=100e-6)
    tilt, bow = 0.1, 1e-3
    tilted = lower_plate(rod, [0.99 * touching_height(rod, PlateContact(imperfection=bow, tilt=tilt))],
                         PlateContact(imperfection=bow, tilt=tilt)).standing
    straight = lower_plate(rod, [0.99 * touching_height(rod, PlateContact(imperfection=bow))],
                           PlateContact(imperfection=bow)).standing
    # unloaded, the tilted rod is the straight one turned by the tilt about its base
    assert tilted.tip[0, 0] == pytest.approx(math.sin(tilt) * straight.tip[0, 1] + math.cos(tilt) * straight.tip[0, 0])
    back = tilted.turned(tilt)
    assert np.allclose(back.x, straight.x, atol=1e-15) and np.allclose(back.z, straight.z, atol=1e-15)
    assert np.allclose(back.angles, straight.angles, atol=1e-15)
    with pytest.raises(RodError, match="tilt = 1.0: expected an angle in rad"):
        PlateContact(tilt=1.0)
