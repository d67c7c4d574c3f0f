"""Benchmarks of the twin, each reported with a baseline measured in the same run."""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

from softtip._core.progress import SILENT, Progress
from softtip._core.units import MM
from softtip.bench.timing import best_of, timed
from softtip.design.model import load_design
from softtip.mechanics.contact import LoadCase
from softtip.mechanics.contact.nodal import penalty_blocks
from softtip.mechanics.indenters import Board
from softtip.mechanics.linsolve import SPDSolver
from softtip.mechanics.mesh import mesh_design
from softtip.mechanics.poses import MagnetPoses
from softtip.twin import Readout, Twin


def bench_twin(design_name: str, mesh_size_mm: float = 1.0, poses: int = 200_000,
               include_neo_hookean: bool = True, log: Callable[[str], None] | None = None) -> dict:
    from threadpoolctl import threadpool_limits

    say = log or (lambda message: None)
    design = load_design(design_name)
    size = mesh_size_mm * MM
    report: dict = {"design": design_name, "mesh_size_mm": mesh_size_mm}
    with threadpool_limits(2):
        mesh, t_cold = timed(mesh_design, design, size, use_cache=False)
        mesh_design(design, size)  # make sure the cache holds it
        t_warm = best_of(lambda: mesh_design(design, size), repeats=20)  # a hit, read and verified
        report["mesh"] = {"cold_s": t_cold, "warm_hit_s": t_warm, "tetrahedra": int(mesh.tets.shape[1])}
        say(f"mesh (cold, no cache): {t_cold:.2f} s, {mesh.tets.shape[1]} tetrahedra; "
            f"from the cache: {1e3 * t_warm:.1f} ms")

        load = LoadCase(Board(1.6e-3, 0.0), 1e-3, friction="stick")
        start = time.perf_counter()
        twin = Twin.finite_element(design, mesh_size=size)
        result = twin.simulate(load, noise=True, rng=np.random.default_rng(0))
        t_push = time.perf_counter() - start
        body = twin.engine.body
        # baseline: one linear solve with the converged contact area prescribed
        nodes = result.solution.contact_nodes
        epsilon = 1e4 * body.stiffness.diagonal()[: body.n_free].mean()
        fixed_area = body.stiffness + penalty_blocks(body, body.node_dofs[nodes],
                                                      epsilon * np.broadcast_to(np.eye(3), (len(nodes), 3, 3)))
        solver = SPDSolver()
        start = time.perf_counter()
        solver.factorize(fixed_area)
        solver.solve(np.ones(body.size))
        t_linear = time.perf_counter() - start
        t_contact = result.timings["contact_solve_s"]
        report["board_push_1mm"] = {
            "total_s_mesh_cached": t_push, "unknowns": int(body.size), "contact_nodes": int(len(nodes)),
            "contact_solve_s": t_contact, "fixed_area_linear_solve_s": t_linear,
            "contact_over_linear": t_contact / t_linear, "factorizations": result.solution.factorizations,
            "feature_dz_mm": [float(v) for v in result.feature_displacements[:, 2] / MM],
            "force_N": [float(v) for v in result.force], "timings_s": result.timings}
        say(f"1 mm board push (stick), mesh cached: {t_push:.2f} s total; contact solve {t_contact:.2f} s = "
            f"{t_contact / t_linear:.2f} x one fixed-area linear solve ({t_linear:.2f} s); "
            f"{result.solution.factorizations} factorisation(s)")

        if include_neo_hookean:
            deep = LoadCase(Board(1.6e-3, 0.0), 3e-3, friction="stick")
            neo, t_neo = timed(twin.simulate, deep, model="neo-hookean", noise=False)
            report["neo_hookean_push_3mm"] = {"total_s": t_neo, "newton_iterations": neo.solution.iterations,
                                              "factorizations": neo.solution.factorizations,
                                              "force_N": [float(v) for v in neo.force],
                                              "feature_dz_mm": [float(v) for v in neo.feature_displacements[:, 2] / MM]}
            say(f"neo-Hookean 3 mm board push: {t_neo:.1f} s, {neo.solution.iterations} Newton iterations")

        report["magnetics_sensor"] = _bench_readings(twin.readout, poses, say)
    return report


def _bench_readings(readout: Readout, poses: int, say) -> dict:
    """Readings per second through the exact field and the sensor model, against magpylib."""
    import magpylib
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(1)
    rest = readout.rest_positions
    moved = MagnetPoses(rng.uniform(-0.5e-3, 0.5e-3, (poses, len(rest), 3)), rng.uniform(-0.1, 0.1, (poses, len(rest), 3)))
    positions, rotvecs = rest + moved.translation, moved.rotvec
    readout.readings(MagnetPoses(moved.translation[:100], moved.rotvec[:100]))  # warm-up
    _, t_ours = timed(readout.readings, moved, noise=True, rng=rng)
    sensors = readout.design.sensor_positions
    readings = poses * len(sensors)
    # baseline: magpylib's vectorised path API on a sub-batch, field only (no sensor model)
    sub = min(poses, 20_000)
    magnets = [magpylib.magnet.Cylinder(polarization=(0, 0, m.polarization), dimension=(m.diameter, m.height),
                                        position=positions[:sub, i], orientation=Rotation.from_rotvec(rotvecs[:sub, i]))
               for i, m in enumerate(readout.design.magnets)]
    _, t_magpy = timed(magpylib.getB, magnets, sensors, sumup=True)
    ours = readings / t_ours
    theirs = sub * len(sensors) / t_magpy
    say(f"magnetics + sensor: {ours:,.0f} readings/s ({poses} poses x {len(sensors)} sensor(s), "
        f"{len(rest)} magnets); magpylib field alone: {theirs:,.0f} readings/s; ratio {ours / theirs:.1f}x")
    return {"poses": poses, "readings_per_s": ours, "magpylib_readings_per_s": theirs,
            "speedup_vs_magpylib": ours / theirs}


def bench_rom(design_name: str, samples: int | None = None, holdout: int = 12, batch: int = 200_000,
              save: str | None = None, contact_layer_mm: float | None = None, friction: str = "stick",
              log: Callable[[str], None] | None = None, progress: Progress = SILENT) -> dict:
    """Build a reduced-order twin (timed), report its held-out errors and its batch speed,
    against the FE seconds per load measured on the held-out solves of the same run; ``samples``
    defaults to the twin's own."""
    from softtip.twin.reduced import SAMPLES, IndenterFamily, ReducedTwin

    say = log or (lambda message: None)
    samples = SAMPLES if samples is None else samples
    rom, t_build = timed(ReducedTwin.build, load_design(design_name), IndenterFamily(friction=friction),
                         samples=samples, holdout=holdout,
                         contact_layer_size=None if contact_layer_mm is None else contact_layer_mm * MM,
                         progress=progress)
    fe_report, exact_report = rom.report["holdout"], rom.report["exact_holdout"]
    params = rom.ranges.sample(np.random.default_rng(7), batch)
    twin = Twin(rom)
    twin.readings(params[:100])  # warm-up
    _, t_batch = timed(twin.readings, params, noise=True, rng=np.random.default_rng(8))
    per_second = batch / t_batch
    fe_seconds = fe_report["fe_seconds_per_load"]
    report = {"design": design_name, "contact_layer_mm": contact_layer_mm, "friction": friction,
              "build_s": rom.report["timings_s"]["build_s"], "build_and_holdout_s": t_build,
              "timings_s": rom.report["timings_s"], "full_scale": rom.report["full_scale"],
              "domain": rom.report["domain"], "held_share": rom.report["held_share"],
              "holdout": fe_report, "exact_holdout": exact_report,
              "exact_sliding_loads": rom.report.get("exact_sliding_loads"), "readings_per_s": per_second,
              "fe_seconds_per_load": fe_seconds, "speedup_vs_fe": per_second * fe_seconds}
    if save:
        report["saved"] = str(rom.save(save))

    def axes(values: list) -> str:
        return ", ".join(f"{e:.2f}" for e in np.ravel(values))

    say(f"reduced twin of {design_name}: built in {report['build_s']:.0f} s ({samples} exact contact samples)")
    say(f"  domain: {report['domain']} ({report['held_share']:.0%} of the loads drawn)")
    sliding = report["exact_sliding_loads"]
    for name, errors in ((f"{fe_report['loads']} held-out FE solves", fe_report),
                         (f"{exact_report['loads']} held-out exact solves", exact_report),
                         *([(f"{sliding['loads']} loads outside the domain (the board slides)", sliding)]
                           if sliding else [])):
        say(f"{name}: sensor axes max {axes(errors['sensor_error_percent_fs'])} % FS "
            f"(p99 {axes(errors['sensor_error_p99_percent_fs'])}); magnet displacements max "
            f"{np.max(errors['magnet_displacement_error_percent_range']):.2f} % of range "
            f"(p99 {np.max(errors['magnet_displacement_error_p99_percent_range']):.2f})")
    say(f"  full scale over the load ranges: sensor axes {axes(report['full_scale']['sensor_uT'])} µT")
    say(f"batch readings: {per_second:,.0f} per second; FE {fe_seconds:.2f} s per load; "
        f"speed-up {report['speedup_vs_fe']:,.0f}x")
    return report
