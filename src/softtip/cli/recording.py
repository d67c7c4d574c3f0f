"""``softtip recording repair``: a torn or damaged recording, made whole for indexed readers."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from softtip.cli.common import FORCE, check_input, check_output, console, printable


def recording_repair(
    recording: Path = typer.Argument(..., help="MCAP recording to repair (torn by a kill mid-write, cut short, "
                                               "or a chunk damaged)."),
    output: Path = typer.Option(None, "--output", "-o", help="Repaired recording to write "
                                                             "(default: RECORDING with .repaired.mcap)."),
    force: bool = FORCE,
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Rewrite a recording with every complete message and the summary and index it lacks, and say what
    was salvaged and what was lost."""
    from softtip.realtime.recording.writer import repair_recording

    check_input(recording, "RECORDING")
    output = check_output(recording.with_suffix(".repaired.mcap") if output is None else output, "--output",
                          [recording], force=force)
    salvage = repair_recording(recording, output)
    summary = {"recording": str(recording), "output": str(output), **salvage.report()}
    if json_output:
        print(json.dumps(summary, indent=2))
    else:
        for key, value in summary.items():
            console.print(printable(f"{key}: {value}"), highlight=False, markup=False, soft_wrap=True)
