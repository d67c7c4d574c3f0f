"""A kind of body a system registers: a truncated cone over a cylindrical cavity, its magnets on a circle.

Read from a design table, built and meshed as softtip's own kinds are (the mesher asks the registered
kind for its solid). References: the frustum's, the cavity's and the magnets' volumes and areas, by hand.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
import pytest

from softtip._core.systems import System, register, unregister
from softtip._core.units import MM
from softtip.design.model import CylindricalCavity, CylindricalMagnets, DesignError, design_from_dict
from softtip.mechanics.mesh import mesh_design, mesh_key
from softtip.plugin import (BodyKind, BodyMaterial, BodySolid, DesignSpec, PositiveNumber, check_system,
                            ring_of_magnets, schema)

BASE_MM, TOP_MM, HEIGHT_MM = 25.0, 20.0, 9.0  # diameters and height of the cone
CAVITY_RADIUS_MM, CAVITY_HEIGHT_MM = 8.0, 5.0
MAGNETS, MAGNET_DIAMETER_MM, MAGNET_HEIGHT_MM, CIRCLE_MM = 4, 2.0, 1.5, 5.5


@schema
class ConeBody(BodyMaterial):
    base_diameter_mm: PositiveNumber
    top_diameter_mm: PositiveNumber
    height_mm: PositiveNumber


@schema
class ConeSpec(DesignSpec):
    kind: Literal["conical"]
    body: ConeBody
    cavity: CylindricalCavity
    magnets: CylindricalMagnets

    @property
    def sensor_positions_mm(self) -> list:
        return self.sensor.positions_mm or [(0.0, 0.0, 0.8)]


def cone_solid(design, occ) -> BodySolid:
    body, cavity = design.spec["body"], design.spec["cavity"]
    base, top = body["base_diameter_mm"] * MM / 2, body["top_diameter_mm"] * MM / 2
    radius, height = cavity["radius_mm"] * MM, cavity["height_mm"] * MM
    return BodySolid(occ.addCone(0, 0, 0, 0, 0, design.height, base, top),
                     occ.addCylinder(0, 0, 0, 0, 0, height, radius), (-radius, -radius, 0.0, radius, radius, height),
                     (top, top))


CONE = BodyKind("conical", ConeSpec, ring_of_magnets, f"{__name__}:cone_solid")

DESIGN = {"kind": "conical", "name": "cone",
          "body": {"base_diameter_mm": BASE_MM, "top_diameter_mm": TOP_MM, "height_mm": HEIGHT_MM},
          "cavity": {"radius_mm": CAVITY_RADIUS_MM, "height_mm": CAVITY_HEIGHT_MM},
          "magnets": {"count": MAGNETS, "circle_radius_mm": CIRCLE_MM, "diameter_mm": MAGNET_DIAMETER_MM,
                      "height_mm": MAGNET_HEIGHT_MM, "depth_mm": 1.25, "polarization_T": 1.2}}


@pytest.fixture
def cones():
    register(System(name="cones", title="Conical fingertips", label="X9", package=__name__,
                    bodies={"conical": f"{__name__}:CONE"}))
    yield
    unregister("cones")


def test_a_registered_body_kind_is_read_and_placed_and_other_kinds_are_refused_naming_it(cones):
    design = design_from_dict(DESIGN, "cone.toml")
    assert design.kind == "conical" and design.height == pytest.approx(HEIGHT_MM * MM)
    centres = np.array([magnet.center for magnet in design.magnets]) / MM
    angles = 2 * np.pi * np.arange(MAGNETS) / MAGNETS
    np.testing.assert_allclose(centres[:, :2], CIRCLE_MM * np.column_stack([np.cos(angles), np.sin(angles)]),
                               atol=1e-12)
    np.testing.assert_allclose(centres[:, 2], HEIGHT_MM - 1.25 - MAGNET_HEIGHT_MM / 2)  # top faces 1.25 mm deep
    with pytest.raises(DesignError, match=r"kind.*expected one of cylindrical, rectangular, conical"):
        design_from_dict({**DESIGN, "kind": "spherical"}, "cone.toml")
    with pytest.raises(DesignError, match=r"top_diameter_mm"):
        design_from_dict({**DESIGN, "body": {"base_diameter_mm": BASE_MM, "height_mm": HEIGHT_MM}}, "cone.toml")
    assert check_system("cones") == []


def test_a_registered_body_kind_is_meshed_with_its_own_solid(cones):
    design = design_from_dict(DESIGN, "cone.toml")
    mesh = mesh_design(design, size=2.0 * MM, curvature_points=40, use_cache=False)
    corners = mesh.points[mesh.tets.T]  # (tets, 4, 3)
    volume = np.abs(np.linalg.det(corners[:, 1:] - corners[:, :1])).sum() / 6

    def area(name: str) -> float:
        a, b, c = (mesh.points[k] for k in mesh.boundaries[name])
        return float(np.linalg.norm(np.cross(b - a, c - a), axis=1).sum() / 2)

    r0, r1, h = BASE_MM / 2 * MM, TOP_MM / 2 * MM, HEIGHT_MM * MM
    rc, hc = CAVITY_RADIUS_MM * MM, CAVITY_HEIGHT_MM * MM
    rm, hm = MAGNET_DIAMETER_MM / 2 * MM, MAGNET_HEIGHT_MM * MM
    frustum = math.pi * h / 3 * (r0**2 + r0 * r1 + r1**2)
    expected = frustum - math.pi * rc**2 * hc - MAGNETS * math.pi * rm**2 * hm
    # a polygon of 40 sides around each circle holds sin(2 pi / 40) / (2 pi / 40) = 99.6 % of its disc's area
    assert volume == pytest.approx(expected, rel=5e-3)
    assert area("base") == pytest.approx(math.pi * (r0**2 - rc**2), rel=5e-3)
    side = math.pi * (r0 + r1) * math.hypot(r0 - r1, h)
    assert area("outer") == pytest.approx(math.pi * r1**2 + side, rel=5e-3)  # the top and the cone's side
    assert area("magnet0") == pytest.approx(2 * math.pi * rm * (rm + hm), rel=5e-3)
    assert mesh.magnet_count == MAGNETS
    assert mesh_key(design, 2.0 * MM, 40) != mesh_key(design_from_dict({**DESIGN, "kind": "cylindrical",
                                                                         "body": {"diameter_mm": BASE_MM,
                                                                                  "height_mm": HEIGHT_MM}}),
                                                      2.0 * MM, 40)
