"""S4's command: ``softtip bench cilia``."""

from __future__ import annotations

import json
import math
from pathlib import Path

import typer

from softtip.cli.common import check_output, console, fail, progress_for


MAX_FORCE_MN = 1000.0


def bench_cilia(
    loads: int = typer.Option(50, "--loads", help="Load steps of the timed force-voltage curve."),
    force_max_mn: float = typer.Option(26.0, "--force-max-mn", help="Largest total force on the die (mN)."),
    repeats: int = typer.Option(3, "--repeats", help="Runs of each timing; the fastest counts."),
    die: Path = typer.Option(None, "--die", help="Die file (default: the shipped, declared layout)."),
    fe: bool = typer.Option(False, "--fe", help="Also time the FE reference curve (3-D neo-Hookean pillar, field, readout; a minute or two)."),
    fe_loads: int = typer.Option(6, "--fe-loads", help="Load steps of the FE reference curve."),
    save: Path = typer.Option(None, "--save", help="Also write the report as JSON to this file."),
    force: bool = typer.Option(False, "--force", help="Overwrite --save's file."),
    seed: int = typer.Option(0, "--seed", help="Seed of the measured curve the fit is timed on."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Time one force-voltage curve (rod + dipole field + readout) beside a plain loop of the same rod
    solves, one fit of moment and diameter beside scipy's least_squares on a two-parameter model of the
    same size, and optionally the FE reference curve beside the rod's curve of the same loads."""
    if not 5 <= loads <= 2000:
        fail(f"--loads = {loads}: expected 5 to 2000 load steps")
    if not (math.isfinite(force_max_mn) and 0 < force_max_mn <= MAX_FORCE_MN):
        fail(f"--force-max-mn = {force_max_mn}: expected a force above 0 and at most {MAX_FORCE_MN:g} mN (past a few "
             "tens of mN the pillars lie on their sides)")
    if seed < 0:
        fail(f"--seed = {seed}: expected an integer >= 0")
    if not 1 <= repeats <= 100:
        fail(f"--repeats = {repeats}: expected 1 to 100")
    if not 2 <= fe_loads <= 50:
        fail(f"--fe-loads = {fe_loads}: expected 2 to 50 load steps")
    if save is not None:
        save = check_output(save, "--save", inputs=[die] if die else (), force=force)
    # the options are checked before the model's modules load (they take seconds on a busy machine)
    from softtip.systems.cilia.benchmark import bench_cilia as run
    from softtip.systems.cilia.layout import read_die

    if die is not None:
        read_die(die)  # a die file that cannot be built is refused before any timing
    report = run(loads, force_max_mn * 1e-3, repeats, die, fe, fe_loads, seed, progress_for(json_output))
    if save is not None:
        save.write_text(json.dumps(report, indent=2), encoding="utf-8")
    if json_output:
        print(json.dumps(report, indent=2))
        return
    for name, figures in report["timings"].items():
        console.print(f"{name:44s} {figures['seconds']:8.3f} s   baseline {figures['baseline']}: "
                      f"{figures['baseline_seconds']:8.3f} s   ratio {figures['ratio']:6.2f}   "
                      f"target {figures['target_seconds'] if figures['target_seconds'] else '-'} s")
    for note in report["notes"]:
        console.print(note)
