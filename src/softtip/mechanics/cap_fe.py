"""Finite elements of a hemispherical elastomer cap on a rigid core under a flat plate: the evidence
for the plate-contact laws of :mod:`softtip.mechanics.plate_contact`, and the bonded-layer law's
effective thickness calibrated on it.

The cap is a hemispherical shell of outer radius R and thickness t, bonded to a rigid core of radius
R − t and to a rigid base at z = 0 (its flat face), dome up. A quarter of it is meshed (x, y >= 0,
symmetry planes held normal to themselves), solved with softtip's P2 elements and frictionless nodal
contact (:func:`~softtip.mechanics.contact.nodal.solve_linear_contact`, small strain) under a
:class:`~softtip.mechanics.indenters.Plate` pushed ``depth`` down from first touch. Rubber is nearly
incompressible; small-strain P2 elements are used at ν = 0.49 (ν = 0.5 has no finite bulk modulus),
and the laws are compared at the same plane-strain modulus E/(1 − ν²).

This is slow (a mesh and one contact solve per depth, seconds each): callers cache what they need.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from softtip.design.model import Material
from softtip.mechanics.contact.load import LoadCase
from softtip.mechanics.contact.nodal import solve_linear_contact
from softtip.mechanics.fe import BodyModel
from softtip.mechanics.indenters import Plate
from softtip.mechanics.mesh import TetMesh, gmsh_session, tet_mesh_from_gmsh
from softtip.mechanics.plate_contact import bonded_layer_force, hertz_force

FE_POISSON_RATIO = 0.49


def cap_mesh(radius: float, thickness: float, size: float, tip_size: float, tip_reach: float) -> TetMesh:
    """A quarter hemispherical shell (m): boundaries ``outer`` (the dome), ``base`` (core and flat
    face, bonded), ``symmetry_x`` (x = 0) and ``symmetry_y`` (y = 0); elements of ``tip_size`` within
    ``tip_reach`` of the apex, ``size`` elsewhere."""
    if not 0 < thickness < radius:
        raise ValueError(f"thickness = {thickness!r}: expected a layer thinner than the radius {radius!r} m")
    with gmsh_session("cap") as gmsh:
        occ = gmsh.model.occ
        outer = occ.addSphere(0, 0, 0, radius)
        core = occ.addSphere(0, 0, 0, radius - thickness)
        quarter = occ.addBox(0, 0, 0, radius, radius, radius)
        shell, _ = occ.cut([(3, outer)], [(3, core)])
        occ.intersect(shell, [(3, quarter)])
        occ.synchronize()
        groups: dict[str, list[int]] = {"outer": [], "base": [], "symmetry_x": [], "symmetry_y": []}
        flat = 1e-3 * thickness  # gmsh pads bounding boxes by a small tolerance
        for _, tag in gmsh.model.getEntities(2):
            x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, tag)
            if x1 - x0 < flat:
                groups["symmetry_x"].append(tag)
            elif y1 - y0 < flat:
                groups["symmetry_y"].append(tag)
            elif z1 - z0 < flat or z1 < radius - thickness / 2:
                groups["base"].append(tag)  # the flat face, or the core's surface
            else:
                groups["outer"].append(tag)
        field = gmsh.model.mesh.field
        ball = field.add("Ball")
        for name, value in (("Radius", tip_reach), ("VIn", tip_size), ("VOut", size), ("XCenter", 0.0),
                            ("YCenter", 0.0), ("ZCenter", radius), ("Thickness", tip_reach)):
            field.setNumber(ball, name, value)
        field.setAsBackgroundMesh(ball)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)
        gmsh.option.setNumber("Mesh.Optimize", 1)
        gmsh.model.mesh.generate(3)
        return tet_mesh_from_gmsh(groups, f"cap-{radius}-{thickness}-{size}-{tip_size}-{tip_reach}")


@dataclass(frozen=True)
class CapCurve:
    """Plate force against depth on the cap by FE, and the laws beside it (N)."""

    radius: float
    thickness: float
    youngs_modulus: float
    depths: np.ndarray
    fe_forces: np.ndarray
    hertz_forces: np.ndarray
    calibrated_thickness: float  # m: the bonded-layer law's thickness that fits the FE best
    calibrated_forces: np.ndarray
    converged: bool

    @property
    def contact_ratio(self) -> np.ndarray:
        """χ = √(Rδ)/t at each depth."""
        return np.sqrt(self.radius * self.depths) / self.thickness


def plate_on_cap_fe(radius: float, thickness: float, youngs_modulus: float, depths, size: float | None = None,
                    tip_size: float | None = None) -> CapCurve:
    """The FE force curve of the cap under a plate at ``depths`` (m), and the Hertz and calibrated
    bonded-layer laws beside it. A contact solve that does not converge raises."""
    depths = np.asarray(depths, dtype=float)
    if depths.ndim != 1 or not len(depths) or np.any(depths <= 0) or np.any(depths >= thickness):
        raise ValueError(f"depths = {depths.tolist()}: expected positive depths below the thickness {thickness} m")
    reach = 1.5 * np.sqrt(radius * depths.max()) + thickness / 2
    mesh = cap_mesh(radius, thickness, size or thickness / 2, tip_size or reach / 6, reach)
    body = BodyModel(mesh, Material(youngs_modulus, FE_POISSON_RATIO, 1100.0), np.zeros((0, 3)),
                     {"base": (0, 1, 2), "symmetry_x": (0,), "symmetry_y": (1,)})
    results = [solve_linear_contact(body, LoadCase(Plate(), float(depth))) for depth in depths]
    fe = 4 * np.array([result.force[2] for result in results])  # four quarters
    plane_strain = youngs_modulus / (1 - FE_POISSON_RATIO**2)
    hertz = hertz_force(depths, radius, plane_strain * 0.75, 0.5)  # E/(1 − ν²) at ν = 0.5 is 4E/3

    def misfit(layer: float) -> float:
        return float(np.sum((bonded_layer_force(depths, radius, plane_strain * 0.75, layer) / fe - 1) ** 2))

    best = minimize_scalar(misfit, bounds=(0.2 * thickness, 20 * thickness), method="bounded")
    return CapCurve(radius, thickness, youngs_modulus, depths, fe, hertz, float(best.x),
                    bonded_layer_force(depths, radius, plane_strain * 0.75, float(best.x)),
                    all(result.converged for result in results))
