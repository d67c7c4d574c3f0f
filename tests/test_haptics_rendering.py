"""The lookup-table renderer against brute force and scikit-learn, its stated choices and refusals,
both personalisations, and the simulated collection."""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest
from sklearn.neighbors import KNeighborsRegressor

from softtip.mechanics.plate_contact import hertz_force
from softtip.sensors.wrench import NANO17_WRENCH
from softtip.systems.haptics.collection import CollectionSettings, collection_duration, motor_grid, sensed_contact
from softtip.systems.haptics.device import forward_kinematics, load_device, move_time
from softtip.systems.haptics.fingertips import FINGERTIP_SENSOR, Fingertip, finger_wrench
from softtip.systems.haptics.personalisation import in_device_axes, personalise_data_driven, personalise_geometric
from softtip.systems.haptics.rendering import LookupTable, NearestNeighbourRenderer, TableError

DEVICE = load_device()
RNG = np.random.default_rng(3)
WRENCHES = RNG.normal(size=(700, 6))
MOTOR = RNG.uniform(0, 3, size=(700, 3))


def brute_force(wanted, forces, motor, k):
    distances = np.linalg.norm(forces - wanted, axis=1)
    nearest = np.argsort(distances)[:k]
    weights = 1 / distances[nearest]
    return weights @ motor[nearest] / weights.sum()


def test_renderer_is_the_brute_force_weighted_average_of_the_nearest_eight():
    renderer = NearestNeighbourRenderer().fit(WRENCHES, MOTOR)
    wanted = RNG.normal(size=(40, 6))
    expected = np.array([brute_force(w[:3], WRENCHES[:, :3], MOTOR, 8) for w in wanted])
    assert np.allclose(renderer.predict(wanted), expected, rtol=1e-12)
    reference = KNeighborsRegressor(n_neighbors=8, weights="distance", algorithm="brute").fit(WRENCHES[:, :3], MOTOR)
    assert np.allclose(renderer.predict(wanted), reference.predict(wanted[:, :3]), rtol=1e-12)
    # the torques play no part: only the force components are features
    shuffled = wanted.copy()
    shuffled[:, 3:] = RNG.normal(size=(40, 3))
    assert np.array_equal(renderer.predict(shuffled), renderer.predict(wanted))


@pytest.mark.parametrize("n_neighbours", [1, 2, 8])
@pytest.mark.parametrize("power", [0.0, 1.0, 2.0, 0.5])
def test_one_rendering_for_the_loop_is_the_batch_rendering(n_neighbours, power):
    renderer = NearestNeighbourRenderer(n_neighbours, weighting_power=power).fit(WRENCHES, MOTOR)
    wanted = np.vstack([RNG.normal(size=(20, 6)), WRENCHES[3], [40.0, 0, 0, 0, 0, 0]])
    batch = renderer.render(wanted)
    for row, expected, outside in zip(wanted, batch.motor_inputs, batch.outside, strict=True):
        motor, flagged = renderer.render_one(row)
        assert np.allclose(motor, expected, rtol=1e-12) and flagged == outside
    with pytest.raises(ValueError, match="finite"):
        renderer.render_one([np.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match="finite"):
        renderer.render_one([0.0, -np.inf, 0.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"shape \(2,\)"):
        renderer.render_one([1.0, 2.0])


def test_with_a_torque_length_the_renderer_searches_the_whole_wrench():
    length = 7.5e-3
    renderer = NearestNeighbourRenderer(torque_length=length).fit(WRENCHES, MOTOR)
    wanted = RNG.normal(size=(40, 6))
    scaled = np.hstack([WRENCHES[:, :3], WRENCHES[:, 3:] / length])  # torques as forces at 7.5 mm
    wanted_scaled = np.hstack([wanted[:, :3], wanted[:, 3:] / length])
    expected = np.array([brute_force(w, scaled, MOTOR, 8) for w in wanted_scaled])
    assert np.allclose(renderer.predict(wanted), expected, rtol=1e-12)
    reference = KNeighborsRegressor(n_neighbors=8, weights="distance", algorithm="brute").fit(scaled, MOTOR)
    assert np.allclose(renderer.predict(wanted), reference.predict(wanted_scaled), rtol=1e-12)
    # the torques now choose the neighbours: other torques, other motor inputs
    shuffled = wanted.copy()
    shuffled[:, 3:] = RNG.normal(size=(40, 3))
    assert not np.allclose(renderer.predict(shuffled), renderer.predict(wanted))
    motor, outside = renderer.render_one(wanted[0])
    assert np.allclose(motor, expected[0], rtol=1e-12) and outside == renderer.render(wanted[:1]).outside[0]
    assert renderer.get_params()["torque_length"] == length
    with pytest.raises(TableError, match=r"a torque length needs \(entries, 6\) wrenches"):
        NearestNeighbourRenderer(torque_length=length).fit(WRENCHES[:, :3], MOTOR)
    with pytest.raises(ValueError, match=r"expected \(\.\.\., 6\)$"):
        renderer.predict(wanted[:, :3])
    with pytest.raises(TableError, match="torque_length = -1"):
        NearestNeighbourRenderer(torque_length=-1.0)


def test_an_exact_match_renders_its_own_entry():
    renderer = NearestNeighbourRenderer().fit(WRENCHES, MOTOR)
    assert np.allclose(renderer.predict(WRENCHES[17]), MOTOR[17])


def test_entries_without_contact_merge_into_the_least_wound_one():
    noise = RNG.normal(scale=1e-3, size=(30, 3))  # readings of configurations that do not touch
    forces = np.vstack([noise, RNG.uniform(0.5, 3, size=(40, 3))])
    motor = RNG.uniform(0.5, 3, size=(70, 3))
    motor[[4, 9]] = [0.1, 0.1, 0.1]  # two least-wound configurations, a tie: the first wins
    motor[9, 0] = 0.2
    motor[9, 1] = 0.0
    renderer = NearestNeighbourRenderer().fit(forces, motor)
    assert renderer.merged_ == 30 and len(renderer.features_) == 41
    assert np.array_equal(renderer.predict(np.zeros(3)), motor[4])
    # without the merge, a zero force would average eight arbitrary non-contact configurations
    unmerged = KNeighborsRegressor(n_neighbors=8, weights="distance").fit(forces, motor).predict(np.zeros((1, 3)))[0]
    assert not np.allclose(unmerged, motor[4])


def test_targets_beyond_the_table_are_flagged_not_extrapolated():
    renderer = NearestNeighbourRenderer().fit(WRENCHES, MOTOR)
    inside, beyond = np.zeros(6), np.array([50.0, 0, 0, 0, 0, 0])
    result = renderer.render(np.stack([inside, beyond]))
    assert result.outside.tolist() == [False, True]
    assert np.all(result.motor_inputs[1] <= MOTOR.max(axis=0))  # a weighted average: never beyond the entries


@pytest.mark.parametrize(("change", "message"), [
    (lambda w, m: (np.where(np.arange(len(w))[:, None] == 3, np.nan, w), m), "wrenches: entry 3 is not finite"),
    (lambda w, m: (np.vstack([w, w[5]]), np.vstack([m, m[5]])), "entries 5 and 700 are the same entry"),
    (lambda w, m: (np.vstack([w, w[5]]), np.vstack([m, m[5] + 0.1])), "entries 5 and 700 read the same force"),
    (lambda w, m: (w, m[:-1]), "motor_inputs has shape"),
    (lambda w, m: (w[:5], m[:5]), "n_neighbours = 8: the table has only 5"),
])
def test_bad_tables_are_refused_in_one_line(change, message):
    wrenches, motor = change(WRENCHES, MOTOR)
    with pytest.raises(TableError, match=message) as refused:
        NearestNeighbourRenderer().fit(wrenches, motor)
    assert "\n" not in str(refused.value)


def test_renderer_parameters_follow_scikit_learn_and_are_checked():
    renderer = NearestNeighbourRenderer(n_neighbours=4)
    assert renderer.get_params() == {"n_neighbours": 4, "contact_threshold": pytest.approx(5 / 320),
                                     "weighting_power": 1.0, "torque_length": None}
    assert renderer.set_params(n_neighbours=2).n_neighbours == 2
    with pytest.raises(TableError, match="n_neighbours = 0"):
        NearestNeighbourRenderer(n_neighbours=0)
    with pytest.raises(ValueError, match="finite"):
        NearestNeighbourRenderer().fit(WRENCHES, MOTOR).predict([np.nan, 0, 0])
    LookupTable(WRENCHES, MOTOR)  # a sound table is accepted


def test_geometric_method_is_the_identity_on_the_fs_and_keeps_indentation_on_a_larger_sphere():
    grid = motor_grid(DEVICE, 7)
    same = personalise_geometric(DEVICE, grid, FINGERTIP_SENSOR.radius, FINGERTIP_SENSOR.radius)
    assert np.allclose(same.motor_inputs, grid, atol=1e-12) and not same.outside.any()
    # two homogeneous rubber spheres (Hertz), only their radii different
    sensor, large = Fingertip(name="FS", radius=7.5e-3), Fingertip(name="large", radius=8.5e-3)
    moved = personalise_geometric(DEVICE, grid, sensor.radius, large.radius)
    ok = ~moved.outside
    _, fs_depth = finger_wrench(sensor, DEVICE, forward_kinematics(DEVICE, grid[ok]))
    wrench, large_depth = finger_wrench(large, DEVICE, forward_kinematics(DEVICE, moved.motor_inputs[ok]))
    assert np.allclose(large_depth, fs_depth, atol=1e-12)  # the same deformation ...
    touching = fs_depth > 1e-4
    fs_force = hertz_force(fs_depth[touching], 7.5e-3, 1.14e6, 0.5)
    # ... takes more force on the larger sphere: Hertz scales with √R at equal depth, so B is not exact
    ratio = np.linalg.norm(wrench[touching, :3], axis=1) / fs_force
    assert np.allclose(ratio, math.sqrt(8.5 / 7.5), rtol=1e-9) and touching.sum() > 50


def test_geometric_method_flags_poses_out_of_reach():
    wound = np.full((1, 3), DEVICE.angle_max)  # the platform at its highest: a smaller finger needs more
    result = personalise_geometric(DEVICE, wound, FINGERTIP_SENSOR.radius, 6.5e-3)
    assert result.outside.tolist() == [True] and np.all(result.motor_inputs <= DEVICE.angle_max)
    with pytest.raises(ValueError, match="user_radius"):
        personalise_geometric(DEVICE, wound, FINGERTIP_SENSOR.radius, float("nan"))


@pytest.mark.parametrize("variant", ["published", "device axes"])
def test_data_driven_method_with_the_fs_as_user_returns_the_fs_table(variant):
    grid = motor_grid(DEVICE, 7)
    exact = sensed_contact(DEVICE, FINGERTIP_SENSOR, grid, CollectionSettings(), None).unsaturated()
    grid = exact.motor_inputs
    result = personalise_data_driven(DEVICE, grid, exact.platform_wrenches, grid, exact.platform_wrenches,
                                     n_neighbours=1, variant=variant)
    touching = np.linalg.norm(exact.platform_wrenches[:, :3], axis=1) >= 5 / 320
    # turned into the device's axes, the DS's force is the opposite of the fingertip's
    turned = in_device_axes(DEVICE, grid, exact.platform_wrenches)[:, :3]
    assert np.allclose(turned, -exact.finger_wrenches[:, :3], atol=1e-12)
    assert np.allclose(result.motor_inputs[touching], grid[touching], atol=1e-12)
    assert not result.outside.any()


def test_published_data_driven_method_needs_no_device_model():
    from dataclasses import replace

    from softtip.systems.haptics.fingertips import cast
    from softtip.systems.haptics.personalisation import DS_TORQUE_LENGTH

    grid = motor_grid(DEVICE, 9)
    fs = sensed_contact(DEVICE, FINGERTIP_SENSOR, grid, CollectionSettings(), None).unsaturated()
    user = sensed_contact(DEVICE, cast("small", 6.5e-3), motor_grid(DEVICE, 5), CollectionSettings(),
                          None).unsaturated()
    tables = (fs.motor_inputs, fs.platform_wrenches, user.motor_inputs, user.platform_wrenches)
    published = personalise_data_driven(DEVICE, *tables)
    # scikit-learn on the raw readings, torques over the FS's radius, the no-contact entries merged as the
    # renderer merges them (into one zero wrench, the least-wound configuration's motor inputs)
    touching = np.linalg.norm(user.platform_wrenches[:, :3], axis=1) >= 5 / 320
    released = np.flatnonzero(~touching)[np.argmin(user.motor_inputs[~touching].sum(axis=1))]
    scale = np.r_[np.ones(3), np.full(3, 1 / DS_TORQUE_LENGTH)]
    features = np.vstack([np.zeros(6), user.platform_wrenches[touching] * scale])
    motor = np.vstack([user.motor_inputs[released], user.motor_inputs[touching]])
    reference = KNeighborsRegressor(n_neighbors=8, weights="distance", algorithm="brute").fit(features, motor)
    wanted = fs.platform_wrenches * scale
    distances, _ = reference.kneighbors(wanted, n_neighbors=9)
    untied = (distances[:, 0] == 0) | (distances[:, 8] - distances[:, 7] > 1e-9)  # an exact match is no tie
    assert np.allclose(published.motor_inputs[untied], reference.predict(wanted[untied]), rtol=1e-10)
    # the device is symmetric: an FS configuration with two (or three) equal motor inputs lies on a mirror
    # plane (or the axis), where the user's mirrored (or rotated) configurations read wrenches equally far:
    # 46 of its 225 such entries here have such a group across the 8th neighbour, and the tie may go any way.
    # There the renderer must give the distance-weighted average of scikit-learn's nearest inside the group's
    # distance and some of the group
    tied = np.flatnonzero(~untied)
    assert np.all((fs.motor_inputs[tied][:, [0, 1, 2]] == fs.motor_inputs[tied][:, [1, 2, 0]]).any(axis=1))
    distances, nearest = reference.kneighbors(wanted[tied], n_neighbors=16)
    for entry, around, order in zip(tied, distances, nearest, strict=True):
        at_eighth = np.abs(around - around[7]) <= 1e-9
        inside = around < around[7] - 1e-9
        group = order[at_eighth]
        assert not at_eighth[-1] and len(np.unique(np.sort(motor[group], axis=1), axis=0)) == 1
        taken = 8 - inside.sum()  # of the group, each weighing 1 / its distance
        weighted, total = motor[order[inside]].T @ (1 / around[inside]), np.sum(1 / around[inside]) + taken / around[7]
        choices = [(weighted + motor[list(kept)].sum(axis=0) / around[7]) / total
                   for kept in itertools.combinations(group, taken)]
        assert any(np.allclose(published.motor_inputs[entry], choice, rtol=1e-10) for choice in choices)
    # another device file changes nothing of the published search, everything of the kinematic one
    wider = replace(DEVICE, device=replace(DEVICE.device, attachment_radius=0.015))
    assert np.array_equal(personalise_data_driven(wider, *tables).motor_inputs, published.motor_inputs)
    kinematic = personalise_data_driven(DEVICE, *tables, variant="device axes").motor_inputs
    assert not np.allclose(personalise_data_driven(wider, *tables, variant="device axes").motor_inputs, kinematic)
    with pytest.raises(ValueError, match="variant = 'raw'"):
        personalise_data_driven(DEVICE, *tables, variant="raw")


def test_collection_reads_each_held_configuration_and_times_the_procedure():
    grid = motor_grid(DEVICE, 2)
    assert len(grid) == 8 and len(np.unique(grid, axis=0)) == 8
    # boustrophedon: one servo moves per step, over its range as its dead band resolves it (333 steps
    # of 0.54 degree) at 600 degrees/s, from half a 50 Hz frame on; the first move is from rest to
    # rest, and each configuration held 1 s
    assert np.all((np.diff(grid, axis=0) != 0).sum(axis=1) == 1)
    expected = 8 * 0.01 + 7 * 333 * 0.54 / 600.0 + 8 * 1.0
    assert collection_duration(DEVICE, grid, 1.0) == pytest.approx(expected)
    assert np.allclose(move_time(DEVICE, np.zeros(3), np.array([math.pi, 0, 0])), 0.01 + 0.3)
    settings = CollectionSettings(hold_s=1.0, window_s=0.2, sensor=NANO17_WRENCH)
    noisy = sensed_contact(DEVICE, FINGERTIP_SENSOR, grid, settings, np.random.default_rng(0))
    exact = sensed_contact(DEVICE, FINGERTIP_SENSOR, grid, settings, None)
    # the window's mean of 200 readings, one step of noise and rounding each: within 5.5 of its spreads
    spread = math.sqrt((1 / 320) ** 2 * (1 + 1 / 12) / 200)
    assert np.max(np.abs(noisy.finger_wrenches[:, :3] - exact.finger_wrenches[:, :3])) < 5.5 * spread
    # the DS reads the opposite of the fingertip's force: along the platform's normal
    normal_force = -noisy.platform_wrenches[:, 2]
    assert np.allclose(normal_force, np.linalg.norm(exact.finger_wrenches[:, :3], axis=1), atol=0.01)
    with pytest.raises(ValueError, match="collection.window_s = 2"):
        CollectionSettings(hold_s=1.0, window_s=2.0)


def test_presses_recover_the_users_modulus_and_the_force_model_renders_the_fs_force():
    from softtip.mechanics.plate_contact import PlateContactLaw
    from softtip.systems.haptics.personalisation import (
        PRESS_DEPTHS,
        fit_presses,
        personalise_force_model,
        press_configurations,
    )

    # the presses' model takes the cables rigid: so does this device (the shipped cables' give is the fit's)
    device = dataclasses.replace(DEVICE, cables=dataclasses.replace(DEVICE.cables, stiffness=1e12))
    softer = Fingertip(name="soft 7 mm", radius=7e-3, contact=PlateContactLaw(law="hertz", youngs_modulus=0.5e6))
    presses = press_configurations(device, softer.radius)
    assert len(presses) == 5 and np.all(presses[:, 0] > 0)
    read = sensed_contact(device, softer, presses, CollectionSettings(), None)
    fit = fit_presses(device, presses, read.platform_wrenches, softer.radius, saturated=read.saturated)
    assert fit.youngs_modulus == pytest.approx(0.5e6, rel=1e-6)  # exact readings: the modulus itself
    # the presses reach the planned depths, but for the servos' dead band (0.54 degree of the pulley)
    assert np.allclose(fit.depths, PRESS_DEPTHS, rtol=0, atol=0.5 * np.radians(0.54) * device.device.pulley_radius)
    grid = motor_grid(device, 7)
    fs = sensed_contact(device, FINGERTIP_SENSOR, grid, CollectionSettings(), None)
    personal = personalise_force_model(device, grid, fs.finger_wrenches, FINGERTIP_SENSOR.radius, softer.radius, fit)
    fs_force = np.linalg.norm(fs.finger_wrenches[:, :3], axis=1)
    wrench, _ = finger_wrench(softer, device, forward_kinematics(device, personal.motor_inputs))
    ok = ~personal.outside & (fs_force > 0.1) & ~fs.saturated
    assert ok.sum() > 30
    # the user feels the FS's force (the servos' dead band aside), where the plain geometric method does not
    assert np.allclose(np.linalg.norm(wrench[ok, :3], axis=1), fs_force[ok], rtol=1e-6)
    geometric = personalise_geometric(device, grid, FINGERTIP_SENSOR.radius, softer.radius)
    plain, _ = finger_wrench(softer, device, forward_kinematics(device, geometric.motor_inputs))
    assert np.median(np.abs(np.linalg.norm(plain[ok, :3], axis=1) / fs_force[ok] - 1)) > 0.2


def test_presses_read_with_the_cables_give_recover_the_modulus_on_the_compliant_device():
    from softtip.mechanics.plate_contact import PlateContactLaw
    from softtip.systems.haptics.fingertips import loaded_contact
    from softtip.systems.haptics.personalisation import fit_presses, personalise_force_model, press_configurations

    # the shipped device: its cables and springs give way under a press, F / 3(k_c + k_s)
    softer = Fingertip(name="soft 7 mm", radius=7e-3, contact=PlateContactLaw(law="hertz", youngs_modulus=0.5e6))
    presses = press_configurations(DEVICE, softer.radius)
    read = sensed_contact(DEVICE, softer, presses, CollectionSettings(), None)
    rigid = fit_presses(DEVICE, presses, read.platform_wrenches, softer.radius, saturated=read.saturated)
    compliant = fit_presses(DEVICE, presses, read.platform_wrenches, softer.radius, saturated=read.saturated,
                            cables="compliant")
    # the rigid kinematics overstate each press's depth by the give, so the fitted pad is too soft
    assert compliant.youngs_modulus == pytest.approx(0.5e6, rel=1e-6)
    assert 0.39 < rigid.youngs_modulus / 0.5e6 < 0.41  # measured 0.402: the give is 31-47 % of each rigid depth
    assert np.allclose(rigid.depths - compliant.depths, -read.platform_wrenches[:, 2] / (3 * (436.8 + 200.0)),
                       rtol=1e-9)
    # placed with the give, the loaded platform renders the FS's force on the user
    grid = motor_grid(DEVICE, 7)
    fs = sensed_contact(DEVICE, FINGERTIP_SENSOR, grid, CollectionSettings(), None)
    personal = personalise_force_model(DEVICE, grid, fs.finger_wrenches, FINGERTIP_SENSOR.radius, softer.radius,
                                       compliant, cables="compliant")
    _, wrench = loaded_contact(softer, DEVICE, personal.motor_inputs)
    fs_force = np.linalg.norm(fs.finger_wrenches[:, :3], axis=1)
    ok = ~personal.outside & (fs_force > 0.1) & ~fs.saturated
    assert ok.sum() > 30
    assert np.allclose(np.linalg.norm(wrench[ok, :3], axis=1), fs_force[ok], rtol=1e-6)
    with pytest.raises(ValueError, match="cables = 'stiff': expected one of rigid, compliant"):
        fit_presses(DEVICE, presses, read.platform_wrenches, softer.radius, cables="stiff")


def test_presses_that_never_touch_are_refused():
    from softtip.systems.haptics.personalisation import fit_presses

    with pytest.raises(ValueError, match="none of the 2 presses touched"):
        fit_presses(DEVICE, np.zeros((2, 3)), np.zeros((2, 6)), 7.5e-3)
    with pytest.raises(ValueError, match="presses: 6 given"):
        fit_presses(DEVICE, np.zeros((6, 3)), np.zeros((6, 6)), 7.5e-3)


def test_saturated_presses_stay_out_of_the_hertz_fit():
    from softtip.mechanics.plate_contact import PlateContactLaw
    from softtip.systems.haptics.personalisation import fit_presses, press_configurations

    # the shipped cables' give takes up the presses (1.6 N at the deepest on this finger): with rigid cables,
    # as the presses' model takes them, the two deepest presses on a stiff 7 mm Hertz finger push the
    # Nano17's Fz past its 17 N range (20 and 28 N by Hertz), the third stays under it (13 N)
    device = dataclasses.replace(DEVICE, cables=dataclasses.replace(DEVICE.cables, stiffness=1e12))
    stiff = Fingertip(name="stiff 7 mm", radius=7e-3, contact=PlateContactLaw(law="hertz", youngs_modulus=6e6))
    presses = press_configurations(device, stiff.radius)
    read = sensed_contact(device, stiff, presses, CollectionSettings(), np.random.default_rng(8))
    assert read.saturated.tolist() == [False, False, False, True, True]
    fit = fit_presses(device, presses, read.platform_wrenches, stiff.radius, saturated=read.saturated)
    assert fit.touching == 3
    # Hertz by hand over the three unsaturated presses: F = (4/3) E/(1 − ν²) √R δ^1.5, least squares in E
    depth, force = fit.depths[:3], np.linalg.norm(read.platform_wrenches[:3, :3], axis=1)
    shape = 4 / 3 / (1 - 0.5**2) * math.sqrt(7e-3) * depth**1.5
    assert fit.youngs_modulus == pytest.approx(np.sum(shape * force) / np.sum(shape**2), rel=1e-12)
    # the modulus off only by the window-averaged noise (one step RMS and rounding, over 200 readings): its
    # standard deviation relative to E is that spread over the forces' norm; within five of it
    spread = math.sqrt((1 / 320) ** 2 * (1 + 1 / 12) / 200)
    assert fit.youngs_modulus == pytest.approx(6e6, rel=5 * spread / np.linalg.norm(force))
    # the clipped 17 N readings would pull it to 4.4 MPa
    clipped = fit_presses(device, presses, read.platform_wrenches, stiff.radius)
    assert clipped.touching == 5 and clipped.youngs_modulus < 0.75 * 6e6
