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
                                                           "shears), insertion (two fingertips, the inverter lid) "
                                                           "or wearable (the side-of-nail force chip, S2)."),
    chips: int = typer.Option(None, "--chips", help="Chips on the board (default: as it reports)."),
    rate: int = typer.Option(None, "--rate", help="Frames per second (default 50; the wearable chip: its 10)."),
    record: Path = typer.Option(None, "--record", help="Record to this MCAP file (ROS 2 message types)."),
    foxglove: int = typer.Option(None, "--foxglove", help="Serve a Foxglove WebSocket live view on this port."),
    ros2: bool = typer.Option(False, "--ros2", help="Also publish the topics as a ROS 2 node (needs rclpy)."),
    duration: float = typer.Option(None, "--duration", help="Seconds to run (default: until Ctrl-C)."),
    baseline_frames: int = typer.Option(None, "--baseline-frames", help="Frames averaged into the baseline "
                                                                       "(default 50; wearable: 1, its protocol's tare)."),
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
    if scenario not in ("push", "insertion", "wearable"):
        fail(f"--scenario = {scenario!r}: expected push, insertion or wearable")
    wearable = emulate and scenario == "wearable"
    if wearable and chips not in (None, 1):
        fail(f"--chips = {chips}: the wearable sensor has one chip")
    source = port
    emulator_source = settings = None
    progress = progress_for(json_output)
    if wearable:  # the emulated wearable sensor comes with its model, identified on the twin
        from softtip.studies.live_demo import wearable_live_setup

        with progress.task("the wearable twin's calibration runs and the identified model"):
            stream = wearable_live_setup()
        if rate not in (None, stream.rate_hz):
            fail(f"--rate = {rate}: the wearable chip streams at {stream.rate_hz:g} Hz")
        source, model = stream.source(), model or [stream.model]
    elif emulate:
        from softtip.lab import load_protocol
        from softtip.lab.scenario import insertion_scenario, pushing_scenario
        from softtip.sensors import MLX90393Settings

        protocol = load_protocol("force3" if scenario == "push" else "inverter")
        with progress.task("computing the twin's scenario"):
            emulator_source = (pushing_scenario if scenario == "push" else insertion_scenario)(protocol, protocol.seed)
        settings = MLX90393Settings.from_dict(protocol.design.sensor_readout)
        source, chips = "emulator", chips or emulator_source.field_uT.shape[1]
        if not model:  # the emulated fingertip comes with its calibration, trained on the twin once
            with progress.task("calibrating the twin"):
                if scenario == "push":
                    from softtip.studies.live_demo import calibrate_force_model

                    model = [calibrate_force_model(protocol.seed, progress, reuse=True)[0]]
                else:
                    from softtip.studies.insertion import trained_model_files

                    model = list(trained_model_files(protocol, progress))
    summary = run_live(source, model,
                       live_sinks(dashboard=not json_output, record=record, foxglove_port=foxglove, ros2=ros2),
                       duration, rate_hz=rate or 50, chips=chips, settings=settings,
                       baseline_frames=baseline_frames or (1 if wearable else 50), drift_time_constant_s=drift_tau,
                       emulator_source=emulator_source)
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
               "channels": list(dataset.channels), "labels": list(dataset.labels), **result.salvage.report()}
    if json_output:
        print(json.dumps(summary, indent=2))
    else:
        console.print(summary)

