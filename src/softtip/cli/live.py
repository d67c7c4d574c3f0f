"""``softtip live`` and ``softtip convert``: live estimates, and recordings back to datasets."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from softtip.cli.common import console, fail, progress_for


def live(
    port: str = typer.Option(None, "--port", help="Serial port of a fingertip board (e.g. /dev/ttyACM0)."),
    model: list[Path] = typer.Option([], "--model", help="Saved softtip model(s) to run on every frame "
                                                         "(with --emulate, default: the twin's force model)."),
    emulate: bool = typer.Option(False, "--emulate", help="An emulated fingertip (pty, firmware protocol) "
                                                         "replaying the twin instead of a port."),
    scenario: str = typer.Option("push", "--scenario", help="With --emulate: push (one fingertip: pushes and "
                                                           "shears) or insertion (two fingertips, the inverter lid)."),
    chips: int = typer.Option(None, "--chips", help="Chips on the board (default: as it reports)."),
    rate: int = typer.Option(50, "--rate", help="Frames per second."),
    record: Path = typer.Option(None, "--record", help="Record to this MCAP file (ROS 2 message types)."),
    foxglove: int = typer.Option(None, "--foxglove", help="Serve a Foxglove WebSocket live view on this port."),
    ros2: bool = typer.Option(False, "--ros2", help="Also publish the topics as a ROS 2 node (needs rclpy)."),
    duration: float = typer.Option(None, "--duration", help="Seconds to run (default: until Ctrl-C)."),
    baseline_frames: int = typer.Option(50, "--baseline-frames", help="Frames averaged into the baseline."),
    drift_tau: float = typer.Option(None, "--drift-tau", help="Track slow baseline drift with this time "
                                                              "constant (s) while nothing touches."),
    json_output: bool = typer.Option(False, "--json", help="Print the session's summary as JSON."),
) -> None:
    """Stream a fingertip (or the emulated one) through baseline -> models -> dashboard, recording,
    Foxglove, ROS 2. Retake the baseline with kill -USR1 PID."""
    from softtip.realtime.session import run_live
    from softtip.realtime.sinks.factory import live_sinks

    if emulate == (port is not None):
        fail("give either --port PORT or --emulate")
    source = None
    settings = None
    if scenario not in ("push", "insertion"):
        fail(f"--scenario = {scenario!r}: expected push or insertion")
    if emulate:
        from softtip.lab import load_protocol
        from softtip.lab.scenario import insertion_scenario, pushing_scenario
        from softtip.sensors import MLX90393Settings

        protocol = load_protocol("force3" if scenario == "push" else "inverter")
        progress = progress_for(json_output)
        with progress.task("computing the twin's scenario"):
            source = (pushing_scenario if scenario == "push" else insertion_scenario)(protocol, protocol.seed)
        settings = MLX90393Settings.from_dict(protocol.design.sensor_readout)
        chips = chips or source.field_uT.shape[1]
        if not model:  # the emulated fingertip comes with its calibration, trained on the twin once
            with progress.task("calibrating the twin"):
                if scenario == "push":
                    from softtip.studies.live_demo import calibrate_force_model

                    model = [calibrate_force_model(protocol.seed, progress, reuse=True)[0]]
                else:
                    from softtip.studies.insertion import trained_model_files

                    model = list(trained_model_files(protocol, progress))
    summary = run_live("emulator" if emulate else port, model,
                       live_sinks(dashboard=not json_output, record=record, foxglove_port=foxglove, ros2=ros2),
                       duration, rate_hz=rate, chips=chips, settings=settings, baseline_frames=baseline_frames,
                       drift_time_constant_s=drift_tau, emulator_source=source)
    if json_output:
        print(json.dumps(summary, indent=2, default=float))


def convert(
    recording: Path = typer.Argument(..., help="MCAP recording from softtip live."),
    output: Path = typer.Argument(..., help="Dataset to write (.parquet)."),
    gap: float = typer.Option(1.0, "--gap", help="A gap longer than this (s) starts a new trial."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Turn a live recording into the calibration tools' trial dataset (changes in µT, labels)."""
    from softtip.realtime.recording.convert import convert as convert_recording

    result = convert_recording(recording, output, gap_s=gap)
    dataset = result.dataset
    summary = {"dataset": str(output), "trials": len(dataset.trials), "samples": int(len(dataset.groups)),
               "channels": list(dataset.channels), "labels": list(dataset.labels)}
    if json_output:
        print(json.dumps(summary, indent=2))
    else:
        console.print(summary)

