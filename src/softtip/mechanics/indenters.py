"""Rigid indenters as signed-distance functions.

Each indenter is described in its own frame with its lowest point at the
origin and offers two gap measures:

``signed_distance(points)``  distance to the indenter's surface (negative
    inside) and the unit normal pointing from the indenter to the point; used
    at deformed positions by the large-deformation solver.
``vertical_gap(points)``     height of the indenter's lower surface above each
    point (inf where it has none, unless ``extend``: then the surface is continued
    beyond its edge, for nodes that stick to it and are carried sideways), with
    the approach direction -z as normal;
    the small-strain gap of classical contact mechanics (Hertz, flat punch),
    valid however deep the indenter is pushed in one step.

The contact solvers move the frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


_DOWN = np.array([0.0, 0.0, -1.0])


def _downward(points: np.ndarray, gap: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return gap, np.tile(_DOWN, (len(points), 1))


@dataclass(frozen=True)
class Board:
    """A thin rigid board pushed edge-first: a slab of ``thickness`` (m), infinitely long
    along the direction at ``angle`` (rad) about the vertical axis, bottom face at z = 0."""

    thickness: float = 1.6e-3
    angle: float = 0.0

    def __post_init__(self):
        if not self.thickness > 0:
            raise ValueError(f"board thickness = {self.thickness}: expected a positive length")

    def signed_distance(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        across = np.array([-math.sin(self.angle), math.cos(self.angle), 0.0])
        s = points @ across
        dx = np.abs(s) - self.thickness / 2  # > 0 beside the board
        dz = -points[:, 2]  # > 0 below its bottom face
        ox, oz = np.maximum(dx, 0), np.maximum(dz, 0)
        outside = np.hypot(ox, oz)
        inside = np.minimum(np.maximum(dx, dz), 0)
        distance = outside + inside
        # gradient in the (across, z) plane, then mapped to 3-D
        with np.errstate(invalid="ignore", divide="ignore"):
            gx = np.where(outside > 0, ox / np.where(outside > 0, outside, 1), (dx >= dz).astype(float))
            gz = np.where(outside > 0, oz / np.where(outside > 0, outside, 1), (dz > dx).astype(float))
        normal = np.sign(s + (s == 0))[:, None] * gx[:, None] * across - gz[:, None] * np.array([0, 0, 1.0])
        return distance, normal

    def vertical_gap(self, points: np.ndarray, extend: bool = False) -> tuple[np.ndarray, np.ndarray]:
        if extend:
            return _downward(points, -points[:, 2])
        across = np.array([-math.sin(self.angle), math.cos(self.angle), 0.0])
        under = np.abs(points @ across) <= self.thickness / 2
        return _downward(points, np.where(under, -points[:, 2], np.inf))


@dataclass(frozen=True)
class Plate:
    """A rigid flat plate covering the whole fingertip, bottom face at z = 0."""

    def signed_distance(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return _downward(points, -points[:, 2])

    def vertical_gap(self, points: np.ndarray, extend: bool = False) -> tuple[np.ndarray, np.ndarray]:
        return self.signed_distance(points)


@dataclass(frozen=True)
class Sphere:
    """A rigid sphere of ``radius`` (m), lowest point at the origin."""

    radius: float = 5e-3

    def __post_init__(self):
        if not self.radius > 0:
            raise ValueError(f"sphere radius = {self.radius}: expected a positive length")

    def signed_distance(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        offset = points - np.array([0.0, 0.0, self.radius])
        distance = np.linalg.norm(offset, axis=1)
        normal = offset / np.where(distance > 0, distance, 1)[:, None]
        return distance - self.radius, normal

    def vertical_gap(self, points: np.ndarray, extend: bool = False) -> tuple[np.ndarray, np.ndarray]:
        r2 = points[:, 0] ** 2 + points[:, 1] ** 2
        inside = r2 <= self.radius**2
        lower = self.radius - np.sqrt(np.where(inside, self.radius**2 - r2, 0.0))
        return _downward(points, np.where(inside | extend, lower - points[:, 2], np.inf))


Indenter = Board | Plate | Sphere


def make_indenter(kind: str, thickness: float = 1.6e-3, angle_deg: float = 0.0, radius: float = 5e-3) -> Indenter:
    if kind == "board":
        return Board(thickness=thickness, angle=math.radians(angle_deg))
    if kind == "plate":
        return Plate()
    if kind == "sphere":
        return Sphere(radius=radius)
    raise ValueError(f"indenter = {kind!r}: expected one of board, plate, sphere")
