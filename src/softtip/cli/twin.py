"""``softtip designs`` and ``softtip simulate``: the shipped designs, one load case on the twin."""

from __future__ import annotations

import json
import math
from enum import Enum
from pathlib import Path

import typer
from rich.table import Table

from softtip import __version__
from softtip._core.files import atomic_write
from softtip._core.units import MM, UT_PER_T
from softtip.cli.common import check_number, check_outputs, console, fail, progress_for
from softtip._core.systems import default


class IndenterKind(str, Enum):
    board = "board"
    plate = "plate"
    sphere = "sphere"


class Friction(str, Enum):
    none = "none"
    stick = "stick"


class Model(str, Enum):
    linear = "linear"
    neo_hookean = "neo-hookean"


class Switch(str, Enum):
    on = "on"
    off = "off"



LARGEST_MM = 1000.0  # a metre: beyond any fingertip and indenter
MAX_AMBIENT_UT = 1e5  # 0.1 T: far beyond any ambient field (the Earth's is about 50 µT)
# Estimated tetrahedra the twin meshes without --force: five times the default 1 mm mesh of the simulate
# command's reference design (estimated 37,500; gmsh makes 16,000, whose contact solve took 40 s on a
# loaded 2-core machine).
MAX_ELEMENTS = 200_000


def designs(json_output: bool = typer.Option(False, "--json", help="Print JSON.")) -> None:
    """List the shipped fingertip designs."""
    from softtip.design.model import load_design, shipped_designs

    rows = [{"name": name, "kind": (d := load_design(name)).kind, "description": d.spec.get("description", ""),
             "magnets": len(d.magnets), "sensors": len(d.sensor_positions)} for name in shipped_designs()]
    if json_output:
        print(json.dumps(rows, indent=2))
        return
    table = Table(title="shipped designs")
    for column in ("name", "kind", "magnets", "sensors", "description"):
        table.add_column(column)
    for row in rows:
        table.add_row(*(str(row[c]) for c in ("name", "kind", "magnets", "sensors", "description")))
    console.print(table)


def simulate(
    design: str = typer.Option(default("simulate"), help="Shipped design name or path to a design TOML file."),
    indenter: IndenterKind = typer.Option(IndenterKind.board, help="Rigid indenter."),
    depth: float = typer.Option(1.0, help="Normal travel after first touch (mm)."),
    angle: float = typer.Option(0.0, help="Board angle about the vertical axis (degrees)."),
    thickness: float = typer.Option(1.6, help="Board thickness (mm)."),
    radius: float = typer.Option(5.0, help="Sphere radius (mm)."),
    shear_x: float = typer.Option(0.0, "--shear-x", help="Tangential travel along x after the push (mm)."),
    shear_y: float = typer.Option(0.0, "--shear-y", help="Tangential travel along y after the push (mm)."),
    x: float = typer.Option(0.0, help="Contact position x on the fingertip (mm)."),
    y: float = typer.Option(0.0, help="Contact position y on the fingertip (mm)."),
    friction: Friction = typer.Option(Friction.stick, help="Contact friction: none, or stick (no slip)."),
    model: Model = typer.Option(Model.linear, help="Linear elasticity (fast) or neo-Hookean (large deformation)."),
    mesh_size: float = typer.Option(1.0, "--mesh-size", help="Largest element edge (mm)."),
    noise: Switch = typer.Option(Switch.on, help="Sensor noise and quantisation (off: the exact field)."),
    ambient: tuple[float, float, float] = typer.Option((0.0, 0.0, 0.0), help="Uniform ambient field x y z (µT)."),
    seed: int = typer.Option(0, help="Seed of the sensor noise."),
    plot: Path = typer.Option(None, help="Save a section of the deformed body to this PNG file."),
    deformed_mesh: Path = typer.Option(None, "--deformed-mesh",
                                       help="Save the mesh and its nodal displacements to this .npz file."),
    force: bool = typer.Option(False, "--force", help="Replace output files that exist; mesh finer than "
                                                      f"{MAX_ELEMENTS:,} estimated tetrahedra."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Run one load case on the physics twin and print magnet poses, sensor readings and force."""
    import numpy as np

    from softtip.design.model import load_design
    from softtip.mechanics.contact import LoadCase
    from softtip.mechanics.indenters import make_indenter
    from softtip.twin import Twin

    for name, value in (("depth", depth), ("thickness", thickness), ("radius", radius), ("mesh-size", mesh_size)):
        if not np.isfinite(value) or value < 0 or (value == 0 and name != "depth"):
            fail(f"--{name} = {value}: expected a positive length in mm")
    check_number(seed, "--seed", minimum=0)
    check_number(mesh_size, "--mesh-size", maximum=LARGEST_MM, unit="mm")
    check_number(angle, "--angle", minimum=-360, maximum=360, unit="degrees")
    for option, value in (("--x", x), ("--y", y), ("--shear-x", shear_x), ("--shear-y", shear_y)):
        check_number(value, option, minimum=-LARGEST_MM, maximum=LARGEST_MM, unit="mm")
    check_number(thickness, "--thickness", maximum=LARGEST_MM, unit="mm")
    check_number(radius, "--radius", maximum=LARGEST_MM, unit="mm")
    for component in ambient:
        check_number(component, "--ambient", minimum=-MAX_AMBIENT_UT, maximum=MAX_AMBIENT_UT, unit="µT")
    if plot is not None and plot.suffix.lower() != ".png":
        fail(f"--plot {plot}: expected a file name ending in .png")
    if deformed_mesh is not None and deformed_mesh.suffix.lower() != ".npz":
        fail(f"--deformed-mesh {deformed_mesh}: expected a file name ending in .npz")
    check_outputs([("--plot", plot), ("--deformed-mesh", deformed_mesh)],
                  [design] if Path(design).is_file() else [], force=force)
    fingertip = load_design(design)
    if depth >= fingertip.height / MM:
        fail(f"--depth = {depth} mm: deeper than the {fingertip.name} body is tall ({fingertip.height / MM:g} mm)")
    check_mesh_work(fingertip, mesh_size, force)
    twin = Twin.finite_element(fingertip, mesh_size=mesh_size * MM, model=model.value,
                               ambient_field=np.array(ambient) / UT_PER_T)
    load = LoadCase(indenter=make_indenter(indenter.value, thickness=thickness * MM, angle_deg=angle,
                                           radius=radius * MM),
                    depth=depth * MM, tangential=(shear_x * MM, shear_y * MM), position=(x * MM, y * MM),
                    friction=friction.value)
    result = twin.simulate(load, noise=noise is Switch.on, rng=np.random.default_rng(seed),
                           progress=progress_for(json_output))
    report = result_json(result, twin, angle, thickness, radius, mesh_size, noise is Switch.on)
    if plot is not None:
        from softtip.report.section import plot_section

        report["plot"] = str(plot_section(result, twin.engine.mesh, plot))
    if deformed_mesh is not None:
        mesh, contact = twin.engine.mesh, result.solution
        vertices = len(mesh.points)  # quadratic nodes: vertices first, then edge midpoints
        arrays = {"points_m": mesh.points, "tetrahedra": mesh.tets.T, "displacements_m": contact.displacements[:vertices],
                  "quadratic_nodes_m": twin.engine.body.space.nodes,
                  "quadratic_displacements_m": contact.displacements, "contact_nodes": contact.contact_nodes}
        atomic_write(deformed_mesh, lambda handle: np.savez_compressed(handle, **arrays))
        report["deformed_mesh"] = str(deformed_mesh)
    if json_output:
        print(json.dumps(report, indent=2))
    else:
        print_result(report)


def check_mesh_work(design, mesh_size_mm: float, force: bool) -> None:
    """Refuse, before any mesh, a mesh too fine to solve here unless ``force``.

    The element count is estimated as the body's volume (cavity included) over that of a regular
    tetrahedron of edge ``mesh_size`` (a³ / (6 √2)): an upper bound, some 2.3 times gmsh's count."""
    height_mm = design.height / MM
    body = design.spec["body"]
    footprint_mm2 = (math.pi * body["diameter_mm"] ** 2 / 4 if "diameter_mm" in body
                     else body["width_mm"] * body["length_mm"])
    volume_mm3 = footprint_mm2 * height_mm  # the cavity left in: an upper bound of the work
    elements = volume_mm3 / (mesh_size_mm**3 / (6 * math.sqrt(2)))
    if elements > MAX_ELEMENTS and not force:
        fail(f"--mesh-size = {mesh_size_mm} mm: some {elements:.2g} tetrahedra for the {volume_mm3:.3g} mm³ body, "
             f"over the {MAX_ELEMENTS:.0e} solved without --force")


def _mm(vector) -> list[float]:
    return [round(float(v) / MM, 6) for v in vector]


def result_json(result, twin, angle: float, thickness: float, radius: float, mesh_size: float, noise: bool) -> dict:
    design = result.design
    saturated = twin.readout.saturated(result.reading_counts)
    load = result.load
    return {
        "softtip": __version__,
        "design": design.name,
        "model": result.model,
        "load": {"indenter": type(load.indenter).__name__.lower(), "depth_mm": load.depth / MM,
                 "angle_deg": angle, "thickness_mm": thickness, "radius_mm": radius,
                 "tangential_mm": _mm(load.tangential), "position_mm": _mm(load.position),
                 "friction": load.friction},
        "magnets": [
            {"index": i, "position_mm": _mm(result.magnet_positions[i]),
             "rotvec": [round(float(v), 9) for v in result.poses.rotvec[i]],
             "feature_displacement_mm": _mm(result.feature_displacements[i]),
             "dimension_mm": _mm([m.diameter, m.height]),
             "polarization_T": [0.0, 0.0, m.polarization]}
            for i, m in enumerate(design.magnets)],
        "sensors": [
            {"index": j, "position_mm": _mm(design.sensor_positions[j]),
             "dB_uT": [round(float(v), 4) for v in result.reading_change_uT[j]],
             "dB_exact_uT": [round(float(v) * UT_PER_T, 4) for v in result.field_change[j]],
             "counts": [int(c) for c in result.reading_counts[j]], "saturated": bool(saturated[j].any())}
            for j in range(len(design.sensor_positions))],
        "noise": noise,
        "sensor_model": sensor_summary(twin.design.chip_settings),
        "force_N": [round(float(f), 6) for f in result.force],
        "contact": {"nodes": int(len(result.solution.contact_nodes)), "iterations": result.solution.iterations,
                    "factorizations": result.solution.factorizations},
        "mesh": {"size_mm": mesh_size, "tetrahedra": int(twin.engine.mesh.tets.shape[1]),
                 "unknowns": int(twin.engine.body.size)},
        "timings_s": {k: round(v, 4) for k, v in result.timings.items()},
    }


def sensor_summary(chips) -> dict:
    """The design's chips as its registered sensor states them at their settings (None where it does not)."""
    kind, settings = chips.kind, chips.values
    seconds = None if kind.conversion_time is None else kind.conversion_time(settings)
    return {"chip": kind.title or kind.name, "settings": chips.to_dict(),
            "lsb_uT": [float(v) for v in kind.step(settings)],
            "noise_rms_uT": None if kind.noise is None else [float(v) for v in kind.noise(settings)],
            "conversion_time_ms": None if seconds is None else seconds * 1e3,
            "max_rate_hz": None if seconds is None else 1.0 / seconds}


def print_result(report: dict) -> None:
    load = report["load"]
    console.print(f"[bold]{report['design']}[/] — {load['indenter']} {load['depth_mm']:.3g} mm, "
                  f"angle {load['angle_deg']:g}°, friction {load['friction']}, {report['model']} model")
    magnets = Table(title="magnets after loading")
    for column in ("#", "position (mm)", "feature displacement (mm)", "rotation vector (mrad)"):
        magnets.add_column(column, justify="right")
    for m in report["magnets"]:
        magnets.add_row(str(m["index"]), _fmt(m["position_mm"], 3), _fmt(m["feature_displacement_mm"], 4),
                        _fmt([v * 1e3 for v in m["rotvec"]], 2))
    console.print(magnets)
    sensors = Table(title="Hall sensors (change from the unloaded state)")
    for column in ("#", "position (mm)", "ΔB reading (µT)", "ΔB exact (µT)", "saturated"):
        sensors.add_column(column, justify="right")
    for s in report["sensors"]:
        sensors.add_row(str(s["index"]), _fmt(s["position_mm"], 2), _fmt(s["dB_uT"], 1), _fmt(s["dB_exact_uT"], 2),
                        "yes" if s["saturated"] else "no")
    console.print(sensors)
    force = report["force_N"]
    console.print(f"force on the indenter (N): Fx {force[0]:.4f}  Fy {force[1]:.4f}  Fz {force[2]:.4f}")
    console.print("timings (s): " + ", ".join(f"{k} {v:.3g}" for k, v in report["timings_s"].items()))
    chip = report["sensor_model"]
    noise = "not stated" if chip["noise_rms_uT"] is None else f"{_fmt(chip['noise_rms_uT'], 2)} µT RMS"
    timing = ("" if chip["conversion_time_ms"] is None else
              f", {chip['conversion_time_ms']:.2f} ms per reading (≤ {chip['max_rate_hz']:.0f} Hz)")
    console.print(f"{chip['chip']}: LSB {_fmt(chip['lsb_uT'], 3)} µT, noise {noise}{timing}")
    for key, label in (("plot", "section plot"), ("deformed_mesh", "deformed mesh")):
        if key in report:
            console.print(f"{label}: {report[key]}")


def _fmt(values, digits: int) -> str:
    return "  ".join(f"{v:+.{digits}f}" for v in values)

