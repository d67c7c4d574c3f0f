"""Field of posed cylindrical magnets at the sensor points, summed over magnets.

A magnet's pose is its centre position and a rotation vector (axis * angle,
rad, as scipy's ``Rotation.from_rotvec``) taking its local frame to the world
frame; it is magnetised along its local +z. The field of magnet m at sensor
s is ``R B_local(R^T (s - p))``. The cylinder field is axisymmetric, so only
the magnet axis ``e = R e_z`` enters: with ``d = s - p``, local coordinates
``z = e . d`` and ``rho = |d - z e|``, and

    R B_local = (B_rho / rho) d + (B_z - z B_rho / rho) e,

which is the rotated field without building or applying a 3x3 matrix.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from softtip.magnetics.cylinder import axial_cylinder_field_rz

# Magnet-sensor pairs per kernel call, the measured optimum: smaller chunks
# pay numpy's per-call overhead more often (3072: -15 %), larger ones leave
# the caches (65536: -8 %). The kernel's work arrays are then 128 KiB each.
_PAIRS_PER_CHUNK = 8192


def _axis_components(
    rotvec_x: NDArray[np.float64], rotvec_y: NDArray[np.float64], rotvec_z: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Rotated z axis R(v) e_z from rotation-vector components (same shapes).

    Rodrigues' formula in Euler-Rodrigues (half-angle) form: with theta = |v|,
    w = cos(theta/2) and q = v sin(theta/2)/theta, the third column of R is
    (2(q_x q_z + w q_y), 2(q_y q_z - w q_x), 1 - 2(q_x^2 + q_y^2)).
    cos and sin of theta/2 come from t = tan(theta/4) by the double-angle
    identities, valid for every finite theta (t is never infinite in floating
    point): numpy's float64 tan is SIMD-vectorised while its sin and cos are
    not (1 ns vs 7.5 ns per element on the development machine).
    """
    theta = rotvec_x * rotvec_x
    theta += rotvec_y * rotvec_y
    theta += rotvec_z * rotvec_z
    np.sqrt(theta, out=theta)
    # tan(x) == x in floating point for the floored theta, so the ratio
    # sin(theta/2)/theta below tends to its limit 1/2 as theta -> 0.
    np.maximum(theta, 1e-30, out=theta)
    tan_quarter = np.multiply(theta, 0.25)
    np.tan(tan_quarter, out=tan_quarter)
    inv_one_plus_t2 = tan_quarter * tan_quarter
    w = np.subtract(1.0, inv_one_plus_t2)  # cos(theta/2) = (1 - t^2) / (1 + t^2)
    inv_one_plus_t2 += 1.0
    np.divide(1.0, inv_one_plus_t2, out=inv_one_plus_t2)
    w *= inv_one_plus_t2
    # sin(theta/2) / theta = 2 t / ((1 + t^2) theta)
    factor = np.multiply(tan_quarter, inv_one_plus_t2, out=tan_quarter)
    factor *= 2.0
    factor /= theta
    qx = rotvec_x * factor
    qy = rotvec_y * factor
    qz = np.multiply(rotvec_z, factor, out=factor)
    axis_x = qx * qz
    axis_x += w * qy
    axis_x *= 2.0
    axis_y = qy * qz
    axis_y -= np.multiply(w, qx, out=w)
    axis_y *= 2.0
    axis_z = np.multiply(qx, qx, out=qx)
    axis_z += np.multiply(qy, qy, out=qy)
    axis_z *= -2.0
    axis_z += 1.0
    return axis_x, axis_y, axis_z


def magnet_axes(rotvecs: ArrayLike) -> NDArray[np.float64]:
    """(..., 3) world direction of each magnet's local +z axis for (..., 3) rotation vectors."""
    rotvecs = np.asarray(rotvecs, dtype=np.float64)
    if rotvecs.shape[-1:] != (3,):
        raise ValueError(f"rotvecs must have shape (..., 3), got {rotvecs.shape}")
    components = _axis_components(*(np.ascontiguousarray(c) for c in np.moveaxis(rotvecs, -1, 0)))
    return np.stack(components, axis=-1)


def _per_magnet(values: ArrayLike, n_magnets: int, name: str) -> NDArray[np.float64]:
    array = np.asarray(values, dtype=np.float64)
    if array.shape not in ((), (n_magnets,)):
        raise ValueError(f"{name} must be a scalar or have shape ({n_magnets},), got {array.shape}")
    return np.broadcast_to(array, (n_magnets,))


class _MagnetConstants(NamedTuple):
    radius: NDArray[np.float64]
    half_height: NDArray[np.float64]
    polarization: NDArray[np.float64]


def _chunk_field(
    sensor_columns: NDArray[np.float64],
    positions: NDArray[np.float64],
    rotvecs: NDArray[np.float64],
    magnets: _MagnetConstants,
) -> NDArray[np.float64]:
    """(n, S, 3) summed field for (n, M, 3) poses; sensors given as (3, 1, S, 1)."""
    # Work arrays are (3, M, S, n): component, magnet, sensor, pose.
    centre = np.ascontiguousarray(positions.transpose(2, 1, 0))[:, :, None, :]
    axis = np.stack(_axis_components(*np.ascontiguousarray(rotvecs.transpose(2, 1, 0))))[:, :, None, :]
    offset = sensor_columns - centre
    z = offset[0] * axis[0]
    z += offset[1] * axis[1]
    z += offset[2] * axis[2]
    rho = offset[0] * offset[0]
    rho += offset[1] * offset[1]
    rho += offset[2] * offset[2]
    # rho^2 = |d|^2 - z^2 loses relative accuracy near the axis, harmlessly:
    # the field depends smoothly on rho^2 there. Rounding can make it < 0.
    rho -= z * z
    np.maximum(rho, 0.0, out=rho)
    np.sqrt(rho, out=rho)
    b_rho_over_rho, b_z = axial_cylinder_field_rz(rho, z, magnets.radius, magnets.half_height)
    b_rho_over_rho *= magnets.polarization
    b_z *= magnets.polarization
    axis_coefficient = np.subtract(b_z, np.multiply(z, b_rho_over_rho, out=z), out=b_z)
    world = offset
    world *= b_rho_over_rho
    world += axis_coefficient * axis
    return world.sum(axis=1).transpose(2, 1, 0)


def magnet_field_at_sensors(
    sensor_positions: ArrayLike,
    magnet_positions: ArrayLike,
    magnet_rotvecs: ArrayLike,
    radius: ArrayLike,
    height: ArrayLike,
    polarization: ArrayLike,
    ambient: ArrayLike | None = None,
) -> NDArray[np.float64]:
    """Summed flux density of M posed cylinders at S sensors, for N pose sets.

    Args:
        sensor_positions: (S, 3) sensor points in the world frame (m).
        magnet_positions: (N, M, 3) magnet centres (m) for N pose sets.
        magnet_rotvecs: (N, M, 3) rotation vectors (rad) local -> world.
        radius, height: (M,) cylinder radius and height (m), > 0 (scalars
            are broadcast to all magnets).
        polarization: (M,) polarisation J (T) along each magnet's local +z;
            negative values point the magnet the other way.
        ambient: optional uniform field (3,) (T) added to every reading.

    Returns:
        (N, S, 3) flux density (T) in the world frame.
    """
    sensors = np.asarray(sensor_positions, dtype=np.float64)
    positions = np.asarray(magnet_positions, dtype=np.float64)
    rotvecs = np.asarray(magnet_rotvecs, dtype=np.float64)
    if sensors.ndim != 2 or sensors.shape[1] != 3:
        raise ValueError(f"sensor_positions must have shape (S, 3), got {sensors.shape}")
    if positions.ndim != 3 or positions.shape[2] != 3:
        raise ValueError(f"magnet_positions must have shape (N, M, 3), got {positions.shape}")
    if rotvecs.shape != positions.shape:
        raise ValueError(f"magnet_rotvecs shape {rotvecs.shape} != magnet_positions shape {positions.shape}")
    n_poses, n_magnets, _ = positions.shape
    n_sensors = sensors.shape[0]
    radius = _per_magnet(radius, n_magnets, "radius")
    height = _per_magnet(height, n_magnets, "height")
    polarization = _per_magnet(polarization, n_magnets, "polarization")
    if np.any(radius <= 0) or np.any(height <= 0):
        raise ValueError("radius and height must be positive")
    if ambient is not None:
        ambient = np.asarray(ambient, dtype=np.float64)
        if ambient.shape != (3,):
            raise ValueError(f"ambient must have shape (3,), got {ambient.shape}")

    # Per-magnet constants shaped (M, 1, 1) against (M, S, poses) work arrays.
    magnet_shape = (n_magnets, 1, 1)
    magnets = _MagnetConstants(
        radius=radius.reshape(magnet_shape),
        half_height=(0.5 * height).reshape(magnet_shape),
        polarization=polarization.reshape(magnet_shape),
    )
    # (3, 1, S, 1): components first so every work array is contiguous.
    sensor_columns = np.ascontiguousarray(sensors.T).reshape(3, 1, n_sensors, 1)

    field = np.zeros((n_poses, n_sensors, 3))
    if n_magnets and n_sensors:
        poses_per_chunk = max(1, _PAIRS_PER_CHUNK // (n_magnets * n_sensors))
        for start in range(0, n_poses, poses_per_chunk):
            poses = slice(start, start + poses_per_chunk)
            field[poses] = _chunk_field(sensor_columns, positions[poses], rotvecs[poses], magnets)
    if ambient is not None:
        field += ambient
    return field
