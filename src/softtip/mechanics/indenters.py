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


@dataclass(frozen=True)
class TiltedPlate:
    """A rigid flat plate tilted by ``tilt`` (rad) about a horizontal axis: its face rises along the
    horizontal direction at ``angle`` (rad) about the vertical axis; passes through the origin.
    A grasped object whose face is not square to the fingertip."""

    tilt: float = 0.0
    angle: float = 0.0

    def __post_init__(self):
        if not abs(self.tilt) < math.radians(60):
            raise ValueError(f"plate tilt = {math.degrees(self.tilt):.1f} deg: expected less than 60 deg")

    def _rise(self, points: np.ndarray) -> np.ndarray:
        uphill = np.array([math.cos(self.angle), math.sin(self.angle), 0.0])
        return math.tan(self.tilt) * (points @ uphill)

    def signed_distance(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        uphill = np.array([math.cos(self.angle), math.sin(self.angle), 0.0])
        normal = -math.cos(self.tilt) * np.array([0.0, 0.0, 1.0]) + math.sin(self.tilt) * uphill
        distance = (self._rise(points) - points[:, 2]) * math.cos(self.tilt)
        return distance, np.tile(normal, (len(points), 1))

    def vertical_gap(self, points: np.ndarray, extend: bool = False) -> tuple[np.ndarray, np.ndarray]:
        return _downward(points, self._rise(points) - points[:, 2])


@dataclass(frozen=True)
class CornerPlate:
    """The corner of a large rigid flat plate: it covers the quadrant u >= 0, v >= 0 of axes turned
    by ``angle`` (rad) about the vertical, corner at the origin, face at z = 0 - a board held
    face-on whose corner lies on the fingertip."""

    angle: float = 0.0

    def _inside(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        c, s = math.cos(self.angle), math.sin(self.angle)
        return points[:, 0] * c + points[:, 1] * s, -points[:, 0] * s + points[:, 1] * c

    def signed_distance(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        u, v = self._inside(points)
        outside = np.hypot(np.maximum(-u, 0), np.maximum(-v, 0))
        beside = outside > 0
        distance = np.where(beside, np.hypot(outside, np.maximum(points[:, 2], 0)), -points[:, 2])
        normal = np.tile(_DOWN, (len(points), 1))
        return distance, normal

    def vertical_gap(self, points: np.ndarray, extend: bool = False) -> tuple[np.ndarray, np.ndarray]:
        u, v = self._inside(points)
        covered = (u >= 0) & (v >= 0)
        return _downward(points, np.where(covered | extend, -points[:, 2], np.inf))


Indenter = Board | Plate | Sphere | TiltedPlate | CornerPlate
INDENTERS = ("board", "plate", "sphere", "tilted-plate", "corner")


def make_indenter(kind: str, thickness: float = 1.6e-3, angle_deg: float = 0.0, radius: float = 5e-3,
                  tilt_deg: float = 0.0) -> Indenter:
    if kind == "board":
        return Board(thickness=thickness, angle=math.radians(angle_deg))
    if kind == "plate":
        return Plate()
    if kind == "sphere":
        return Sphere(radius=radius)
    if kind == "tilted-plate":
        return TiltedPlate(tilt=math.radians(tilt_deg), angle=math.radians(angle_deg))
    if kind == "corner":
        return CornerPlate(angle=math.radians(angle_deg))
    raise ValueError(f"indenter = {kind!r}: expected one of {', '.join(INDENTERS)}")
