"""The distal finger pad under a 3-axis fingertip force, as a sensor on the side of the nail feels it.

A person presses the pad of the distal phalanx on an object mounted on a table force sensor; a
rigid C-shaped ring clamped across the last joint holds a 3-axis tactile chip against the side of
the nail (S2). Frame of the finger: x radial, y distal, z palmar (from the nail into the object),
origin at the pad's nominal contact point; the force F = (Fx, Fy, Fz) is what the finger applies to
the object (Fz > 0 pressing). The chip's axes are (distal shear, dorsal shear, pressure).

What the model holds, and where each piece comes from:

**Nonlinear stiffening.** The pulp's force against a flat surface grows exponentially with its
displacement, F = (b/m)(e^{mδ} − 1) (Serina, Mote & Rempel, J. Biomech. 30:1035, 1997, over
0.25–7 N; Pawluk & Howe, J. Biomech. Eng. 121:178, 1999, as the instantaneous elastic response of
quasi-linear viscoelasticity). The tangent stiffness b + mF is linear in the force. The published
fitted values were not available to us; b = 0.33 N/mm and m = 1.7 /mm put the instantaneous law at
about 1.07 mm for 1 N and 1.81 mm for 4 N, with a stiffness of 2 N/mm at 1 N and 7 N/mm at 4 N:
the range of those in-vivo measurements, not a fit to them.

**Contact shape.** The pad is an ellipsoidal cap (Serina et al., J. Biomech. 31:639, 1998, model
the pulp as an inflated ellipsoidal membrane) with principal radii R_x = W/2 across the finger and
R_y = 1.6 R_x along it (assumed; W the fingertip's breadth). An object of radii r_x, r_y meets it
with the gap of two paraboloids, h = x²/2R'_x + y²/2R'_y, 1/R' = 1/R_pad + 1/r (a flat plate has
r = ∞, a sphere r_x = r_y, an edge running across the finger r_x = ∞). The pressure is local in the
compression c = δ − h (a Winkler layer): p(c) = b e^{mc}/(2π R̄) with R̄ = √(R_x R_y), the one law
whose integral over a flat plate's contact gives the cited F(δ) exactly; on any paraboloidal gap it
gives F = (R̄'/R̄)(b/m)(e^{mδ} − 1), the indentation volume V = π R̄' δ² and contact area
A = 2π R̄' δ. To first order the pressure is an inverted paraboloid, the shape Pawluk & Howe
(J. Biomech. Eng. 121:605, 1999) observed under a flat probe. The centre of force is the gap's apex.

**Incompressible bulge.** The pulp is an incompressible layer between the bone and the skin; the
volume V the object pushes in leaves through the pad's free surfaces. As a thin layer (potential
flow, ∇²p = −source, p = 0 at the free edges), the pad is a strip of width W with free sides at
x = ±W/2 and a free distal tip (image source); the outflow per unit length of a side at y from a
unit volume at (x₀, y₀) is the strip's harmonic measure,

    K = sin θ / (2W (cosh a + s cos θ)),   θ = π(x₀ + W/2)/W,   a = π(y − y₀)/W,

s = +1 on the radial side, −1 on the ulnar side, minus the same for the image at 2 y_tip − y₀.
Its integral over both sides and the tip is exactly the volume (a test checks it), and a source
nearer a side sends more out of it. The volume is spread over the contact ellipse with its
compression δ − h as weight. The outflow at the chip, divided by the height of the side surface it
spreads over, is the lateral bulge pressing on the chip.

**Asymmetric bulge under tangential load.** The contact sticks and the bone moves u = F_t/k_t
relative to it (k_t = 2/3 of the normal tangent stiffness: Mindlin's ratio 2(1−ν)/(2−ν) at ν = 0.5,
Johnson, Contact Mechanics, 1985, §7.2, which makes k_t linear in the normal force as Pataky, Latash
& Zatsiorsky, J. Biomech. 38:1441, 2005, measured). The pulp column under the contact (area A,
thickness t) shears, moving a volume moment −A t u / 2 away from the direction of the force: a
source dipole that lowers the bulge on the side the force points to and raises it on the other.

**Stick and slip.** The tangential force the finger can put on the object is at most μ Fz
(Coulomb, isotropic, full slip; partial slip is not modelled). Beyond it the finger slides, the
object receives μ Fz, and the pad's shear stops growing: the part of the person's intended force
above the limit reaches neither sensor.

**Viscoelastic pad under force control.** The tissue follows Fung's quasi-linear viscoelasticity
with Pawluk & Howe's three relaxation times (≈ 4 ms, 70 ms, 1.4 s, plus a constant). A person
controls force, so the deformation creeps: the elastic-equivalent force F_e is
:func:`softtip.mechanics.viscoelastic.qlv_elastic_history` of the force on the object (the exact
inverse of the QLV operator), and the depth and shear follow from F_e through the elastic laws.
The chip, held by a rigid ring, imposes displacement on the side tissue instead: its force relaxes
(:func:`~softtip.mechanics.viscoelastic.qlv_response`).

With one relaxation function for all three (the pad pressed, the pad sheared, the tissue under the
chip), the chip's force is that function applied to (nearly) linear functions of its inverse applied
to the force: the two cancel, and the chip follows the table's force with no dynamics beyond the
laws' curvature (a test shows it). A real finger has no such symmetry; two parts, each measured on
fingers and each switchable (None: the pad's own function), break it:

- *tangential creep* (``shear_prony``): loaded tangentially, the finger pad relaxes far more slowly
  than pressed: Pataky, Latash & Zatsiorsky (J. Biomech. 38:1441, 2005) measured a tangential force
  relaxing over 11.8 s on average, logarithmic in time, on eight subjects. :data:`TANGENTIAL_RELAXATION`
  spreads it over terms a decade apart up to 11.8 s; its relaxed share (half) is assumed;
- *the tissue under the chip* (``ChipMount.tissue_prony``): the chip presses the thin skin and
  the nail fold over the nail's edge, not the pulp's bulk: skin relaxes faster and further than the
  pulp. :data:`NAIL_FOLD_RELAXATION` takes the skin's one-term QLV fit in compression (τ ≈ 0.2 s,
  relaxed to 0.28-0.47 of its elastic force: Wang, Marshall, Baba, Lumpkin & Gerling, PLoS ONE
  10:e0120897, 2015, excised mouse skin: no human value was available to us) with 0.4 remaining.

**Ring clamp.** The ring presses the chip into the side tissue with a preload P₀ (its value once
relaxed). The side tissue follows the pad's Winkler law over the chip's face (area A_f): its force
A_f p_edge (e^{md} − 1) from an indentation d, p_edge = b/(2π R̄). The chip therefore reads P₀ at
rest (a static offset) and the bulge through the tangent stiffness m(P₀/g_∞ + A_f p_edge): a firmer
clamp reads the same bulge more strongly (a change of sensitivity). Its shear is 2/3 of that
stiffness times the skin's tangential displacement, up to the chip face's own friction limit.

**Skin drag at the chip.** The pad's displacement relative to the bone at the contact (−u_x, −u_y,
+δ upwards) reaches the skin under the chip, at the nail fold where the pulp's fibrous septa anchor
the skin to the phalanx, reduced by a transmission factor (0.1, assumed): the chip's distal shear
follows −u_y, its dorsal shear +δ, and (``lateral_drag``) its pressure −s u_x on side s on top of the
bulge: a radial force drags the pulp away from a radial chip. The same factor for all three: without
``lateral_drag`` the lateral component is the bulge's alone, and radial force reaches the chip only
through the bulge's asymmetry, which placing the finger off-centre mimics.

**The last joint's lateral compliance** (``joint_stiffness``). The ring is clamped across the
distal interphalangeal (DIP) joint: it holds on the middle phalanx, and the chip presses the side
of the nail, on the distal phalanx. No muscle turns the DIP sideways: its collateral ligaments carry
the moment M = r_y F_x − r_x F_y of the object's reaction about the joint (r the contact from the
joint: r_y along the finger, r_x the placement across it), so the distal phalanx turns by
θ = M/k and the nail's side at the chip, a lever L_s distal of the joint, moves by −θ L_s radially
(the fingertip is pushed back against the force). The tissue between the ring's chip and the nail
is compressed by that much more (s θ L_s less on side s): a path from radial force to the chip's
pressure beside the bulge, nearly independent of where the finger is placed, through the nail
fold's own relaxation. k = 0.3 N·m per 5° = 3.44 N·m/rad: lateral stress of 30 N·cm turned the
*middle* joint (PIP) of twelve cadaver index fingers by 5° on average (15° at most; Minamikawa,
Horii, Amadio, Cooney, Linscheid & An, J. Hand Surg. 18A:198, 1993). No value for the last joint
was available to us, and that one was measured with the muscles unloaded, which they found to leave
the joint far laxer than loaded ones; the DIP is described as the more stable of the two (its short
lever and its adherent soft tissue): the value is the compliant end of what is plausible for a
pressing finger. The ligaments' creep is not modelled (no value). The joint lies 12 mm proximal of the pad's contact for
a 15 mm fingertip (assumed: the pad's centre about midway along an index distal segment of
22-25 mm); a chip proximal of the joint is on the middle phalanx and is not moved. The joint's
flexion is not modelled: pressing, its moment is carried by the flexor tendon under the person's
control, whose stiffness no source here gives (passive flexion stiffness, 0.05 N·cm/° at the PIP,
Dionysian et al., J. Hand Surg. 30A:573, 2005, is that of relaxed muscles). The distal phalanx's
inertia is left out: a few grams at a centimetre put its resonance with k near 400 Hz.

**Leaning.** A person making a tangential force tilts the finger; rotating the bone about the stuck
contact by φ = u/h (h the height of the bone's centre above the contact) rolls the pressure centre
by R φ. ``lean`` is the share of the shear made that way (0 for a pure translation).

Every length scales with the fingertip's breadth (geometric similarity across people).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Optional

import numpy as np

from softtip._core.config import Flag, Fraction, NonNegativeNumber, PositiveNumber, Real, choice, instance, schema
from softtip.mechanics.plate_contact import exponential_depth, exponential_force
from softtip.mechanics.viscoelastic import PronySeries, qlv_elastic_history, qlv_response

MINDLIN_TANGENTIAL_RATIO = 2.0 / 3.0  # 2(1 − ν)/(2 − ν) at ν = 0.5: incompressible tissue
CONTACT_SHAPES = ("flat", "curved", "edge", "point")
SIDES = {"radial": 1.0, "ulnar": -1.0}
# Pawluk & Howe (1999): three decaying exponentials of about 4 ms, 70 ms and 1.4 s plus a constant.
# Their weights were not available to us: ours leave 40 % of a held indentation's force after relaxation.
PAD_RELAXATION = PronySeries(g=(0.25, 0.15, 0.2), tau=(0.004, 0.07, 1.4))
# Pataky et al. (2005): the pad's tangential force relaxes over 11.8 s, logarithmically in time: equal
# weights a decade apart up to it (a logarithm over two decades); half relaxes (assumed)
TANGENTIAL_RELAXATION = PronySeries(g=(0.25, 0.25), tau=(1.18, 11.8))
# Wang et al. (2015): skin in compression, one term of about 0.2 s relaxing to 0.28-0.47 (0.4 kept)
NAIL_FOLD_RELAXATION = PronySeries(g=(0.6,), tau=(0.2,))
# Minamikawa et al. (1993): 30 N·cm turned the PIP of cadaver index fingers by 5° on average (no DIP value)
DIP_LATERAL_STIFFNESS = 3.44  # N·m/rad: 0.3 N·m / 5° (0.0873 rad)
# the contact's quadrature: 4 radial Gauss points x 8 angles on the unit disk
_RADII, _RADIAL_WEIGHTS = np.polynomial.legendre.leggauss(4)
_RADII, _RADIAL_WEIGHTS = (_RADII + 1) / 2, _RADIAL_WEIGHTS / 2
_ANGLES = 2 * np.pi * (np.arange(8) + 0.5) / 8
_EDGE_MARGIN = 0.05  # share of the breadth kept between a contact point and a free edge


# ---------------------------------------------------------------------------------------------- kernels


def relative_radius(pad_radius, object_radius):
    """1/R' = 1/R_pad + 1/r; ``object_radius`` = inf for a flat surface."""
    return 1.0 / (1.0 / np.asarray(pad_radius, dtype=float) + 1.0 / np.asarray(object_radius, dtype=float))


def winkler_pressure(compression, stiffness, stiffening, pad_mean_radius):
    """p(c) = b e^{mc}/(2π R̄) where the layer is compressed (c > 0), 0 elsewhere (Pa)."""
    compression = np.asarray(compression, dtype=float)
    pressure = stiffness / (2 * np.pi * pad_mean_radius) * np.exp(stiffening * np.maximum(compression, 0.0))
    return np.where(compression > 0, pressure, 0.0)


def indentation_volume(depth, radius_x, radius_y):
    """Volume (m³) of the pad inside the object at depth δ: π √(R'_x R'_y) δ²."""
    return np.pi * np.sqrt(radius_x * radius_y) * np.asarray(depth, dtype=float) ** 2


def contact_area(depth, radius_x, radius_y):
    """Area (m²) of the contact ellipse at depth δ: 2π √(R'_x R'_y) δ."""
    return 2 * np.pi * np.sqrt(radius_x * radius_y) * np.asarray(depth, dtype=float)


def friction_limited(intended, friction):
    """The force (..., 3) the finger puts on the object when it means ``intended`` (..., 3): no pull
    (Fz >= 0) and at most ``friction`` × Fz tangentially, along the intended direction. Also returns
    where the finger, on the object, slides (...)."""
    intended = np.asarray(intended, dtype=float)
    normal = np.maximum(intended[..., 2], 0.0)
    tangential = intended[..., :2]
    size = np.linalg.norm(tangential, axis=-1)
    limit = friction * normal
    sliding = (size > limit) & (normal > 0)  # off the object the finger does not slide: it is lifted
    scale = np.where(sliding, limit / np.where(sliding, size, 1.0), 1.0)
    return np.concatenate([tangential * scale[..., None], normal[..., None]], axis=-1), sliding


def side_outflow(source_x, source_y, side_y, side, width, tip_y):
    """Outflow per unit side length at ``side_y`` on side ``side`` (+1 radial, −1 ulnar) from a unit
    volume at (``source_x``, ``source_y``), in 1/m, and its gradient with respect to the source
    position (∂/∂x₀, ∂/∂y₀), in 1/m²: the harmonic measure of a strip of breadth ``width`` with free
    sides and a free tip at ``tip_y`` (method of images). All arguments broadcast."""
    theta = np.pi * (np.asarray(source_x, dtype=float) + width / 2) / width
    sin, cos = np.sin(theta), np.cos(theta)
    outflow, d_x, d_y = 0.0, 0.0, 0.0
    for sign, centre in ((1.0, source_y), (-1.0, 2 * tip_y - np.asarray(source_y, dtype=float))):
        a = np.pi * (side_y - centre) / width
        # in sech a and tanh a, which stay finite however far the point is from the source
        decay = np.exp(-np.abs(a))
        sech, tanh = 2 * decay / (1 + decay ** 2), np.sign(a) * (1 - decay ** 2) / (1 + decay ** 2)
        share = 1 + side * cos * sech  # (cosh a + s cos θ) / cosh a
        outflow = outflow + sign * sin * sech / (2 * width * share)
        d_x = d_x + sign * np.pi * (cos + side * sech) * sech / (2 * width ** 2 * share ** 2)
        # the image moves opposite to the source along y: its a grows where the source's falls
        d_y = d_y + np.pi * sin * tanh * sech / (2 * width ** 2 * share ** 2)
    return outflow, d_x, d_y


def contact_points(centre, semi_axes):
    """Quadrature points (..., P, 2) of the contact ellipse and the weights (P,) of its compression
    δ − h (the pulp volume pushed in) and of its area (the column that shears), each summing to 1."""
    radius, angle = np.meshgrid(_RADII, _ANGLES, indexing="ij")
    unit = np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=-1).reshape(-1, 2)
    weight = np.repeat(_RADIAL_WEIGHTS * _RADII, len(_ANGLES))  # r dr dθ
    compression = weight * np.repeat(1 - _RADII ** 2, len(_ANGLES))
    points = np.asarray(centre)[..., None, :] + np.asarray(semi_axes)[..., None, :] * unit
    return points, compression / compression.sum(), weight / weight.sum()


def lateral_outflow(volume, moment, centre, semi_axes, side_y, side, width, tip_y):
    """Outflow per unit side length (m²) at ``side_y`` (...) on ``side``: the ``volume`` (...) pushed in
    over the contact ellipse (``centre`` (..., 2), ``semi_axes`` (..., 2)) plus the dipole of the
    sheared column's volume ``moment`` (..., 2) (m⁴). Contact points keep a margin from the free
    edges, where the strip's kernel is singular."""
    points, compression, area = contact_points(centre, semi_axes)
    margin = _EDGE_MARGIN * width
    x = np.clip(points[..., 0], -width / 2 + margin, width / 2 - margin)
    y = np.minimum(points[..., 1], tip_y - margin)
    kernel, d_x, d_y = side_outflow(x, y, np.asarray(side_y, dtype=float)[..., None], side, width, tip_y)
    moment = np.asarray(moment)
    dipole = moment[..., 0, None] * d_x + moment[..., 1, None] * d_y
    return volume * (kernel @ compression) + dipole @ area


# ---------------------------------------------------------------------------------------------- parameters

Relaxation = instance(PronySeries, "a PronySeries")


@schema(section="finger")
class FingerPad:
    """One person's distal finger pad (SI units; see the module notes for every value's source).

    width: breadth of the fingertip across the nail (m), which sets every other length.
    stiffness, stiffening: b (N/m) and m (1/m) of the pulp's instantaneous force-depth law.
    friction: the pad's friction coefficient on the object.
    transmission: share of the pad's displacement at the contact that reaches the skin under the chip.
    lateral_drag: the lateral share of that displacement presses the chip too (False: distal and dorsal only).
    joint_stiffness: the last joint's lateral (radial/ulnar) angular stiffness (N·m/rad; None: a rigid joint).
    prony: the tissue's reduced relaxation function.
    shear_prony: its relaxation under tangential load (None: ``prony``).
    """

    width: PositiveNumber = 15e-3
    stiffness: PositiveNumber = 330.0
    stiffening: PositiveNumber = 1700.0
    friction: PositiveNumber = 0.9
    transmission: Fraction = 0.1
    lateral_drag: Flag = True
    joint_stiffness: Optional[PositiveNumber] = DIP_LATERAL_STIFFNESS
    prony: Relaxation = PAD_RELAXATION
    shear_prony: Optional[Relaxation] = None

    @property
    def tangential_prony(self) -> PronySeries:
        return self.prony if self.shear_prony is None else self.shear_prony

    # lengths as shares of the breadth (assumed, for a 15 mm index fingertip): the pad's radii of
    # curvature 7.5 and 12 mm, its distal free edge 9 mm ahead of the contact, the last joint 12 mm behind
    # it, a pulp 4 mm thick under the bone whose sides bulge over 5 mm, the bone's centre 6 mm above the contact
    @property
    def radius_x(self) -> float:
        return self.width / 2

    @property
    def radius_y(self) -> float:
        return 1.6 * self.radius_x

    @property
    def tip_y(self) -> float:
        return 0.6 * self.width

    @property
    def joint_y(self) -> float:
        """Where the last joint lies along the finger from the pad's contact point (m, proximal < 0)."""
        return -0.8 * self.width

    @property
    def pulp_thickness(self) -> float:
        return 4 / 15 * self.width

    @property
    def bulge_height(self) -> float:
        return 5 / 15 * self.width

    @property
    def bone_height(self) -> float:
        return 6 / 15 * self.width

    @property
    def mean_radius(self) -> float:
        return math.sqrt(self.radius_x * self.radius_y)

    @property
    def edge_pressure(self) -> float:
        """p_edge = b/(2π R̄), the Winkler law's pressure where compression begins (Pa)."""
        return self.stiffness / (2 * np.pi * self.mean_radius)

    def contact_radii(self, object_radii) -> np.ndarray:
        """The gap's relative radii R'_x, R'_y (..., 2) for an object of principal radii (..., 2)."""
        return relative_radius(np.array([self.radius_x, self.radius_y]), object_radii)

    def share(self, object_radii) -> np.ndarray:
        """R̄'/R̄ (...): the share of a flat plate's force an object of radii (..., 2) meets at one depth."""
        return np.sqrt(np.prod(self.contact_radii(object_radii), axis=-1)) / self.mean_radius

    def force(self, depth, object_radii=(np.inf, np.inf)):
        """Instantaneous elastic force (N) at ``depth`` against an object of radii ``object_radii``."""
        return self.share(object_radii) * exponential_force(depth, self.stiffness, self.stiffening)

    def depth(self, force, object_radii=(np.inf, np.inf)):
        """The depth (m) at which :meth:`force` reaches ``force``."""
        return exponential_depth(np.asarray(force) / self.share(object_radii), self.stiffness, self.stiffening)


@schema(section="ring")
class ChipMount:
    """The chip as the ring holds it against the side of the nail (SI units; assumed values).

    side: which side of the nail ("radial" or "ulnar").
    position_y: the chip's place along the finger from the pad's contact point (m, distal > 0);
        the nail's side is reached proximal of the pad's centre.
    preload: the ring's relaxed clamping force (N): snug but comfortable.
    face_area: the chip package's face on the skin (m²), a 3 mm disc.
    friction: friction coefficient of the chip's face on the skin.
    tissue_prony: the relaxation of the tissue the chip presses (None: the pad's).
    """

    side: choice(*SIDES) = "radial"
    position_y: Real = -3e-3
    preload: NonNegativeNumber = 0.5
    face_area: PositiveNumber = 7e-6
    friction: PositiveNumber = 0.6
    tissue_prony: Optional[Relaxation] = None

    def relaxation(self, pad: FingerPad) -> PronySeries:
        """The relaxation function of the tissue under the chip on finger ``pad``."""
        return pad.prony if self.tissue_prony is None else self.tissue_prony


# ---------------------------------------------------------------------------------------------- responses


@dataclass(frozen=True)
class PadResponse:
    """The finger pad over a force history (N samples, any batch ...), SI units."""

    force: np.ndarray  # (N, ..., 3) on the object, after friction
    sliding: np.ndarray  # (N, ...) the finger slides: the intended tangential force exceeded μ Fz
    depth: np.ndarray  # (N, ...)
    shear: np.ndarray  # (N, ..., 2) the bone's tangential displacement from the stuck contact
    centre: np.ndarray  # (N, ..., 2) the centre of force on the pad (NaN without contact)
    volume: np.ndarray  # (N, ...) pulp volume pushed in
    skin: np.ndarray  # (N, ..., 3) skin displacement under the chip: distal, dorsal, outward (bulge)


def pad_response(times, intended, pad: FingerPad, mount: ChipMount, object_radii=(np.inf, np.inf),
                 rest_centre=(0.0, 0.0), lean: float = 0.0) -> PadResponse:
    """The pad pressed with the ``intended`` force (N, ..., 3) at ``times`` (N,): friction, creep under
    force control, the contact of an object of principal radii ``object_radii`` (..., 2) first met at
    ``rest_centre`` (..., 2) on the pad, and the skin's displacement under the chip.

    The history starts at times[0]; start it in the air (zero force) to begin from an undeformed pad.
    """
    force, sliding = friction_limited(intended, pad.friction)
    elastic = qlv_elastic_history(times, force, pad.prony)
    if pad.shear_prony is not None:
        elastic[..., :2] = qlv_elastic_history(times, force[..., :2], pad.shear_prony)
    normal = np.maximum(elastic[..., 2], 0.0)  # F ≥ 0 gives F_e ≥ 0: this only clears round-off
    radii, share = pad.contact_radii(object_radii), pad.share(object_radii)
    depth = exponential_depth(normal / share, pad.stiffness, pad.stiffening)
    volume = indentation_volume(depth, radii[..., 0], radii[..., 1])
    area = contact_area(depth, radii[..., 0], radii[..., 1])
    tangent = share * pad.stiffness + pad.stiffening * normal  # d F_e / d δ
    shear = elastic[..., :2] / (MINDLIN_TANGENTIAL_RATIO * tangent)[..., None]
    centre = np.asarray(rest_centre) + lean * np.array([pad.radius_x, pad.radius_y]) * shear / pad.bone_height
    semi_axes = np.sqrt(2 * radii * depth[..., None])
    moment = -0.5 * (area * pad.pulp_thickness)[..., None] * shear
    outflow = lateral_outflow(volume, moment, centre, semi_axes, mount.position_y, SIDES[mount.side], pad.width,
                              pad.tip_y)
    lateral = outflow / pad.bulge_height
    if pad.lateral_drag:  # the chip's face normal points out of side s: the pulp dragged by −u_x meets it as −s u_x
        lateral = lateral - SIDES[mount.side] * pad.transmission * shear[..., 0]
    if pad.joint_stiffness is not None:
        lateral = lateral + SIDES[mount.side] * nail_deflection(force, centre, pad, mount)
    skin = np.stack([-pad.transmission * shear[..., 1], pad.transmission * depth, lateral], axis=-1)
    touching = force[..., 2] > 0
    return PadResponse(force=force, sliding=sliding, depth=depth, shear=shear,
                       centre=np.where(touching[..., None], centre, np.nan), volume=volume, skin=skin)


def nail_deflection(force, centre, pad: FingerPad, mount: ChipMount):
    """The nail's radial displacement (m, ...) at the chip as the last joint turns under the ``force`` on the
    object (..., 3) applied at ``centre`` on the pad (..., 2): −θ L_s with θ = (r_y F_x − r_x F_y)/k the
    joint's turn (r the contact from the joint) and L_s the chip's lever from the joint (none proximal of it)."""
    force, centre = np.asarray(force, dtype=float), np.asarray(centre, dtype=float)
    moment = (centre[..., 1] - pad.joint_y) * force[..., 0] - centre[..., 0] * force[..., 1]
    return -moment / pad.joint_stiffness * max(mount.position_y - pad.joint_y, 0.0)


def chip_forces(times, skin, pad: FingerPad, mount: ChipMount) -> np.ndarray:
    """Forces (N, ..., 3) on the chip (distal shear, dorsal shear, pressure; N) from the skin's
    displacement under it (N, ..., 3, the last :class:`PadResponse` ``skin``): the ring imposes the
    displacement, so the tissue's force relaxes. The history is taken relative to the relaxed preload
    (the ring was seated long before); the pressure never pulls and the shear is limited by friction."""
    face = mount.face_area * pad.edge_pressure * pad.stiffening  # b of the side tissue under the face
    relaxation = mount.relaxation(pad)
    relaxed = mount.preload / relaxation.g_inf  # the elastic force that relaxes to the preload
    seated = exponential_depth(relaxed, face, pad.stiffening)
    normal_elastic = exponential_force(seated + skin[..., 2], face, pad.stiffening)
    pressure = mount.preload + qlv_response(times, normal_elastic - relaxed, relaxation)
    pressure = np.maximum(pressure, 0.0)
    tangent = face + pad.stiffening * np.maximum(normal_elastic, 0.0)
    shear = qlv_response(times, MINDLIN_TANGENTIAL_RATIO * tangent[..., None] * skin[..., :2], relaxation)
    size = np.linalg.norm(shear, axis=-1)
    limit = mount.friction * pressure
    shear = shear * np.where(size > limit, limit / np.maximum(size, 1e-300), 1.0)[..., None]
    return np.concatenate([shear, pressure[..., None]], axis=-1)


def shape_radii(shape: str, curved_radius: float, edge_radius: float, point_radius: float) -> tuple[float, float]:
    """Principal radii (across, along the finger; m) of each contact shape: a flat plate; a sphere
    (curved); a straight edge running across the finger, rounded to ``edge_radius``; a point, a
    hemispherical tip."""
    if shape not in CONTACT_SHAPES:
        raise ValueError(f"contact shape {shape!r}: expected one of {', '.join(CONTACT_SHAPES)}")
    return {"flat": (np.inf, np.inf), "curved": (curved_radius, curved_radius), "edge": (np.inf, edge_radius),
            "point": (point_radius, point_radius)}[shape]


def scaled(pad: FingerPad, width: float, stiffness_factor: float = 1.0, friction: float | None = None) -> FingerPad:
    """The pad of another person: breadth ``width`` (m), stiffness × ``stiffness_factor``, own friction."""
    return replace(pad, width=width, stiffness=pad.stiffness * stiffness_factor,
                   friction=pad.friction if friction is None else friction)

