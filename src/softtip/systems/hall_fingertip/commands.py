"""The Hall fingertip's commands: ``softtip demo`` (the main job), ``softtip demo insertion`` and
``softtip fingertip drift`` and ``softtip fingertip tolerance``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import typer
from rich.table import Table

from softtip._core.files import save_figure
from softtip._core.units import MM
from softtip.cli.common import (FORCE, check_number, check_output, check_outputs, console, demo_report, fail,
                                progress_for)

app = typer.Typer(help="S1: the Hall-effect soft fingertip.", no_args_is_help=True)


def demo(
    context: typer.Context,
    seed: int = typer.Option(1, "--seed", help="Seed of the experiments, the fabricated unit and the training."),
    duration: float = typer.Option(None, "--duration", help="Seconds of live streaming (default: the baseline's "
                                                            "second, then one loop of the twin's three motions, about 17 s)."),
    record: Path = typer.Option(None, "--record", help="Also record the live stream to this MCAP file."),
    force: bool = FORCE,
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """The main job on the built-in simulated sensor, in three steps: twin (the 3-axis force calibration's
    motions, pushed and released as the live stream plays them, run on the physics twin), calibration (a
    network is fitted to them and saved), live (an emulated fingertip streams the twin's pushes through the
    live pipeline, whose estimates are scored against the twin's true force, by phase as offline). It ends
    by naming the model it saved and the command to run it next."""
    if context.invoked_subcommand is not None:
        return
    report = demo_report("softtip.systems.hall_fingertip.demo:run_main_demo", seed, duration, record, force,
                         json_output)
    if report is None:
        return
    from softtip.systems.hall_fingertip.force_model import FORCES  # loaded with the demo already

    speed = f"{report['live_speed_mm_s']:g} mm/s"
    table = Table(title=f"force estimates: the calibration's held-out trials at the live stream's {speed} (offline) "
                        "and live frames from the emulator, every sample; at rest: the estimate's mean ± sd where "
                        "no force acts; by phase: rest / loading / unloading")
    for column in ("axis", "offline MAE (N)", "offline at rest (N)", "offline by phase (N)", "offline R²",
                   "live MAE (N)", "live at rest (N)", "live by phase (N)", "phase shares offline, live"):
        table.add_column(column, justify="right")
    nan = float("nan")

    def by_phase(scores: dict, figure: str, form: str) -> str:
        return "/".join(format(scores.get("by_phase", {}).get(f"{phase}_{figure}", nan), form)
                        for phase in ("rest", "loading", "unloading"))

    def cells(scores: dict) -> list[str]:
        return [f"{scores.get('mean_abs_error_N', nan):.3f}",
                f"{scores.get('rest_mean_N', nan):+.3f} ± {scores.get('rest_sd_N', nan):.3f}",
                by_phase(scores, "mean_abs_error_N", ".3f")]

    for axis in FORCES:
        offline = report["calibration"]["validation"]["by_speed"].get(speed, {}).get(axis, {})
        live = report["live"].get(axis, {})
        table.add_row(axis, *cells(offline), f"{offline.get('r2', nan):.4f}", *cells(live),
                      f"{by_phase(offline, 'share', '.2f')}, {by_phase(live, 'share', '.2f')}")
    console.print(table)
    if report["live_device_times_s"]:
        (first, last), loop = report["live_device_times_s"], report["live_loop_s"]
        whole = report["live_whole_loops"].get("fz_N")
        console.print(f"live scores over device times {first:.1f}-{last:.1f} s of the stream's {loop:.1f} s loop of "
                      "the three motions: what it covered twice weighs its phases"
                      + (f"; over whole loops, Fz {whole['mean_abs_error_N']:.3f} N (rest/loading/unloading "
                         f"{by_phase(whole, 'mean_abs_error_N', '.3f')} N)" if whole else ""), highlight=False)
    pipeline = report["pipeline"]
    console.print(f"{report['estimated_frames']} frames estimated live; lost frames: "
                  f"{pipeline.get('lost_in_transit', 0)}", highlight=False)
    saved = [f"the force model: {report['model']}"] + ([f"the live recording: {record}"] if record else [])
    console.print("saved " + "; ".join(saved), markup=False, highlight=False, soft_wrap=True)
    console.print(f"next: softtip live --emulate --scenario push --model {report['model']}  (the model on the "
                  "emulated fingertip, with its dashboard)"
                  + (f"; softtip convert {record} pushes.parquet  (the recording as a dataset)" if record else ""),
                  markup=False, highlight=False, soft_wrap=True)


def demo_insertion(
    case: str = typer.Option("good", "--case", help="good, left-clip or right-clip."),
    seed: int = typer.Option(1, "--seed", help="Seed of the training data and the sensors' noise."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON (outcome, state_detected, "
                                                           "force_at_detection_N, every decision)."),
) -> None:
    """Feedback-controlled insertion of the inverter lid on the simulated arm: stop and retract when the
    fingertips see a clip on part B's rim (state 2 or 3), done when the target pose is reached."""
    from softtip.systems.hall_fingertip.insertion_world import CASES
    from softtip.systems.hall_fingertip.insertion import run_insertion

    if case not in CASES:
        fail(f"--case = {case!r}: expected one of {', '.join(CASES)}")
    check_number(seed, "--seed", minimum=0)
    progress = progress_for(json_output)
    with progress.task(f"insertion, case {case}"):
        outcome = run_insertion(case, seed, progress=progress)
    if json_output:
        print(json.dumps(outcome, indent=2))
        return
    for decision in outcome["decisions"]:
        if decision["action"] != "approach" or decision["cycle"] % 25 == 0:
            console.print(f"t = {decision['time_s']:6.2f} s  height {decision['pose'][0] / MM:+.3f} mm  "
                          f"state {decision['state']}  force {decision['force_N']:.3f} N  -> {decision['action']}")
    estimated = outcome["force_at_detection_N"]
    console.print(f"[bold]{outcome['outcome']}[/]: state {outcome['state_detected']} at an estimated "
                  f"{'-' if estimated is None else f'{estimated:.3f}'} N "
                  f"(true {outcome['true_force_at_decision_N']:.3f} N)")


@app.command("drift")
def drift(
    seed: int = typer.Option(1, "--seed", help="Seed of the fabricated unit, its trials and the network."),
    quick: bool = typer.Option(False, "--quick", help="4 trials per motion instead of 15: a smoke run (some 3 "
                                                      "minutes), not the study."),
    plot: Path = typer.Option(None, "--plot", help="Save the causes' sizes and the correction's curve to this PNG."),
    force: bool = FORCE,
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """The size of each cause of drift between sessions (the magnets' and the chips' temperature, the
    elastomer's aging and creep, a steel plate near the chips) on one unit of design D in the 3-axis
    force protocol, and the force error of a later session with all of them, re-calibrated from its
    first 0..5 presses."""
    if seed < 0:
        fail(f"--seed = {seed}: expected an integer >= 0")
    if plot is not None:
        if plot.suffix.lower() != ".png":
            fail(f"--plot {plot}: expected a file name ending in .png")
        check_output(plot, "--plot", force=force)
    from softtip.systems.hall_fingertip.drift import PRESSES, TARGETS, drift_study, plot_drift

    study = drift_study(seed, quick, progress_for(json_output))
    if plot is not None:
        plot_drift(study, plot)
    if json_output:
        print(json.dumps({**study.to_dict(), "plot": None if plot is None else str(plot)}, indent=2))
        return
    table = Table(title=f"Drift between sessions, unit of seed {seed}: force RMSE (N) on the later session, "
                        f"as calibrated and after {PRESSES} presses")
    for column in ("cause", "readings' change (%)", *TARGETS, *(f"{t} after {PRESSES}" for t in TARGETS)):
        table.add_column(column, justify="right")
    table.add_row("none (the calibration session)", "0", *(f"{v:.3f}" for v in study.calibration_rmse_N),
                  *("" for _ in TARGETS))
    for cause in study.causes:
        table.add_row(cause.name, f"{100 * cause.reading_change:.2f}",
                      *(f"{v:.3f}" for v in (*cause.force_rmse_N, *cause.corrected_rmse_N)))
    console.print(table)
    curve = Table(title=f"Every cause at once, re-calibrated from its first presses ({study.scored_rows} rows scored)")
    for column in ("presses", *(f"{t}: gains" for t in TARGETS), *(f"{t}: affine" for t in TARGETS)):
        curve.add_column(column, justify="right")
    curve.add_row("predicting zero", *(f"{v:.3f}" for v in (*study.zero_rmse_N, *study.zero_rmse_N)))
    for k, (gains, affine) in enumerate(zip(study.presses_rmse_N, study.affine_presses_rmse_N, strict=True)):
        curve.add_row(str(k), *(f"{v:.3f}" for v in (*gains, *affine)))
    console.print(curve)


@app.command("tolerance")
def tolerance(
    design: str = typer.Option("cylindrical-D", "--design", help="A shipped design's name or a design TOML file."),
    seed: int = typer.Option(1, "--seed", help="The first seed: units, trials and noise of seed, seed + 1, ..."),
    seeds: int = typer.Option(3, "--seeds", help="How many seeds (at least 2: the interval needs a scatter)."),
    errors: list[str] = typer.Option(None, "--error", help="An error to rank (repeatable; default all of them)."),
    tolerances: list[str] = typer.Option(None, "--tolerance", help="NAME=VALUE: an error's tolerance other than "
                                                                   "its default (repeatable)."),
    estimates: list[str] = typer.Option(None, "--estimate", help="orientation or force (repeatable; default both)."),
    quick: bool = typer.Option(False, "--quick", help="Fewer angles and trials: a smoke run for CI, not the study."),
    report: Path = typer.Option(None, "--report", help="Write the HTML report here (.html)."),
    plot: Path = typer.Option(None, "--plot", help="Save the ranked bar charts to this PNG."),
    force: bool = FORCE,
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Which fabrication and bench errors degrade each estimate most: each error one at a time at ± its
    tolerance, and all at once, on a coarse pushing and 3-axis force protocol, each run re-calibrated
    and validated; ranked with 95 % intervals over seeds."""
    from softtip.systems.hall_fingertip.tolerance import (ERROR_NAMES, ESTIMATES, FORCE as FORCE_PROTOCOL, PUSHING,
                                                          check_tolerances, error_named, plot_tolerance, protocols_of,
                                                          tolerance_report, tolerance_study)

    check_number(seed, "--seed", minimum=0)
    check_number(seeds, "--seeds", minimum=2, maximum=100)
    for name in errors or ():
        if name not in ERROR_NAMES:
            fail(f"--error {name!r}: expected one of {', '.join(ERROR_NAMES)}")
    chosen_tolerances = {}
    for item in tolerances or ():
        name, _, text = item.partition("=")
        if name not in ERROR_NAMES:
            fail(f"--tolerance {item!r}: expected NAME=VALUE with NAME one of {', '.join(ERROR_NAMES)}")
        try:
            value = float(text)
        except ValueError:
            fail(f"--tolerance {item!r}: expected NAME=VALUE with VALUE a number")
        if not np.isfinite(value) or value < 0 or value > 100:
            fail(f"--tolerance {item!r}: expected a tolerance between 0 and 100")
        chosen_tolerances[name] = value
    groups = {"orientation": PUSHING, "force": FORCE_PROTOCOL}
    for name in estimates or ():
        if name not in groups:
            fail(f"--estimate {name!r}: expected orientation or force")
    wanted = [groups[name] for name in estimates or groups]
    check_outputs([("--report", report), ("--plot", plot)], force=force)
    for option, path, suffix in (("--report", report, ".html"), ("--plot", plot, ".png")):
        if path is not None and path.suffix.lower() != suffix:
            fail(f"{option} {path}: expected a file name ending in {suffix}")
    from softtip.design.model import load_design

    try:
        unit = load_design(design)
    except (ValueError, OSError) as error:
        fail(f"--design {design}: {error}")
    chosen = tuple(errors or ERROR_NAMES)
    wanted_estimates = tuple(e for e, (protocol, _) in ESTIMATES.items() if protocol in wanted)
    try:
        check_tolerances(unit, tuple(map(error_named, chosen)),
                         {name: error_named(name).tolerance for name in chosen} | chosen_tolerances,
                         protocols_of(wanted_estimates), quick)
    except ValueError as problem:
        fail(f"--tolerance: {problem}")
    study = tolerance_study(unit, tuple(range(seed, seed + seeds)), chosen, chosen_tolerances, wanted_estimates, quick,
                            progress_for(json_output))
    figure = plot_tolerance(study)
    if plot is not None:
        save_figure(figure, plot, dpi=110)
    if report is not None:
        tolerance_report(study, figure).write(report)
    if json_output:
        print(json.dumps({**study.to_dict(), "report": None if report is None else str(report),
                          "plot": None if plot is None else str(plot)}, indent=2))
        return
    for estimate, result in study.to_dict()["estimates"].items():
        nominal, unit_name = result["nominal_error"], result["unit"]
        table = Table(title=f"{estimate}: nominal validation error {nominal['mean']:.3g} ± "
                            f"{nominal['sd_over_seeds']:.2g} {unit_name}; degradation by error, worst first")
        for column in ("rank", "error", "worst run", f"degradation ({unit_name})", "95 % interval", "verdict"):
            table.add_column(column, justify="right")
        for r in result["ranking"]:
            table.add_row(str(r["rank"]), r["error"], r["worst_run"], f"{r['degradation_mean']:+.3g}",
                          f"{r['interval_95'][0]:+.3g} … {r['interval_95'][1]:+.3g}",
                          "inside the seed scatter" if r["inside_seed_scatter"] else "degrades")
        joint = result["joint"]
        table.add_row("", "all at once", "", f"{joint['degradation_mean']:+.3g}",
                      f"{joint['interval_low']:+.3g} … {joint['interval_high']:+.3g}", "")
        console.print(table)
