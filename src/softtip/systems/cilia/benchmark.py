"""``softtip bench cilia``: the speeds the S4 issue sets, each beside a baseline measured in the same run.

* one force–voltage curve (rod, dipole chains averaged over every spin valve, readout) of ``loads`` steps,
  beside a plain Python loop of the same rod solves one load at a time (the mechanics alone);
* one fit of moment and diameter to a measured curve of those loads (from cold: no cached fields), beside
  scipy's ``least_squares`` with the same options on a two-parameter saturating model (a·tanh(F/b)) of the
  same number of points;
* optionally the FE reference curve: the 3-D neo-Hookean pillar (:mod:`softtip.mechanics.pillar_fe`) meshed and
  solved under the same loads per pillar, its slices' centre line as the dipole chain, through the same
  field and readout; beside the rod's curve of those loads (both with a bonded base), with their gap.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy import optimize

from softtip._core.progress import SILENT, Progress
from softtip.mechanics.rod import solve_tip_force
from softtip.systems.cilia.fit import fit_curve
from softtip.systems.cilia.layout import SHIPPED_DIE, read_die
from softtip.systems.cilia.model import CiliaModel, chain_dipoles, element_fields
from softtip.systems.cilia.study import measure

# the targets, for an idle machine: each is judged on the CPU time (single-threaded work, so an idle
# run's wall time; on a shared machine the wall time is the load's), the wall time printed beside it
CURVE_TARGET_S, FIT_TARGET_S, FE_TARGET_S = 0.3, 5.0, 120.0
FE_MESH_SIZE = 60e-6  # m: ~8.7k unknowns; about 2.5 % too soft in bending at this size (test_pillar_fe_convergence)
# N per pillar: the largest load step the FE curve takes, the default run's (26 mN in 6 loads of 2 steps, 5
# pillars); Newton from the straight pillar does not converge in 30 iterations at 1.3 mN (2 loads of 2 steps)
FE_STEP_N = 0.45e-3


@dataclass(frozen=True)
class Timing:
    """The fastest of repeated runs (s): by the wall clock and by this process's CPU time."""

    wall: float
    cpu: float


def fastest(run: Callable[[], object], repeats: int) -> Timing:
    """The fastest of ``repeats`` runs of ``run``, by wall clock and by CPU time."""
    walls, cpus = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        run()
        walls.append(time.perf_counter() - start)
        cpus.append(time.process_time() - start_cpu)
    return Timing(min(walls), min(cpus))


def _entry(timed: Timing, baseline: str, baseline_timed: Timing, target: float | None) -> dict:
    return {"seconds": timed.wall, "cpu_seconds": timed.cpu, "baseline": baseline,
            "baseline_seconds": baseline_timed.wall, "baseline_cpu_seconds": baseline_timed.cpu,
            "ratio": timed.cpu / baseline_timed.cpu, "target_seconds": target,
            "meets_target": None if target is None else timed.cpu <= target}


def _fe_curve(model: CiliaModel, force_max: float, loads: int, repeats: int) -> tuple[Timing, Timing, float, int, int]:
    """The FE reference curve of the die's first sensor (mesh, solve, the slices' centre line as the dipole
    chain, the readout) beside the rod's curve of the same loads, both bonded to a rigid base (the rod with the bonded
    root's end effect, :func:`softtip.mechanics.rod.bonded_root_flexibility`); their largest relative gap
    in the voltage change."""
    from softtip.mechanics.pillar_fe import PillarFE

    pillars = model.die.pillars
    rod = replace(pillars.rod, base_stiffness=None)
    bonded = replace(model, die=model.die.with_pillars(replace(pillars, rod=replace(rod, bonded_root=True))))
    forces = np.linspace(force_max / loads, force_max, loads)
    meander = model.die.meanders[0]
    start, start_cpu = time.perf_counter(), time.process_time()
    solid = PillarFE(rod, size=FE_MESH_SIZE, slices=model.chain_count)
    steps = max(2, math.ceil(force_max / loads / model.pillar_count / FE_STEP_N))
    solution = solid.solve(np.concatenate([[0.0], forces / model.pillar_count]), steps_per_force=steps, tolerance=1e-7)
    points, tangents = solid.centreline(solution)
    volts = meander.readout.voltage(element_fields(meander, chain_dipoles(pillars, points, tangents)))
    fe_s = Timing(time.perf_counter() - start, time.process_time() - start_cpu)
    rod_s = fastest(lambda: bonded.curve(forces, meander.name), repeats)
    change = bonded.curve(forces, meander.name).change
    gap = float(np.max(np.abs((volts[1:] - volts[0]) / change - 1)))
    return fe_s, rod_s, gap, solid.unknowns, solution.iterations


def bench_cilia(loads: int, force_max: float, repeats: int, die: Path | None, fe: bool, fe_loads: int, seed: int,
                progress: Progress = SILENT) -> dict:
    """Timings on the die file ``die`` (default: the shipped one); forces in N."""
    model = CiliaModel(read_die(die or SHIPPED_DIE))
    rod, pillars = model.die.pillars.rod, model.pillar_count
    forces = np.linspace(force_max / loads, force_max, loads)
    timings, notes = {}, []
    load = os.getloadavg()
    with progress.task("cilia: curve, fit" + (", FE" if fe else ""), total=3 if fe else 2) as task:
        sensor = model.die.meanders[0].name  # the die file's first sensor
        curve_s = fastest(lambda: model.curve(forces, sensor), repeats)
        loop_s = fastest(lambda: [solve_tip_force(rod, [[f / pillars, 0.0]]) for f in forces], repeats)
        timings[f"force-voltage curve, {loads} loads"] = _entry(
            curve_s, f"a Python loop of the same {loads} rod solves (mechanics only)", loop_s, CURVE_TARGET_S)
        task.advance()
        truth = model.curve(forces, sensor)
        measured = measure(model, truth, 0.01, np.random.default_rng(seed))
        found = {}

        def fit() -> None:
            found["fit"] = fit_curve(model, measured)

        fit_s = fastest(fit, repeats)
        scale = float(np.abs(measured.change).max())

        def baseline() -> None:
            optimize.least_squares(lambda q: np.exp(q[0]) * np.tanh(measured.force / np.exp(q[1])) - measured.change,
                                   np.log([scale, force_max]), method="trf", diff_step=1e-5, xtol=1e-10,
                                   ftol=1e-12, gtol=1e-12, max_nfev=200)

        timings[f"fit of moment and diameter, {loads} points"] = _entry(
            fit_s, f"scipy least_squares, 2-parameter tanh model, {loads} points", fastest(baseline, repeats),
            FIT_TARGET_S)
        notes.append(f"fit: {found['fit'].evaluations} model evaluations; moment "
                     f"{found['fit'].moment / 1e-6:.3f} memu, diameter {found['fit'].diameter / 1e-6:.1f} µm "
                     f"(truth: the die file's)")
        task.advance()
        if fe:
            fe_s, rod_s, gap, unknowns, iterations = _fe_curve(model, force_max, fe_loads, repeats)
            timings[f"FE reference curve (mesh, solve, field, readout), {fe_loads} loads"] = _entry(
                fe_s, f"the rod's curve of the same {fe_loads} loads", rod_s, FE_TARGET_S)
            notes.append(f"FE: {unknowns} unknowns, {iterations} Newton iterations; its voltage changes within "
                         f"{100 * gap:.2f} % of the rod's (both bonded to a rigid base, the rod with the bonded "
                         "root's end effect: the solid has no compliant film here).")
            task.advance()
        else:
            notes.append(f"FE reference curve not timed: pass --fe (a mesh of ~{FE_MESH_SIZE / 1e-6:.0f} µm "
                         "tetrahedra, tens of seconds per load on two cores).")
    return {"die": str(die) if die else "shipped", "sensor": sensor, "loads": loads, "force_max_N": force_max,
            "repeats": repeats, "cpus": os.cpu_count(), "load_average_before": list(load),
            "load_average_after": list(os.getloadavg()), "timings": timings, "notes": notes,
            "all_targets_met": all(t["meets_target"] in (True, None) for t in timings.values())}
