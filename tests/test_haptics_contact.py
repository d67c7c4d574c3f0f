"""Plate-on-cap contact laws and the 6-axis force/torque sensor, against analytic and independent references."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from softtip.mechanics.plate_contact import exponential_force
from softtip.mechanics.plate_contact import (
    PlateContactLaw,
    cap_indentation,
    contact_radius,
    layer_force,
    normal_force,
    plate_wrench,
)
from softtip.sensors.wrench import NANO17_WRENCH, held_wrench, read_wrenches, shift_wrench, wrench_in_frame

HERTZ = PlateContactLaw(law="hertz", youngs_modulus=1.14e6, poisson_ratio=0.5)


def test_hertz_matches_the_contact_radius_form_of_the_analytic_solution():
    radius, depth = 7.5e-3, 0.4e-3
    reduced = 1.14e6 / (1 - 0.25)
    a = math.sqrt(radius * depth)  # Johnson (1985) eq. 4.22: F = 4 E* a³ / 3R
    assert normal_force(HERTZ, depth, radius) == pytest.approx(4 * reduced * a**3 / (3 * radius), rel=1e-12)
    assert normal_force(HERTZ, -1e-4, radius) == 0.0


def test_tilted_plate_on_a_sphere_pushes_along_its_normal_through_the_centre_line():
    normal = np.array([0.0, math.sin(0.3), math.cos(0.3)])
    centre = np.zeros(3)
    plate_point = centre - (7.5e-3 - 0.4e-3) * normal  # the plate 0.4 mm into the cap
    wrench, depth = plate_wrench(HERTZ, centre, [7.5e-3] * 3, plate_point, normal, centre)
    assert depth == pytest.approx(0.4e-3)
    assert np.allclose(wrench[:3], normal_force(HERTZ, 0.4e-3, 7.5e-3) * normal)
    assert np.allclose(wrench[3:], 0.0, atol=1e-15)  # the force line passes through the centre


def test_ellipsoid_indentation_matches_a_sampled_surface():
    semi_axes = np.array([7e-3, 11e-3, 5e-3])
    normal = np.array([0.2, -0.3, 0.93])
    normal /= np.linalg.norm(normal)
    plate_point = np.array([0.001, 0.0, -0.0045])
    depth, point, radius = cap_indentation(np.zeros(3), semi_axes, plate_point, normal)
    theta, phi = np.meshgrid(np.linspace(0, np.pi, 1500), np.linspace(0, 2 * np.pi, 3000))
    surface = semi_axes * np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)
    penetration = -np.min((surface - plate_point) @ normal)
    assert depth == pytest.approx(penetration, abs=2e-8)
    assert np.dot(point - plate_point, normal) == pytest.approx(0.0, abs=1e-15)  # on the plate's face
    # a sphere's effective radius is its radius
    assert cap_indentation(np.zeros(3), [6e-3] * 3, plate_point, normal)[2] == pytest.approx(6e-3)


def test_exponential_law_is_the_finger_pad_law_scaled_by_radius():
    law = PlateContactLaw(law="exponential", stiffness=330.0, stiffening=1700.0, reference_radius=7.5e-3)
    assert normal_force(law, 1e-3, 7.5e-3) == pytest.approx(exponential_force(1e-3, 330.0, 1700.0))
    assert normal_force(law, 1e-3, 15e-3) == pytest.approx(2 * exponential_force(1e-3, 330.0, 1700.0))


def test_thin_layer_law_solves_the_layer_equation():
    """Integrate the thin-layer pressure equation p'' + p'/r = −3G w(r)/t³ inwards from the contact edge
    (p = p' = 0): only at the stated edge radius is the pressure regular at the axis, and its integral
    is the stated force."""
    law = PlateContactLaw(law="layer", youngs_modulus=1.2e6, poisson_ratio=0.5, layer_thickness=2e-3)
    radius, depth = 8e-3, 0.3e-3
    shear, thickness = law.shear_modulus, law.layer_thickness

    def inwards(edge):
        def rhs(r, state):
            pressure, slope, force = state
            source = -3 * shear * (depth - r**2 / (2 * radius)) / thickness**3
            return [slope, source - slope / r, -2 * np.pi * r * pressure]
        return solve_ivp(rhs, (edge, edge * 1e-6), [0.0, 0.0, 0.0], rtol=1e-11, atol=1e-14)

    edge = contact_radius(law, depth, radius)
    exact = inwards(edge)
    scale = 3 * shear * depth * edge**2 / thickness**3  # the pressure's scale (Pa)

    def singular_part(solution):  # r p'(r) at the axis over the pressure's scale: 0 for a pressure regular there
        return abs(solution.t[-1] * solution.y[1, -1]) / scale

    assert singular_part(exact) < 1e-9
    assert exact.y[2, -1] == pytest.approx(normal_force(law, depth, radius), rel=1e-6)
    assert exact.y[2, -1] == pytest.approx(layer_force(depth, radius, shear, thickness), rel=1e-6)
    wrong = inwards(edge * 0.9)
    assert singular_part(wrong) > 1e-2


def test_unknown_law_and_bad_poisson_ratio_are_refused():
    with pytest.raises(ValueError, match="contact.law = .hooke.: expected one of hertz, bonded-layer, exponential"):
        PlateContactLaw(law="hooke")
    with pytest.raises(ValueError, match="contact.poisson_ratio = 0.6"):
        PlateContactLaw(law="hertz", poisson_ratio=0.6)
    with pytest.raises(ValueError, match="plate_normal"):
        plate_wrench(HERTZ, np.zeros(3), [7e-3] * 3, np.zeros(3), np.zeros(3), np.zeros(3))


def test_nano17_reads_within_its_datasheet_ranges_and_flags_saturation():
    reading, saturated = read_wrenches(np.array([20.0, 0.0, -5.0, 0.2, 0.0, 0.001]), NANO17_WRENCH)
    assert reading[0] == 12.0 and reading[3] == 0.12
    assert saturated.tolist() == [True, False, False, True, False, False]
    assert NANO17_WRENCH.torque.resolution[0] == pytest.approx(1 / 64 * 1e-3)  # 1/64 N·mm


def test_a_held_reading_averages_the_noise_over_its_window():
    rng = np.random.default_rng(1)
    wrench = np.tile([1.0, -2.0, 3.0, 0.01, 0.0, -0.02], (4000, 1))
    mean, saturated = held_wrench(wrench, NANO17_WRENCH, 0.2, rng)
    assert not saturated.any()
    # 200 samples at 1 kHz of one step RMS, rounded to the step: the mean's spread is
    # √(σ² + step²/12)/√200 for σ = one step
    step = 1 / 320
    expected = math.sqrt(step**2 + step**2 / 12) / math.sqrt(200)
    assert np.std(mean[:, 0]) == pytest.approx(expected, rel=0.05)
    assert np.mean(mean[:, 2]) == pytest.approx(3.0, abs=4 * expected / math.sqrt(4000))
    with pytest.raises(ValueError, match="window_s"):
        held_wrench(wrench, NANO17_WRENCH, 0.0, rng)


def test_wrench_moves_and_turns_as_forces_and_torques_do():
    force, point = np.array([0.3, -1.0, 2.0]), np.array([0.002, 0.001, -0.01])
    about_origin = np.concatenate([force, np.cross(point, force)])
    other = np.array([0.0, 0.005, 0.0])
    assert np.allclose(shift_wrench(about_origin, np.zeros(3), other)[3:], np.cross(point - other, force))
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # axes turned 90 degrees about z
    assert np.allclose(wrench_in_frame(about_origin, turn)[:3], [force[1], -force[0], force[2]])


def test_bonded_layer_law_tends_to_hertz_for_a_thick_layer_and_stiffens_on_a_thin_one():
    from softtip.mechanics.plate_contact import bonded_layer_force, hertz_force

    thick = bonded_layer_force(1e-4, 7.5e-3, 1e6, 1.0)  # a 1 m layer: Hertz's half space
    assert thick == pytest.approx(hertz_force(1e-4, 7.5e-3, 1e6, 0.5), rel=1e-3)
    # χ = √(Rδ)/t = 1: the printed series sums to 1 + 1.133 + 1.283 + 0.769 + 0.0975
    law = PlateContactLaw(law="bonded-layer", youngs_modulus=1e6, layer_thickness=math.sqrt(7.5e-3 * 1e-3))
    hertz = normal_force(PlateContactLaw(law="hertz", youngs_modulus=1e6), 1e-3, 7.5e-3)
    assert normal_force(law, 1e-3, 7.5e-3) == pytest.approx(4.2825 * hertz)
    with pytest.raises(ValueError, match="contact.poisson_ratio = 0.45: expected 0.5"):
        PlateContactLaw(law="bonded-layer", poisson_ratio=0.45)
