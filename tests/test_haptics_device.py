"""The S3 device: kinematics exact both ways, the spec's cable-length rule, the device file's
refusals, the servos' frames, dead band and slew, and the cables' statics."""

from __future__ import annotations

import dataclasses
import math

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
    quantised,
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
    ("stall_torque = 0.078", "stall_torque = -1", "servo.stall_torque"),
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
def test_loaded_platform_gives_way_along_its_normal_by_the_force_over_three_cables(angles):
    # the reference: the give s that solves s = F(δ₀ − s) / 3k, found by scipy's brentq on the contact law
    rigid = forward_kinematics(DEVICE, angles)
    _, depth = finger_wrench(FINGERTIP_SENSOR, DEVICE, rigid)
    assert depth > 1e-4  # the press is real
    radius = cap_indentation(FINGERTIP_SENSOR.centre(DEVICE), FINGERTIP_SENSOR.semi_axes, rigid.centroid,
                             rigid.normal)[2]
    three_cables = 3 * DEVICE.cables.stiffness
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
