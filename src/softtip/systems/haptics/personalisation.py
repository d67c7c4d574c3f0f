"""The two personalisations of the FS table, exactly as the spec describes them.

**A, data-driven.** During the FS collection the device-mounted sensor (DS) also read d* for each
configuration m*. The user wears the device and a smaller set of configurations m*,U is driven while
the DS reads d*,U. For each FS entry, its d* is rendered from the user's table (the n nearest d*,U,
their m*,U averaged with inverse-distance weights, :class:`~.rendering.NearestNeighbourRenderer`)
into m̃*, which replaces m* in the FS table. The DS turns with the platform: its force, read in the
platform's axes, is the contact's normal force alone when the contact is frictionless, the same for
every tilt. Each DS reading is therefore turned into the static platform's axes by the orientation
the forward kinematics give for its own configuration (which the device knows, dead band included), so that d* carries
the direction of the force as f* does.

**B, geometric.** The FS and the user's fingertip are spheres of radii r_F and r_U at one centre p.
For each FS entry the forward kinematics give the platform's pose (centroid p_c, normal z1); the FS
point facing the platform is p_o = p − r_F z1 and the imposed deformation d_F = p_c − p_o; the user's
platform goes to p̃_c = p − r_U z1 + d_F = p_c + (r_F − r_U) z1 with the same orientation, and the
inverse kinematics give m̃*. A pose the servos cannot reach is held at the servos' range and flagged.
"""

from __future__ import annotations

import numpy as np

from softtip.sensors.wrench import wrench_in_frame
from softtip.systems.haptics.device import DeviceSpec, forward_kinematics, inverse_kinematics_unchecked, quantised, reachable
from softtip.systems.haptics.rendering import NearestNeighbourRenderer, Rendering


def in_device_axes(device: DeviceSpec, motor_inputs, platform_wrenches) -> np.ndarray:
    """DS readings (entries, 6, in the platform's axes) turned into the static platform's axes by the
    platform's orientation at their ``motor_inputs`` (entries, 3), as the servos resolve them."""
    turn = forward_kinematics(device, quantised(device, motor_inputs)).frame()
    return wrench_in_frame(platform_wrenches, np.swapaxes(turn, -1, -2))


def personalise_data_driven(device: DeviceSpec, fs_motor_inputs, fs_platform_wrenches, user_motor_inputs,
                            user_platform_wrenches, n_neighbours: int = 8,
                            contact_threshold: float | None = None) -> Rendering:
    """Personalised motor inputs m̃* (entries, 3) for the FS table (m*, its DS readings d*), from the
    user's table (m*,U, d*,U); flagged where a d* lies outside the user's table."""
    options = {} if contact_threshold is None else {"contact_threshold": contact_threshold}
    user = NearestNeighbourRenderer(n_neighbours, **options).fit(
        in_device_axes(device, user_motor_inputs, user_platform_wrenches), user_motor_inputs)
    return user.render(in_device_axes(device, fs_motor_inputs, fs_platform_wrenches))


def personalise_geometric(device: DeviceSpec, fs_motor_inputs, fs_radius: float, user_radius: float) -> Rendering:
    """Personalised motor inputs m̃* (entries, 3) for the FS table's m* by the geometric method;
    flagged (and held at the servos' range) where the user's pose is out of reach."""
    if not (np.isfinite(user_radius) and user_radius > 0):
        raise ValueError(f"user_radius = {user_radius!r}: expected a positive radius (m)")
    pose = forward_kinematics(device, fs_motor_inputs)
    moved = pose.moved_along_normal(np.full(pose.tilt.shape, fs_radius - user_radius))
    angles = inverse_kinematics_unchecked(device, moved)
    return Rendering(np.clip(angles, 0.0, device.angle_max), ~reachable(device, angles, moved.tilt))
