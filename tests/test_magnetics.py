"""Tests of softtip.magnetics against independent references.

References: magpylib's ``Cylinder`` (an independent implementation of the
exact field), the point dipole, the exact on-axis formula, scipy's rotations,
and physical laws (superposition, rotation covariance, the jump of B_z by J
across the lateral surface).
"""

from __future__ import annotations


import magpylib as magpy
import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from softtip.design.model import polarization_from_surface_field
from softtip.magnetics import (
    axial_cylinder_field,
    magnet_axes,
    magnet_field_at_sensors,
)

MU0 = 4e-7 * np.pi
SHAPES = [(2e-3, 2e-3), (1e-3, 5e-3), (5e-3, 0.5e-3)]  # (radius, height): Ø4x2, long, flat


def relative_errors(field: NDArray[np.float64], reference: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.linalg.norm(field - reference, axis=-1) / np.linalg.norm(reference, axis=-1)


def magpylib_cylinder(radius: float, height: float, polarization: float) -> magpy.magnet.Cylinder:
    return magpy.magnet.Cylinder(polarization=(0.0, 0.0, polarization), dimension=(2.0 * radius, height))


def dipole_field(points: NDArray[np.float64], moment_z: float) -> NDArray[np.float64]:
    """Field (T) of a point dipole moment_z e_z (A m^2) at the origin."""
    r = np.linalg.norm(points, axis=1, keepdims=True)
    unit = points / r
    moment = np.array([0.0, 0.0, moment_z])
    return MU0 / (4.0 * np.pi * r**3) * (3.0 * (unit @ moment)[:, None] * unit - moment)


def magpylib_field(
    sensors: NDArray[np.float64],
    positions: NDArray[np.float64],
    rotvecs: NDArray[np.float64],
    radius: NDArray[np.float64],
    height: NDArray[np.float64],
    polarization: NDArray[np.float64],
) -> NDArray[np.float64]:
    """(N, S, 3) reference: each magnet as a magpylib Cylinder whose path is the N poses."""
    total = np.zeros((positions.shape[0], sensors.shape[0], 3))
    for m in range(positions.shape[1]):
        magnet = magpy.magnet.Cylinder(
            polarization=(0.0, 0.0, polarization[m]),
            dimension=(2.0 * radius[m], height[m]),
            position=positions[:, m],
            orientation=Rotation.from_rotvec(rotvecs[:, m]),
        )
        total += magnet.getB(sensors, squeeze=False)[0, :, 0]
    return total


def distance_to_edges(points: NDArray[np.float64], radius: float, height: float) -> NDArray[np.float64]:
    rho = np.hypot(points[:, 0], points[:, 1])
    dz = np.minimum(np.abs(points[:, 2] - 0.5 * height), np.abs(points[:, 2] + 0.5 * height))
    return np.hypot(rho - radius, dz)


def near_surface_points(
    rng: np.random.Generator, radius: float, height: float, n: int, offset: float
) -> NDArray[np.float64]:
    """Points `offset` inside or outside the faces and the mantle, kept 5 % of R from the edges."""
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    side = rng.choice([-1.0, 1.0], n)
    on_face = rng.random(n) < 0.5
    face_rho = radius * rng.uniform(0.0, 0.95, n)
    mantle_z = 0.5 * height * rng.uniform(-0.95, 0.95, n)
    top_or_bottom = rng.choice([-1.0, 1.0], n)
    rho = np.where(on_face, face_rho, radius + side * offset)
    z = np.where(on_face, top_or_bottom * (0.5 * height + side * offset), mantle_z)
    return np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=1)


def random_poses(
    rng: np.random.Generator, n_poses: int, n_magnets: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    positions = rng.uniform(-6e-3, 6e-3, (n_poses, n_magnets, 3))
    rotations = Rotation.random(n_poses * n_magnets, random_state=rng)
    return positions, rotations.as_rotvec().reshape(n_poses, n_magnets, 3)


@pytest.mark.parametrize(("radius", "height"), SHAPES)
def test_local_field_matches_magpylib_inside_outside_and_near_surfaces(radius: float, height: float) -> None:
    rng = np.random.default_rng(1)
    polarization = -1.3  # also checks the sign convention
    box = rng.uniform(-1.0, 1.0, (4000, 3)) * [2.0 * radius, 2.0 * radius, 1.5 * height]
    points = np.concatenate(
        [
            box[distance_to_edges(box, radius, height) > 1e-3 * radius],
            near_surface_points(rng, radius, height, 2000, offset=1e-7 * radius),
        ]
    )
    rho = np.hypot(points[:, 0], points[:, 1])
    inside = (rho < radius) & (np.abs(points[:, 2]) < 0.5 * height)
    assert 500 < inside.sum() < len(points) - 500  # both regions well sampled
    reference = magpylib_cylinder(radius, height, polarization).getB(points)

    field = axial_cylinder_field(points, radius, height, polarization)

    assert np.max(relative_errors(field, reference)) <= 1e-6


@pytest.mark.parametrize(("radius", "height"), SHAPES)
def test_local_field_matches_magpylib_to_rounding_close_to_the_edges(radius: float, height: float) -> None:
    # Slow AGM convergence (small kc) happens here; agreement is limited only
    # by the conditioning (~1e-16 R / distance), so the bound is tight.
    rng = np.random.default_rng(9)
    n = 600
    distance = radius * np.repeat([1e-2, 1e-4, 1e-6], n // 3)
    phi, around = rng.uniform(0.0, 2.0 * np.pi, (2, n))
    top_or_bottom = rng.choice([-1.0, 1.0], n)
    rho = radius + distance * np.cos(around)
    z = top_or_bottom * (0.5 * height + distance * np.sin(around))
    points = np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=1)
    reference = magpylib_cylinder(radius, height, 0.9).getB(points)

    field = axial_cylinder_field(points, radius, height, 0.9)

    assert np.max(relative_errors(field, reference)) <= 1e-9


def test_posed_magnets_match_magpylib_over_several_chunks() -> None:
    rng = np.random.default_rng(2)
    n_poses, n_magnets = 2500, 3  # 9 pairs per pose -> 910 poses per chunk -> 3 chunks
    positions, rotvecs = random_poses(rng, n_poses, n_magnets)
    sensors = rng.uniform(-6e-3, 6e-3, (3, 3))
    radius = np.array([2e-3, 1e-3, 3e-3])
    height = np.array([2e-3, 4e-3, 1e-3])
    polarization = np.array([1.2, -0.9, 1.4])
    reference = magpylib_field(sensors, positions, rotvecs, radius, height, polarization)

    field = magnet_field_at_sensors(sensors, positions, rotvecs, radius, height, polarization)

    assert field.shape == (n_poses, 3, 3)
    assert np.max(relative_errors(field, reference)) <= 1e-6


@pytest.mark.parametrize(
    ("radius", "height", "ratio_per_doubling"),
    # A centred cylinder has no quadrupole, so the first correction to the
    # dipole is the octupole: relative error ~ r^-2 (absolute ~ r^-5). At
    # height/diameter = sqrt(3)/2 the octupole vanishes too: relative ~ r^-4.
    [(r, h, 4.0) for r, h in SHAPES] + [(1e-3, np.sqrt(3.0) * 1e-3, 16.0)],
)
def test_far_field_converges_to_the_point_dipole(radius: float, height: float, ratio_per_doubling: float) -> None:
    polarization = 1.1
    moment_z = polarization * np.pi * radius**2 * height / MU0
    directions = np.random.default_rng(3).normal(size=(300, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    size = max(2.0 * radius, height)
    worst = []
    for factor in (20.0, 40.0, 80.0):
        points = directions * factor * size
        field = axial_cylinder_field(points, radius, height, polarization)
        worst.append(np.max(relative_errors(field, dipole_field(points, moment_z))))

    assert worst[0] <= 5e-3
    assert worst[0] / worst[1] == pytest.approx(ratio_per_doubling, rel=0.05)
    assert worst[1] / worst[2] == pytest.approx(ratio_per_doubling, rel=0.05)


@pytest.mark.parametrize(("radius", "height"), SHAPES)
def test_on_axis_field_is_the_closed_form(radius: float, height: float) -> None:
    polarization = -0.8
    half = 0.5 * height
    z = np.linspace(-4.0 * height, 4.0 * height, 801)  # through the magnet and its faces
    upper, lower = z + half, z - half
    expected_z = 0.5 * polarization * (upper / np.hypot(radius, upper) - lower / np.hypot(radius, lower))
    points = np.stack([np.zeros_like(z), np.zeros_like(z), z], axis=1)

    field = axial_cylinder_field(points, radius, height, polarization)

    assert np.all(field[:, :2] == 0.0)
    np.testing.assert_allclose(field[:, 2], expected_z, rtol=1e-12, atol=1e-15)


def test_polarization_from_surface_field_for_a_4x2_magnet() -> None:
    assert polarization_from_surface_field(0.330, 4e-3, 2e-3) == pytest.approx(0.933, abs=1e-3)


@pytest.mark.parametrize(("radius", "height"), SHAPES)
def test_polarization_from_surface_field_gives_that_face_centre_field(radius: float, height: float) -> None:
    polarization = polarization_from_surface_field(0.25, 2.0 * radius, height)

    face_centre = axial_cylinder_field([0.0, 0.0, 0.5 * height], radius, height, polarization)

    np.testing.assert_allclose(face_centre, [0.0, 0.0, 0.25], rtol=1e-12, atol=1e-15)


def test_field_is_the_superposition_of_single_magnets() -> None:
    rng = np.random.default_rng(5)
    positions, rotvecs = random_poses(rng, 400, 3)
    sensors = rng.uniform(-6e-3, 6e-3, (2, 3))
    radius = np.array([2e-3, 1e-3, 3e-3])
    height = np.array([2e-3, 4e-3, 1e-3])
    polarization = np.array([1.2, -0.9, 0.5])

    together = magnet_field_at_sensors(sensors, positions, rotvecs, radius, height, polarization)
    separately = sum(
        magnet_field_at_sensors(
            sensors, positions[:, m : m + 1], rotvecs[:, m : m + 1], radius[m], height[m], polarization[m]
        )
        for m in range(3)
    )

    np.testing.assert_allclose(together, separately, rtol=1e-12, atol=1e-12 * np.abs(together).max())


def test_rigid_motion_of_magnets_and_sensors_rotates_the_field() -> None:
    rng = np.random.default_rng(6)
    n_poses, n_magnets = 300, 4
    positions, rotvecs = random_poses(rng, n_poses, n_magnets)
    sensors = rng.uniform(-6e-3, 6e-3, (2, 3))
    radius, height, polarization = 2e-3, 2e-3, np.array([1.2, -1.2, 1.0, 0.7])
    motion = Rotation.from_rotvec([0.3, -1.1, 0.7])
    shift = np.array([1e-3, -2e-3, 5e-4])
    moved_rotvecs = (motion * Rotation.from_rotvec(rotvecs.reshape(-1, 3))).as_rotvec().reshape(rotvecs.shape)

    field = magnet_field_at_sensors(sensors, positions, rotvecs, radius, height, polarization)
    moved = magnet_field_at_sensors(
        motion.apply(sensors) + shift,
        motion.apply(positions.reshape(-1, 3)).reshape(positions.shape) + shift,
        moved_rotvecs,
        radius,
        height,
        polarization,
    )

    rotated = field @ motion.as_matrix().T
    np.testing.assert_allclose(moved, rotated, rtol=1e-9, atol=1e-12 * np.abs(field).max())


def test_zero_polarization_gives_exactly_zero_even_on_edges_and_surfaces() -> None:
    radius, height = 2e-3, 2e-3
    centre = np.array([1e-3, 2e-3, 3e-3])
    # Centre, face centre, an edge point, a lateral-surface point, the axis outside, far away.
    local = np.array([[0, 0, 0], [0, 0, 1e-3], [2e-3, 0, 1e-3], [2e-3, 0, 0], [0, 0, -5e-3], [1.0, 2.0, 3.0]])
    positions = np.broadcast_to(centre, (2, 1, 3))
    rotvecs = np.zeros((2, 1, 3))

    ambient = np.array([2e-5, -1e-5, 4.5e-5])
    args = (local + centre, positions, rotvecs, radius, height, 0.0)

    field = magnet_field_at_sensors(*args)
    with_ambient = magnet_field_at_sensors(*args, ambient=ambient)

    assert np.array_equal(field, np.zeros_like(field))
    assert np.array_equal(with_ambient, np.broadcast_to(ambient, with_ambient.shape))


def test_ambient_field_is_added_to_every_reading() -> None:
    rng = np.random.default_rng(7)
    positions, rotvecs = random_poses(rng, 50, 2)
    sensors = rng.uniform(-6e-3, 6e-3, (3, 3))
    ambient = np.array([3e-5, -2e-5, 4e-5])
    args = (sensors, positions, rotvecs, [2e-3, 1e-3], [2e-3, 3e-3], [1.2, -1.2])

    difference = magnet_field_at_sensors(*args, ambient=ambient) - magnet_field_at_sensors(*args)

    scale = np.abs(magnet_field_at_sensors(*args)).max()
    expected = np.broadcast_to(ambient, difference.shape)
    np.testing.assert_allclose(difference, expected, rtol=0, atol=1e-15 * scale)


def test_lateral_surface_returns_the_mean_of_the_limits_and_bz_jumps_by_j() -> None:
    radius, height, polarization = 2e-3, 2e-3, 1.2
    z = np.linspace(-0.9e-3, 0.9e-3, 7)
    on = np.stack([np.full_like(z, radius), np.zeros_like(z), z], axis=1)
    inside, outside = on * [1 - 1e-10, 1, 1], on * [1 + 1e-10, 1, 1]

    field_on, field_in, field_out = (
        axial_cylinder_field(p, radius, height, polarization) for p in (on, inside, outside)
    )

    np.testing.assert_allclose(field_in[:, 2] - field_out[:, 2], polarization, rtol=1e-6)
    np.testing.assert_allclose(field_on, 0.5 * (field_in + field_out), rtol=1e-6, atol=1e-9)


def test_edge_circles_return_the_documented_finite_value() -> None:
    radius, height, polarization = 2e-3, 2e-3, 1.2
    phi = np.linspace(0.0, 2.0 * np.pi, 5)
    ring = np.stack([radius * np.cos(phi), radius * np.sin(phi), np.full_like(phi, 0.5 * height)], axis=1)
    edges = np.concatenate([ring, ring * [1, 1, -1]])

    field = axial_cylinder_field(edges, radius, height, polarization)

    assert np.all(np.isfinite(field))
    # Mirror symmetry: B_rho odd in z, B_z even.
    np.testing.assert_allclose(field[:5], field[5:] * [-1, -1, 1], rtol=1e-12, atol=1e-12)
    b_rho = np.einsum("ij,ij->i", field[:5, :2], ring[:, :2]) / radius
    # B_rho ~ c0 + c1 ln(distance) near the edge: extrapolate magpylib's values
    # 1e-5 R and 1e-7 R outside to the documented 2e-15 R.
    top = np.array([radius, 0.0, 0.5 * height])
    offsets = np.array([1e-5, 1e-7])
    outside_points = top * np.stack([1 + offsets, [1, 1], [1, 1]], axis=1)
    beside = magpylib_cylinder(radius, height, polarization).getB(outside_points)
    slope = (beside[1, 0] - beside[0, 0]) / np.log(offsets[1] / offsets[0])
    extrapolated = beside[1, 0] + slope * np.log(2e-15 / offsets[1])
    np.testing.assert_allclose(b_rho, extrapolated, rtol=1e-4)
    assert b_rho[0] > 3.0 * polarization  # log-divergent, outward at the top
    # B_z: the mean of its limits from inside and outside.
    limits = axial_cylinder_field(top * [[1 - 1e-9, 1, 1], [1 + 1e-9, 1, 1]], radius, height, polarization)
    np.testing.assert_allclose(field[:5, 2], 0.5 * (limits[0, 2] + limits[1, 2]), rtol=1e-6)


def test_a_point_does_not_depend_on_the_rest_of_its_batch() -> None:
    radius, height, polarization = 2e-3, 2e-3, 1.2
    far = np.array([[3e-3, 1e-3, 5e-3]])
    alone = axial_cylinder_field(far, radius, height, polarization)
    # An almost-edge point forces more AGM steps on the whole batch.
    almost_edge = [[radius * (1 + 1e-12), 0.0, 0.5 * height]]
    with_edge = axial_cylinder_field(np.vstack([far, almost_edge]), radius, height, polarization)
    np.testing.assert_allclose(with_edge[0], alone[0], rtol=1e-14)


@pytest.mark.parametrize("angle", [0.0, 1e-9, 5e-4, 0.4, np.pi, 2.0 * np.pi, 3.5, 31.0])
def test_magnet_axes_match_scipy_rotations(angle: float) -> None:
    directions = np.random.default_rng(8).normal(size=(200, 3))
    rotvecs = angle * directions / np.linalg.norm(directions, axis=1, keepdims=True)

    axes = magnet_axes(rotvecs)

    np.testing.assert_allclose(axes, Rotation.from_rotvec(rotvecs).as_matrix()[:, :, 2], rtol=0, atol=2e-15)


def test_per_point_parameters_broadcast() -> None:
    points = np.array([[1e-3, 0.0, 3e-3], [0.0, 2e-3, -4e-3]])
    radius, height, polarization = np.array([1e-3, 2e-3]), np.array([2e-3, 1e-3]), np.array([1.0, -0.5])

    together = axial_cylinder_field(points, radius, height, polarization)

    for i in range(2):
        alone = axial_cylinder_field(points[i], radius[i], height[i], polarization[i])
        np.testing.assert_allclose(together[i], alone, rtol=1e-14)


@pytest.mark.parametrize(
    ("sensors", "positions", "rotvecs", "radius"),
    [
        (np.zeros((2, 2)), np.zeros((1, 1, 3)), np.zeros((1, 1, 3)), 1e-3),  # sensors not (S, 3)
        (np.zeros((2, 3)), np.zeros((1, 3)), np.zeros((1, 3)), 1e-3),  # positions not (N, M, 3)
        (np.zeros((2, 3)), np.zeros((1, 1, 3)), np.zeros((2, 1, 3)), 1e-3),  # rotvecs mismatch
        (np.zeros((2, 3)), np.zeros((1, 1, 3)), np.zeros((1, 1, 3)), 0.0),  # degenerate magnet
        (np.zeros((2, 3)), np.zeros((1, 2, 3)), np.zeros((1, 2, 3)), [1e-3, 1e-3, 1e-3]),  # 3 radii, 2 magnets
    ],
)
def test_invalid_inputs_are_rejected(
    sensors: NDArray[np.float64],
    positions: NDArray[np.float64],
    rotvecs: NDArray[np.float64],
    radius: float | list[float],
) -> None:
    with pytest.raises(ValueError):
        magnet_field_at_sensors(sensors, positions, rotvecs, radius, 2e-3, 1.0)


def test_ambient_must_be_a_3_vector() -> None:
    with pytest.raises(ValueError):
        magnet_field_at_sensors(np.zeros((1, 3)), np.ones((1, 1, 3)), np.zeros((1, 1, 3)), 1e-3, 1e-3, 1.0, [0.0, 0.0])


def test_empty_batches_and_no_magnets_give_empty_or_ambient_fields() -> None:
    ambient = np.array([1e-5, 0.0, -2e-5])
    sensors = np.zeros((2, 3))
    no_poses = magnet_field_at_sensors(sensors, np.zeros((0, 3, 3)), np.zeros((0, 3, 3)), 1e-3, 1e-3, 1.0)
    no_magnets = magnet_field_at_sensors(sensors, np.zeros((4, 0, 3)), np.zeros((4, 0, 3)), [], [], [], ambient)

    assert no_poses.shape == (0, 2, 3)
    assert np.array_equal(no_magnets, np.broadcast_to(ambient, (4, 2, 3)))
    assert axial_cylinder_field(np.zeros((0, 3)), 1e-3, 1e-3, 1.0).shape == (0, 3)
