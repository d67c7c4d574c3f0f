"""The Hall fingertip's commands: ``softtip demo`` (the main job) and ``softtip demo insertion``."""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.table import Table

from softtip._core.units import MM
from softtip.cli.common import FORCE, check_number, console, demo_report, fail, progress_for


def demo(
    context: typer.Context,
    seed: int = typer.Option(1, "--seed", help="Seed of the experiments, the fabricated unit and the training."),
    duration: float = typer.Option(20.0, "--duration", help="Seconds of live streaming."),
    record: Path = typer.Option(None, "--record", help="Also record the live stream to this MCAP file."),
    force: bool = FORCE,
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """The main job on the built-in simulated sensor, in three steps: twin (the 3-axis force calibration
    runs on the physics twin), calibration (a network is fitted to it and saved), live (an emulated
    fingertip streams the twin's pushes through the live pipeline, whose estimates are scored against
    the twin's true force). It ends by naming the model it saved and the command to run it next."""
    if context.invoked_subcommand is not None:
        return
    report = demo_report("softtip.systems.hall_fingertip.demo:run_main_demo", seed, duration, record, force,
                         json_output)
    if report is None:
        return
    table = Table(title="force estimates: validation trials (offline) and live frames from the emulator")
    for column in ("axis", "offline MAE (N)", "offline R²", "live MAE (N)", "live peak |F| (N)"):
        table.add_column(column, justify="right")
    for axis, offline in report["calibration"]["validation"].items():
        live = report["live"].get(axis, {})
        table.add_row(axis, f"{offline['mean_abs_error_N']:.3f}", f"{offline['r2']:.4f}",
                      f"{live.get('mean_abs_error_N', float('nan')):.3f}", f"{live.get('peak_true_N', float('nan')):.2f}")
    console.print(table)
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

