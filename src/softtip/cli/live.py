"""``softtip live`` and ``softtip convert``: live estimates, and recordings back to datasets."""

from __future__ import annotations

import json
import time
import zipfile
from enum import Enum
from pathlib import Path

import typer

from softtip._core.systems import default, names, owner
from softtip.cli.common import (FORCE, LONGEST_S, check_input, check_number, check_output, claimed, console, errors,
                                fail, printable, progress_for)

SCENARIOS = tuple(names("scenario"))
SCENARIO_HELP = "; ".join(f"{name} ({owner('scenario', name).name})" for name in SCENARIOS)
Scenario = Enum("Scenario", {name: name for name in SCENARIOS}, type=str)  # the choices shown in the help
MAX_RATE_HZ = 10_000  # frames per second the pipeline is specified for (a frame of 4 chips in 100 µs)
MAX_CHIPS = 64  # chips on one board's bus
MAX_REST_BAND = 1e6  # above any reading's full scale (the widest Hall chip's is about 1.4e5 µT)


def live(
    port: str = typer.Option(None, "--port", help="Serial port of a fingertip board (e.g. /dev/ttyACM0)."),
    driver_name: str = typer.Option("softtip", "--driver", "--format",
                                    help="The wire format of the board on --port, a registered driver: softtip's "
                                         "firmware (softtip), a ReSkin / AnySkin board's binary records (reskin, "
                                         "anyskin: 5 chips unless --chips), or one a system registers."),
    model: list[Path] = typer.Option([], "--model", help="Saved softtip model(s) to run on every frame "
                                                         "(with --emulate, default: the scenario's own)."),
    emulate: bool = typer.Option(False, "--emulate", help="An emulated sensor replaying a registered system's "
                                                         "scenario instead of a port."),
    scenario: Scenario = typer.Option(default("scenario"), "--scenario",
                                 help=f"With --emulate, one of: {SCENARIO_HELP}."),
    chips: int = typer.Option(None, "--chips", help="Chips on the board (default: as it reports)."),
    rate: int = typer.Option(None, "--rate", help="Frames per second (default 50; a paced sensor: its own)."),
    record: Path = typer.Option(None, "--record", help="Record to this MCAP file (ROS 2 message types)."),
    foxglove: int = typer.Option(None, "--foxglove", help="Serve a Foxglove WebSocket live view on this port."),
    ros2: bool = typer.Option(False, "--ros2", help="Also publish the topics as a ROS 2 node "
                                                   "(pip install 'softtip[ros2]')."),
    duration: float = typer.Option(None, "--duration", help="Seconds to run (default: until Ctrl-C)."),
    baseline_frames: int = typer.Option(None, "--baseline-frames", help="Frames averaged into the baseline "
                                                                       "(default 50, or the scenario's)."),
    drift_tau: float = typer.Option(None, "--drift-tau", help="Track slow baseline drift with this time "
                                                              "constant (s) while nothing touches."),
    rezero_at_rest: float = typer.Option(None, "--rezero-at-rest", help="Re-zero when the sensor has rested "
                                         "this many seconds: every channel within --rest-band (peak to peak) and "
                                         "within the drift threshold (20 µT; 0.05 N for a force chip) of the "
                                         "baseline, and in a free contact state; the rest's mean becomes the "
                                         "baseline."),
    rest_band: float = typer.Option(None, "--rest-band", help="With --rezero-at-rest, the largest peak-to-peak "
                                    "change of a channel at rest, in the reading's unit (default: half the drift "
                                    "threshold, 10 µT)."),
    force: bool = FORCE,
    json_output: bool = typer.Option(False, "--json", help="Print the session's summary as JSON."),
) -> None:
    """Stream a fingertip (or an emulated sensor) through baseline -> models -> dashboard, recording,
    Foxglove, ROS 2. Re-zero (retake the baseline) with the z key on the dashboard or kill -USR1 PID,
    or at rest with --rezero-at-rest."""
    import psutil

    from softtip._core.systems import load
    from softtip.realtime.session import run_live
    from softtip.realtime.sinks.factory import live_sinks
    from softtip.realtime.sinks.ros2 import ros2_problem

    if emulate == (port is not None):
        fail("give either --port PORT or --emulate")
    check_number(duration, "--duration", above=0, maximum=LONGEST_S, unit="s")
    check_number(drift_tau, "--drift-tau", above=0, maximum=LONGEST_S, unit="s")
    check_number(rezero_at_rest, "--rezero-at-rest", above=0, maximum=LONGEST_S, unit="s")
    check_number(rest_band, "--rest-band", above=0, maximum=MAX_REST_BAND)
    if rest_band is not None and rezero_at_rest is None:
        fail(f"--rest-band = {rest_band:g}: only with --rezero-at-rest SECONDS")
    for path in model:
        if not zipfile.is_zipfile(check_input(path, "--model")):
            fail(f"--model = {path}: not a saved softtip model (an .npz archive)")
    check_number(rate, "--rate", minimum=1, maximum=MAX_RATE_HZ, unit="Hz")
    check_number(chips, "--chips", minimum=1, maximum=MAX_CHIPS)
    check_number(baseline_frames, "--baseline-frames", minimum=1, maximum=MAX_RATE_HZ * 60)
    check_number(foxglove, "--foxglove", minimum=1, maximum=65535)
    if ros2 and (problem := ros2_problem()) is not None:
        fail(f"--ros2: {problem}")
    if record is not None:
        check_output(record, "--record", model, force=force)
    scenario = getattr(scenario, "value", scenario)
    source, settings, emulator_source, frames = port, None, None, baseline_frames or 50
    if driver_name != "softtip" or not emulate:
        from softtip.hardware.drivers import PortRequest, driver

        wire = driver(driver_name)
        if emulate:
            fail(f"--driver {driver_name}: reads a board on --port; --emulate plays softtip's firmware")
        if wire.own_rate and rate is not None:
            fail(f"--rate = {rate}: a {driver_name} board streams at its own rate; leave --rate out")
        source = wire.source(PortRequest(port, chips, rate))
    # claimed before any scenario is computed: a second live recording to the same file stops here
    with claimed(record, "--record"):
        if emulate:
            if scenario not in SCENARIOS:
                fail(f"--scenario = {scenario!r}: expected one of {', '.join(SCENARIOS)}")

            def check_stream(scenario_chips: int, scenario_rate_hz: float | None) -> None:
                if chips not in (None, scenario_chips):
                    fail(f"--chips = {chips}: the {scenario} scenario streams {scenario_chips}")
                if scenario_rate_hz is not None and rate not in (None, scenario_rate_hz):
                    fail(f"--rate = {rate}: the {scenario} scenario streams at {scenario_rate_hz:g} Hz")

            stream = load(owner("scenario", scenario).scenarios[scenario])(progress_for(json_output), check_stream)
            check_stream(stream.chips, stream.rate_hz)  # what it streams, whether or not it said so first
            source, chips, settings = stream.source, stream.chips, stream.settings
            emulator_source = stream.emulator_source
            model, frames = model or list(stream.models), baseline_frames or stream.baseline_frames
        started = psutil.Process().create_time()  # the process's start (s since the epoch): what a user waits from
        first_frame = []

        def note_first_frame(frame) -> None:
            if not first_frame:
                first_frame.append(time.time() - started)

        sinks = live_sinks(dashboard=not json_output, record=record, foxglove_port=foxglove, ros2=ros2)
        if foxglove is not None:
            from softtip.realtime.sinks.foxglove import FoxgloveSink

            for sink in sinks:
                if isinstance(sink, FoxgloveSink):
                    errors.print(sink.where_to_open(), markup=False, highlight=False, soft_wrap=True)
        summary = run_live(source, model, sinks, duration, rate_hz=rate or 50, chips=chips, settings=settings,
                           baseline_frames=frames, drift_time_constant_s=drift_tau, rest_s=rezero_at_rest,
                           rest_band=rest_band, emulator_source=emulator_source, callbacks=[note_first_frame])
        summary["first_frame_s"] = first_frame[0] if first_frame else None
        for sink in sinks:
            summary.update(sink.report())
        if json_output:
            print(json.dumps(summary, indent=2, default=float))


def convert(
    recording: Path = typer.Argument(..., help="MCAP recording from softtip live."),
    output: Path = typer.Argument(..., help="Dataset to write (.parquet)."),
    gap: float = typer.Option(1.0, "--gap", help="A gap longer than this (s) starts a new trial."),
    force: bool = FORCE,
    salvage: bool = typer.Option(False, "--salvage", help="Convert what parses of a recording whose data section "
                                 "fails its CRC beside damaged records (a name outside them may be altered too)."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Turn a live recording into the calibration tools' trial dataset (changes in the chips' unit, labels)."""
    from softtip.realtime.recording.convert import convert as convert_recording

    check_number(gap, "--gap", above=0, maximum=LONGEST_S, unit="s")
    check_input(recording, "RECORDING")
    check_output(output, "OUTPUT", [recording], force=force)
    result = convert_recording(recording, output, gap_s=gap, salvage=salvage)
    dataset = result.dataset
    salvage = result.salvage
    if salvage.truncated or salvage.damaged_records or salvage.resynchronised or salvage.data_crc_ok is False:
        errors.print(printable(f"warning: {recording} is damaged: converted the {salvage.messages} messages salvaged "
                               f"({salvage.bytes_lost} bytes lost, {salvage.damaged_records} damaged records skipped, "
                               f"{salvage.resynchronised} resynchronised; the summary says which times)"),
                     markup=False, highlight=False, soft_wrap=True)
    summary = {"dataset": str(output), "trials": len(dataset.trials), "samples": int(len(dataset.groups)),
               "channels": list(dataset.channels), "labels": list(dataset.labels), **result.salvage.report()}
    if json_output:
        print(json.dumps(summary, indent=2))
    else:
        console.print(summary)

