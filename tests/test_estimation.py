"""The estimation-quality objectives against hand-computed Cramér-Rao bounds, and the new indenters."""

from __future__ import annotations

import math

import numpy as np
import pytest

from softtip._core.units import MM
from softtip.design.model import load_design
from softtip.mechanics.indenters import CornerPlate, TiltedPlate
from softtip.optimize.estimation import (Steps, _simulations, cramer_rao, estimation_bounds,
                                         reading_covariance_uT2)
from softtip.optimize.runs import FEResult, Simulation
from softtip.sensors.mlx90393 import SENSOR, MLX90393Settings


def test_cramer_rao_of_one_parameter_is_variance_over_squared_slope():
    bound = cramer_rao(np.array([[2.0], [0.0], [1.0]]), np.array([4.0, 1.0, 1.0]))
    # Fisher = 2^2/4 + 1^2/1 = 2
    assert bound[0, 0] == pytest.approx(0.5)


def test_cramer_rao_of_a_redundant_parameter_is_infinite():
    jacobian = np.array([[1.0, 2.0], [2.0, 4.0], [0.5, 1.0]])
    assert np.isinf(cramer_rao(jacobian, np.ones(3))).all()


def test_reading_noise_includes_quantisation():
    settings = MLX90393Settings(gain_sel=7, res_xyz=(0, 0, 0), osr=0, dig_filt=2)
    variance = reading_covariance_uT2(SENSOR.at(settings), 2)
    # noise: 0.25 µT RMS on x and y at OSR 3 / DIG_FILT 7 (8 x 130 samples averaged), white, so at
    # OSR 0 / DIG_FILT 2 (1 x 6 samples) 0.25 sqrt(1040 / 6) µT; z the same in counts, so larger by
    # the sensitivity ratio 0.242 / 0.150; quantisation: LSB^2 / 12 with the LSBs of GAIN_SEL 7,
    # RES 0 (datasheet table 17: 0.150 µT on x and y, 0.242 µT on z). Quantisation is 2e-4 of the
    # total: the tolerance is far below it.
    noise_xy2 = 0.25**2 * 1040 / 6
    expected = np.array([noise_xy2 + 0.150**2 / 12, noise_xy2 + 0.150**2 / 12,
                         noise_xy2 * (0.242 / 0.150) ** 2 + 0.242**2 / 12])
    np.testing.assert_allclose(variance, np.tile(expected, 2), rtol=1e-6)


def _result(change_uT: np.ndarray, force: np.ndarray, rest_uT=np.zeros((1, 3))) -> FEResult:
    zeros = np.zeros((4, 3))
    return FEResult(feature_displacements_m=zeros, magnet_positions_m=zeros, magnet_rotvecs_rad=zeros,
                    force_N=np.asarray(force, float), field_rest_T=rest_uT * 1e-6,
                    field_change_T=np.asarray(change_uT, float).reshape(1, 3) * 1e-6,
                    contact_nodes=1, tetrahedra=1, unknowns=1)


def _linear_results(jacobian_uT: np.ndarray, force_jacobian: np.ndarray, steps: Steps, base: Simulation,
                    rest_uT=np.zeros((1, 3))):
    """FE results of a sensor whose readings are exactly linear in (angle rad, depth m, tx m, ty m)."""
    out = []
    for simulation in _simulations(base, steps):
        p = np.array([math.radians(simulation.angle_deg), simulation.depth_mm * MM,
                      simulation.tangential_mm[0] * MM, simulation.tangential_mm[1] * MM])
        out.append(_result(jacobian_uT @ p, force_jacobian @ p[1:], rest_uT))
    return out


def test_bounds_of_a_linear_sensor_match_the_analytic_formula():
    design = load_design("cylindrical-A")
    steps, base = Steps(), Simulation(depth_mm=1.5, angle_deg=22.5)
    jacobian = np.array([[30.0, 1e5, 2e5, 0.0],  # µT per rad and per m
                         [-10.0, 2e4, 0.0, 1.5e5],
                         [5.0, -3e5, 1e4, 1e4]])
    force_jacobian = np.array([[0.0, 800.0, 0.0], [0.0, 0.0, 800.0], [3000.0, 0.0, 0.0]])  # N per m
    bounds = estimation_bounds(design, _linear_results(jacobian, force_jacobian, steps, base), steps)
    variance = reading_covariance_uT2(design.chip_settings, 1)
    weights = np.diag(1 / variance)
    angle_depth = jacobian[:, :2]
    expected_angle = math.degrees(math.sqrt(np.linalg.inv(angle_depth.T @ weights @ angle_depth)[0, 0]))
    assert bounds.orientation_deg == pytest.approx(expected_angle, rel=1e-9)
    force_params = jacobian[:, 1:]
    expected_force = force_jacobian @ np.linalg.inv(force_params.T @ weights @ force_params) @ force_jacobian.T
    np.testing.assert_allclose(bounds.force_mN, np.sqrt(np.diag(expected_force)) * 1e3, rtol=1e-9)
    assert bounds.saturation_margin > 0


def test_a_saturating_design_has_a_negative_margin():
    design = load_design("cylindrical-A")
    steps, base = Steps(), Simulation(depth_mm=1.5, angle_deg=22.5)
    jacobian = np.zeros((3, 4))
    jacobian[2, 1] = 1e5
    rest = np.array([[0.0, 0.0, 60_000.0]])  # 60 mT: beyond every gain's full scale
    bounds = estimation_bounds(design, _linear_results(jacobian, np.eye(3), steps, base, rest), steps)
    assert bounds.saturation_margin < 0


def test_tilted_plate_gap_rises_along_its_uphill_direction():
    plate = TiltedPlate(tilt=math.radians(20), angle=math.radians(90))
    points = np.array([[0.0, 0.0, 0.0], [0.0, 2.0, 0.0], [3.0, 0.0, -1.0]])
    gap = plate.vertical_gap(points)[0]
    np.testing.assert_allclose(gap, [0.0, 2 * math.tan(math.radians(20)), 1.0], atol=1e-12)
    distance, normal = plate.signed_distance(points)
    np.testing.assert_allclose(distance, gap * math.cos(math.radians(20)), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(normal, axis=1), 1.0)


def test_corner_plate_covers_one_quadrant_of_its_turned_axes():
    corner = CornerPlate(angle=math.radians(45))
    points = np.array([[1.0, 0.0, -0.5], [-1.0, 0.0, -0.5], [0.0, 1.0, -0.5], [0.0, -1.0, -0.5]])
    gap = corner.vertical_gap(points)[0]
    # turned 45 deg: (1, 0) -> u, v = (0.707, -0.707) outside; (0, 1) -> (0.707, 0.707) inside
    assert np.isinf(gap[[0, 1, 3]]).all() and gap[2] == pytest.approx(0.5)
    assert corner.vertical_gap(points, extend=True)[0] == pytest.approx([0.5] * 4)
