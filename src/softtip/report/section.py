"""A vertical section through the deformed fingertip, with its magnets and the indenter."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from softtip._core.files import save_figure
from softtip._core.units import MM
from softtip.mechanics.indenters import Board, Sphere


def section_polygons(points: np.ndarray, tets: np.ndarray, origin: np.ndarray, normal: np.ndarray):
    """Intersections of the tetrahedra with a plane: a list of (k, 3) polygons (k = 3 or 4)
    and, for each, the barycentric weights of its corners over the cut edges' end points."""
    distance = (points - origin) @ normal
    d = distance[tets.T]  # (nt, 4)
    crossing = np.flatnonzero((d.min(axis=1) < 0) & (d.max(axis=1) > 0))
    edges = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    polygons = []
    for t in crossing:
        corners = []
        for a, b in edges:
            da, db = d[t, a], d[t, b]
            if (da < 0) != (db < 0):
                s = da / (da - db)
                corners.append((tets[a, t], tets[b, t], s))
        polygons.append(corners)
    return polygons


def plot_section(result, mesh, path: str | Path) -> Path:
    """Draw the deformed section of ``result`` (a finite-element twin result on ``mesh``) across the
    indenter, coloured by |u|."""
    from matplotlib.figure import Figure as PlotFigure
    from matplotlib.patches import Circle
    from matplotlib.collections import PolyCollection

    contact = result.solution
    design = result.design
    indenter = result.load.indenter
    angle = indenter.angle if isinstance(indenter, Board) else 0.0
    # the section plane contains the vertical axis and is perpendicular to a board's length
    across = np.array([-math.sin(angle), math.cos(angle), 0.0])
    along = np.array([math.cos(angle), math.sin(angle), 0.0])
    origin = np.array([*result.load.position, 0.0])
    mesh_points = mesh.points
    vertex_u = contact.displacements[: len(mesh_points)]  # P2 vertex nodes come first
    polygons, colours = [], []
    for corners in section_polygons(mesh_points, mesh.tets, origin, along):
        xyz = []
        mags = []
        for a, b, s in corners:
            p = (1 - s) * mesh_points[a] + s * mesh_points[b]
            u = (1 - s) * vertex_u[a] + s * vertex_u[b]
            xyz.append(p + u)
            mags.append(np.linalg.norm(u))
        xyz = np.array(xyz)
        h = (xyz - origin) @ across
        centre = np.array([h.mean(), xyz[:, 2].mean()])
        order = np.argsort(np.arctan2(xyz[:, 2] - centre[1], h - centre[0]))
        polygons.append(np.column_stack([h[order], xyz[order, 2]]) / MM)
        colours.append(np.mean(mags) / MM)
    fig = PlotFigure(figsize=(8, 4.2))
    ax = fig.subplots()
    collection = PolyCollection(polygons, array=np.array(colours), cmap="viridis", edgecolors="face", linewidths=0.2)
    ax.add_collection(collection)
    fig.colorbar(collection, ax=ax, label="|u| (mm)")
    for m, position, rotvec in zip(design.magnets, result.magnet_positions, result.poses.rotvec):
        offset = (position - origin) @ along
        if abs(offset) > m.diameter:  # only magnets the section cuts
            continue
        h0 = (position - origin) @ across
        tilt = rotvec @ along  # (across, z, along) is right-handed: counter-clockwise in the plot
        corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * [m.diameter / 2, m.height / 2]
        c, s = math.cos(tilt), math.sin(tilt)
        rotated = corners @ np.array([[c, s], [-s, c]])
        ax.fill(*((rotated + [h0, position[2]]) / MM).T, color="firebrick", alpha=0.85, zorder=3)
    frame_z = design.height - result.load.depth
    if isinstance(indenter, Board):
        t = indenter.thickness / 2
        ax.fill(np.array([-t, t, t, -t]) / MM, np.array([frame_z, frame_z, frame_z + 3 * MM, frame_z + 3 * MM]) / MM,
                color="0.6", zorder=4)
    elif isinstance(indenter, Sphere):
        ax.add_patch(Circle((0, (frame_z + indenter.radius) / MM), indenter.radius / MM, color="0.6", zorder=4))
    else:
        ax.axhspan(frame_z / MM, frame_z / MM + 1.5, color="0.6", zorder=4)
    for position in design.sensor_positions:
        ax.plot((position - origin) @ across / MM, position[2] / MM, "ks", ms=6, zorder=5)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("across the indenter (mm)")
    ax.set_ylabel("z (mm)")
    ax.set_title(f"{design.name}: {type(indenter).__name__.lower()} {result.load.depth / MM:.2f} mm, "
                 f"{result.model}; Fz = {result.force[2]:.3f} N")
    fig.tight_layout()
    return save_figure(fig, path, dpi=150)
