"""S4's commands: ``softtip bench cilia``, ``softtip cilia design`` and ``softtip cilia roughness``."""

from __future__ import annotations

import json
import math
from pathlib import Path

import typer

from softtip._core.files import atomic_write, save_figure
from softtip.cli.common import check_output, check_outputs, console, fail, progress_for


MAX_FORCE_MN = 1000.0
MAX_RANGE_MN = 200.0  # beyond, every pillar of the design space lies flat long before
COARSE = {"steps": 3, "budget": 8, "points": 13}  # --coarse: a smoke run of the search

app = typer.Typer(help="S4: the GMR cilia force sensor.", no_args_is_help=True)


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
        atomic_write(save, json.dumps(report, indent=2))
    if json_output:
        print(json.dumps(report, indent=2))
        return
    for name, figures in report["timings"].items():
        console.print(f"{name:44s} {figures['seconds']:8.3f} s   baseline {figures['baseline']}: "
                      f"{figures['baseline_seconds']:8.3f} s   ratio {figures['ratio']:6.2f}   "
                      f"target {figures['target_seconds'] if figures['target_seconds'] else '-'} s")
    for note in report["notes"]:
        console.print(note)


@app.command("design")
def design_cilia(
    range_mn: list[float] = typer.Option(None, "--range-mn", help="A stated force range, 0 to this (mN); repeat "
                                         "for several. Default: 13, 26 (the published) and 39."),
    steps: int = typer.Option(None, "--steps", help="Values per design parameter (default 5; --coarse 3)."),
    budget: int = typer.Option(None, "--budget", help="Designs evaluated per range (default 30; --coarse 8)."),
    points: int = typer.Option(None, "--points", help="Forces along each design's curve (default 17; --coarse 13)."),
    coarse: bool = typer.Option(False, "--coarse", help="A coarse, fast search: 3 values per parameter, 8 "
                                "evaluations per range, 13 forces per curve (options given still count)."),
    sensor: str = typer.Option("X", "--sensor", help="The sensor read: X or Y."),
    die: Path = typer.Option(None, "--die", help="Die file (default: the shipped, declared layout)."),
    plot: Path = typer.Option(None, "--plot", help="Write the trade-off curve to this image file (.png, .svg, .pdf)."),
    save: Path = typer.Option(None, "--save", help="Also write the result as JSON to this file."),
    force: bool = typer.Option(False, "--force", help="Overwrite --plot's and --save's files."),
    seed: int = typer.Option(0, "--seed", help="Seed of the search."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Search pillar diameter, taper, height, moment, placement and number of pillars on the same die for the
    smallest force resolved over each stated range (the largest 3σ minimum force from 0 to the range), with
    softtip's Bayesian optimiser; print the best designs beside the published one and the trade-off."""
    ranges = tuple(range_mn or ())
    for value in ranges:
        if not (math.isfinite(value) and 0 < value <= MAX_RANGE_MN):
            fail(f"--range-mn = {value}: expected a force above 0 and at most {MAX_RANGE_MN:g} mN")
    chosen = {"steps": steps, "budget": budget, "points": points}
    for option, value, low, high in (("--steps", steps, 2, 9), ("--budget", budget, 1, 500),
                                     ("--points", points, 5, 200)):
        if value is not None and not low <= value <= high:
            fail(f"{option} = {value}: expected an integer from {low} to {high}")
    if sensor not in ("X", "Y"):
        fail(f"--sensor = {sensor!r}: expected X or Y")
    if seed < 0:
        fail(f"--seed = {seed}: expected an integer >= 0")
    inputs = [die] if die else ()
    if plot is not None and plot.suffix.lower() not in (".png", ".svg", ".pdf"):
        fail(f"--plot = {plot}: expected a .png, .svg or .pdf file")
    check_outputs([("--plot", plot), ("--save", save)], inputs, force=force)
    from softtip.systems.cilia.design import search_designs
    from softtip.systems.cilia.layout import read_die
    from softtip.systems.cilia.study import CiliaSettings

    study = CiliaSettings()  # the defaults: the cilia protocol's search
    full = {"steps": study.design_steps, "budget": study.design_budget, "points": study.design_points}
    settings = {key: (value if value is not None else (COARSE if coarse else full)[key]) for key, value in chosen.items()}
    ranges = ranges or study.design_ranges_mN
    layout = read_die(die) if die is not None else read_die()  # a die file that cannot be built is refused here
    found = search_designs(layout, tuple(r * 1e-3 for r in ranges), sensor, settings["steps"], settings["budget"],
                           settings["points"], seed=seed, progress=progress_for(json_output))
    report = found.to_dict()
    if plot is not None:
        save_figure(found.figure, plot, dpi=120)
        report["plot"] = str(plot)
    if save is not None:
        atomic_write(save, json.dumps(report, indent=2))
    if json_output:
        print(json.dumps(report, indent=2))
        return
    console.print(f"{report['candidates']} candidates, refused: "
                  + (", ".join(f"{n} {why}" for why, n in report["refused"].items()) or "none")
                  + f"; {report['evaluated']} evaluated in {report['seconds']:.1f} s")
    for entry in report["ranges"]:
        for who in ("best", "published"):
            design = entry[who]
            if design is None:
                console.print(f"0-{entry['range_mN']:g} mN  {who:9s}  no design with a figure")
                continue
            worst = design["worst_minimum_force_uN"]
            console.print(f"0-{entry['range_mN']:g} mN  {who:9s}  {design['pillars']} pillar(s), tip "
                          f"{design['tip_diameter_um']:g} um, taper {design['taper']:g}, height {design['height_mm']:g} "
                          f"mm, {design['moment_memu']:g} memu: largest minimum force "
                          + ("- (ambiguous)" if worst is None else f"{worst:.1f} uN")
                          + f", at rest {design['minimum_force_at_rest_uN']:.1f} uN")


@app.command("roughness")
def roughness_cilia(
    dataset: Path = typer.Argument(..., help="A dataset (.parquet) with brushing trials: softtip lab run cilia's, or "
                                   "a measured one with the same conditions."),
    speed_mm_s: float = typer.Option(1.0, "--speed-mm-s", help="The stage speed of the level and the rate curve (mm/s)."),
    rate_hz: float = typer.Option(50.0, "--rate-hz", help="The sampling rate of the level and the classifier (/s)."),
    channel: str = typer.Option("gmr_x_V", "--channel", help="The channel read."),
    seed: int = typer.Option(0, "--seed", help="Seed of the classifier."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """The roughness study of a dataset's brushings: the AC rms against the surfaces' roughness (with the flat
    surface's floor removed, and its slope), against the sampling rate, and a classifier of the surfaces
    validated by strip and at a held-out stage speed."""
    for option, value in (("--speed-mm-s", speed_mm_s), ("--rate-hz", rate_hz)):
        if not (math.isfinite(value) and 0 < value <= 1e6):
            fail(f"{option} = {value}: expected a positive number")
    if seed < 0:
        fail(f"--seed = {seed}: expected an integer >= 0")
    from softtip.data import Dataset
    from softtip.systems.cilia.bench import recordings_of
    from softtip.systems.cilia.layout import DieError
    from softtip.systems.cilia.roughness import analyse_roughness

    data = Dataset.read(dataset)
    if channel not in data.channels:
        fail(f"--channel = {channel!r}: expected one of {dataset}'s channels: {', '.join(data.channels)}")
    try:
        recordings = recordings_of(data, channel)
        with progress_for(json_output).task("roughness: the brushings, the classifier"):
            study = analyse_roughness(recordings, speed_mm_s * 1e-3, rate_hz, seed)
    except DieError as problem:  # the dataset holds no study of these settings: say which file
        fail(f"{dataset}: {problem}")
    c = study.classification
    report = {"dataset": str(dataset), "channel": channel, **study.to_dict()}
    if json_output:
        print(json.dumps(report, indent=2))
        return
    for name, roughness, total, above in zip(study.surfaces, report["roughness_um"], report["ac_rms_uV"],
                                             report["above_floor_uV"]):
        console.print(f"{name:10s} {roughness:8.2f} um rms   AC rms {total:9.3f} uV   above the floor {above:9.3f} uV",
                      markup=False)
    console.print(f"slope {report['slope_uV_per_um']:.3f} uV per um, floor {report['floor_uV']:.3f} uV; "
                  f"accuracy {c.by_recording:.3f} by strip, {c.at_held_speed:.3f} at the held-out "
                  f"{report['held_speed_mm_s']:g} mm/s ({c.windows} windows)", markup=False)
