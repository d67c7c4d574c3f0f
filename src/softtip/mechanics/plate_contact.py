"""A rigid flat plate pressed on a curved elastic cap (a fingertip), vectorised over plate poses.

The cap is an ellipsoid with semi-axes (a, b, c) along the frame's axes, centred at ``centre``
(a sphere when a = b = c). A plate is a point ``plate_point`` on its face and the unit normal
``plate_normal`` pointing from the plate towards the cap. The cap's surface point farthest towards
the plate lies at the support distance h(n) = √(a²n_x² + b²n_y² + c²n_z²) from the centre; the
indentation is δ = h(n) − n·(centre − plate_point) (δ <= 0: no contact). The contact is
frictionless: the plate pushes the cap along n only, at the foot of that surface point on the plate,
so the wrench about a sensor origin is (F n, (x − origin) × F n).

Three normal laws F(δ) on the cap's effective radius R (for an ellipsoid the Gaussian curvature
radius at the contact point, R = abc / h(n)², the equivalent-sphere approximation of Johnson,
*Contact Mechanics*, 1985, §4.2):

- **Hertz** (a homogeneous elastic half space): F = (4/3) E* √R δ^{3/2}, E* = E / (1 − ν²),
  contact radius √(Rδ) (Johnson, §4.2). Valid while the contact radius is small beside the
  elastomer's thickness over any rigid core.
- **Exponential**, as measured on human finger pads (Pawluk & Howe, J. Biomech. Eng. 121:178,
  1999): F = (R/R_ref)(b/m)(e^{mδ} − 1), the finger pad's law (:func:`exponential_force`) scaled by
  the radius as its Winkler layer scales it (contact area 2πRδ).
- **Bonded layer over a rigid core** (``bonded-layer``): Hertz corrected for an incompressible layer
  of thickness t bonded to a rigid substrate, F = F_Hertz (1 + 1.133χ + 1.283χ² + 0.769χ³ +
  0.0975χ⁴), χ = √(Rδ)/t (Dimitriadis, Horkay, Maresca, Kachar & Chadwick, Biophys. J. 82:2798,
  2002, their bonded case at ν = 0.5, derived for χ up to about 1; a flat on a cap has the same gap
  as a sphere on a flat). It tends to Hertz for a thick layer. :mod:`softtip.mechanics.cap_fe`
  calibrates its effective thickness by finite elements.
- **Thin layer over a rigid core** (``layer``), the thin-layer limit: an incompressible layer of shear modulus G
  and thickness t bonded to the core and pressed by a frictionless plate. Thin-layer (lubrication)
  theory gives ∇²p = −3Gw/t³ for the local compression w = δ − r²/2R, and a smooth contact edge
  (p = p' = 0) puts the edge at a = 2√(Rδ), so F = 2πG R² δ³ / t³. Valid while the contact
  radius is large beside t (the opposite limit to Hertz); stiffer than Hertz there, and far steeper.
"""

from __future__ import annotations

import numpy as np

from softtip._core.config import PositiveNumber, Refusal, choice, number, schema


# the human finger pad's law against a flat plate (Pawluk & Howe 1999), for any model of a finger pad
def exponential_force(depth, stiffness, stiffening):
    """F = (b/m)(e^{mδ} − 1): the pulp's force (N) at a depth δ (m) against a flat plate."""
    return stiffness / stiffening * np.expm1(stiffening * np.asarray(depth, dtype=float))


def exponential_depth(force, stiffness, stiffening):
    """The depth (m) at which :func:`exponential_force` reaches ``force`` (N >= 0)."""
    return np.log1p(stiffening * np.asarray(force, dtype=float) / stiffness) / stiffening


CONTACT_LAWS = ("hertz", "bonded-layer", "exponential", "layer")


@schema(section="contact")
class PlateContactLaw:
    """The normal law of a cap under a flat plate, and its material figures (SI).

    ``law``: hertz uses ``youngs_modulus`` and ``poisson_ratio``; bonded-layer ``youngs_modulus``
    and ``layer_thickness`` (m), incompressible (``poisson_ratio`` must be 0.5); exponential uses
    ``stiffness`` (b, N/m), ``stiffening`` (m, 1/m) and ``reference_radius`` (m); layer uses ``youngs_modulus``, ``poisson_ratio`` (through
    G = E / 2(1 + ν)) and ``layer_thickness``."""

    law: choice(*CONTACT_LAWS)
    youngs_modulus: PositiveNumber = 1.0e6
    poisson_ratio: number("a number from 0 to 0.5", ge=0, le=0.5) = 0.5
    stiffness: PositiveNumber = 330.0
    stiffening: PositiveNumber = 1700.0
    reference_radius: PositiveNumber = 7.5e-3
    layer_thickness: PositiveNumber = 3.0e-3

    def __post_init__(self) -> None:
        if self.law == "bonded-layer" and self.poisson_ratio != 0.5:
            raise Refusal("poisson_ratio", "expected 0.5: the bonded-layer law is the incompressible case")

    @property
    def shear_modulus(self) -> float:
        return self.youngs_modulus / (2 * (1 + self.poisson_ratio))


def hertz_force(depth, radius, youngs_modulus, poisson_ratio):
    """F = (4/3) E* √R δ^{3/2} (N) of a sphere of radius R (m) on a rigid flat at depth δ (m); 0 without contact."""
    depth = np.maximum(np.asarray(depth, dtype=float), 0.0)
    reduced = youngs_modulus / (1 - poisson_ratio**2)
    return 4.0 / 3.0 * reduced * np.sqrt(radius) * depth**1.5


def hertz_depth(force, radius, youngs_modulus, poisson_ratio):
    """The depth δ (m) at which :func:`hertz_force` reaches ``force`` (N >= 0): its exact inverse."""
    force = np.maximum(np.asarray(force, dtype=float), 0.0)
    reduced = youngs_modulus / (1 - poisson_ratio**2)
    return (force / (4.0 / 3.0 * reduced * np.sqrt(radius))) ** (2.0 / 3.0)


def fit_hertz_modulus(depth, force, radius, poisson_ratio=0.5) -> float:
    """Young's modulus (Pa) whose Hertz law best fits presses of ``depth`` (m) and ``force`` (N) on a
    cap of ``radius`` (m), by least squares in force (the law is linear in the modulus)."""
    depth, force = np.asarray(depth, dtype=float), np.asarray(force, dtype=float)
    shape = hertz_force(depth, radius, 1.0, 0.0)  # F per unit reduced modulus
    if depth.shape != force.shape or not np.any(shape > 0):
        raise ValueError("presses: expected matching depths and forces with at least one press in contact")
    reduced = float(np.sum(shape * force) / np.sum(shape**2))
    if not reduced > 0:
        raise ValueError("presses: the forces do not grow with depth; no modulus fits them")
    return reduced * (1 - poisson_ratio**2)


# Dimitriadis et al. (2002), bonded incompressible layer: the coefficients of χ⁰..χ⁴ as printed
_BONDED_LAYER_SERIES = (1.0, 1.133, 1.283, 0.769, 0.0975)


def bonded_layer_force(depth, radius, youngs_modulus, thickness):
    """Hertz's force (N) on an incompressible layer of ``thickness`` (m) bonded to a rigid core."""
    depth = np.maximum(np.asarray(depth, dtype=float), 0.0)
    chi = np.sqrt(np.asarray(radius, dtype=float) * depth) / thickness
    return hertz_force(depth, radius, youngs_modulus, 0.5) * np.polynomial.polynomial.polyval(chi, _BONDED_LAYER_SERIES)


def layer_force(depth, radius, shear_modulus, thickness):
    """F = 2πG R² δ³ / t³ (N): a thin incompressible layer on a rigid core under a frictionless flat."""
    depth = np.maximum(np.asarray(depth, dtype=float), 0.0)
    return 2 * np.pi * shear_modulus * np.asarray(radius, dtype=float) ** 2 * depth**3 / thickness**3


def normal_force(law: PlateContactLaw, depth, radius):
    """The plate's normal force (N) at indentation ``depth`` (m) on a cap of effective ``radius`` (m)."""
    if law.law == "hertz":
        return hertz_force(depth, radius, law.youngs_modulus, law.poisson_ratio)
    if law.law == "layer":
        return layer_force(depth, radius, law.shear_modulus, law.layer_thickness)
    if law.law == "bonded-layer":
        return bonded_layer_force(depth, radius, law.youngs_modulus, law.layer_thickness)
    depth = np.maximum(np.asarray(depth, dtype=float), 0.0)
    return np.asarray(radius) / law.reference_radius * exponential_force(depth, law.stiffness, law.stiffening)


def contact_radius(law: PlateContactLaw, depth, radius):
    """The contact's radius (m): √(Rδ) for Hertz (and the bonded layer's Hertz term), 2√(Rδ) for
    the thin layer, √(2Rδ) (the geometric
    intersection) for the exponential law's Winkler layer."""
    factor = {"hertz": 1.0, "bonded-layer": 1.0, "layer": 4.0, "exponential": 2.0}[law.law]
    return np.sqrt(factor * np.asarray(radius) * np.maximum(np.asarray(depth, dtype=float), 0.0))


def _unit_normals(plate_normal: np.ndarray) -> np.ndarray:
    plate_normal = np.asarray(plate_normal, dtype=float)
    if plate_normal.shape[-1:] != (3,):
        raise ValueError(f"plate_normal has shape {plate_normal.shape}: expected (..., 3)")
    length = np.linalg.norm(plate_normal, axis=-1, keepdims=True)
    if not np.all(np.isfinite(length)) or np.any(length < 1e-12):
        raise ValueError("plate_normal: expected finite, non-zero normals")
    return plate_normal / length


def _checked_cap(semi_axes, plate_normal) -> tuple[np.ndarray, np.ndarray]:
    """The cap's semi-axes (m) and the plates' unit normals, refused in one line if unusable."""
    semi_axes = np.asarray(semi_axes, dtype=float)
    if semi_axes.shape[-1:] != (3,) or np.any(semi_axes <= 0):
        raise ValueError(f"semi_axes = {semi_axes.tolist()}: expected 3 positive lengths (m)")
    return semi_axes, _unit_normals(plate_normal)


def cap_indentation(centre, semi_axes, plate_point, plate_normal):
    """Indentation δ (m, (...)), the contact point on the plate (..., 3) and the effective radius R
    (m, (...)) of an ellipsoidal cap under plates; arrays broadcast over their leading axes."""
    semi_axes, normal = _checked_cap(semi_axes, plate_normal)
    return _indentation(np.asarray(centre, dtype=float), semi_axes, plate_point, normal)


def _indentation(centre: np.ndarray, semi_axes: np.ndarray, plate_point, normal: np.ndarray):
    """:func:`cap_indentation` on checked semi-axes and unit ``normal``."""
    support = np.sqrt(np.sum((semi_axes * normal) ** 2, axis=-1))
    height = np.sum(normal * (centre - np.asarray(plate_point, dtype=float)), axis=-1)
    depth = support - height
    surface = centre - semi_axes**2 * normal / support[..., None]  # the cap's point nearest the plate
    point = surface + depth[..., None] * normal  # its foot on the plate's face
    radius = np.prod(semi_axes, axis=-1) / support**2
    return depth, point, radius


def plate_wrench(law: PlateContactLaw, centre, semi_axes, plate_point, plate_normal, origin):
    """The wrench (..., 6: N, N·m about ``origin``) a frictionless plate applies to the cap, and the
    indentation (m, (...)); no contact gives a zero wrench and a negative indentation."""
    semi_axes, normal = _checked_cap(semi_axes, plate_normal)
    depth, point, radius = _indentation(np.asarray(centre, dtype=float), semi_axes, plate_point, normal)
    force = normal_force(law, depth, radius)[..., None] * normal
    torque = np.cross(point - np.asarray(origin, dtype=float), force)
    return np.concatenate([force, torque], axis=-1), depth
