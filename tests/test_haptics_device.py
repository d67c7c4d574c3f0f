"""The S3 device: kinematics exact both ways, the spec's cable-length rule, the device file's
refusals, the servos' frames, dead band and slew, and the cables' statics."""

from __future__ import annotations

import dataclasses
import math
import tomllib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq

from softtip.mechanics.plate_contact import cap_indentation, normal_force
from softtip.systems.haptics.device import (
    DEVICE_FILE,
    DeviceError,
    PlatformPose,
    UnreachablePose,
    cable_lengths,
    cable_tensions,
    forward_kinematics,
    inverse_kinematics,
    inverse_kinematics_unchecked,
    load_device,
    loaded_pose,
    move_time,
    quantised,
    reachable,
    servo_angles,
    spring_forces,
)
from softtip.systems.haptics.fingertips import FINGERTIP_SENSOR, finger_wrench, loaded_contact

DEVICE = load_device()
angle = st.floats(0.0, DEVICE.angle_max)


@settings(max_examples=200, deadline=None)
@given(st.tuples(angle, angle, angle))
def test_inverse_kinematics_undoes_forward_over_the_workspace(angles):
    pose = forward_kinematics(DEVICE, np.array(angles))
    assert np.allclose(inverse_kinematics(DEVICE, pose), angles, rtol=0, atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(st.tuples(angle, angle, angle), st.floats(-0.01, 0.01), st.floats(-0.01, 0.01))
def test_forward_kinematics_undoes_inverse_from_any_point_of_the_plane(angles, dx, dy):
    pose = forward_kinematics(DEVICE, np.array(angles))
    # another point of the same plane: the inverse must not depend on which point names the plane
    along = np.array([dx, dy, 0.0]) - np.dot([dx, dy, 0.0], pose.normal) * pose.normal
    back = forward_kinematics(DEVICE, inverse_kinematics(DEVICE, PlatformPose(pose.centroid + along, pose.normal)))
    assert np.allclose(back.normal, pose.normal, atol=1e-12)
    assert np.allclose(back.centroid, pose.centroid, atol=1e-12)


def test_moving_the_plane_along_its_normal_changes_each_cable_by_the_distance_over_cos_tilt():
    angles = np.array([[0.5, 3.0, 1.6], [1.0, 1.0, 1.0]])
    pose = forward_kinematics(DEVICE, angles)
    down = pose.moved_along_normal(np.full(2, -1e-3))  # 1 mm down, away from the pad
    moved = inverse_kinematics_unchecked(DEVICE, down)
    change = cable_lengths(DEVICE, moved) - cable_lengths(DEVICE, angles)
    assert np.allclose(change, 1e-3 / np.cos(pose.tilt)[:, None], rtol=1e-12)
    assert np.degrees(pose.tilt[0]) > 5  # the tilted case is really tilted (the fitted stroke allows about 8 degrees)


def test_level_platform_sits_at_the_cable_length():
    pose = forward_kinematics(DEVICE, np.full(3, math.pi / 2))
    expected_z = -(DEVICE.device.released_length - DEVICE.device.pulley_radius * math.pi / 2)
    assert np.allclose(pose.normal, [0, 0, 1]) and np.allclose(pose.centroid, [0, 0, expected_z])


def test_unreachable_pose_is_refused_in_one_line():
    level_too_high = PlatformPose(np.array([0.0, 0.0, -0.005]), np.array([0.0, 0.0, 1.0]))
    with pytest.raises(UnreachablePose, match=r"servo angles .* expected angles within 0..180"):
        inverse_kinematics(DEVICE, level_too_high)
    steep = PlatformPose(np.array([0.0, 0.0, -0.016]), np.array([0.0, math.sin(0.6), math.cos(0.6)]))
    with pytest.raises(UnreachablePose, match="tilt"):
        inverse_kinematics(DEVICE, steep)


@pytest.mark.parametrize(("old", "new", "named"), [
    ("attachment_angles_deg = [90.0, 210.0, 330.0]", "attachment_angles_deg = [90.0, 90.5, 270.0]",
     "device.attachment_angles_deg"),
    ("released_length = 0.0162558 ", "released_length = 0.002  ", "device.released_length"),
    ("free_length = 0.025 ", "free_length = 0.010 ", "springs.free_length"),
    ("centre = [0.0, 0.0, -0.0085]", "centre = [0.0, 0.0, 0.004]", "finger.centre"),
    ("centre = [0.0, 0.0, -0.0085]", "centre = [1e300, 0.0, -0.0085]",
     "finger.centre = .*: expected the centre inside"),
    ("attachment_radius = 0.012 ", "attachment_radius = 1e300 ", "device.attachment_radius = 1e.300: expected a "
                                                                  "length in m, above 0 and at most 0.1"),
    ("command_rate_hz = 50.0", "command_rate_hz = 1e9",
     "servo.command_rate_hz = 1000000000.0: expected a rate in Hz above 0 and at most the render loop's 1000"),
    ("stall_torque = 0.078", "stall_torque = -1", "servo.stall_torque"),
    # a servo that could not hold its spring, whichever side is absurd (issue 37: these rendered as shipped)
    ("stall_torque = 0.078", "stall_torque = 1e-9", "servo.stall_torque = 1e-09: expected above 0.00217 N m"),
    ("stiffness = 200.0 ", "stiffness = 1e308 ",
     r"servo.stall_torque = 0.078: expected above 1.08e\+303 N m.*1.17e\+306 N: springs.stiffness"),
    ("[springs]", "[springs]\ndamping = 3", "springs.damping: unknown key"),
    ("[cables]\nstiffness", "[cables]\nstiffness = 1.0\nspan", "cables.span: unknown key"),
    ('"cables.stiffness"]', '"cables.nothing"]', "fit.parameters"),
    ("standard_errors = [", "standard_errors = [1.0, ", "fit.standard_errors"),
    ("correlation = [[1.0,", "correlation = [[2.0,", "fit.correlation"),
])
def test_device_file_that_breaks_the_kinematics_is_refused_naming_the_key(tmp_path, old, new, named):
    text = DEVICE_FILE.read_text()
    assert old in text
    broken = tmp_path / "device.toml"
    broken.write_text(text.replace(old, new, 1))
    with pytest.raises(DeviceError, match=named) as refused:
        load_device(broken)
    assert "\n" not in str(refused.value)


def test_servo_reads_commands_once_per_frame_resolves_its_dead_band_and_slews():
    rate = 1000.0
    commands = np.zeros((200, 3))
    commands[5:, 0] = math.radians(60.0)  # arrives 5 ms into the first frame: read at the second (20 ms)
    commands[:, 1] = math.radians(10.0)  # from the start; 10 degrees is not a multiple of the 0.54 dead band
    angles = servo_angles(DEVICE, np.zeros(3), commands, rate)
    assert np.all(angles[:20, 0] == 0.0)
    slew = math.radians(DEVICE.servo.slew_deg_per_s) / rate
    assert angles[20, 0] == pytest.approx(slew)
    # 60 degrees at 600 degrees/s take 100 ms after the frame that read the command
    reached = np.flatnonzero(np.isclose(angles[:, 0], quantised(DEVICE, np.array([math.radians(60.0), 0, 0]))[0]))[0]
    assert reached == 20 + 100 - 1
    final = np.degrees(angles[-1, 1])
    assert final == pytest.approx(round(10.0 / 0.54) * 0.54) and final != pytest.approx(10.0)


def test_cables_hold_the_springs_and_share_a_central_load():
    level = np.full(3, 1.0)
    lengths = cable_lengths(DEVICE, level)
    springs = DEVICE.springs.stiffness * (DEVICE.springs.free_length - lengths)
    assert np.allclose(cable_tensions(DEVICE, level, np.zeros(6)), springs)
    assert np.allclose(spring_forces(DEVICE, lengths), springs)
    # 3 N up on the finger at the centre line: each cable carries a third more
    wrench = np.array([0.0, 0.0, 3.0, 0.0, 0.0, 0.0])
    assert np.allclose(cable_tensions(DEVICE, level, wrench), springs + 1.0)
    # the same force 5 mm off towards cable 0 (at 90 degrees, +y) loads that cable most
    off = np.array([0.0, 0.0, 3.0, 0.005 * 3.0, 0.0, 0.0])  # torque (r x F)_x = y F_z
    tensions = cable_tensions(DEVICE, level, off) - springs
    assert tensions.sum() == pytest.approx(3.0) and tensions[0] > tensions[1] == pytest.approx(tensions[2])


def test_replaced_device_keeps_its_own_dimensions():
    wider = dataclasses.replace(DEVICE, device=dataclasses.replace(DEVICE.device, attachment_radius=0.02))
    assert np.allclose(np.linalg.norm(wider.anchors, axis=1), 0.02)


@pytest.mark.parametrize("angles", [np.full(3, math.pi), np.array([math.pi, 2.2, 2.9])], ids=["level", "tilted"])
def test_loaded_platform_gives_way_along_its_normal_by_the_force_over_three_cables_and_springs(angles):
    # the reference: the give s that solves s = F(δ₀ − s) / 3k, found by scipy's brentq on the contact law
    rigid = forward_kinematics(DEVICE, angles)
    _, depth = finger_wrench(FINGERTIP_SENSOR, DEVICE, rigid)
    assert depth > 1e-4  # the press is real
    radius = cap_indentation(FINGERTIP_SENSOR.centre(DEVICE), FINGERTIP_SENSOR.semi_axes, rigid.centroid,
                             rigid.normal)[2]
    three_cables = 3 * (DEVICE.cables.stiffness + DEVICE.springs.stiffness)  # each spring eases as its cable stretches
    give = brentq(lambda s: s - normal_force(FINGERTIP_SENSOR.contact, depth - s, radius) / three_cables, 0.0, depth,
                  xtol=1e-15)
    pose, wrench = loaded_contact(FINGERTIP_SENSOR, DEVICE, angles)
    assert np.allclose(pose.normal, rigid.normal, atol=1e-15)
    assert np.allclose(pose.centroid, rigid.centroid - give * rigid.normal, atol=1e-12)
    assert np.dot(wrench[:3], rigid.normal) == pytest.approx(three_cables * give, rel=1e-9)


def test_stiff_cables_leave_the_platform_where_its_kinematics_put_it():
    stiff = dataclasses.replace(DEVICE, cables=dataclasses.replace(DEVICE.cables, stiffness=1e12))
    angles = np.array([[math.pi, 2.2, 2.9], [0.1, 0.2, 0.3]])
    pose, wrench = loaded_contact(FINGERTIP_SENSOR, stiff, angles)
    rigid = forward_kinematics(stiff, angles)
    assert np.allclose(pose.centroid, rigid.centroid, atol=1e-9)
    assert np.allclose(wrench, finger_wrench(FINGERTIP_SENSOR, stiff, rigid)[0], rtol=1e-3, atol=1e-9)


def _linear_press(device, angles, stiffness, depth):
    """A level platform at ``angles`` pressing a flat linear spring (``stiffness`` N/m) ``depth`` m
    deep at its rigid pose: the loaded pose's force and give, and the rigid pose."""
    rigid = forward_kinematics(device, angles)
    surface = rigid.centroid[2] - depth

    def contact(pose):
        force = stiffness * np.maximum(pose.centroid[..., 2] - surface, 0.0)
        return np.concatenate([force[..., None] * pose.normal, np.zeros(force.shape + (3,))], axis=-1)

    pose, wrench = loaded_pose(device, angles, contact)
    return wrench[2], rigid.centroid[2] - pose.centroid[2]


def _with(device, section, **values):
    return dataclasses.replace(device, **{section: dataclasses.replace(getattr(device, section), **values)})


LEVEL = np.full(3, 1.5)
CONTACT_STIFFNESS, DEPTH = 3000.0, 2e-3  # N/m, m: 6 N on rigid cables


def test_cables_and_springs_give_way_together_as_computed_by_hand():
    # a cable stretched by s pulls k_c s more; its spring, lengthened by s, pushes k_s s less: per cable
    # k_f (d - s) / 3 = (k_c + k_s) s, so F = k_f d / (1 + k_f / 3(k_c + k_s))
    for cable, spring in ((436.8, 200.0), (636.8, 1e-6), (200.0, 436.8), (5000.0, 200.0)):
        device = _with(_with(DEVICE, "cables", stiffness=cable), "springs", stiffness=spring)
        force, give = _linear_press(device, LEVEL, CONTACT_STIFFNESS, DEPTH)
        expected = CONTACT_STIFFNESS * DEPTH / (1 + CONTACT_STIFFNESS / (3 * (cable + spring)))
        assert force == pytest.approx(expected, rel=1e-12)
        assert give == pytest.approx(expected / (3 * (cable + spring)), rel=1e-9)
    shipped, _ = _linear_press(DEVICE, LEVEL, CONTACT_STIFFNESS, DEPTH)
    assert shipped == pytest.approx(6.0 / (1 + 3000.0 / 1910.4), rel=1e-12)  # 2.334 N


def test_a_stalled_servo_pays_out_cable_and_caps_the_force_as_computed_by_hand():
    lengths = cable_lengths(DEVICE, LEVEL)
    spring_push = DEVICE.springs.stiffness * (DEVICE.springs.free_length - lengths[0])
    k_s = DEVICE.springs.stiffness
    # a stall leaving each cable 0.5 N above its spring's push: below the 0.778 N a cable would carry
    headroom = 0.5
    stall = (spring_push + headroom) * DEVICE.device.pulley_radius
    weak = _with(DEVICE, "servo", stall_torque=stall)
    assert weak.stall_tension == pytest.approx(spring_push + headroom)
    force, give = _linear_press(weak, LEVEL, CONTACT_STIFFNESS, DEPTH)
    # stalled: H + k_s s = k_f (d - s) / 3, so s = (k_f d / 3 - H) / (k_s + k_f / 3) = 1.25 mm
    expected_give = (CONTACT_STIFFNESS * DEPTH / 3 - headroom) / (k_s + CONTACT_STIFFNESS / 3)
    assert expected_give == pytest.approx(1.25e-3)
    assert give == pytest.approx(expected_give, rel=1e-9)
    assert force == pytest.approx(CONTACT_STIFFNESS * (DEPTH - expected_give), rel=1e-9)  # 2.25 N, not 2.334 N
    # each cable at the stall: its spring's push at the paid-out length plus its share of the force
    assert spring_push - k_s * give + force / 3 == pytest.approx(weak.stall_tension, rel=1e-9)
    # a stall the press never reaches changes nothing
    strong, _ = _linear_press(_with(DEVICE, "servo", stall_torque=10 * DEVICE.servo.stall_torque), LEVEL,
                              CONTACT_STIFFNESS, DEPTH)
    shipped, _ = _linear_press(DEVICE, LEVEL, CONTACT_STIFFNESS, DEPTH)
    assert strong == shipped


def test_a_weak_servo_caps_what_the_platform_renders_on_a_finger():
    angles = np.array([[math.pi, math.pi, math.pi], [math.pi, 2.2, 2.9], [0.6, 0.4, 0.5]])
    _, shipped = loaded_contact(FINGERTIP_SENSOR, DEVICE, angles)
    push = spring_forces(DEVICE, cable_lengths(DEVICE, angles)).max(axis=-1)
    weak = _with(DEVICE, "servo", stall_torque=(push.max() + 0.2) * DEVICE.device.pulley_radius)
    pose, capped = loaded_contact(FINGERTIP_SENSOR, weak, angles)
    rigid = forward_kinematics(DEVICE, angles)
    give = np.sum((rigid.centroid - pose.centroid) * rigid.normal, axis=-1)
    along = np.sum(capped[:, :3] * rigid.normal, axis=-1)
    shipped_along = np.sum(shipped[:, :3] * rigid.normal, axis=-1)
    # the two hard presses stall: each cable at the stall, F / 3 = H + k_s s (H the headroom over the spring)
    assert shipped_along[:2].min() > 3 * 0.2 * 2 and np.all(along[:2] < shipped_along[:2])
    assert along[:2] == pytest.approx(3 * (weak.stall_tension - push[:2] + DEVICE.springs.stiffness * give[:2]),
                                      rel=1e-9)
    # the light press stays below the stall and renders as on the shipped servos
    assert 0 < shipped_along[2] < 3 * (weak.stall_tension - push[2])
    assert np.allclose(capped[2], shipped[2], rtol=1e-12, atol=0)


# every value a device file documents, as dotted keys with a changed value that keeps the device valid
DOCUMENTED = {
    "device.attachment_radius": 0.013, "device.attachment_angles_deg": (80.0, 210.0, 330.0),
    "device.pulley_radius": 0.00095, "device.released_length": 0.0165, "device.max_tilt_deg": 5.0,
    "servo.angle_max_deg": 170.0, "servo.command_rate_hz": 40.0, "servo.slew_deg_per_s": 500.0,
    "servo.resolution_deg": 0.6, "servo.stall_torque": 0.0035, "springs.stiffness": 150.0,
    "springs.free_length": 0.024, "cables.stiffness": 500.0, "finger.centre": (0.0, 0.0, -0.0088),
}


def _behaviour(device) -> np.ndarray:
    """What a device does, in numbers: loaded presses on the FS (hard, tilted, light), the servos'
    response to commands, a move's time and which tilted configurations it reaches."""
    angles = np.array([[math.pi, math.pi, math.pi], [math.pi, 2.2, 2.9], [1.6, 1.2, 1.4], [3.0, 0.0, 3.0]])
    _, wrench = loaded_contact(FINGERTIP_SENSOR, device, np.clip(angles, 0, device.angle_max))
    commands = np.tile(np.radians([[170.0, 10.0, 95.0]]), (120, 1))
    return np.concatenate([wrench.ravel(), servo_angles(device, np.zeros(3), commands, 1000.0).ravel(),
                           np.ravel(move_time(device, np.zeros(3), np.full(3, math.pi))),
                           reachable(device, angles).astype(float), quantised(device, np.full(3, 4.0))])


def test_documented_device_values_are_the_file_s_keys():
    sections = tomllib.loads(DEVICE_FILE.read_text())
    keys = {f"{section}.{key}" for section, values in sections.items() if section != "fit" for key in values}
    assert keys - {"device.name"} == set(DOCUMENTED)


@pytest.mark.parametrize("key", list(DOCUMENTED))
def test_every_documented_device_value_reaches_the_computation(key):
    # on servos that stall under the hardest presses, so the stall torque and the springs' preload act too
    weak = _with(DEVICE, "servo", stall_torque=0.003)
    section, _, name = key.partition(".")
    changed = _with(weak, section, **{name: DOCUMENTED[key]})
    assert not np.allclose(_behaviour(changed), _behaviour(weak), rtol=1e-9, atol=0)
