"""Tetrahedral meshes of fingertip bodies, built with gmsh and cached on disk.

The body is meshed with holes where the magnets sit: magnets are rigid and tied
to the elastomer, so only their surfaces enter the finite-element model (as
rigid-body constraints). Boundary triangles are grouped by role:

``base``      the face bonded to the rigid base (fixed),
``cavity``    the walls of the hollow (free),
``outer``     top surface, fillet and sides (free; where contact can happen),
``magnet<i>`` the surface of magnet i's hole (moves rigidly with the magnet).
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from types import ModuleType

import numpy as np

from softtip._core.cache import artefact_key, cache_dir, code_hash, read_entry, write_entry
from softtip._core.stopping import stop_handlers_kept
from softtip._core.systems import load
from softtip._core.units import MM
from softtip.design.model import Design, body_kind

_GMSH_LOCK = threading.Lock()  # gmsh keeps global state


@contextmanager
def gmsh_session(model: str) -> Iterator[ModuleType]:
    """gmsh, one model at a time (it keeps global state): the lock held, gmsh initialised without its own
    signal handler (it may run off the main thread) and silent, an empty model named ``model`` added;
    finalised on leaving."""
    import gmsh

    with _GMSH_LOCK:
        with stop_handlers_kept():
            gmsh.initialize(interruptible=False)
        try:
            gmsh.option.setNumber("General.Terminal", 0)
            gmsh.model.add(model)
            yield gmsh
        finally:
            gmsh.finalize()


@dataclass(frozen=True)
class TetMesh:
    points: np.ndarray  # (n, 3) m
    tets: np.ndarray  # (4, nt) vertex indices
    boundaries: dict[str, np.ndarray]  # name -> (3, k) triangles (vertex indices)
    key: str  # hash of what produced it

    @property
    def magnet_count(self) -> int:
        return sum(1 for name in self.boundaries if name.startswith("magnet"))


def mesh_key(design: Design, size: float, curvature_points: int,
             contact_layer: tuple[float, float] | None = None) -> str:
    """The cache key of a mesh: its geometry and settings, the gmsh version and the source of this
    mesher and of the design model that describes the geometry."""
    import gmsh

    recipe = {"geometry": design.geometry_key, "size": size, "curvature_points": curvature_points,
              "contact_layer": None if contact_layer is None else list(contact_layer), "gmsh": gmsh.__version__}
    solid_module = body_kind(design.kind).solid.partition(":")[0]
    return artefact_key(recipe, code_hash(__name__, "softtip.design.model", solid_module), length=20)


def mesh_design(design: Design, size: float = 1.5 * MM, curvature_points: int = 10,
                use_cache: bool = True, contact_layer: tuple[float, float] | None = None) -> TetMesh:
    """Mesh the design's body; ``size`` is the largest element edge (m).

    Element size near the magnets follows their curvature (``curvature_points``
    elements around a circle) so the small holes are resolved at any ``size``.
    ``contact_layer = (depth, layer_size)``: elements of at most ``layer_size`` in the top
    ``depth`` of the body (m), where indenters press; a thin indenter (a 1.6 mm board) is
    only resolved by a surface mesh finer than itself.
    """
    if size <= 0:
        raise ValueError(f"mesh size = {size}: expected a positive length in metres")
    if contact_layer is not None and not (len(contact_layer) == 2 and all(v > 0 for v in contact_layer)):
        raise ValueError(f"contact_layer = {contact_layer!r}: expected (depth, element size) in metres, both > 0")
    key = mesh_key(design, size, curvature_points, contact_layer)
    path = cache_dir() / "meshes" / f"{key}.npz"
    entry = read_entry(path, key, "mesh") if use_cache else None
    if entry is not None:
        metadata, arrays = entry
        return TetMesh(points=arrays["points"], tets=arrays["tets"],
                       boundaries={name: arrays[f"boundary_{name}"] for name in metadata["boundaries"]}, key=key)
    mesh = _build(design, size, curvature_points, key, contact_layer)
    if use_cache:
        write_entry(path, key, "mesh", {"boundaries": sorted(mesh.boundaries)},
                    {"points": mesh.points, "tets": mesh.tets,
                     **{f"boundary_{name}": tris for name, tris in mesh.boundaries.items()}})
    return mesh


def _build(design: Design, size: float, curvature_points: int, key: str,
           contact_layer: tuple[float, float] | None) -> TetMesh:
    with gmsh_session("fingertip") as gmsh:
        occ = gmsh.model.occ
        body, cavity_box = _body_and_cavity(design, occ)
        magnet_tags = []
        for magnet in design.magnets:
            cx, cy, cz = magnet.center
            magnet_tags.append(occ.addCylinder(cx, cy, cz - magnet.height / 2, 0, 0, magnet.height,
                                               magnet.diameter / 2))
        occ.cut([(3, body)], [(3, t) for t in magnet_tags], removeObject=True, removeTool=True)
        occ.synchronize()

        volumes = gmsh.model.getEntities(3)
        if len(volumes) != 1:
            raise RuntimeError(f"meshing {design.name}: expected one body volume, got {len(volumes)}")
        groups = _classify_surfaces(design, cavity_box)

        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.option.setNumber("Mesh.MeshSizeMin", size / 20)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", curvature_points)
        if contact_layer is not None:
            depth, layer_size = contact_layer
            field = gmsh.model.mesh.field
            box = field.add("Box")
            reach = 1.0  # m: the whole body sideways
            for name, value in (("VIn", layer_size), ("VOut", size), ("XMin", -reach), ("XMax", reach),
                                ("YMin", -reach), ("YMax", reach), ("ZMin", design.height - depth),
                                ("ZMax", design.height + 1.0), ("Thickness", depth)):
                field.setNumber(box, name, value)
            field.setAsBackgroundMesh(box)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)
        gmsh.option.setNumber("Mesh.Optimize", 1)
        gmsh.option.setNumber("Mesh.ElementOrder", 1)
        gmsh.model.mesh.generate(3)

        return tet_mesh_from_gmsh(groups, key)


def tet_mesh_from_gmsh(groups: dict[str, list[int]], key: str) -> TetMesh:
    """The tetrahedra of the current (meshed) gmsh model, with boundary triangles
    grouped by name from lists of surface tags; nodes renumbered from 0."""
    import gmsh

    node_tags, coords, _ = gmsh.model.mesh.getNodes()
    coords = coords.reshape(-1, 3)
    _, elem_nodes = gmsh.model.mesh.getElementsByType(4)  # 4-node tetrahedra
    tets_tags = elem_nodes.reshape(-1, 4)
    used = np.unique(tets_tags)
    index_of = np.full(int(node_tags.max()) + 1, -1, dtype=np.int64)
    index_of[node_tags.astype(np.int64)] = np.arange(len(node_tags))
    renumber = np.full(int(node_tags.max()) + 1, -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    points = coords[index_of[used]]
    tets = _positive_orientation(points, renumber[tets_tags].T.copy())
    boundaries = {}
    for name, surfaces in groups.items():
        tris = [gmsh.model.mesh.getElementsByType(2, tag=s)[1].reshape(-1, 3) for s in surfaces]
        boundaries[name] = renumber[np.vstack(tris)].T.copy()
    return TetMesh(points=points, tets=tets, boundaries=boundaries, key=key)


@dataclass(frozen=True)
class BodySolid:
    """A body kind's gmsh solid (what ``BodyKind.solid(design, occ)`` returns): the body's and its
    cavity's volume tags, the cavity's bounding box (x0, y0, z0, x1, y1, z1, m) and how far the top
    face's edges reach from the axis in x and y (m; their fillet is the design's ``fillet_mm``). The
    body stands on z = 0 with its top at ``design.height``; the mesher fillets, hollows and meshes it."""

    body: int
    cavity: int
    cavity_box: tuple[float, float, float, float, float, float]
    top_reach: tuple[float, float]


def cylindrical_solid(design: Design, occ) -> BodySolid:
    """A cylinder with a cylindrical cavity, both on the z axis."""
    radius = design.spec["body"]["diameter_mm"] * MM / 2
    c_radius, c_height = design.spec["cavity"]["radius_mm"] * MM, design.spec["cavity"]["height_mm"] * MM
    return BodySolid(occ.addCylinder(0, 0, 0, 0, 0, design.height, radius),
                     occ.addCylinder(0, 0, 0, 0, 0, c_height, c_radius),
                     (-c_radius, -c_radius, 0.0, c_radius, c_radius, c_height), (radius, radius))


def rectangular_solid(design: Design, occ) -> BodySolid:
    """A box with a box-shaped cavity, both centred on the z axis."""
    w, l = design.spec["body"]["width_mm"] * MM, design.spec["body"]["length_mm"] * MM
    cw, cl, ch = (design.spec["cavity"][k] * MM for k in ("width_mm", "length_mm", "height_mm"))
    return BodySolid(occ.addBox(-w / 2, -l / 2, 0, w, l, design.height), occ.addBox(-cw / 2, -cl / 2, 0, cw, cl, ch),
                     (-cw / 2, -cl / 2, 0.0, cw / 2, cl / 2, ch), (w, l))


def _body_and_cavity(design: Design, occ) -> tuple[int, tuple[float, ...]]:
    """Create the filleted body minus its hollow; return its tag and the hollow's bounding box."""
    solid = load(body_kind(design.kind).solid)(design, occ)
    if not isinstance(solid, BodySolid):
        raise TypeError(f"body kind {design.kind!r}: its solid returned {type(solid).__name__}, expected a BodySolid")
    h = design.height
    fillet = design.spec["body"].get("fillet_mm", 0.0) * MM
    occ.synchronize()
    body = solid.body
    if fillet > 0:
        x, y = (reach * 1.01 for reach in solid.top_reach)
        edges = [e for _, e in occ.getEntitiesInBoundingBox(-x, -y, h * 0.999, x, y, h * 1.001, 1)]
        body = occ.fillet([body], edges, [fillet])[0][1]
    out, _ = occ.cut([(3, body)], [(3, solid.cavity)])
    occ.synchronize()
    return out[0][1], solid.cavity_box


def _classify_surfaces(design: Design, cavity_box: tuple[float, ...]) -> dict[str, list[int]]:
    import gmsh

    tol = 1e-6
    groups: dict[str, list[int]] = {"base": [], "cavity": [], "outer": []}
    groups.update({f"magnet{i}": [] for i in range(len(design.magnets))})
    for _, tag in gmsh.model.getEntities(2):
        x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, tag)
        if z1 < tol:
            groups["base"].append(tag)
            continue
        for i, magnet in enumerate(design.magnets):
            cx, cy, cz = magnet.center
            r, hh = magnet.diameter / 2 + tol, magnet.height / 2 + tol
            if cx - r <= x0 and x1 <= cx + r and cy - r <= y0 and y1 <= cy + r and cz - hh <= z0 and z1 <= cz + hh:
                groups[f"magnet{i}"].append(tag)
                break
        else:
            bx0, by0, bz0, bx1, by1, bz1 = cavity_box
            inside = bx0 - tol <= x0 and x1 <= bx1 + tol and by0 - tol <= y0 and y1 <= by1 + tol and z1 <= bz1 + tol
            groups["cavity" if inside else "outer"].append(tag)
    empty = [name for name, tags in groups.items() if not tags]
    if empty:
        raise RuntimeError(f"meshing {design.name}: no surface classified as {empty[0]}")
    return groups


def _positive_orientation(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Order every tetrahedron's vertices so its signed volume is positive."""
    a, b, c, d = (points[tets[i]] for i in range(4))
    volume = np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a)
    flipped = volume < 0
    tets = tets.copy()
    tets[[1, 2]] = np.where(flipped, tets[[2, 1]], tets[[1, 2]])
    return tets
