"""The virtual lab: its mechanics against equilibrium and hand-computed cases, its realism against
the sensor datasheet, its protocol files, and a small experiment end to end."""

from __future__ import annotations

import json
import math
import textwrap
import tomllib

import numpy as np
import pytest

from softtip.data import Dataset
from softtip._core.units import MM
from softtip.design.model import load_design
from softtip.lab import load_protocol, protocol_from_dict, run_protocol
from softtip.systems.hall_fingertip.engine import HeldPart, _contact_forces, interpolate_path, path_table
from softtip._core.systems import is_own, names, owner
from softtip.lab.protocols import bench_of, shipped_protocol_path
from dataclasses import asdict
from softtip.systems.hall_fingertip.realism import FabricatedUnit, Realism
from softtip.mechanics.contact import LoadCase
from softtip.mechanics.indenters import Board
from softtip.mechanics.poses import MagnetPoses
from softtip.sensors.mlx90393 import MLX90393Settings, lsb_uT, noise_rms_uT
from softtip._core.config import ConfigError
from softtip.twin.influence import InfluenceEngine


@pytest.fixture(scope="module")
def coarse_rectangular() -> InfluenceEngine:
    return InfluenceEngine.build(load_design("rectangular"), 3.0 * MM, 2.0 * MM, curvature_points=3)


def test_contact_forces_of_two_points_by_hand():
    # D = [[2, 1], [1, 2]] m/N, both points 1 m into the plane: lambda = D^-1 [1, 1] = [1/3, 1/3]
    forces = _contact_forces(np.array([[2.0, 1.0], [1.0, 2.0]]), np.array([-1.0, -1.0]))
    np.testing.assert_allclose(forces, [1 / 3, 1 / 3])
    # only the first point reaches the plane far enough to touch: 1.5 lambda_0 = 1, point 2 stays off
    forces = _contact_forces(np.array([[1.5, 1.0], [1.0, 2.0]]), np.array([-1.0, 1.0]))
    np.testing.assert_allclose(forces, [2 / 3, 0.0])
    assert (_contact_forces(np.eye(2), np.array([0.5, 0.1])) == 0).all()


def test_held_part_is_in_equilibrium_and_touches_without_penetrating(coarse_rectangular):
    part = HeldPart.grasp(coarse_rectangular, 1.0 * MM, 1.7 * MM, (2 * MM, -1 * MM))
    normal = np.array([0.1, 0.5, 0.8])
    normal /= np.linalg.norm(normal)
    points = np.array([[0.04, -0.06, 0.0], [-0.04, -0.06, 0.0]])
    travel = np.array([0.0, 0.5e-3, 1e-3])
    out = part.collide(points, normal, -normal, travel)
    assert (out["contact_forces"][0] == 0).all() and (out["contact_forces"][-1] > 0).any()
    for k in range(len(travel)):
        # the pads' forces, turned into the part's frame, balance the plane's push (third law through
        # the pads' own nodal forces, not the stiffness the solver used)
        pads = sum(pad.rotation @ out[f"force_{i}"][k] for i, pad in enumerate(part.pads))
        plane = out["contact_forces"][k].sum() * normal
        np.testing.assert_allclose(pads, plane, atol=1e-9 + 1e-6 * np.abs(plane).max())
        # every touching point sits on the plane, no point is inside it
        q = out["q"][k]
        gaps = ((points - points[np.argmin(points @ normal)]) @ normal - travel[k]
                + (q[:3] + np.cross(q[3:], points)) @ normal)
        assert (gaps > -1e-12).all()
        touching = out["contact_forces"][k] > 0
        np.testing.assert_allclose(gaps[touching], 0.0, atol=1e-12)


def test_path_interpolation_is_exact_at_the_solved_states(coarse_rectangular):
    solution = coarse_rectangular.press(LoadCase(Board(), 1.0 * MM, tangential=(0.5 * MM, 0.0), friction="stick"),
                                        normal_steps=2, tangential_steps=2)
    table = path_table(solution)
    depth = np.array([0.0, 0.5, 1.0, 1.0, 1.0]) * MM
    tangential = np.array([[0, 0], [0, 0], [0, 0], [0.25, 0], [0.5, 0]]) * MM
    poses, force = interpolate_path(table, depth, tangential)
    np.testing.assert_allclose(poses.rigid, table[1], atol=1e-15)
    np.testing.assert_allclose(force, table[2], atol=1e-12)


def test_a_fabricated_unit_reads_the_datasheet_noise():
    design = load_design("cylindrical-A")
    rng = np.random.default_rng(3)
    exact = FabricatedUnit(design, Realism.off(), rng)
    np.testing.assert_array_equal(exact.sensor_positions, design.sensor_positions)
    still = MagnetPoses.at_rest(4, (4000,))
    times = np.arange(4000) / 20.0
    noisy = FabricatedUnit(design, Realism(drift_K_per_sqrt_s=0.0), rng).record(still, times, rng)
    settings = design.chip_settings.values
    # each reading is the field plus the noise, rounded to the LSB (the first sample, the baseline
    # subtracted from all, is a constant offset of the rest)
    expected = np.sqrt(noise_rms_uT(settings) ** 2 + lsb_uT(settings) ** 2 / 12)
    # the standard deviation of n Gaussian samples has a standard error of sd / sqrt(2 (n - 1)): 1.1 %
    # for these 3999; five of them
    np.testing.assert_allclose(noisy[1:, 0].std(axis=0), expected, rtol=5 / np.sqrt(2 * (len(times) - 2)))
    assert (exact.record(still, times, rng) == 0).all()


def test_every_shipped_protocol_lists_every_parameter_with_its_default_and_loads_as_written():
    for name in [name for name in names("protocol") if is_own(owner("protocol", name))]:  # softtip's own files
        text = shipped_protocol_path(name).read_text()
        written = tomllib.loads(text)
        # the files are the parameters' documentation: every parameter with its default (TOML has no
        # "none": a parameter unset by default is named in a comment); lists as TOML writes them
        defaults = json.loads(json.dumps(bench_of(name).defaults(name)))
        unset = [key for key, value in defaults.items() if value is None]
        assert written["parameters"] == {k: v for k, v in defaults.items() if v is not None}, name
        assert all(f"# {key}" in text for key in unset), (name, unset)
        protocol = load_protocol(name)
        assert protocol.name == name and json.loads(json.dumps(asdict(protocol.parameters))) == {
            **written["parameters"], **dict.fromkeys(unset)}
        assert protocol.realism.to_dict() == written["realism"] and protocol.seed == written["seed"]


@pytest.mark.parametrize("change, message", [
    ({"parameters": {"angles_deg": "all"}}, "parameters.angles_deg"),
    ({"parameters": {"speed": 1.0}}, "unknown key"),
    ({"protocol": "juggling"}, "protocol"),
    ({"realism": {"noise": 1}}, "realism.noise"),
    ({"realism": {"position_sd": 0.1}}, "unknown key"),
    ({"design": "cylindrical-Z"}, "design"),
])
def test_protocol_mistakes_are_one_line_errors(change, message):
    table = {"protocol": "pushing", "design": "cylindrical-A", "seed": 1, **change}
    with pytest.raises(ConfigError, match=message) as error:
        protocol_from_dict(table, "bad.toml")
    assert "\n" not in str(error.value)


@pytest.mark.slow
def test_a_small_pushing_experiment_gives_a_labelled_trial_dataset(tmp_path):
    path = tmp_path / "push.toml"
    path.write_text(textwrap.dedent("""
        protocol = "pushing"
        design = "cylindrical-D"
        seed = 4
        [parameters]
        mesh_size_mm = 2.5
        angles_deg = [0, 45]
        calibration_trials = 2
        validation_trials = 1
    """))
    dataset, _ = run_protocol(load_protocol(path))
    written = Dataset.read(dataset.write(tmp_path / "push.parquet"))
    assert len(written.trials) == 6 and written.metadata.seed == 4
    assert list(written.channels) == ["s0_bx_uT", "s0_by_uT", "s0_bz_uT"]
    depth, bz = written.column("depth_mm"), written.column("s0_bz_uT")
    assert depth.max() == pytest.approx(3.0, abs=0.06)
    # in the air the reading is the baseline's noise; pressed 3 mm the magnets approach the chip
    noise = noise_rms_uT(MLX90393Settings.from_dict(written.metadata.sensor_settings))[2]
    assert np.abs(bz[depth == 0]).max() < 8 * noise
    assert np.abs(bz[depth > 2.5]).min() > 100 * noise
    roles = written.trial_conditions["role"]
    assert list(roles).count("calibration") == 4
    assert math.isclose(written.column("time_s")[1], 1 / 20)
