"""The reduced-order twin: influence-matrix contact against the finite-element solver,
storage without pickle, and time series of motions."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import scipy.sparse.linalg

from softtip._core.archive import write_archive
from softtip._core.progress import Task
from softtip._core.units import MM
from softtip.design.model import load_design
from softtip.mechanics.contact import (FootprintBody, LoadCase, SurfaceInfluence, SurfacePatch, solve_footprint_contact,
                                      solve_influence_contact, solve_linear_contact)
from softtip.mechanics.fe import BodyModel
from softtip.mechanics.indenters import Board, Sphere
from softtip.mechanics.mesh import mesh_design
from softtip.mechanics.motion import Motion
from softtip.mechanics.viscoelastic import PronySeries
from softtip.twin import Twin
from softtip.twin.reduced import IndenterFamily, LoadRanges, ReducedTwin, _fit_networks, _held_loads


@pytest.fixture(scope="module")
def coarse():
    design = load_design("cylindrical-A")
    body = BodyModel.for_design(design, mesh_design(design, 2.5 * MM))
    return design, body, SurfaceInfluence.build(body, lowest_z=5 * MM)


@pytest.mark.parametrize(
    "load",
    [
        LoadCase(Board(1.6e-3, 0.0), 1e-3, friction="none"),
        LoadCase(Board(1.6e-3, 0.6), 1.5e-3, position=(1e-3, -2e-3), friction="stick"),
        LoadCase(Board(1.6e-3, 0.3), 2e-3, tangential=(1e-3, -0.5e-3), friction="stick"),
        # without friction, nodes the board travels off are released
        LoadCase(Board(1.6e-3, 1.1), 1.5e-3, tangential=(0.6e-3, 0.4e-3), friction="none"),
        LoadCase(Sphere(5e-3), 1e-3, position=(2e-3, 0.0), friction="none"),
    ],
)
def test_influence_matrix_contact_equals_the_finite_element_solution(coarse, load):
    _, body, influence = coarse
    fe = solve_linear_contact(body, load)
    exact = solve_influence_contact(influence, load)
    fe_rigid = fe.magnet_poses.rigid
    # the FE solver enforces contact by a stiff penalty (1e-4 relative), the influence solve exactly
    np.testing.assert_allclose(exact.force, fe.force, atol=1e-3 * np.abs(fe.force).max())
    np.testing.assert_allclose(exact.magnet_poses.rigid[:, :3], fe_rigid[:, :3], atol=1e-3 * np.abs(fe_rigid[:, :3]).max())


def test_compliance_is_reciprocal_and_positive_definite(coarse):
    _, body, influence = coarse
    # Maxwell-Betti: any two loads f1, f2 on the surface do equal work through each other's
    # displacements, f1 . u(f2) = f2 . u(f1). Checked on raw back-substitutions with the whole
    # stiffness (SuperLU reads both triangles; the build's matrix is symmetrised, and its solver
    # reads one triangle only) for eight random surface loads
    columns = body.node_dofs[influence.node_ids].ravel()
    loads = np.random.default_rng(5).normal(size=(len(columns), 8))
    full = np.zeros((body.size, 8))
    full[columns] = loads
    work = loads.T @ scipy.sparse.linalg.splu(body.stiffness.tocsc()).solve(full)[columns]  # f_a . u(f_b)
    scale = np.abs(work).max()
    np.testing.assert_allclose(work, work.T, rtol=0, atol=1e-10 * scale)
    # and the influence matrix does the same work: it is the compliance, not only symmetric
    np.testing.assert_allclose(loads.T @ influence.compliance @ loads, work, rtol=0, atol=1e-10 * scale)
    np.linalg.cholesky(influence.compliance)  # positive definite, all of it: fails otherwise


def test_a_board_shifted_along_itself_is_the_same_load(coarse):
    # the physics behind the network's inputs: only the board's centre line matters
    _, _, influence = coarse
    angle, shift = 0.6, 2e-3
    along = np.array([math.cos(angle), math.sin(angle)])
    results = [solve_influence_contact(influence, LoadCase(Board(1.6e-3, angle), 1.2e-3, tangential=(0.4e-3, 0.2e-3),
                                                 position=tuple(np.array([0.5e-3, -0.3e-3]) + k * shift * along),
                                                 friction="stick"))
               for k in (0, 1)]
    np.testing.assert_allclose(results[1].force, results[0].force, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(results[1].magnet_poses.rigid, results[0].magnet_poses.rigid, rtol=1e-9, atol=1e-15)


def test_network_inputs_of_a_board_are_invariant_along_it_and_under_a_half_turn():
    from softtip.twin.reduced import _features

    board, sphere = IndenterFamily("board"), IndenterFamily("sphere")
    angle = 0.4
    along = np.array([math.cos(angle), math.sin(angle)])
    loads = np.array([[1e-3, 2e-3, angle, 1e-3, 2e-4, -1e-4]] * 3)
    loads[1, :2] += 1.5e-3 * along  # the same board line
    loads[2, 2] += math.pi  # the same board turned half a turn
    features = _features(loads, board)
    np.testing.assert_allclose(features[1], features[0], atol=1e-15)
    np.testing.assert_allclose(features[2], features[0], atol=1e-15)
    # hand-computed foot of the line from the axis: (p . a) a, a = (-sin, cos)
    across = np.array([-math.sin(angle), math.cos(angle)])
    np.testing.assert_allclose(features[0, :2], (loads[0, :2] @ across) * across)
    # a sphere has no such line: its position is its own
    np.testing.assert_allclose(_features(loads, sphere)[1, :2], loads[1, :2])


def test_a_load_slides_when_it_needs_more_friction_than_mu():
    # hand-computed: |Ft| / Fz = 0.6, 0.8 and hypot(0.5, 0.5) = 0.707 against mu = 0.7
    forces = np.array([[0.6, 0.0, 1.0], [0.0, -0.8, 1.0], [0.5, 0.5, 1.0]])
    assert IndenterFamily(friction="stick").slides(forces).tolist() == [False, True, True]
    assert IndenterFamily(friction="stick", mu=0.75).slides(forces).tolist() == [False, True, False]
    # without friction nothing holds the board, and with Coulomb's law sliding is part of the model
    assert not IndenterFamily(friction="none").slides(forces).any()
    assert not IndenterFamily(friction="coulomb").slides(forces).any()


def test_a_sticking_twin_samples_the_loads_the_board_holds(coarse):
    design, body, influence = coarse
    patch = SurfacePatch(body, 5 * MM)
    family = IndenterFamily(friction="stick")
    ranges = LoadRanges(position_radius=2 * MM, depth=1.5 * MM, shear_fraction=1.0)
    params, solutions, (sliding, slid), share = _held_loads(influence, patch, family, ranges,
                                                            np.random.default_rng(0), 24, 1, Task())
    assert len(params) == 24 and 0 < share < 1 and len(sliding)  # shallow drags slide
    assert not family.slides(solutions[:, -3:]).any() and family.slides(slid[:, -3:]).all()
    assert share == pytest.approx(len(params) / (len(params) + len(sliding)), abs=0.1)
    # every load keeps its own solution
    for p, solution in ((params[5], solutions[5]), (sliding[0], slid[0])):
        exact = solve_footprint_contact(FootprintBody(patch, influence.compliance_of), family.load(p))
        np.testing.assert_allclose(solution[-3:], exact.force, rtol=1e-12)


@pytest.fixture(scope="module")
def tiny_twin():
    design = load_design("cylindrical-A")
    # frictionless normal pushes keep the build to seconds; stick and shear are covered above
    ranges = LoadRanges(position_radius=2 * MM, depth=1.5 * MM, shear_fraction=0.0)
    return ReducedTwin.build(design, IndenterFamily("board", friction="none"), ranges, mesh_size=2.5 * MM,
                             samples=200, holdout=3, exact_holdout=40, hidden=(8,), workers=1)


def test_reduced_twin_reports_its_held_out_fe_error(tiny_twin):
    holdout, exact = tiny_twin.report["holdout"], tiny_twin.report["exact_holdout"]
    assert holdout["loads"] == 3 and exact["loads"] == 40
    assert np.array(holdout["magnet_displacement_error_percent_range"]).shape == (4, 3)
    assert holdout["fe_seconds_per_load"] > holdout["reduced_seconds_per_load_unbatched"]
    # What an 8-neuron network fitted to 200 normal pushes achieves (this seeded build: on the FE loads
    # 12 / 11 / 6.9 % of full scale on x / y / z, force 9.8 % of the largest; on the exact loads 46 / 38
    # / 5.9 % and 3.7 %). Normal pushes load z: it is followed to a few percent; x and y see only the
    # small lateral field of an off-centre push (full scale 240 µT against 1280 µT on z), which so small
    # a network follows coarsely. The bounds leave a third for rounding between machines; a twin that
    # learnt nothing errs by 100 % of full scale. The realistic build meets 2 % (test_rom_default_size.py).
    for report, sensor_bounds, force_bound in ((holdout, [16, 16, 10], 13), (exact, [60, 50, 8], 5)):
        errors = np.array(report["sensor_error_percent_fs"])
        assert errors.shape == (1, 3)  # one sensor
        assert np.all(errors[0] < sensor_bounds)
        assert report["force_error_percent_of_largest"][:2] == [None, None]  # normal pushes: no shear force
        assert report["force_error_percent_of_largest"][2] < force_bound


def test_networks_fit_side_by_side_as_they_would_one_after_the_other(tiny_twin):
    rng = np.random.default_rng(0)
    features, targets = rng.normal(size=(120, 7)), rng.normal(size=(120, 5))
    serial = _fit_networks(features, targets, (6,), 3, 2, workers=1)
    parallel = _fit_networks(features, targets, (6,), 3, 2, workers=2)
    for a, b in zip(serial, parallel):
        for wa, wb in zip(a["weights"], b["weights"]):
            np.testing.assert_array_equal(wa, wb)
    # independent initialisations: two different networks, and the twin averages its own two
    assert not np.allclose(serial[0]["weights"][0], serial[1]["weights"][0])
    assert len(tiny_twin.networks) == 2


def test_errors_are_percent_of_the_full_scale_over_the_load_ranges(tiny_twin):
    params = tiny_twin.ranges.sample(np.random.default_rng(5), 20)
    rigid, force = tiny_twin.predict(params)
    scales = {"field_T": np.full((1, 3), 1e-3), "displacement_m": np.full((4, 3), 1e-4)}
    # a reference 10 µm off in every magnet's x: 10 % of a 100 µm range, field errors of that shift
    shifted = rigid.copy()
    shifted[..., 0] += 10e-6
    errors = tiny_twin._errors((rigid, force), shifted, force, scales)
    np.testing.assert_allclose(np.array(errors["magnet_displacement_error_percent_range"])[:, 0], 10.0)
    np.testing.assert_allclose(np.array(errors["magnet_displacement_error_percent_range"])[:, 1:], 0.0, atol=1e-9)
    field_change = np.abs(tiny_twin._field(rigid) - tiny_twin._field(shifted)).max(axis=0)
    np.testing.assert_allclose(errors["sensor_error_percent_fs"], field_change / 1e-3 * 100)


def test_reduced_twin_round_trips_through_its_archive(tiny_twin, tmp_path):
    path = tiny_twin.save(tmp_path / "twin")
    again = ReducedTwin.load(path)
    params = tiny_twin.ranges.sample(np.random.default_rng(3), 50)
    for a, b in zip(tiny_twin.predict(params), again.predict(params)):
        np.testing.assert_array_equal(a, b)
    assert again.report == json.loads(json.dumps(tiny_twin.report))


def test_tampered_truncated_and_foreign_files_are_refused(tiny_twin, tmp_path):
    path = tiny_twin.save(tmp_path / "twin")
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="truncated or unreadable"):
        ReducedTwin.load(path)
    foreign = tmp_path / "model.npz"
    write_archive(foreign, {"format": "someone-else", "schema_version": 3}, {"weights": np.zeros(3)})
    with pytest.raises(ValueError, match="not a softtip reduced twin file"):
        ReducedTwin.load(foreign)
    np.savez(foreign, network_0_weight_0=np.zeros(3))
    with pytest.raises(ValueError, match="no metadata entry"):
        ReducedTwin.load(foreign)


def test_no_contact_no_response(tiny_twin):
    rigid, force = tiny_twin.predict(np.array([[0.0, 0.0, 0.3, 0.0, 0.0, 0.0]]))
    assert not rigid.any() and not force.any()


def test_series_of_a_load_unload_cycle_at_any_rate(tiny_twin):
    motion = Motion().push(1.5e-3, 1e-3).hold(1.0).release(1e-3)
    slow = Twin(tiny_twin).series(motion, 20.0, noise=False)
    fast = Twin(tiny_twin).series(motion, 200.0, noise=False)
    assert len(slow["times_s"]) == math.floor(motion.duration * 20) + 1
    peak = np.argmax(slow["depth_m"])
    assert slow["depth_m"][peak] == pytest.approx(1.5e-3)
    # readings depend on the pose only, so the two clocks agree where they share a time (to the
    # single-precision rounding of the networks, which depends on the batch: ~1e-5 µT, far below
    # the sensor's least significant bit)
    np.testing.assert_allclose(slow["readings_uT"][peak], fast["readings_uT"][np.argmax(fast["depth_m"])], atol=1e-3)
    prony = PronySeries(g=(0.3, 0.1), tau=(1.0, 0.2))
    relaxed = Twin(tiny_twin).series(motion, 20.0, prony=prony, noise=False)
    times, elastic = relaxed["times_s"], relaxed["elastic_force_N"][:, 2]
    closed = _qlv_of_a_piecewise_linear_history(times, elastic, prony)
    assert closed.max() < elastic.max() and closed.min() < -0.05 * elastic.max()  # relaxed: it would pull back
    # the twin's force is the QLV force, clipped where it would pull: a contact only pushes
    np.testing.assert_allclose(relaxed["force_N"][:, 2], np.maximum(closed, 0.0), rtol=1e-9, atol=1e-12)


def _qlv_of_a_piecewise_linear_history(times: np.ndarray, elastic: np.ndarray, prony: PronySeries) -> np.ndarray:
    """Fung's F(t) = g_inf F_e(t) + sum_k g_k int_0^t exp(-(t - s) / tau_k) dF_e(s) for F_e zero before
    times[0] and linear between samples: a piece of slope r over [s0, s1] before t contributes
    r tau (exp(-(t - s1) / tau) - exp(-(t - s0) / tau)), a jump J at times[0] J exp(-(t - times[0]) / tau)."""
    t, start, end = times[:, None], times[None, :-1], times[None, 1:]
    slopes = np.diff(elastic) / np.diff(times)
    force = prony.g_inf * elastic
    for g, tau in zip(prony.g, prony.tau):
        pieces = np.where(end <= t, tau * (np.exp(-(t - end) / tau) - np.exp(-(t - start) / tau)), 0.0)
        force = force + g * (pieces @ slopes + elastic[0] * np.exp(-(times - times[0]) / tau))
    return force
