"""A bent, tapered, axially magnetised magnet as a continuous magnet: a stack of uniformly magnetised
cylinders along its centre line (magpylib's exact cylinder field), the reference the point-dipole chains of
:mod:`softtip.magnetics.dipoles` are checked against.

Each piece of the centre line is a cylinder of its own mid diameter and length, along the local tangent,
magnetised uniformly at the magnet's magnetisation M (A/m), so it carries M times its own volume; the stack
converges to the continuous magnet as the pieces shrink. Its in-plane field is averaged over rectangles by
Gauss–Legendre quadrature (the field is smooth there: the rectangles lie in a plane below the magnet).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.constants import mu_0
from scipy.spatial.transform import Rotation

from softtip.magnetics.dipoles import DipoleError, Rectangles


def cylinder_stack(points: ArrayLike, tangents: ArrayLike, diameters: ArrayLike, length: float,
                   magnetisation: float):
    """magpylib cylinders of ``length`` (m) and ``diameters`` (K,) m centred at ``points`` (K, 3) along unit
    ``tangents`` (K, 3), magnetised ``magnetisation`` A/m (signed: negative against the tangents)."""
    import magpylib

    points, tangents, diameters = (np.asarray(v, dtype=np.float64) for v in (points, tangents, diameters))
    if points.ndim != 2 or points.shape[1] != 3 or tangents.shape != points.shape or diameters.shape != points.shape[:1]:
        raise DipoleError(f"cylinder stack: expected points and tangents (K, 3) and diameters (K,), got "
                          f"{points.shape}, {tangents.shape}, {diameters.shape}")
    if not (np.all(np.isfinite(points)) and np.all(diameters > 0) and length > 0 and np.isfinite(magnetisation)):
        raise DipoleError("cylinder stack: expected finite points, positive diameters and length, a finite magnetisation")
    turns = Rotation.concatenate([Rotation.align_vectors([t], [[0.0, 0.0, 1.0]])[0] for t in tangents])
    return [magpylib.magnet.Cylinder(polarization=(0.0, 0.0, mu_0 * magnetisation), dimension=(d, length),
                                     position=p, orientation=turn)
            for p, d, turn in zip(points, diameters, turns)]


def stack_in_plane_average(magnets: list, rectangles: Rectangles, axis: int, nodes: int = 4) -> NDArray[np.float64]:
    """(R,) mean field (T) along ``axis`` (0: x, 1: y) of ``magnets`` over each rectangle, by ``nodes`` ×
    ``nodes`` Gauss–Legendre points."""
    import magpylib

    if axis not in (0, 1) or nodes < 1:
        raise DipoleError(f"axis = {axis!r}, nodes = {nodes!r}: expected an in-plane axis (0, 1) and nodes >= 1")
    g, w = np.polynomial.legendre.leggauss(nodes)
    half_x, half_y = np.diff(rectangles.x, axis=1) / 2, np.diff(rectangles.y, axis=1) / 2
    xs = (rectangles.x.mean(axis=1)[:, None] + half_x * g[None, :])[:, :, None]
    ys = (rectangles.y.mean(axis=1)[:, None] + half_y * g[None, :])[:, None, :]
    grid = np.broadcast_arrays(xs, ys)
    points = np.column_stack([grid[0].ravel(), grid[1].ravel(), np.full(grid[0].size, rectangles.z)])
    field = magpylib.getB(magnets, points, sumup=True)[:, axis].reshape(len(rectangles), nodes, nodes)
    return np.einsum("rij,i,j->r", field, w, w) / 4
