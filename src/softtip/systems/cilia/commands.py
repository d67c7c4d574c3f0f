"""S4's commands: ``softtip bench cilia``, ``softtip cilia design`` and ``softtip cilia roughness``."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from softtip._core.files import atomic_write, save_figure
from softtip.cli.common import check_input, check_output, check_outputs, console, fail, progress_for

if TYPE_CHECKING:
    from softtip.systems.cilia.roughness import Recording


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
    seed: int = typer.Option(1, "--seed", help="Seed of the measured curve the fit is timed on."),
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
    from softtip.systems.cilia.layout import read_die

    if die is not None:
        read_die(die)  # a die file that cannot be built is refused before any timing, and the timed modules load
    from softtip.systems.cilia.benchmark import bench_cilia as run

    report = run(loads, force_max_mn * 1e-3, repeats, die, fe, fe_loads, seed, progress_for(json_output))
    if save is not None:
        atomic_write(save, json.dumps(report, indent=2))
    if json_output:
        print(json.dumps(report, indent=2))
        return
    missed = []
    load = ", ".join(f"{value:.1f}" for value in report["load_average_before"])
    console.print(f"load average before the timings (1, 5, 15 min): {load}; each figure the fastest of "
                  f"{report['repeats']} runs", markup=False, soft_wrap=True)
    for name, figures in report["timings"].items():
        target = figures["target_seconds"]
        verdict = "no target" if target is None else f"target {target:g} s of CPU, idle: " + (
            "met" if figures["meets_target"] else "MISSED")
        if figures["meets_target"] is False:
            missed.append(name)
        what = name.split(" (")[0].split(",")[0]  # the figure's name without its details
        console.print(f"{name}: {figures['cpu_seconds']:.3f} s of CPU, {figures['seconds']:.3f} s wall ({verdict})",
                      markup=False, soft_wrap=True)
        console.print(f"  baseline, {figures['baseline']}: {figures['baseline_cpu_seconds']:.3f} s of CPU; the {what} "
                      f"takes {figures['ratio']:.3g} times the baseline's CPU time", markup=False, soft_wrap=True)
    for note in report["notes"]:
        console.print(note, markup=False)
    console.print("verdict: " + ("every target met" if not missed else
                                 f"{len(missed)} of {len(report['timings'])} targets missed: {'; '.join(missed)}"),
                  markup=False, soft_wrap=True)  # one line, however narrow the terminal: its last line is the verdict


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
    seed: int = typer.Option(1, "--seed", help="Seed of the search (1: the one softtip reproduce cilia uses)."),
    descend: bool = typer.Option(False, "--descend", help="After each range's search, descend on the grid to a "
                                 "local minimum (no neighbour better; about twice the evaluations)."),
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
    from softtip.systems.cilia.layout import read_die

    # a die file that cannot be built is refused here, before the search's modules load
    layout = read_die(die) if die is not None else read_die()
    from softtip.systems.cilia.design import search_designs
    from softtip.systems.cilia.study import CiliaSettings

    study = CiliaSettings()  # the defaults: the cilia protocol's search
    full = {"steps": study.design_steps, "budget": study.design_budget, "points": study.design_points}
    settings = {key: (value if value is not None else (COARSE if coarse else full)[key]) for key, value in chosen.items()}
    ranges = ranges or study.design_ranges_mN
    found = search_designs(layout, tuple(r * 1e-3 for r in ranges), sensor, settings["steps"], settings["budget"],
                           settings["points"], seed=seed, progress=progress_for(json_output), descend=descend)
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
        console.print(f"0-{entry['range_mN']:g} mN  verdict: the best design found "
                      + ("beats the published one" if entry["beats_published"] else
                         f"does NOT beat the published one (its search: {entry['evaluations']} evaluations"
                         + (f", then {entry['descent_evaluations']} in its descent to a local minimum of the grid)"
                            if descend else ")")))


@app.command("fit")
def fit_cilia(
    curve: Path = typer.Argument(..., help="A measured force-voltage curve: a CSV table with a force and a voltage "
                                 "column, or a dataset (.parquet, e.g. softtip import's) with a force label and a "
                                 "voltage channel."),
    force_column: str = typer.Option("force_N", "--force-column", help="The force column (a dataset's label)."),
    force_unit: str = typer.Option(None, "--force-unit", help="A CSV's force unit: N (default), mN or g (a balance's "
                                   "reading, times standard gravity); a dataset declares its own."),
    voltage_column: str = typer.Option("voltage_V", "--voltage-column", help="The voltage column (a dataset's "
                                       "channel; V): the change from the unloaded reading, or with --tare the "
                                       "sensor's voltage."),
    trial: int = typer.Option(None, "--trial", help="A dataset's trial holding the curve (needed when it has several)."),
    tare: bool = typer.Option(False, "--tare", help="Subtract the mean voltage of the rows at zero force."),
    sensor: str = typer.Option("X", "--sensor", help="The sensor the curve was read from."),
    die: Path = typer.Option(None, "--die", help="Die file (default: the shipped, declared layout): the pillars' "
                             "height, modulus, taper and base, the layout and the readout."),
    plot: Path = typer.Option(None, "--plot", help="Write the curve and both fits to this image file (.png, .svg, .pdf)."),
    force: bool = typer.Option(False, "--force", help="Overwrite --plot's file."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Fit the pillars' moment and diameter to a measured curve with both models: the publication's (uniform
    cylinders clamped to the die, loaded at the tip, height and modulus held) and softtip's (the die file's
    tapered pillars on their base), each with 95 % intervals (Student's t), the parameters' correlation and
    the residuals' rms."""
    table = curve.suffix.lower() == ".csv"
    if not table and curve.suffix.lower() != ".parquet":
        fail(f"curve = {curve}: expected a CSV table (.csv) or a dataset (.parquet)")
    check_input(curve, "curve")
    if die is not None:
        from softtip.systems.cilia.layout import read_die

        read_die(die)  # a die file that cannot be built is refused before the fit's modules load
    from softtip.systems.cilia.bench import FORCE_UNITS

    if force_unit is not None and (not table or force_unit not in FORCE_UNITS):
        fail(f"--force-unit = {force_unit!r}: " + (f"expected one of {', '.join(FORCE_UNITS)}" if table else
                                                   "a dataset declares its labels' units; give it for a CSV only"))
    if trial is not None and (table or trial < 0):
        fail(f"--trial = {trial}: " + ("a CSV table is one curve; give it for a dataset only" if table else
                                       "expected a trial number >= 0"))
    if sensor not in ("X", "Y"):
        fail(f"--sensor = {sensor!r}: expected X or Y")
    if plot is not None:
        if plot.suffix.lower() not in (".png", ".svg", ".pdf"):
            fail(f"--plot = {plot}: expected a .png, .svg or .pdf file")
        plot = check_output(plot, "--plot", inputs=[curve, *([die] if die else [])], force=force)
    from softtip.systems.cilia.bench import curve_from_csv, curve_from_dataset
    from softtip.systems.cilia.measured import fit_both

    if table:
        measured = curve_from_csv(curve, force_column, voltage_column, force_unit or "N", sensor, tare)
    else:
        from softtip.data import Dataset

        measured = curve_from_dataset(curve, Dataset.read(curve), force_column, voltage_column, sensor, tare, trial)
    found = fit_both(die, measured, progress_for(json_output))
    report = {"curve": str(curve), "sensor": sensor, "points": int(measured.force.size), **found.to_dict()}
    if plot is not None:
        save_figure(found.figure(), plot, dpi=120)
        report["plot"] = str(plot)
    if json_output:
        print(json.dumps(report, indent=2))
        return
    for name, entry in report["fits"].items():
        console.print(f"{name}: moment {entry['moment_memu']:.3g} memu ({entry['moment_interval_memu'][0]:.3g}-"
                      f"{entry['moment_interval_memu'][1]:.3g}), diameter {entry['diameter_um']:.1f} um "
                      f"({entry['diameter_interval_um'][0]:.1f}-{entry['diameter_interval_um'][1]:.1f}), correlation "
                      f"{entry['correlation']:+.3f}, residual rms {entry['residual_rms_uV']:.3g} uV"
                      + ("; a parameter ended on its bound: the curve does not hold it" if entry["at_bound"] else ""),
                      markup=False)


@app.command("roughness")
def roughness_cilia(
    data: Path = typer.Argument(..., help="Brushings: a dataset (.parquet: softtip lab run cilia's, or a measured one "
                                "with the same conditions) or a CSV table, one row per reading, with the columns "
                                "surface, roughness_um, speed_mm_s, rate_hz, the --channel and optionally strip."),
    speed_mm_s: float = typer.Option(None, "--speed-mm-s", help="The stage speed of the level and the rate curve "
                                     "(mm/s; default: the speed and rate brushed most often)."),
    rate_hz: float = typer.Option(None, "--rate-hz", help="The sampling rate of the level, the speed curve and the "
                                  "classifier (/s; default: the rate brushed most often at the speed)."),
    channel: str = typer.Option("gmr_x_V", "--channel", help="The channel (column) read, V."),
    seed: int = typer.Option(1, "--seed", help="Seed of the classifier."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """The roughness study of brushings at any number of speeds, rates, strips and surfaces (one flat): the AC
    rms (less its linear trend) against the surfaces' roughness, its slope fitted as published (a line with
    intercept) and through the origin above the flat surface's floor, each with 95 % intervals; the AC rms
    against the sampling rate and the stage speed; and a classifier of the surfaces, validated by strip and
    at a held-out speed where the recordings allow it (the report says which could not be)."""
    for option, value in (("--speed-mm-s", speed_mm_s), ("--rate-hz", rate_hz)):
        if value is not None and not (math.isfinite(value) and 0 < value <= 1e6):
            fail(f"{option} = {value}: expected a positive number")
    if seed < 0:
        fail(f"--seed = {seed}: expected an integer >= 0")
    if data.suffix.lower() not in (".parquet", ".csv"):
        fail(f"data = {data}: expected a dataset (.parquet) or a CSV table (.csv)")
    check_input(data, "data")
    from softtip.systems.cilia.bench import recordings_from_csv, recordings_of
    from softtip.systems.cilia.layout import DieError
    from softtip.systems.cilia.roughness import analyse_roughness

    try:
        if data.suffix.lower() == ".csv":
            recordings = recordings_from_csv(data, channel)
        else:
            from softtip.data import Dataset

            dataset = Dataset.read(data)
            if channel not in dataset.channels:
                fail(f"--channel = {channel!r}: expected one of {data}'s channels: {', '.join(dataset.channels)}")
            recordings = recordings_of(dataset, channel)
        speed, rate = _most_brushed(recordings, None if speed_mm_s is None else speed_mm_s * 1e-3, rate_hz)
        with progress_for(json_output).task("roughness: the brushings, the classifier"):
            study = analyse_roughness(recordings, speed, rate, seed)
    except DieError as problem:  # the file holds no study of these settings: say which file
        fail(f"{data}: {problem}")
    report = {"data": str(data), "channel": channel, "speed_mm_s": speed * 1e3, "rate_hz": rate, **study.to_dict()}
    if json_output:
        print(json.dumps(report, indent=2))
        return
    console.print(f"{report['recordings']} recordings; level at {speed * 1e3:g} mm/s and {rate:g} readings/s",
                  markup=False)
    for name, roughness, total, above in zip(study.surfaces, report["roughness_um"], report["ac_rms_uV"],
                                             report["above_floor_uV"]):
        console.print(f"{name:10s} {roughness:8.2f} um rms   AC rms {total:9.3f} uV   above the floor {above:9.3f} uV",
                      markup=False)
    for label, fit in (("slope, a line with intercept (as published)", report["slope_as_published_uV_per_um"]),
                       ("slope through the origin, above the floor", report["slope_through_origin_uV_per_um"])):
        if fit is None:
            console.print(f"{label}: - (needs the flat surface and two rough ones)", markup=False)
        else:
            low, high = fit["slope_interval"]
            console.print(f"{label}: {fit['slope']:.3f} uV per um (95 %: {low:.3f} to {high:.3f}, "
                          f"{fit['degrees_of_freedom']} degrees of freedom)", markup=False)
    c = study.classification
    if c is None:
        console.print(f"classifier: not trained ({study.unclassified})", markup=False)
        return
    shown = [f"{c.by_strip:.3f} by strip" if c.by_strip is not None else "",
             f"{c.at_held_speed:.3f} at the held-out {c.held_speed * 1e3:g} mm/s" if c.at_held_speed is not None else ""]
    console.print(f"classifier accuracy: {', '.join(v for v in shown if v)} ({c.windows} windows; chance "
                  f"{1 / len(c.surfaces):.2f})" + (f"; not validated {'; '.join(c.missing)}" if c.missing else ""),
                  markup=False)


def _most_brushed(recordings: list[Recording], speed: float | None, rate: float | None) -> tuple[float, float]:
    """The (speed m/s, rate /s) of the level: as given, else the pair brushed most often (ties: the slower
    speed, the faster rate); a speed or rate never brushed is left for the study to refuse."""
    if not recordings:
        return speed or 0.0, rate or 0.0
    counts: dict[tuple[float, float], int] = {}
    for recording in recordings:
        if (speed is None or math.isclose(recording.speed, speed, rel_tol=1e-9)) and (
                rate is None or math.isclose(recording.rate, rate, rel_tol=1e-9)):
            key = (recording.speed, recording.rate)
            counts[key] = counts.get(key, 0) + 1
    if not counts:
        return speed if speed is not None else recordings[0].speed, rate if rate is not None else recordings[0].rate
    return min(counts, key=lambda key: (-counts[key], key[0], -key[1]))
