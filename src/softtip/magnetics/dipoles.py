"""Point dipoles, chains of them along a bent magnet, and their field averaged exactly over rectangles.

A point dipole of moment m (A·m²) at r₀ has the scalar potential φ = m·R / (4π|R|³), R = r − r₀, and the
flux density B = −μ₀∇φ = μ₀/(4π) (3(m·R̂)R̂ − m)/|R|³ outside it.

A bent, axially magnetised slender magnet (a magnetic pillar) is a **chain**: K dipoles at points of its
deformed centre line, each along the local tangent, carrying a share of the total moment (1/K each,
as the published simulation did, or in proportion to the local cross-section of a tapered magnet).

A planar sensor (a magnetoresistive strip lying in a plane z = const) responds to the in-plane field
averaged over its rectangle. The average is exact here, not a grid: because B = −μ₀∇φ,

    ∫∫ B_x dx dy = −μ₀ ∫ [φ(x₂, y) − φ(x₁, y)] dy,

a line integral of the potential along the two edges across x, and along y the dipole's potential
integrates in closed form (ρ² = X² + Z², X, Z the edge's offsets from the dipole):

    ∫ φ dY = [ (m_x X + m_z Z) Y / (ρ² √(ρ² + Y²)) − m_y / √(ρ² + Y²) ] / (4π),

and likewise for B_y with x and y exchanged. The tests hold it against adaptive quadrature and a very
fine grid. B_z is not averaged (it is not a line integral; in-plane sensors do not see it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.constants import mu_0

_MU0_OVER_4PI = mu_0 / (4.0 * np.pi)
# dipole–observer pairs per chunk of the rectangle kernel: keeps its temporaries near 10 MB
_PAIRS_PER_CHUNK = 1 << 18
# corners' primitives summed per batch at a time: keeps those sums near 16 MB
_SUMMED_CORNERS = 1 << 21


class DipoleError(ValueError):
    """Dipoles, chains or rectangles that cannot describe a physical case."""


def _array(values: ArrayLike, name: str, last: int | None = 3) -> NDArray[np.float64]:
    array = np.asarray(values, dtype=np.float64)
    if last is not None and array.shape[-1:] != (last,):
        raise DipoleError(f"{name}: expected an array of shape (..., {last}), got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise DipoleError(f"{name}: expected finite numbers")
    return array


def dipole_field(points: ArrayLike, positions: ArrayLike, moments: ArrayLike) -> NDArray[np.float64]:
    """Flux density (T) at ``points`` (P, 3) of the dipoles at ``positions`` (..., D, 3) with ``moments``
    (..., D, 3), summed over the dipoles: shape (..., P, 3). A point on a dipole is refused."""
    points = _array(points, "points")
    positions = _array(positions, "positions")
    moments = _array(moments, "moments")
    if points.ndim != 2:
        raise DipoleError(f"points: expected shape (P, 3), got {points.shape}")
    if positions.shape != moments.shape:
        raise DipoleError(f"moments: expected the shape of positions {positions.shape}, got {moments.shape}")
    offsets = points[..., :, None, :] - positions[..., None, :, :]  # (..., P, D, 3)
    distance2 = np.einsum("...i,...i->...", offsets, offsets)
    if np.any(distance2 == 0):
        raise DipoleError("points: a point coincides with a dipole, where its field is infinite")
    inverse = 1.0 / np.sqrt(distance2)
    inverse3 = inverse**3
    projection = np.einsum("...pdi,...di->...pd", offsets, moments) * inverse * inverse
    field = 3.0 * projection[..., None] * offsets - moments[..., None, :, :]
    return _MU0_OVER_4PI * np.einsum("...pdi,...pd->...pi", field, inverse3)


@dataclass(frozen=True)
class Dipoles:
    """Point dipoles: ``positions`` and ``moments`` (..., D, 3), m and A·m²."""

    positions: NDArray[np.float64]
    moments: NDArray[np.float64]

    def field(self, points: ArrayLike) -> NDArray[np.float64]:
        """(..., P, 3) flux density at ``points`` (P, 3), T."""
        return dipole_field(points, self.positions, self.moments)

    def in_plane_average(self, rectangles: Rectangles, axes: tuple[int, ...] = (0, 1)) -> NDArray[np.float64]:
        """(..., R, len(axes)) mean in-plane field along ``axes`` over each rectangle, T (exact)."""
        return rectangle_average_in_plane(rectangles, self.positions, self.moments, axes)


def dipole_chain(points: ArrayLike, tangents: ArrayLike, moment: float,
                 shares: ArrayLike | None = None) -> Dipoles:
    """A bent axial magnet of total ``moment`` (A·m², signed: negative points against the tangents) as
    dipoles at its centre-line ``points`` (..., K, 3), each along the local unit tangent (..., K, 3) and
    carrying ``shares`` (K,) of the moment (default: 1/K each; they must sum to 1)."""
    points = _array(points, "points")
    tangents = _array(tangents, "tangents")
    if points.shape != tangents.shape or points.ndim < 2:
        raise DipoleError(f"tangents: expected the shape of points {points.shape} (..., K, 3), got {tangents.shape}")
    if not np.isfinite(moment):
        raise DipoleError(f"moment = {moment!r}: expected a finite number")
    count = points.shape[-2]
    shares = np.full(count, 1.0 / count) if shares is None else _array(shares, "shares", None)
    if shares.shape != (count,) or np.any(shares < 0) or abs(shares.sum() - 1.0) > 1e-9:
        raise DipoleError(f"shares: expected {count} numbers >= 0 summing to 1")
    norms = np.linalg.norm(tangents, axis=-1, keepdims=True)
    if np.any(np.abs(norms - 1.0) > 1e-6):
        raise DipoleError("tangents: expected unit vectors")
    return Dipoles(points, moment * shares[:, None] * tangents)


def frustum_shares(base_diameter: float, tip_diameter: float, count: int) -> NDArray[np.float64]:
    """Shares of a uniformly magnetised cone frustum's moment held by ``count`` equal pieces along its
    axis, base first: each piece's volume over the whole (exact for a linear taper)."""
    edges = np.linspace(0.0, 1.0, count + 1)
    diameter = base_diameter + (tip_diameter - base_diameter) * edges
    # volume of a frustum piece ∝ (d₀² + d₀d₁ + d₁²) for equal heights
    pieces = diameter[:-1] ** 2 + diameter[:-1] * diameter[1:] + diameter[1:] ** 2
    return pieces / pieces.sum()


@dataclass(frozen=True)
class Rectangles:
    """Axis-aligned rectangles in the plane z = ``z``: ``x`` and ``y`` (R, 2) hold each one's lower and
    upper edges (m)."""

    x: NDArray[np.float64]
    y: NDArray[np.float64]
    z: float

    def __post_init__(self) -> None:
        x, y = _array(self.x, "x", 2), _array(self.y, "y", 2)
        if x.ndim != 2 or x.shape != y.shape:
            raise DipoleError(f"rectangles: expected x and y of one shape (R, 2), got {x.shape} and {y.shape}")
        if np.any(x[:, 1] <= x[:, 0]) or np.any(y[:, 1] <= y[:, 0]):
            raise DipoleError("rectangles: every upper edge must lie above its lower edge")
        if not np.isfinite(self.z):
            raise DipoleError(f"rectangles: z = {self.z!r}: expected a finite number")
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "y", y)

    @property
    def area(self) -> NDArray[np.float64]:
        return (self.x[:, 1] - self.x[:, 0]) * (self.y[:, 1] - self.y[:, 0])

    def __len__(self) -> int:
        return self.x.shape[0]


def _edge_integral(across: NDArray, along_low: NDArray, along_high: NDArray, height: NDArray,
                   m_across: NDArray, m_along: NDArray, m_height: NDArray) -> NDArray:
    """∫ φ d(along) from along_low to along_high on a line at offset ``across`` and ``height`` from the
    dipole, times 4π (the closed form of the module notes)."""
    rho2 = across * across + height * height
    axial = m_across * across + m_height * height

    def primitive(along: NDArray) -> NDArray:
        root = np.sqrt(rho2 + along * along)
        return (axial * along / rho2 - m_along) / root

    return primitive(along_high) - primitive(along_low)


def rectangle_average_in_plane(rectangles: Rectangles, positions: ArrayLike, moments: ArrayLike,
                               axes: tuple[int, ...] = (0, 1)) -> NDArray[np.float64]:
    """Mean in-plane field (T) along ``axes`` (0: B_x, 1: B_y) over each rectangle (R) of the dipoles at
    ``positions`` with ``moments`` (..., D, 3), summed over the dipoles: shape (..., R, len(axes)). Exact
    (closed form, module notes); a dipole in the rectangles' plane is refused (its field is not
    integrable there)."""
    positions = _array(positions, "positions")
    moments = _array(moments, "moments")
    if positions.shape != moments.shape or positions.ndim < 2:
        raise DipoleError(f"moments: expected the shape of positions {positions.shape} (..., D, 3), got {moments.shape}")
    if not axes or any(axis not in (0, 1) for axis in axes):
        raise DipoleError(f"axes = {axes!r}: expected in-plane axes among 0 (x) and 1 (y)")
    if np.any(positions[..., 2] == rectangles.z):
        raise DipoleError("positions: a dipole lies in the rectangles' plane")
    per_batch = positions.shape[-2]
    flat_positions = positions.reshape(-1, 3)
    flat_moments = moments.reshape(-1, 3)
    batches = int(np.prod(positions.shape[:-2]))
    count = len(rectangles)
    xs, x_index = np.unique(rectangles.x, return_inverse=True)
    ys, y_index = np.unique(rectangles.y, return_inverse=True)
    (x_low, x_high), (y_low, y_high) = x_index.reshape(-1, 2).T, y_index.reshape(-1, 2).T
    # rectangles that share their edges (a meander's area elements: runs of strips cut along their length)
    # have far fewer distinct corners than 4 each: the potential's line integral is then taken once per corner
    corners = xs.size * ys.size
    if corners < 4 * count:
        out = np.empty((batches, count, len(axes)))
        chunk = max(1, _PAIRS_PER_CHUNK // corners)
        # each element's four corners as flat indices into the (X, Y) grid of corners
        high_high, high_low = x_high * ys.size + y_high, x_high * ys.size + y_low
        low_high, low_low = x_low * ys.size + y_high, x_low * ys.size + y_low
        # the corners' primitives are summed over each batch's dipoles before the elements gather them (the
        # gather is linear): one gather per batch, not per dipole; batches are taken in groups that bound the sums
        group = max(1, _SUMMED_CORNERS // corners)
        summed = np.empty((min(group, batches), len(axes), corners))
        # the two (d, X, Y) buffers are made once: fresh ones per chunk cost the kernel page faults, not numbers
        distances = np.empty((min(chunk, flat_positions.shape[0]), xs.size, ys.size))
        primitives = np.empty_like(distances)
        for first in range(0, batches, group):
            last = min(first + group, batches)
            sums = summed[:last - first]
            sums.fill(0.0)
            for start in range(first * per_batch, last * per_batch, chunk):
                stop = min(start + chunk, last * per_batch)
                p = flat_positions[start:stop]  # (d, 3)
                m = flat_moments[start:stop]
                # the chunk's dipoles by batch: contiguous runs, each summed into its batch's row
                owners = np.arange(start, stop) // per_batch
                runs = np.flatnonzero(np.diff(owners, prepend=-1))
                rows = owners[runs] - first
                # offsets to the corners' lines (d, X) and (d, Y), heights (d, 1): only the distance and the
                # primitive itself are taken on the full (d, X, Y) grid, in place
                dx, dy = xs[None, :] - p[:, 0:1], ys[None, :] - p[:, 1:2]
                height = rectangles.z - p[:, 2:3]
                height2 = height * height
                root, primitive = distances[:p.shape[0]], primitives[:p.shape[0]]
                np.add((dx * dx)[:, :, None], (dy * dy + height2)[:, None, :], out=root)
                np.sqrt(root, out=root)  # (d, X, Y): each corner's distance
                for column, axis in enumerate(axes):
                    # the primitive of ∫ φ d(along) at each corner (module notes), across = the edges across ``axis``
                    across, along = (dx, dy) if axis == 0 else (dy, dx)
                    slope = (m[:, axis:axis + 1] * across + m[:, 2:3] * height) / (across * across + height2)
                    if axis == 0:
                        np.multiply(slope[:, :, None], along[:, None, :], out=primitive)
                    else:
                        np.multiply(along[:, :, None], slope[:, None, :], out=primitive)
                    np.subtract(primitive, m[:, 1 - axis, None, None], out=primitive)
                    np.divide(primitive, root, out=primitive)
                    sums[rows, column] += np.add.reduceat(primitive.reshape(primitive.shape[0], -1), runs, axis=0)
            for column in range(len(axes)):
                flat = sums[:, column]

                def at(corner: NDArray) -> NDArray:  # np.take: twice as fast as indexing flat[:, corner]
                    return np.take(flat, corner, axis=1)

                # either axis: (upper edge across − lower edge across) of (upper end − lower end) along it
                out[first:last, :, column] = at(high_high) - at(high_low) - at(low_high) + at(low_low)
        out *= -_MU0_OVER_4PI / rectangles.area[None, :, None]
        return out.reshape(*positions.shape[:-2], count, len(axes))
    out = np.zeros((flat_positions.shape[0], count, len(axes)))
    chunk = max(1, _PAIRS_PER_CHUNK // max(count, 1))
    edges = (rectangles.x, rectangles.y)
    for start in range(0, flat_positions.shape[0], chunk):
        p = flat_positions[start:start + chunk, None, :]
        m = flat_moments[start:start + chunk, None, :]
        offsets = [edges[axis][None, :, :] - p[..., axis:axis + 1] for axis in (0, 1)]  # (d, R, 2) each
        height = rectangles.z - p[..., 2:3]
        for column, axis in enumerate(axes):
            # B_axis: the potential along the two edges across ``axis``, integrated along the other
            other = 1 - axis
            along = _edge_integral(offsets[axis], offsets[other][..., 0:1], offsets[other][..., 1:2], height,
                                   m[..., axis:axis + 1], m[..., other:other + 1], m[..., 2:3])
            out[start:start + chunk, :, column] = along[..., 1] - along[..., 0]
    out *= -_MU0_OVER_4PI / rectangles.area[None, :, None]
    return out.reshape(*positions.shape[:-1], count, len(axes)).sum(axis=-3)
