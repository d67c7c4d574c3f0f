"""The two personalisations of the FS table, exactly as the spec describes them.

**A, data-driven.** During the FS collection the device-mounted sensor (DS) also read d* for each
configuration m*. The user wears the device and a smaller set of configurations m*,U is driven while
the DS reads d*,U. For each FS entry, its d* is rendered from the user's table (the n nearest d*,U,
their m*,U averaged with inverse-distance weights, :class:`~.rendering.NearestNeighbourRenderer`)
into m̃*, which replaces m* in the FS table. Two variants of what "nearest" means:

- ``published`` (the publication's): the DS's raw wrenches, 6-D, as it read them in the platform's
  axes, the torques divided by ``torque_length`` (:func:`~.rendering.wrench_features`); no model of
  the device. With a frictionless contact the DS's force is the normal force alone, the same for
  every tilt; its torques, the force times the contact point's offset on the platform, carry the
  tilt. :data:`DS_TORQUE_LENGTH` is the FS's radius: tilting the platform by θ about a fingertip of
  radius r moves the contact about r sin θ across it, so τ / r ≈ |F| sin θ, the size of the
  tangential force the same tilt gives in the device's axes.
- ``device axes`` (softtip's earlier variant): the DS's forces alone, 3-D, each turned into the
  static platform's axes by the orientation the forward kinematics give for its own configuration
  (which the device knows, dead band included), so that d* carries the direction of the force as f* does.

**B, geometric.** The FS and the user's fingertip are spheres of radii r_F and r_U at one centre p.
For each FS entry the forward kinematics give the platform's pose (centroid p_c, normal z1); the FS
point facing the platform is p_o = p − r_F z1 and the imposed deformation d_F = p_c − p_o; the user's
platform goes to p̃_c = p − r_U z1 + d_F = p_c + (r_F − r_U) z1 with the same orientation, and the
inverse kinematics give m̃*. A pose the servos cannot reach is held at the servos' range and flagged.

**B with a force–deformation model** (beyond the publication; the authors' future work). Equal
indentation of a larger or stiffer sphere takes more force, so the geometric method is not exact
for force. Here the platform presses the user at most five times (level presses 0.2–1 mm deep as
the sphere model places the pad, read by the DS);
the geometric indentation of each press under the sphere model and the DS's force fit the user's
Hertz modulus (:func:`~softtip.mechanics.plate_contact.fit_hertz_modulus`). Each FS entry's
measured force |f*| is then rendered as the indentation that gives that force on the user's sphere,
δ_U = Hertz⁻¹(|f*|), with the platform at p̃_c = p − (r_U − δ_U) z1 in the same orientation. An entry
without contact keeps the geometric method's placement. Both steps take the cables rigid, as the
kinematics do; ``cables = "compliant"`` takes each press's depth less the platform's give under its
force and commands each entry that much further (the report's ablation of B+).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from softtip.mechanics.plate_contact import cap_indentation, fit_hertz_modulus, hertz_depth
from softtip.sensors.wrench import wrench_in_frame
from softtip.systems.haptics.device import (
    DeviceSpec,
    PlatformPose,
    forward_kinematics,
    inverse_kinematics_unchecked,
    normal_give,
    quantised,
    reachable,
    servo_angles_of_lengths,
)
from softtip.systems.haptics.rendering import CONTACT_THRESHOLD, NearestNeighbourRenderer, Rendering


DATA_DRIVEN_VARIANTS = ("published", "device axes")
DS_TORQUE_LENGTH = 7.5e-3  # m: the FS's radius (see the module's notes)


def in_device_axes(device: DeviceSpec, motor_inputs, platform_wrenches) -> np.ndarray:
    """DS readings (entries, 6, in the platform's axes) turned into the static platform's axes by the
    platform's orientation at their ``motor_inputs`` (entries, 3), as the servos resolve them."""
    turn = forward_kinematics(device, quantised(device, motor_inputs)).frame()
    return wrench_in_frame(platform_wrenches, np.swapaxes(turn, -1, -2))


def readings_renderer(device_readings, user_motor_inputs, n_neighbours: int = 8,
                      contact_threshold: float | None = None, weighting_power: float = 1.0,
                      torque_length: float | None = None) -> NearestNeighbourRenderer:
    """The inverse of the user's table α_U: DS readings (the variant's: raw, or in the device's axes,
    :func:`in_device_axes`) to motor inputs; a ``torque_length`` searches the whole wrench."""
    options = {} if contact_threshold is None else {"contact_threshold": contact_threshold}
    return NearestNeighbourRenderer(n_neighbours, weighting_power=weighting_power, torque_length=torque_length,
                                    **options).fit(device_readings, user_motor_inputs)


def personalise_data_driven(device: DeviceSpec, fs_motor_inputs, fs_platform_wrenches, user_motor_inputs,
                            user_platform_wrenches, n_neighbours: int = 8,
                            contact_threshold: float | None = None, weighting_power: float = 1.0,
                            variant: str = "published", torque_length: float = DS_TORQUE_LENGTH) -> Rendering:
    """Personalised motor inputs m̃* (entries, 3) for the FS table (m*, its DS readings d*), from the
    user's table (m*,U, d*,U), by ``variant`` (:data:`DATA_DRIVEN_VARIANTS`; ``published`` searches
    the raw wrenches with the torques over ``torque_length``, m); flagged where a d* lies outside the
    user's table."""
    if variant == "published":
        user, fs = user_platform_wrenches, fs_platform_wrenches
    elif variant == "device axes":
        user = in_device_axes(device, user_motor_inputs, user_platform_wrenches)
        fs = in_device_axes(device, fs_motor_inputs, fs_platform_wrenches)
        torque_length = None
    else:
        raise ValueError(f"variant = {variant!r}: expected one of {', '.join(DATA_DRIVEN_VARIANTS)}")
    renderer = readings_renderer(user, user_motor_inputs, n_neighbours, contact_threshold, weighting_power,
                                 torque_length)
    return renderer.render(fs)


@dataclass(frozen=True)
class PressFit:
    """The user's fingertip as the presses found it: its Hertz modulus (Pa), the presses' geometric
    indentations (m) and DS forces (N), and how many touched."""

    youngs_modulus: float
    depths: np.ndarray
    forces: np.ndarray
    touching: int


MAX_PRESSES = 5


PRESS_DEPTHS = (0.2e-3, 0.4e-3, 0.6e-3, 0.8e-3, 1.0e-3)  # m: light presses, as the sphere model places them


def press_configurations(device: DeviceSpec, user_radius: float, depths=PRESS_DEPTHS) -> np.ndarray:
    """Level presses (presses, 3): the platform raised to ``depths`` into the user's pad as the
    geometric model places it (a sphere of ``user_radius`` at the device's finger centre), within
    the servos' range."""
    depths = np.asarray(depths, dtype=float)
    if not 1 <= len(depths) <= MAX_PRESSES or np.any(depths <= 0):
        raise ValueError(f"depths = {depths.tolist()}: expected 1 to {MAX_PRESSES} positive depths (m)")
    if not (np.isfinite(user_radius) and user_radius > 0):
        raise ValueError(f"user_radius = {user_radius!r}: expected a positive radius (m)")
    lengths = -(device.centre[2] - user_radius + depths)  # each cable to the level plane at that depth
    angles = servo_angles_of_lengths(device, lengths)
    return np.repeat(np.clip(angles, 0.0, device.angle_max)[:, None], 3, axis=1)


CABLE_MODELS = ("rigid", "compliant")  # how B+ places the platform: its kinematics, or less the cables' give


def fit_presses(device: DeviceSpec, motor_inputs, platform_wrenches, user_radius: float,
                contact_threshold: float = CONTACT_THRESHOLD, poisson_ratio: float = 0.5,
                saturated=None, cables: str = "rigid") -> PressFit:
    """Fit the user's Hertz modulus from at most five presses (``motor_inputs`` and the DS's readings);
    presses where the DS ``saturated`` (presses,) are left out: their force is the range's end. With
    ``cables = "compliant"`` each press's depth is the kinematics' less the platform's give under the
    force the DS read (:func:`~.device.normal_give`, the device file's stiffnesses)."""
    if cables not in CABLE_MODELS:
        raise ValueError(f"cables = {cables!r}: expected one of {', '.join(CABLE_MODELS)}")
    motor_inputs = np.asarray(motor_inputs, dtype=float)
    if not 1 <= len(motor_inputs) <= MAX_PRESSES:
        raise ValueError(f"presses: {len(motor_inputs)} given, expected 1 to {MAX_PRESSES}")
    pose = forward_kinematics(device, quantised(device, motor_inputs))
    depths = cap_indentation(device.centre, np.full(3, user_radius), pose.centroid, pose.normal)[0]
    forces = np.linalg.norm(np.asarray(platform_wrenches, dtype=float)[:, :3], axis=1)
    if cables == "compliant":
        depths = depths - normal_give(device, forces)
    usable = np.ones(len(forces), bool) if saturated is None else ~np.asarray(saturated, dtype=bool)
    touching = (forces >= contact_threshold) & (depths > 0) & usable
    if not touching.any():
        raise ValueError(f"presses: none of the {len(motor_inputs)} presses touched the fingertip within the "
                         f"sensor's range (forces from {contact_threshold:g} N, unsaturated): "
                         "no stiffness can be fitted")
    modulus = fit_hertz_modulus(depths[touching], forces[touching], user_radius, poisson_ratio)
    return PressFit(modulus, depths, forces, int(touching.sum()))


def personalise_force_model(device: DeviceSpec, fs_motor_inputs, fs_wrenches, fs_radius: float,
                            user_radius: float, user: PressFit, contact_threshold: float = CONTACT_THRESHOLD,
                            poisson_ratio: float = 0.5, geometric: Rendering | None = None,
                            cables: str = "rigid") -> Rendering:
    """Personalised motor inputs (entries, 3) by the geometric method with the user's fitted Hertz law;
    flagged (and held at the servos' range) where the pose is out of reach. ``geometric``: the
    geometric method's personalisation of the same table, if already computed (without contact, the
    entry keeps it). With ``cables = "compliant"`` the platform is commanded past the indentation by
    its give under the entry's force (:func:`~.device.normal_give`)."""
    if cables not in CABLE_MODELS:
        raise ValueError(f"cables = {cables!r}: expected one of {', '.join(CABLE_MODELS)}")
    if geometric is None:
        geometric = personalise_geometric(device, fs_motor_inputs, fs_radius, user_radius)
    pose = forward_kinematics(device, fs_motor_inputs)
    force = np.linalg.norm(np.asarray(fs_wrenches, dtype=float)[:, :3], axis=1)
    depth = hertz_depth(force, user_radius, user.youngs_modulus, poisson_ratio)
    if cables == "compliant":
        depth = depth + normal_give(device, force)
    # p̃_c = p − (r_U − δ_U) z1: the plane at distance r_U − δ_U from the centre, towards the platform
    point = device.centre - (user_radius - depth)[:, None] * pose.normal
    angles = inverse_kinematics_unchecked(device, PlatformPose(point, pose.normal))
    contact = force >= contact_threshold
    angles = np.where(contact[:, None], angles, geometric.motor_inputs)
    out = np.where(contact, ~reachable(device, angles, pose.tilt), geometric.outside)
    return Rendering(np.clip(angles, 0.0, device.angle_max), out)


def personalise_geometric(device: DeviceSpec, fs_motor_inputs, fs_radius: float, user_radius: float) -> Rendering:
    """Personalised motor inputs m̃* (entries, 3) for the FS table's m* by the geometric method;
    flagged (and held at the servos' range) where the user's pose is out of reach."""
    if not (np.isfinite(user_radius) and user_radius > 0):
        raise ValueError(f"user_radius = {user_radius!r}: expected a positive radius (m)")
    pose = forward_kinematics(device, fs_motor_inputs)
    moved = pose.moved_along_normal(np.full(pose.tilt.shape, fs_radius - user_radius))
    angles = inverse_kinematics_unchecked(device, moved)
    return Rendering(np.clip(angles, 0.0, device.angle_max), ~reachable(device, angles, moved.tilt))
