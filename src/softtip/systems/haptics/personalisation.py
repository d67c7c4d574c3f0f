"""The two personalisations of the FS table, exactly as the spec describes them.

**A, data-driven.** During the FS collection the device-mounted sensor (DS) also read d* for each
configuration m*. The user wears the device and a smaller set of configurations m*,U is driven while
the DS reads d*,U. For each FS entry, its d* is rendered from the user's table (the n nearest d*,U,
their m*,U averaged with inverse-distance weights, :class:`~.rendering.NearestNeighbourRenderer`)
into m̃*, which replaces m* in the FS table.

**B, geometric.** The FS and the user's fingertip are spheres of radii r_F and r_U at one centre p.
For each FS entry the forward kinematics give the platform's pose (centroid p_c, normal z1); the FS
point facing the platform is p_o = p − r_F z1 and the imposed deformation d_F = p_c − p_o; the user's
platform goes to p̃_c = p − r_U z1 + d_F = p_c + (r_F − r_U) z1 with the same orientation, and the
inverse kinematics give m̃*. A pose the servos cannot reach is held at the servos' range and flagged.
"""

from __future__ import annotations

import numpy as np

from softtip.systems.haptics.device import DeviceSpec, forward_kinematics, inverse_kinematics_unchecked, reachable
from softtip.systems.haptics.rendering import NearestNeighbourRenderer, Rendering


def personalise_data_driven(fs_platform_wrenches, user_platform_wrenches, user_motor_inputs,
                            n_neighbours: int = 8, contact_threshold: float | None = None) -> Rendering:
    """Personalised motor inputs m̃* (entries, 3) for the FS table's DS readings d* (entries, 6), from
    the user's table (d*,U, m*,U); flagged where a d* lies outside the user's table."""
    options = {} if contact_threshold is None else {"contact_threshold": contact_threshold}
    user = NearestNeighbourRenderer(n_neighbours, **options).fit(user_platform_wrenches, user_motor_inputs)
    return user.render(fs_platform_wrenches)


def personalise_geometric(device: DeviceSpec, fs_motor_inputs, fs_radius: float, user_radius: float) -> Rendering:
    """Personalised motor inputs m̃* (entries, 3) for the FS table's m* by the geometric method;
    flagged (and held at the servos' range) where the user's pose is out of reach."""
    if not (np.isfinite(user_radius) and user_radius > 0):
        raise ValueError(f"user_radius = {user_radius!r}: expected a positive radius (m)")
    pose = forward_kinematics(device, fs_motor_inputs)
    moved = pose.moved_along_normal(np.full(pose.tilt.shape, fs_radius - user_radius))
    angles = inverse_kinematics_unchecked(device, moved)
    return Rendering(np.clip(angles, 0.0, device.angle_max), ~reachable(device, angles, moved.tilt))
