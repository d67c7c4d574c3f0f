"""The twin composed once: the same readout after every engine, one magnet-pose type.

References: the engines are checked against each other on the same loads (the finite-element
solve with its penalty against the exact solve on the influence matrices it was built from),
and the readout against magpylib's cylinder field at the fabricated geometry.
"""

from __future__ import annotations

import magpylib
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from softtip.design.model import MM, load_design
from softtip.systems.hall_fingertip.realism import FabricatedUnit, Realism
from softtip.mechanics.contact import LoadCase
from softtip.mechanics.indenters import Board, Sphere
from softtip.mechanics.poses import MagnetPoses
from softtip.twin import Readout, Twin
from softtip.twin.influence import InfluenceEngine
from softtip.twin.reduced import IndenterFamily, LoadRanges, ReducedTwin


@pytest.fixture(scope="module")
def design():
    return load_design("cylindrical-A")


def test_finite_element_and_influence_engines_give_the_same_readings(design):
    load = LoadCase(Board(1.6e-3, 0.4), 1.2e-3, position=(0.5e-3, -1e-3), friction="stick")
    fe = Twin.finite_element(design, mesh_size=2.5 * MM).simulate(load, noise=False)
    influence = Twin(InfluenceEngine.build(design, 2.5 * MM, reach=5 * MM)).simulate(load, noise=False)
    assert fe.model == "linear" and influence.model == "influence"
    # the FE solver enforces contact by a stiff penalty (1e-4 relative), the influence solve exactly
    np.testing.assert_allclose(influence.force, fe.force, atol=2e-3 * np.abs(fe.force).max())
    np.testing.assert_allclose(influence.field_change, fe.field_change, atol=2e-3 * np.abs(fe.field_change).max())
    np.testing.assert_allclose(influence.feature_displacements, fe.feature_displacements,
                               atol=2e-3 * np.abs(fe.feature_displacements).max())


def test_a_fabricated_unit_reads_magpylibs_field_at_its_own_geometry(design):
    unit = FabricatedUnit(design, Realism(), np.random.default_rng(5))
    assert not np.allclose(unit.sensor_positions, design.sensor_positions)
    rng = np.random.default_rng(6)
    poses = MagnetPoses(rng.uniform(-3e-4, 3e-4, (3, 4, 3)), rng.uniform(-0.05, 0.05, (3, 4, 3)))
    ours = unit.field(poses)
    for k in range(3):
        magnets = [magpylib.magnet.Cylinder(polarization=(0, 0, j), dimension=(m.diameter, m.height),
                                            position=c + t, orientation=Rotation.from_rotvec(r))
                   for m, j, c, t, r in zip(design.magnets, unit.polarizations, unit.rest_positions,
                                            poses.translation[k], poses.rotvec[k])]
        expected = magpylib.getB(magnets, unit.sensor_positions, sumup=True).reshape(-1, 3)
        np.testing.assert_allclose(ours[k], expected, rtol=1e-6, atol=1e-12)


def test_noiseless_readings_are_magpylibs_field_change_from_rest(design):
    readout = Readout(design)
    translation = np.array([1e-4, 1e-4, -1e-4])  # every magnet moved alike, not rotated

    def magpylib_field(shift: np.ndarray) -> np.ndarray:
        magnets = [magpylib.magnet.Cylinder(polarization=(0, 0, m.polarization), dimension=(m.diameter, m.height),
                                            position=np.array(m.center) + shift) for m in design.magnets]
        return magpylib.getB(magnets, design.sensor_positions, sumup=True).reshape(-1, 3)

    change, counts = readout.readings(MagnetPoses.from_rigid(np.tile(np.r_[translation, 0, 0, 0], (1, 4, 1))),
                                      noise=False)
    expected_uT = (magpylib_field(translation) - magpylib_field(np.zeros(3))) * 1e6
    np.testing.assert_allclose(change[0], expected_uT, rtol=1e-6, atol=1e-6)
    assert counts.dtype.kind in "iu"


@pytest.fixture(scope="module")
def small_reduced_twin(design):
    ranges = LoadRanges(position_radius=2 * MM, depth=1.5 * MM, shear_fraction=0.0)
    return ReducedTwin.build(design, IndenterFamily("board", friction="none"), ranges, mesh_size=2.5 * MM,
                             samples=150, holdout=2, exact_holdout=20, hidden=(8,), workers=1)


def test_the_reduced_engine_answers_load_cases_and_parameters_alike(small_reduced_twin):
    twin = Twin(small_reduced_twin)
    params = np.array([[0.5e-3, -0.2e-3, 0.3, 1.0e-3, 0.0, 0.0], [-1e-3, 0.4e-3, 2.0, 0.6e-3, 0.0, 0.0]])
    loads = [small_reduced_twin.family.load(p) for p in params]
    np.testing.assert_array_equal(small_reduced_twin.family.parameters(loads[1]), params[1])
    by_load = twin.readings(loads, noise=False)
    by_params = twin.readings(params, noise=False)
    for a, b in zip(by_load, by_params):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)


def test_the_reduced_engine_refuses_loads_it_was_not_built_for(small_reduced_twin):
    family = small_reduced_twin.family
    with pytest.raises(ValueError, match="sphere"):
        family.parameters(LoadCase(Sphere(5e-3), 1e-3))
    with pytest.raises(ValueError, match="thickness"):
        family.parameters(LoadCase(Board(2.0e-3), 1e-3))
    with pytest.raises(ValueError, match="friction"):
        family.parameters(LoadCase(Board(1.6e-3), 1e-3, friction="stick"))
    with pytest.raises(TypeError, match="load parameters"):
        Twin.finite_element(small_reduced_twin.design, mesh_size=2.5 * MM).readings(np.zeros((1, 6)))
