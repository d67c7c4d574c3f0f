"""Static large deflection of a slender tapered rod in a plane: bending, shear, stretch, base compliance.

A planar geometrically exact (Reissner–Cosserat) rod stands on a base at the origin along +z and bends in
the x–z plane. Its centre line is cut into ``segments`` pieces of equal reference length h, each with one
rotation θ_j (the angle of its cross-section's normal d3 = (sin θ, cos θ) from +z, positive towards +x).
Under a force F at the tip (no loads along the length) the internal force is F everywhere, so each
segment's axial strain ε = F·d3/EA and shear strain γ = F·d1/(κGA) follow from its own θ
(d1 = (cos θ, −sin θ)), and its chord is a = h[(1 + ε) d3 + γ d1] (Reissner, ZAMP 23, 1972). The
bending moment at a joint is EI κ with κ the change of θ over the distance between segment centres; at
the base a rotational spring (the substrate's compliance) sits in series with the first half segment, or,
for a root bonded to a rigid support, the root's joints are stiffened by the end effect of the bond
(:func:`bonded_root_flexibility`).
Moment balance of segment j,

    M_j − M_{j+1} = F × a_j          (F × a = F_x a_z − F_z a_x),

with M_N = 0 at the free tip, is solved by Newton's method for all load cases at once (a batch of dense
(N + 2) systems: the N angles and the tip force's two components, which two closing conditions fix).
The closing conditions give the load modes:

* a dead force (fixed direction) — :func:`solve_tip_force`;
* a force of given size parallel to the tip's top face (a follower, perpendicular to the deformed axis
  at the tip) — :func:`solve_follower_force`;
* an imposed tip position in x and z (the tip stuck on a plate), or an imposed tip height with a
  sliding friction force — the steps of :func:`lower_plate`, the die lowered onto a flat plate; once the
  rod lies on the plate, the same with its free length as one more unknown (its end tangent to the plate).

The discretisation is second order in h (midpoint angles, central curvatures). A uniform, unshearable,
inextensible rod under a dead tip force is Euler's elastica, whose tip position is known exactly through
elliptic integrals; the tests hold the solver to it. Every solve either meets its tolerance or raises
:class:`~softtip._core.errors.NotConverged`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import brentq

from softtip._core.config import Flag, PositiveNumber, Refusal, integer, number, schema
from softtip._core.errors import NotConverged
from softtip._core.threads import single_threaded_blas


class RodError(ValueError):
    """A rod or a load that cannot describe a physical case."""


@schema(section="rod", error=RodError)
class Rod:
    """A straight conical rod on a compliant base (SI units).

    ``base_stiffness`` is the base's rotational stiffness in N·m/rad; None clamps the base rigidly
    (:func:`half_space_rotational_stiffness` gives the one of a rod rooted in an elastic substrate).
    ``shear_coefficient`` is Timoshenko's κ of the cross-section; the default is Cowper's value for a
    solid circle, 6(1 + ν)/(7 + 6ν), used when it is None. ``shear_and_stretch`` False makes the rod
    Kirchhoff's (unshearable, inextensible): Euler's elastica for a uniform rod. ``bonded_root`` True:
    the base is bonded to a rigid support, which stiffens a nearly incompressible rod's root
    (:func:`bonded_root_flexibility`); it excludes a compliant base.
    """

    length: PositiveNumber
    base_diameter: PositiveNumber
    tip_diameter: PositiveNumber
    youngs_modulus: PositiveNumber
    poisson_ratio: number("a number from 0 to 0.5", ge=0.0, le=0.5) = 0.5
    base_stiffness: PositiveNumber | None = None
    shear_coefficient: number("a number from 0 (excluded) to 1", gt=0.0, le=1.0) | None = None
    segments: integer(4, 2000) = 60
    shear_and_stretch: Flag = True
    bonded_root: Flag = False

    def __post_init__(self) -> None:
        if max(self.base_diameter, self.tip_diameter) > self.length:
            raise Refusal("base_diameter", f"the rod is wider than long ({self.length} m): not a rod")
        if self.bonded_root and self.base_stiffness is not None:
            raise Refusal("bonded_root", "a root bonded to a rigid support has no base compliance: "
                                         "give base_stiffness or bonded_root, not both")
        if self.bonded_root and not BONDED_ROOT_POISSON[0] <= self.poisson_ratio <= BONDED_ROOT_POISSON[-1]:
            raise Refusal("poisson_ratio", f"a bonded root's stiffening is known for Poisson's ratios from "
                                           f"{BONDED_ROOT_POISSON[0]} to {BONDED_ROOT_POISSON[-1]}, "
                                           f"not {self.poisson_ratio}")

    @property
    def shear_modulus(self) -> float:
        return self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))

    @property
    def kappa(self) -> float:
        nu = self.poisson_ratio
        return self.shear_coefficient or 6.0 * (1.0 + nu) / (7.0 + 6.0 * nu)

    def diameter(self, s: ArrayLike) -> NDArray[np.float64]:
        """Diameter at reference arc length ``s`` (linear taper from base to tip)."""
        fraction = np.asarray(s, dtype=np.float64) / self.length
        return self.base_diameter + (self.tip_diameter - self.base_diameter) * fraction

    @property
    def volume(self) -> float:
        a, b = self.base_diameter, self.tip_diameter
        return math.pi * self.length * (a * a + a * b + b * b) / 12.0


def half_space_rotational_stiffness(youngs_modulus: float, poisson_ratio: float, diameter: float) -> float:
    """Rocking stiffness (N·m/rad) of a rigid circular footing of ``diameter`` on an elastic half-space:
    K = 8 G a³ / (3 (1 − ν)) with a the radius (Gazetas, J. Geotech. Eng. 117, 1991, Table 1; the same as
    the tilted flat punch of K. L. Johnson, *Contact Mechanics*, §5.2). A pillar moulded on a layer of its
    own material tilts at its root this way."""
    shear = youngs_modulus / (2.0 * (1.0 + poisson_ratio))
    return 8.0 * shear * (diameter / 2.0) ** 3 / (3.0 * (1.0 - poisson_ratio))


# The end effect of a circular cylinder bonded at its base to a rigid support, under a bending moment M at
# the root: beyond about one radius r its sections have turned less than a clamped Timoshenko rod's, by
# c M / (E r³), built up over a length λ r from the face. Computed with 3-D elasticity
# (softtip.mechanics.pillar_fe.bonded_root_end_effect: a cylinder of length 8 r under a small tip force,
# P2 tetrahedra of 20 µm for r = 125 µm, 25 slices; no published value for a circular section was found).
# The bonded rim is a stress singularity, so c converges slowly with the mesh: 0.1826, 0.1791, 0.1747 at
# 40, 28, 20 µm (ν = 0.49), not yet at an asymptotic rate; the limit is probably a few per cent lower.
# Per Poisson's ratio: (ν, c, λ).
BONDED_ROOT_TABLE = np.array([
    [0.30, 0.0680, 0.621],
    [0.45, 0.1447, 0.367],
    [0.49, 0.1747, 0.311],
])
BONDED_ROOT_POISSON = tuple(BONDED_ROOT_TABLE[[0, -1], 0])


def bonded_root_flexibility(rod: Rod, lower: ArrayLike, upper: ArrayLike) -> NDArray[np.float64]:
    """The bending flexibility (rad per N·m) a root bonded to a rigid support takes away from the rod between
    reference arc lengths ``lower`` and ``upper`` (m): c (e^(−lower/λr) − e^(−upper/λr)) / (E r³), r the base
    radius (:data:`BONDED_ROOT_TABLE`).

    Why: bent, a section stretches on one side and shortens on the other, and a nearly incompressible
    material keeps its volume by contracting or swelling sideways; at a bonded face it cannot, so near the
    face bending strains the volume, against the far larger bulk modulus (the same restraint that makes a
    thin bonded rubber disc far stiffer in tilt than its E I suggests: Gent & Meinecke, Polym. Eng. Sci. 10,
    1970). A beam theory has no such restraint; the correction is Saint-Venant's: the end zone acts on the
    rest of the rod only through a rotation offset proportional to the root moment. It vanishes with ν
    (c < 0.005 at ν = 0)."""
    nu = rod.poisson_ratio
    c = float(np.interp(nu, BONDED_ROOT_TABLE[:, 0], BONDED_ROOT_TABLE[:, 1]))
    decay = float(np.interp(nu, BONDED_ROOT_TABLE[:, 0], BONDED_ROOT_TABLE[:, 2])) * rod.base_diameter / 2
    lower, upper = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
    return c * (np.exp(-lower / decay) - np.exp(-upper / decay)) / (rod.youngs_modulus * (rod.base_diameter / 2) ** 3)


@dataclass(frozen=True)
class RodShapes:
    """Deformed shapes of one rod under a batch of B loads.

    ``x``, ``z`` (B, N + 1): node positions (base first); ``angles`` (B, N): each segment's rotation;
    ``force`` (B, 2): the tip force (F_x, F_z) in N; ``saturated`` (B,): the rod lies on its side (under
    a follower force its shape is the one at the onset, the rest of the load going into the side wall;
    under a plate the plate folds it further, :func:`lower_plate`); ``iterations``,
    ``residual``: Newton's work and the largest final moment residual relative to EI/L.
    """

    rod: Rod
    x: NDArray[np.float64]
    z: NDArray[np.float64]
    angles: NDArray[np.float64]
    force: NDArray[np.float64]
    saturated: NDArray[np.bool_]
    iterations: int
    residual: float

    @property
    def tip(self) -> NDArray[np.float64]:
        """(B, 2) tip position (x, z)."""
        return np.stack([self.x[:, -1], self.z[:, -1]], axis=-1)

    @property
    def tip_angle(self) -> NDArray[np.float64]:
        """(B,) rotation of the last segment (second-order accurate at a free tip, where κ = 0)."""
        return self.angles[:, -1]

    def take(self, rows: slice | NDArray) -> RodShapes:
        """The shapes of the loads ``rows`` only."""
        return replace(self, x=self.x[rows], z=self.z[rows], angles=self.angles[rows], force=self.force[rows],
                       saturated=self.saturated[rows])

    def concatenate(self, other: RodShapes) -> RodShapes:
        """These shapes followed by ``other``'s (the solver's record, ``iterations`` and ``residual``, is
        ``other``'s)."""
        return replace(other, x=np.concatenate([self.x, other.x]), z=np.concatenate([self.z, other.z]),
                       angles=np.concatenate([self.angles, other.angles]),
                       force=np.concatenate([self.force, other.force]),
                       saturated=np.concatenate([self.saturated, other.saturated]))

    def turned(self, angle: float) -> RodShapes:
        """The same shapes in a frame turned by ``angle`` (rad) about the base: every angle less by it (a
        direction at θ from +z towards +x is at θ − angle in the new frame)."""
        c, s = math.cos(angle), math.sin(angle)
        return replace(self, x=self.x * c - self.z * s, z=self.z * c + self.x * s, angles=self.angles - angle,
                       force=np.stack([self.force[:, 0] * c - self.force[:, 1] * s,
                                       self.force[:, 1] * c + self.force[:, 0] * s], axis=-1))

    def centreline(self, fractions: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Points on the deformed centre line at reference arc-length ``fractions`` of the length (K,),
        and the unit tangents there: ((B, K, 2), (B, K, 2)) in the x–z plane.

        Positions are interpolated linearly between nodes; the tangent is the chord direction of the
        segment holding the point (the material line along the axis, shear included)."""
        fractions = np.asarray(fractions, dtype=np.float64)
        if fractions.ndim != 1 or np.any((fractions < 0) | (fractions > 1)):
            raise RodError(f"fractions: expected a 1-D array of numbers in [0, 1], got {fractions!r}")
        n = self.angles.shape[1]
        position = fractions * n
        index = np.minimum(position.astype(int), n - 1)
        weight = position - index
        x = self.x[:, index] * (1 - weight) + self.x[:, index + 1] * weight
        z = self.z[:, index] * (1 - weight) + self.z[:, index + 1] * weight
        chord = np.stack([np.diff(self.x, axis=1), np.diff(self.z, axis=1)], axis=-1)[:, index]
        tangent = chord / np.linalg.norm(chord, axis=-1, keepdims=True)
        return np.stack([x, z], axis=-1), tangent

    def slice_means(self, count: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The rod cut into ``count`` equal slices of its reference length: each slice's centroid (B, K, 2)
        and the unit direction of its volume-mean tangent (B, K, 2), base first.

        A cross-section's own centroid is its centre-line point (the section is symmetric about it), so a
        slice's centroid is the centre line averaged with the sections' areas as weights; this is what a
        solid's slice centroid is compared with (and where a uniformly magnetised slice's dipole sits).
        Gauss–Legendre quadrature with three points per rod segment spanned."""
        if not (isinstance(count, int) and 1 <= count <= self.angles.shape[1]):
            raise RodError(f"count = {count!r}: expected an integer from 1 to the rod's "
                           f"{self.angles.shape[1]} segments")
        order = 3 * -(-self.angles.shape[1] // count)
        nodes, weights = np.polynomial.legendre.leggauss(order)
        fractions = ((np.arange(count)[:, None] + 0.5 * (nodes[None, :] + 1)) / count).ravel()
        points, tangents = self.centreline(fractions)
        area = (weights[None, :] * self.rod.diameter(fractions * self.rod.length).reshape(count, order) ** 2).ravel()
        shape = (len(points), count, order, 2)
        centroids = np.einsum("bkqj,kq->bkj", points.reshape(shape), area.reshape(count, order))
        centroids /= area.reshape(count, order).sum(axis=1)[None, :, None]
        mean_tangent = np.einsum("bkqj,kq->bkj", tangents.reshape(shape), area.reshape(count, order))
        return centroids, mean_tangent / np.linalg.norm(mean_tangent, axis=-1, keepdims=True)


# ---------------------------------------------------------------------------------------------- kernel


@dataclass(frozen=True)
class _Discrete:
    """Per-segment and per-joint stiffnesses of a rod."""

    h: float
    bending: NDArray[np.float64]  # (N,) joint stiffness EI/Δs; joint 0 is the base in series with a half segment
    axial: NDArray[np.float64]  # (N,) EA of each segment
    shear: NDArray[np.float64]  # (N,) κGA of each segment
    scale: float  # EI/L at the base: the moment scale of the residual


def _discretise(rod: Rod) -> _Discrete:
    n = rod.segments
    h = rod.length / n
    nodes = np.arange(n) * h  # joint j sits at the start of segment j
    centres = (np.arange(n) + 0.5) * h
    inertia = np.pi * rod.diameter(nodes) ** 4 / 64.0
    area = np.pi * rod.diameter(centres) ** 2 / 4.0
    flexibility = h / (rod.youngs_modulus * inertia)  # joint j spans the rod between segment centres
    flexibility[0] /= 2.0  # the base joint: the first half segment
    if rod.base_stiffness is not None:
        flexibility[0] += 1.0 / rod.base_stiffness
    if rod.bonded_root:  # at most c/λ = 0.56/(E r⁴) per metre at the face, below a section's 4/(π E r⁴)
        flexibility -= bonded_root_flexibility(rod, np.concatenate([[0.0], centres[:-1]]), centres)
    bending = 1.0 / flexibility
    rigid = 1.0 if rod.shear_and_stretch else np.inf
    return _Discrete(h=h, bending=bending, axial=rigid * rod.youngs_modulus * area,
                     shear=rigid * rod.kappa * rod.shear_modulus * area, scale=rod.youngs_modulus * inertia[0] / rod.length)


Closure = Literal["force", "follower", "pinned", "sliding"]


def _chords(d: _Discrete, theta: NDArray, force: NDArray) -> tuple[NDArray, ...]:
    """Segment chords a (B, N, 2) and their derivatives in θ (B, N, 2) and in F (B, N, 2, 2)."""
    s, c = np.sin(theta), np.cos(theta)
    d3 = np.stack([s, c], axis=-1)
    d1 = np.stack([c, -s], axis=-1)
    fx, fz = force[:, None, 0], force[:, None, 1]
    axial_force = fx * s + fz * c  # F·d3
    shear_force = fx * c - fz * s  # F·d1
    ea, ga = d.axial[None, :, None], d.shear[None, :, None]
    chord = d.h * (d3 * (1 + axial_force[..., None] / ea) + d1 * (shear_force[..., None] / ga))
    compliance = 1.0 / ea - 1.0 / ga
    d_theta = d.h * (d1 + compliance * (shear_force[..., None] * d3 + axial_force[..., None] * d1))
    d_force = d.h * (d3[..., :, None] * d3[..., None, :] / ea[..., None] + d1[..., :, None] * d1[..., None, :] / ga[..., None])
    return chord, d_theta, d_force


def _system(d: _Discrete, theta: NDArray, force: NDArray, rest: NDArray, closure: Closure,
            target: NDArray) -> tuple[NDArray, NDArray]:
    """Residual (B, N + 2) and Jacobian (B, N + 2, N + 2) of moment balance and the closing conditions.

    ``target`` (B, 2) holds the closure's data: the force (force), the force size and unused (follower),
    the tip position (pinned), or the friction coefficient times the sliding direction and the tip height
    (sliding: F_x = target_0 · F_z, z_tip = target_1; F_z < 0 presses the tip down)."""
    batch, n = theta.shape
    rows = np.arange(n)
    chord, d_theta, d_force = _chords(d, theta, force)
    fx, fz = force[:, 0:1], force[:, 1:2]
    lever = fx * chord[..., 1] - fz * chord[..., 0]
    bend = theta - rest
    moments = np.zeros((batch, n + 1))  # M_N = 0 at the free tip
    moments[:, 0] = d.bending[0] * bend[:, 0]
    moments[:, 1:n] = d.bending[1:] * np.diff(bend, axis=1)
    residual = np.empty((batch, n + 2))
    residual[:, :n] = moments[:, :n] - moments[:, 1:] - lever
    tip = chord.sum(axis=1)
    jacobian = np.zeros((batch, n + 2, n + 2))
    # M_j − M_{j+1}: M_j = k_j (b_j − b_{j−1}) (b_{−1} = 0), M_{j+1} = k_{j+1} (b_{j+1} − b_j)
    k = d.bending
    jacobian[:, rows, rows] = k + np.append(k[1:], 0.0) - (fx * d_theta[..., 1] - fz * d_theta[..., 0])
    jacobian[:, rows[1:], rows[:-1]] = -k[1:]
    jacobian[:, rows[:-1], rows[1:]] = -k[1:]
    jacobian[:, :n, n] = -(chord[..., 1] + fx * d_force[..., 1, 0] - fz * d_force[..., 0, 0])
    jacobian[:, :n, n + 1] = -(-chord[..., 0] + fx * d_force[..., 1, 1] - fz * d_force[..., 0, 1])
    if closure == "force":
        residual[:, n:] = force - target
        jacobian[:, n, n] = jacobian[:, n + 1, n + 1] = 1.0
    elif closure == "follower":  # F = f d1(θ_tip): parallel to the tip's face
        size, last = target[:, 0], theta[:, -1]
        residual[:, n] = force[:, 0] - size * np.cos(last)
        residual[:, n + 1] = force[:, 1] + size * np.sin(last)
        jacobian[:, n, n] = jacobian[:, n + 1, n + 1] = 1.0
        jacobian[:, n, n - 1] = size * np.sin(last)
        jacobian[:, n + 1, n - 1] = size * np.cos(last)
    elif closure == "pinned":
        residual[:, n:] = tip - target
        jacobian[:, n, :n] = d_theta[..., 0]
        jacobian[:, n + 1, :n] = d_theta[..., 1]
        jacobian[:, n:, n:] = d_force.sum(axis=1)
    else:  # sliding
        residual[:, n] = force[:, 0] - target[:, 0] * force[:, 1]
        residual[:, n + 1] = tip[:, 1] - target[:, 1]
        jacobian[:, n, n] = 1.0
        jacobian[:, n, n + 1] = -target[:, 0]
        jacobian[:, n + 1, :n] = d_theta[..., 1]
        jacobian[:, n + 1, n:] = d_force.sum(axis=1)[:, 1, :]
    return residual, jacobian


def _newton(d: _Discrete, theta: NDArray, force: NDArray, rest: NDArray, closure: Closure, target: NDArray,
            tolerance: float = 1e-10, max_iterations: int = 40) -> tuple[NDArray, NDArray, int, float]:
    """Newton's method on :func:`_system` for a batch; returns (θ, F, iterations, residual size)."""
    n = theta.shape[1]
    theta, force = theta.copy(), force.copy()
    force_scale, length = d.scale / (d.h * n), d.h * n
    scales = {"force": (force_scale, force_scale), "follower": (force_scale, force_scale),
              "pinned": (length, length), "sliding": (force_scale, length)}[closure]
    for iteration in range(1, max_iterations + 1):
        residual, jacobian = _system(d, theta, force, rest, closure, target)
        size = _residual_size(d, residual, scales)
        if size <= tolerance:
            return theta, force, iteration, size
        try:
            with single_threaded_blas():  # many small systems: a second BLAS thread only slows them down
                step = np.linalg.solve(jacobian, -residual[..., None])[..., 0]
        except np.linalg.LinAlgError:
            raise NotConverged("rod: singular Newton system (a load exactly at a bifurcation)") from None
        # at most 0.3 rad per angle and step: Newton's full step can jump branches far from the solution
        damping = np.minimum(1.0, 0.3 / np.maximum(np.abs(step[:, :n]).max(axis=1, keepdims=True), 1e-300))
        theta += damping * step[:, :n]
        force += damping * step[:, n:]
    raise NotConverged(f"rod: Newton did not converge in {max_iterations} iterations (residual {size:.2e} of EI/L)")


def _unstable(d: _Discrete, theta: NDArray, force: NDArray, rest: NDArray, closure: Closure,
              target: NDArray) -> bool:
    """Whether one equilibrium under a tip constraint is unstable (has a direction of negative stiffness).

    The tip force follows the angles through the closing conditions (dF = −D⁻¹ C dθ for the Jacobian's
    blocks [[K, B], [C, D]]; D is invertible for an extensible rod), so the stiffness of the angles is
    K − B D⁻¹ C; it must be positive definite. Its symmetric part is tested: friction makes it slightly
    non-symmetric, and the energy test is the symmetric one."""
    _, jacobian = _system(d, theta, force, rest, closure, target)
    n = theta.shape[1]
    k, b, c, dd = jacobian[0, :n, :n], jacobian[0, :n, n:], jacobian[0, n:, :n], jacobian[0, n:, n:]
    with single_threaded_blas():  # one small matrix: a second BLAS thread only slows it down
        stiffness = k - b @ np.linalg.solve(dd, c)
        values = np.linalg.eigvalsh(0.5 * (stiffness + stiffness.T))
    return bool(values[0] < -1e-9 * abs(values).max())


def _residual_size(d: _Discrete, residual: NDArray, closing_scale: tuple[float, float]) -> float:
    """Largest residual: moments relative to EI/L, each closing condition relative to its own scale."""
    n = d.axial.size
    moments = np.abs(residual[:, :n]).max() / d.scale
    closing = np.abs(residual[:, n:]) / np.asarray(closing_scale)
    return float(max(moments, closing.max()))


def _shapes(rod: Rod, d: _Discrete, theta: NDArray, force: NDArray, saturated: NDArray, iterations: int,
            residual: float) -> RodShapes:
    chord, _, _ = _chords(d, theta, force)
    zero = np.zeros((theta.shape[0], 1))
    x = np.concatenate([zero, np.cumsum(chord[..., 0], axis=1)], axis=1)
    z = np.concatenate([zero, np.cumsum(chord[..., 1], axis=1)], axis=1)
    return RodShapes(rod=rod, x=x, z=z, angles=theta, force=force, saturated=saturated, iterations=iterations,
                     residual=residual)


def _load_array(values: ArrayLike, name: str, width: int | None = None) -> NDArray[np.float64]:
    array = np.asarray(values, dtype=np.float64)
    if width is not None:
        if array.ndim != 2 or array.shape[1] != width:
            raise RodError(f"{name}: expected an array of shape (B, {width}), got shape {array.shape}")
    elif array.ndim != 1:
        raise RodError(f"{name}: expected a 1-D array, got shape {array.shape}")
    if array.size == 0 or not np.all(np.isfinite(array)):
        raise RodError(f"{name}: expected a non-empty array of finite numbers")
    return array


def _ramp(d: _Discrete, rest: NDArray, closure: Closure, target: NDArray, largest: float) -> tuple[NDArray, NDArray, int, float]:
    """Continuation from the unloaded rod to ``target`` through load fractions whose steps in the
    dimensionless load q = F L²/EI are at most max(0.5, q/4): even at first, proportional later (the shape
    changes ever less as the rod aligns with its load). ``largest`` is the largest force in the batch."""
    batch = target.shape[0]
    theta = np.broadcast_to(rest, (batch, rest.shape[-1])).copy()
    force = np.zeros((batch, 2))
    iterations, residual = 0, 0.0
    total = largest * d.h * rest.shape[-1] / d.scale
    load = 0.0
    while load < total:
        load = min(total, load + max(0.5, 0.25 * load))
        theta, force, used, residual = _newton(d, theta, force, rest, closure, target * (load / total))
        iterations += used
    if total == 0.0:
        theta, force, iterations, residual = _newton(d, theta, force, rest, closure, target)
    return theta, force, iterations, residual


def solve_tip_force(rod: Rod, force: ArrayLike) -> RodShapes:
    """The rod under dead tip forces ``force`` (B, 2) = (F_x, F_z) in N, all at once.

    The paper's load "at the tip, perpendicular to the axis" in its fixed-direction reading is
    ``force = [[F, 0]]``: such a rod bends towards the horizontal without reaching it, so it never lies on
    its side (``saturated`` is all False)."""
    force = _load_array(force, "force", 2)
    d = _discretise(rod)
    rest = np.zeros((1, rod.segments))
    theta, solved, iterations, residual = _ramp(d, rest, "force", force, float(np.abs(force).max()))
    return _shapes(rod, d, theta, solved, np.zeros(len(force), dtype=bool), iterations, residual)


def side_clearance(shapes: RodShapes) -> NDArray[np.float64]:
    """(B,) height above the base plane of the lowest side-wall point of the rod's outer half (m).

    The rod lies on its side when this reaches zero: the outer half's cross-sections extend d/2 along d1,
    so their lowest point is z − (d/2)|sin θ|. The root half is left out: its lowest edge dips below the
    base plane as soon as the base tilts, which is the root's own deformation, not lying down."""
    rod = shapes.rod
    n = rod.segments
    centres = (np.arange(n) + 0.5) / n
    outer = centres >= 0.5
    z_centres = 0.5 * (shapes.z[:, :-1] + shapes.z[:, 1:])
    lowest = z_centres - 0.5 * rod.diameter(centres * rod.length) * np.abs(np.sin(shapes.angles))
    return lowest[:, outer].min(axis=1)


def solve_follower_force(rod: Rod, size: ArrayLike) -> RodShapes:
    """The rod under tip forces of ``size`` (B,) N parallel to its tip face (perpendicular to the deformed
    axis at the tip), all at once: the paper's load in its follower reading.

    Such a force curls the rod over until its side touches the base plane: from that load on (found to
    1e-6 relative) the rod lies on its side, its shape stays the one at the onset and the rest of the
    force goes into the side wall (``saturated``)."""
    size = _load_array(size, "size")
    if np.any(size < 0):
        raise RodError("size: expected forces >= 0 (the direction is set by the tip face)")
    d = _discretise(rod)
    rest = np.zeros((1, rod.segments))
    target = np.stack([size, np.zeros_like(size)], axis=-1)

    def solve(target: NDArray) -> tuple[NDArray, NDArray, int, float]:
        return _ramp(d, rest, "follower", target, float(target[:, 0].max()))

    theta, force, iterations, residual = solve(target)
    shapes = _shapes(rod, d, theta, force, np.zeros(len(size), dtype=bool), iterations, residual)
    lying = side_clearance(shapes) <= 0.0
    if not lying.any():
        return shapes

    def clearance(value: float) -> float:
        nonlocal iterations
        t, f, used, _ = solve(np.array([[value, 0.0]]))
        iterations += used
        return float(side_clearance(_shapes(rod, d, t, f, np.zeros(1, dtype=bool), 0, 0.0))[0])

    standing = size[~lying]
    low = float(standing.max()) if standing.size else 0.0
    onset = brentq(clearance, low, float(size[lying].min()), xtol=1e-12, rtol=1e-6)
    t, f, used, final = solve(np.array([[onset, 0.0]]))
    theta[lying], force[lying] = t[0], f[0]
    return _shapes(rod, d, theta, force, lying, iterations + used, max(residual, final))


# ---------------------------------------------------------------------------------------------- the plate


@dataclass(frozen=True)
class PlateContact:
    """How the rod's tip meets a plate lowered onto it: sliding friction ``friction`` (Coulomb, static =
    kinetic) and an initial stress-free bow that makes a straight column choose a side when it buckles:
    a half sine bulging towards +x with its tip above its base, θ(s) = ``imperfection`` cos(π s/L) (its
    slope at the base, rad; the bulge is imperfection × L/π). Both the free column's mode (a lean) and the
    stuck one's (a bulge) then start towards +x. ``tilt`` (rad): the base's axis leans from the plate's
    normal by it (a die not parallel to the plate), towards +x if positive; the rod's frame is the plate's
    (z along its normal), so the stress-free angles are the bow's plus the tilt."""

    friction: float = 0.5
    imperfection: float = 0.01
    tilt: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.tilt) and abs(self.tilt) < math.pi / 4):
            raise RodError(f"tilt = {self.tilt!r}: expected an angle in rad, |tilt| < pi/4")
        if not (math.isfinite(self.friction) and self.friction >= 0):
            raise RodError(f"friction = {self.friction!r}: expected a number >= 0")
        if not (math.isfinite(self.imperfection) and 0 < abs(self.imperfection) < math.pi / 4):
            raise RodError(f"imperfection = {self.imperfection!r}: expected a slope in rad, 0 < |slope| < pi/4")


@dataclass(frozen=True)
class PlatePath:
    """The rod's states as the plate comes down: ``gaps`` (G,) plate height above the base (m),
    ``shapes`` (a batch of G), ``vertical_force`` (G,) the plate's push on the rod (N, > 0), ``sliding``
    (G,) the tip (or, lying, the part on the plate) slides, ``lying`` (G,) the rod lies on its side (its
    last section has turned across the plate: the plate presses its side wall and folds it further);
    ``standing`` the unloaded rod with its imperfection, before the plate touches it."""

    gaps: NDArray[np.float64]
    shapes: RodShapes
    standing: RodShapes
    vertical_force: NDArray[np.float64]
    sliding: NDArray[np.bool_]

    @property
    def lying(self) -> NDArray[np.bool_]:
        """(G,) the rod lies on its side: its shapes' ``saturated``."""
        return self.shapes.saturated


def _bow(rod: Rod, contact: PlateContact, length: float | None = None) -> NDArray[np.float64]:
    """(1, N) the stress-free angles of the bowed, tilted rod (:class:`PlateContact`) at the centres of N
    equal segments of its first ``length`` (m; the whole rod when None)."""
    centres = (np.arange(rod.segments) + 0.5) / rod.segments * (rod.length if length is None else length)
    return (contact.imperfection * np.cos(np.pi * centres / rod.length) + contact.tilt)[None, :]


def touching_height(rod: Rod, contact: PlateContact = PlateContact()) -> float:
    """The plate's height (m) when it first touches the unloaded, bowed rod's tip."""
    return float(_shapes(rod, _discretise(rod), _bow(rod, contact), np.zeros((1, 2)), np.zeros(1, dtype=bool),
                         0, 0.0).tip[0, 1])


def lower_plate(rod: Rod, gaps: ArrayLike, contact: PlateContact = PlateContact()) -> PlatePath:
    """The balance test of one pillar: a flat plate lowered step by step to the heights ``gaps`` (m,
    decreasing from at most the bowed rod's height), pressing on the tip.

    The tip touches the plate where the bowed rod ends; it sticks there (pinned: x and z imposed, zero
    moment at a point contact) while the friction needed stays within ``friction`` × the push, then
    slides against the friction force. Friction makes the path history-dependent, so the gaps are stepped
    in order (each from the previous state). Once the tip face turns parallel to the plate the pillar
    lies on its side: from then on the plate presses its side wall, the part from the base to where it
    meets the plate bends as a rod whose end is tangent to the plate, and the rest lies straight along the
    plate, stuck where it came down while friction holds it, else sliding outwards (:func:`_fold_solve`).
    The push rises as the free part shortens (as 1/height² for a uniform rod, Euler's elastica); gaps so
    small that the free part is no longer longer than wide are refused."""
    gaps = _load_array(gaps, "gaps")
    if not rod.shear_and_stretch:
        raise RodError("rod.shear_and_stretch = False: a plate needs an extensible rod (an inextensible straight "
                       "column cannot shorten to meet it)")
    d = _discretise(rod)
    rest = _bow(rod, contact)
    standing = _shapes(rod, d, rest, np.zeros((1, 2)), np.zeros(1, dtype=bool), 0, 0.0)
    start = standing.tip[0]
    if np.any(np.diff(gaps) > 0) or gaps[0] > start[1] * (1 + 1e-12) or gaps[-1] <= 0:
        raise RodError(f"gaps: expected plate heights decreasing from at most {start[1]:.6g} m to above 0")
    state = _PlateState(rest.copy(), np.zeros((1, 2)), sliding=False, friction=0.0)
    rows: list[tuple[NDArray, NDArray, NDArray, NDArray]] = []  # per gap: angles, x, z (nodes), force
    lying: list[bool] = []
    sliding: list[bool] = []
    folded: _Folded | None = None
    iterations, residual, height = 0, 0.0, float(start[1])
    largest_step, smallest_step = 0.01 * rod.length, 1e-9 * rod.length
    for gap in gaps:
        if folded is None:
            before, step = state, largest_step
            while height > gap:
                # plate steps of at most 1 % of the length, halved where Newton fails (the buckled branch turns fast)
                next_height = max(gap, height - step)
                try:
                    state, used, final = _plate_step(d, rest, contact, start, state, next_height)
                except NotConverged:
                    step /= 2
                    if step < smallest_step:
                        raise
                    continue
                height, step = next_height, min(2 * step, largest_step)
                iterations, residual = iterations + used, max(residual, final)
            if abs(state.theta[0, -1]) < math.pi / 2:
                shape = _shapes(rod, d, state.theta, state.force, np.zeros(1, dtype=bool), 0, 0.0)
                rows.append((state.theta, shape.x, shape.z, state.force))
                lying.append(False)
                sliding.append(state.sliding)
                continue
            state = _lying_onset(d, rest, before, state, start)
            tip = _chords(d, state.theta, state.force)[0].sum(axis=1)[0]
            height = float(tip[1])
            folded = _Folded(rod.length, state.theta, state.force, float(np.sign(state.theta[0, -1])), height,
                             float(tip[0]), state.friction if state.sliding else None)
        folded, height, used = _fold_to(rod, contact, folded, height, gap, largest_step, smallest_step)
        iterations += used
        rows.append(folded.whole_rod(rod))
        lying.append(True)
        sliding.append(folded.friction is not None)
    theta_all, x_all, z_all, force_all = (np.concatenate(column) for column in zip(*rows, strict=True))
    shapes = RodShapes(rod=rod, x=x_all, z=z_all, angles=theta_all, force=force_all, saturated=np.array(lying),
                       iterations=iterations, residual=residual)
    return PlatePath(gaps=gaps, shapes=shapes, standing=standing, vertical_force=-force_all[:, 1],
                     sliding=np.array(sliding))


@dataclass(frozen=True)
class _PlateState:
    theta: NDArray[np.float64]  # (1, N)
    force: NDArray[np.float64]  # (1, 2)
    sliding: bool
    friction: float  # F_x = friction × F_z while sliding (signed by the sliding direction)

    def closure(self, start: NDArray, height: float) -> tuple[Closure, NDArray]:
        if self.sliding:
            return "sliding", np.array([[self.friction, height]])
        return "pinned", np.array([[start[0], height]])


def _plate_step(d: _Discrete, rest: NDArray, contact: PlateContact, start: NDArray, state: _PlateState,
                height: float) -> tuple[_PlateState, int, float]:
    """The next state with the plate at ``height``: stuck if friction can hold the tip, else sliding."""
    closure, target = state.closure(start, height)
    theta, force, used, final = _stable(d, state.theta, state.force, rest, closure, target)
    if state.sliding:
        return _PlateState(theta, force, True, state.friction), used, final
    needed, push = force[0, 0], -force[0, 1]
    if abs(needed) <= contact.friction * max(push, 0.0):
        return _PlateState(theta, force, False, 0.0), used, final
    direction = -np.sign(needed)  # the tip moves against the force that held it
    sliding = _PlateState(state.theta, state.force, True, float(direction * contact.friction))
    closure, target = sliding.closure(start, height)
    theta, force, more, final = _stable(d, state.theta, state.force, rest, closure, target)
    return _PlateState(theta, force, True, sliding.friction), used + more, final


def _stable(d: _Discrete, theta: NDArray, force: NDArray, rest: NDArray, closure: Closure,
            target: NDArray) -> tuple[NDArray, NDArray, int, float]:
    """A stable equilibrium of one rod near the given state. An unstable one (the plate stepped past the
    turn of an imperfect column's path, and Newton found the straight column's continuation) raises
    :class:`NotConverged`, so that the caller takes a shorter step."""
    theta, force, used, final = _newton(d, theta, force, rest, closure, target)
    if _unstable(d, theta, force, rest, closure, target):
        raise NotConverged("rod: the equilibrium found under the plate is unstable")
    return theta, force, used, final


def _lying_onset(d: _Discrete, rest: NDArray, before: _PlateState, after: _PlateState,
                 start: NDArray) -> _PlateState:
    """The state between ``before`` and ``after`` (one plate step) whose tip face is parallel to the plate."""

    def state(height: float) -> _PlateState:
        closure, target = after.closure(start, height)
        theta, force, _, _ = _newton(d, 0.5 * (before.theta + after.theta), 0.5 * (before.force + after.force),
                                     rest, closure, target)
        return _PlateState(theta, force, after.sliding, after.friction)

    def height(row: _PlateState) -> float:
        return float(_chords(d, row.theta, row.force)[0][..., 1].sum())

    onset = brentq(lambda h: abs(state(h).theta[0, -1]) - math.pi / 2, height(after), height(before),
                   xtol=1e-12, rtol=1e-8)
    return state(onset)


# ------------------------------------------------------------------------------------ the rod lying down


@dataclass(frozen=True)
class _Folded:
    """A rod lying on the plate: its free part, ``free`` (m) of reference length from the base, bends from
    the base to where it meets the plate tangentially (its last angle ``side`` × π/2); the rest lies
    straight along the plate. ``theta`` (1, N) and ``force`` (1, 2) are the free part's (N segments of
    free/N), ``height`` the plate's; ``anchor`` and ``friction``: see :func:`_fold_solve`."""

    free: float
    theta: NDArray[np.float64]
    force: NDArray[np.float64]
    side: float
    height: float
    anchor: float  # x where the tip came down (m)
    friction: float | None  # sliding: F_x = friction × F_z; None while the lying part sticks

    def whole_rod(self, rod: Rod) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        """The whole rod's angles (1, N), node x and z (1, N + 1) at its own N equal segments, and the force."""
        part = _free_part(rod, self.free)
        shape = _shapes(part, _discretise(part), self.theta, self.force, np.zeros(1, dtype=bool), 0, 0.0)
        n = rod.segments
        nodes = np.arange(n + 1) * rod.length / n
        centres = (np.arange(n) + 0.5) * rod.length / n
        free_nodes = np.arange(n + 1) * self.free / n
        free_centres = (np.arange(n) + 0.5) * self.free / n
        beyond = np.maximum(nodes - self.free, 0.0)  # along the plate, past the touchdown point
        x = np.interp(nodes, free_nodes, shape.x[0]) + self.side * beyond
        z = np.interp(nodes, free_nodes, shape.z[0])
        angles = np.where(centres < self.free, np.interp(centres, free_centres, self.theta[0]),
                          self.side * math.pi / 2)
        return angles[None, :], x[None, :], z[None, :], self.force


def _free_part(rod: Rod, free: float) -> Rod:
    """The rod's first ``free`` metres as a rod of its own (N segments)."""
    if free <= max(rod.base_diameter, float(rod.diameter(free))):
        raise RodError(f"gaps: the plate has folded the rod flat (its free part {free:.3g} m is no longer "
                       "longer than wide): expected larger gaps")
    return replace(rod, length=free, tip_diameter=float(rod.diameter(free)))


def _fold_to(rod: Rod, contact: PlateContact, folded: _Folded, height: float, gap: float, largest_step: float,
             smallest_step: float) -> tuple[_Folded, float, int]:
    """The lying rod with the plate lowered from ``height`` to ``gap``, in steps halved where Newton fails."""
    step, iterations = largest_step, 0
    while height > gap:
        next_height = max(gap, height - step)
        try:
            folded, used = _fold(rod, contact, folded, next_height)
        except NotConverged:
            step /= 2
            if step < smallest_step:
                raise
            continue
        height, step, iterations = next_height, min(2 * step, largest_step), iterations + used
    return folded, height, iterations


def _fold(rod: Rod, contact: PlateContact, folded: _Folded, height: float) -> tuple[_Folded, int]:
    """The lying rod with the plate at ``height``: its lying part stuck on the plate if friction can hold it,
    else sliding (and sliding from then on, as :func:`_plate_step`)."""
    if folded.friction is None:
        stuck, used = _fold_solve(rod, contact, folded, height, None)
        needed, push = stuck.force[0, 0], -stuck.force[0, 1]
        if abs(needed) <= contact.friction * max(push, 0.0):
            return stuck, used
        # the lying part slides the way the force that held it points against
        sliding, more = _fold_solve(rod, contact, folded, height, float(-np.sign(needed) * contact.friction))
        return sliding, used + more
    return _fold_solve(rod, contact, folded, height, folded.friction)


def _fold_solve(rod: Rod, contact: PlateContact, folded: _Folded, height: float, friction: float | None,
                tolerance: float = 1e-10, max_iterations: int = 40) -> tuple[_Folded, int]:
    """The lying rod's equilibrium with the plate at ``height``. Unknowns: the free part's angles, the
    force where it meets the plate and its length ℓ; equations: its moment balance, its last angle ± π/2
    (tangent to the plate: the lying part is straight and carries no moment), its end at the plate's height
    and either stuck (``friction`` None: the material that has come down stays where it landed, so the
    touchdown point is at anchor ± (ℓ − L)) or sliding with F_x = ``friction`` × F_z. Newton's method; the
    column in ℓ by central differences."""
    n = rod.segments

    def system(theta: NDArray, force: NDArray, free: float) -> tuple[NDArray, NDArray, _Discrete]:
        d = _discretise(_free_part(rod, free))
        rest = _bow(rod, contact, free)
        if friction is None:
            closure, target = "pinned", np.array([[folded.anchor + folded.side * (free - rod.length), height]])
        else:
            closure, target = "sliding", np.array([[friction, height]])
        residual, jacobian = _system(d, theta, force, rest, closure, target)
        return np.append(residual[0], theta[0, -1] - folded.side * math.pi / 2), jacobian[0], d

    # the start: the last state, its free part shortened with the plate's height (exact for a uniform rod)
    theta, force = folded.theta.copy(), folded.force.copy()
    free = folded.free * height / folded.height
    for iteration in range(1, max_iterations + 1):
        residual, jacobian, d = system(theta, force, free)
        scales = (free, free) if friction is None else (d.scale / free, free)
        size = max(_residual_size(d, residual[None, :n + 2], scales), abs(residual[-1]))
        if size <= tolerance:
            return replace(folded, free=free, theta=theta, force=force, height=height, friction=friction), iteration
        delta = 1e-6 * free
        column = (system(theta, force, free + delta)[0] - system(theta, force, free - delta)[0]) / (2 * delta)
        whole = np.zeros((n + 3, n + 3))
        whole[:n + 2, :n + 2] = jacobian
        whole[:, n + 2] = column
        whole[n + 2, n - 1] = 1.0
        try:
            with single_threaded_blas():
                step = np.linalg.solve(whole, -residual)
        except np.linalg.LinAlgError:
            raise NotConverged("rod: singular Newton system for the rod lying on the plate") from None
        # as in _newton: at most 0.3 rad per angle, and the free length by at most a tenth, per step
        damping = min(1.0, 0.3 / max(np.abs(step[:n]).max(), 1e-300), 0.1 * free / max(abs(step[-1]), 1e-300))
        theta += damping * step[None, :n]
        force += damping * step[None, n:n + 2]
        free += damping * step[-1]
    raise NotConverged(f"rod: the rod lying on the plate did not converge in {max_iterations} iterations")
