"""Exact magnetic flux density of a uniformly, axially magnetised solid cylinder.

Frame: the magnet is centred at the origin with its axis along z; the
polarisation ``J = mu0 * M`` (tesla) points along +z (negative J: along -z).
SI units throughout (m, T).

Formula: N. Derby and S. Olbert, "Cylindrical magnets and ideal solenoids",
Am. J. Phys. 78, 229 (2010), arXiv:0909.3880, eqs. for B_rho and B_z in terms
of Bulirsch's generalised complete elliptic integral

    cel(kc, p, c, s) = int_0^{pi/2} (c cos^2 t + s sin^2 t)
                       / ((cos^2 t + p sin^2 t) sqrt(cos^2 t + kc^2 sin^2 t)) dt,

with z_pm = z +- h/2 for the two end faces of a cylinder of radius a,

    alpha = a / sqrt(z_pm^2 + (rho + a)^2),  beta = z_pm / sqrt(z_pm^2 + (rho + a)^2),
    kc^2  = (z_pm^2 + (a - rho)^2) / (z_pm^2 + (rho + a)^2),  gamma = (a - rho) / (a + rho),
    B_rho = J/pi [alpha cel(kc, 1, 1, -1)]_-^+,
    B_z   = J/pi a/(a + rho) [beta cel(kc, gamma^2, 1, gamma)]_-^+,

where [f]_-^+ = f(z_+) - f(z_-).

Both cel values of one face share kc, so they share one arithmetic-geometric
mean (AGM) sequence; Bulirsch's recurrence is run on that shared sequence in
unscaled form. The radial cel is carried divided by rho (its first step is
proportional to 1 - kc^2 = 4 a rho / (z_pm^2 + (rho + a)^2)), which keeps it
free of cancellation far from the magnet and returns B_rho / rho without a
division by rho, so the axis needs no special case.

Singular sets (the field is finite everywhere except on the two edge circles):
- lateral surface (rho = a exactly): B_z jumps by J across it; the mean of
  the inside and outside limits is returned.
- edge circles (rho = a, z = +-h/2): B_rho diverges logarithmically. kc is
  floored at 1e-15, so on an edge (to rounding) B_rho is that of a point
  2e-15 a away, about 5 |J|; the bounded but discontinuous B_z is the mean
  of its inside and outside limits, as on the lateral surface.
- end faces: the field is continuous there; no special handling.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

_KC_FLOOR = 1e-15
# Added to |gamma| = sqrt(p) so it is nonzero on the lateral surface; below
# rounding for any other point, and large enough that the 1/|gamma| terms of
# the recurrence cannot overflow.
_GAMMA_FLOOR = 1e-200
# Stop after the step that uses a pair with relative gap (A - G)/A below
# this: the truncation error left is then under ~0.2 gap^2 (measured against
# 30 steps), i.e. ~2e-15, the level of rounding in the rest of the formula.
_AGM_GAP_TOLERANCE = 1e-7
# Points per kernel call in `axial_cylinder_field`: the kernel was fastest
# with 4096-8192 points and 3x slower with 16384 on the development machine.
_CHUNK_POINTS = 8192


def agm_steps(kc_min: float) -> int:
    """Number of AGM steps that converge cel for every kc >= kc_min.

    The AGM of (1, kc) converges slowest for the smallest kc, so the count
    found by running the scalar AGM on ``kc_min`` holds for a whole array.
    1 for kc = 1 (the axis), 4-5 for typical kc, 9 at the 1e-15 floor (the
    edge circles); a NaN counts as the floor.
    """
    if not kc_min >= _KC_FLOOR:
        kc_min = _KC_FLOOR
    arithmetic, geometric, steps = 1.0, float(kc_min), 1
    while arithmetic - geometric > _AGM_GAP_TOLERANCE * arithmetic:
        arithmetic, geometric = 0.5 * (arithmetic + geometric), (arithmetic * geometric) ** 0.5
        steps += 1
    return steps


def axial_cylinder_field_rz(
    rho: NDArray[np.float64],
    z: NDArray[np.float64],
    radius: ArrayLike,
    half_height: ArrayLike,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Field of an axially magnetised cylinder per unit polarisation, in (rho, z).

    Args:
        rho: radial distances from the axis (m), any shape, >= 0.
        z: axial coordinates (m), same shape as ``rho``.
        radius, half_height: cylinder radius and half its height (m), > 0,
            broadcastable to ``rho.shape`` (scalars are fastest).

    Returns:
        ``(b_rho_over_rho, b_z)``: B_rho / rho (1/m) and B_z (dimensionless),
        both for J = 1 T; multiply by the polarisation (T). The Cartesian
        field in the magnet frame is ``J * (b_rho_over_rho * x, b_rho_over_rho * y, b_z)``.

    The number of AGM steps is set by the smallest kc in the call: a point
    near an edge makes the whole call slower (up to 9 steps instead of 4-5)
    but never less accurate, and a point's value agrees to rounding whatever
    else is in its call. Keep calls to a few thousand points for cache
    efficiency.
    """
    radius = np.asarray(radius, dtype=np.float64)
    half_height = np.asarray(half_height, dtype=np.float64)
    # Shared by both end faces.
    a_plus_rho = radius + rho
    a_minus_rho_sq = radius - rho
    gamma = a_minus_rho_sq / a_plus_rho
    a_minus_rho_sq *= a_minus_rho_sq
    a_plus_rho_sq = a_plus_rho * a_plus_rho
    sqrt_p = np.abs(gamma)
    sqrt_p += _GAMMA_FLOOR
    sign_gamma = np.divide(gamma, sqrt_p, out=gamma)  # 0 on the lateral surface

    # Axis 0 indexes the end-face terms: z_- = z - h/2, then z_+ = z + h/2.
    face_signs = np.array([-1.0, 1.0]).reshape((2,) + (1,) * np.ndim(z))
    z_face = face_signs * half_height + z
    z_face_sq = z_face * z_face
    inv_far = z_face_sq + a_plus_rho_sq
    np.sqrt(inv_far, out=inv_far)
    np.divide(1.0, inv_far, out=inv_far)  # 1 / sqrt(z^2 + (rho + a)^2)
    kc = z_face_sq + a_minus_rho_sq
    np.sqrt(kc, out=kc)
    kc *= inv_far
    np.maximum(kc, _KC_FLOOR, out=kc)
    steps = agm_steps(float(kc.min()) if kc.size else 1.0)

    # First AGM step (A0, G0) = (1, kc), done by hand for both integrals.
    # Radial: cel(kc, 1, 1, -1) / rho; Bulirsch's p = 1 sequence equals the
    # arithmetic mean, so it needs no separate p.
    radial_s = np.multiply(inv_far, inv_far, out=z_face_sq)
    radial_s *= -4.0 * radius
    arithmetic = kc + 1.0
    radial_s /= arithmetic
    arithmetic *= 0.5
    radial_c = np.zeros_like(kc)
    # Axial: cel(kc, gamma^2, 1, gamma), Bulirsch's p > 0 branch with
    # sqrt(p) = |gamma| and s / sqrt(p) = sign(gamma).
    work = kc / sqrt_p
    axial_s = work + sign_gamma
    axial_c = np.empty_like(kc)
    np.divide(sign_gamma, sqrt_p, out=axial_c)
    axial_c += 1.0
    axial_p = work + sqrt_p
    axial_p *= 0.5
    geometric = np.sqrt(kc, out=kc)

    product = np.empty_like(geometric)
    ratio = np.empty_like(geometric)
    for _ in range(steps - 1):
        np.multiply(arithmetic, geometric, out=product)
        np.divide(radial_s, arithmetic, out=ratio)
        np.multiply(radial_c, geometric, out=work)
        radial_s += work
        radial_c += ratio
        arithmetic += geometric
        arithmetic *= 0.5
        np.sqrt(product, out=geometric)
        np.divide(1.0, axial_p, out=work)
        np.multiply(axial_s, work, out=ratio)
        work *= product
        axial_p += work
        axial_p *= 0.5
        work *= axial_c
        axial_s += work
        axial_c += ratio

    # cel = pi/2 * 2^-steps (s + c A) / (A (A + p)), with p = A for the radial one.
    radial_c *= arithmetic
    radial_s += radial_c
    radial_s *= inv_far  # alpha / a
    radial_s /= arithmetic
    radial_s /= arithmetic
    axial_c *= arithmetic
    axial_s += axial_c
    axial_s *= z_face
    axial_s *= inv_far  # beta
    axial_p += arithmetic
    axial_p *= arithmetic
    axial_s /= axial_p

    # J/pi * pi/2 * 2^-steps, the radial one also with its 1/2 from p = A.
    scale = 0.5**steps
    b_rho_over_rho = np.subtract(radial_s[1], radial_s[0])
    b_rho_over_rho *= (0.25 * scale) * radius
    b_z = np.subtract(axial_s[1], axial_s[0])
    b_z *= (0.5 * scale) * radius
    b_z /= a_plus_rho
    return b_rho_over_rho, b_z


def axial_cylinder_field(
    points_local: ArrayLike,
    radius: ArrayLike,
    height: ArrayLike,
    polarization: ArrayLike,
) -> NDArray[np.float64]:
    """B (T) of an axially magnetised cylinder, in its own frame.

    Args:
        points_local: (..., 3) observation points (m), magnet centred at the
            origin with its axis along z.
        radius, height: cylinder radius and height (m), > 0, broadcastable
            to ``points_local.shape[:-1]``.
        polarization: J = mu0 M (T) along +z, broadcastable likewise.

    Returns:
        (..., 3) flux density (T). Finite everywhere; see the module docstring
        for the values returned on the edge circles and the lateral surface.
    """
    points = np.asarray(points_local, dtype=np.float64)
    if points.shape[-1:] != (3,):
        raise ValueError(f"points_local must have shape (..., 3), got {points.shape}")
    batch_shape = points.shape[:-1]
    radius = np.asarray(radius, dtype=np.float64)
    height = np.asarray(height, dtype=np.float64)
    if np.any(radius <= 0) or np.any(height <= 0):
        raise ValueError("radius and height must be positive")
    flat = points.reshape(-1, 3)
    # Per-point parameters are flattened alongside the points; scalars stay
    # scalars (cheaper in the kernel).
    per_point = [
        p if p.ndim == 0 else np.broadcast_to(p, batch_shape).ravel()
        for p in (radius, 0.5 * height, np.asarray(polarization, dtype=np.float64))
    ]
    field = np.empty_like(flat)
    for start in range(0, flat.shape[0], _CHUNK_POINTS):
        rows = slice(start, start + _CHUNK_POINTS)
        a, half_h, j = (p if p.ndim == 0 else p[rows] for p in per_point)
        x, y, z = flat[rows].T
        rho = x * x
        rho += y * y
        np.sqrt(rho, out=rho)
        b_rho_over_rho, b_z = axial_cylinder_field_rz(rho, np.ascontiguousarray(z), a, half_h)
        b_rho_over_rho *= j
        np.multiply(b_rho_over_rho, x, out=field[rows, 0])
        np.multiply(b_rho_over_rho, y, out=field[rows, 1])
        np.multiply(b_z, j, out=field[rows, 2])
    return field.reshape(batch_shape + (3,))
