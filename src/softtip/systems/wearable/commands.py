"""The wearable's command: ``softtip demo wearable``."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.table import Table

from softtip.cli.common import FORCE, console, demo_report, fail


def demo_wearable(
    seed: int = typer.Option(1, "--seed", help="Seed of the wearable protocol (participant, seatings, noise)."),
    duration: float = typer.Option(None, "--duration", help="Seconds of live streaming (default: the whole "
                                                            "streamed seating, 105 s)."),
    record: Path = typer.Option(None, "--record", help="Also record the live stream to this MCAP file."),
    force: bool = FORCE,
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """The wearable sensor (S2) end to end: the twin's calibration seatings, a 6th-order transfer function
    identified on them, and the emulated side chip streaming a further seating through the live pipeline,
    scored against the table force and against the offline simulation of the same frames."""
    report = demo_report("softtip.systems.wearable.live:run_wearable_demo", seed, duration, record, force,
                         json_output)
    if report is None:
        return
    if "live" not in report:
        fail("no frame was estimated: stream for longer (--duration)")
    table = Table(title="fingertip force from the side chip on the seating after the calibration: offline (the "
                        "whole seating) and live (the frames streamed), both tared per trial")
    for column in ("axis", "offline R²", "offline RMSE (% FS)", "live R²", "live RMSE (% FS)",
                   "|live − offline| (FS)"):
        table.add_column(column, justify="right")
    offline, live = report["offline_next_seating"]["outputs"], report["live"]["outputs"]
    for axis, gap in zip(offline, report["live_minus_offline_over_full_scale"], strict=True):
        table.add_row(axis, f"{offline[axis]['r2']:.2f}", f"{offline[axis]['rmse_fs_percent']:.1f}",
                      f"{live[axis]['r2']:.2f}", f"{live[axis]['rmse_fs_percent']:.1f}", f"{gap:.1e}")
    console.print(table)
    console.print(f"{report['estimated_frames']} frames estimated live; model saved at {report['model']}; "
                  f"full scale: {report['live']['full_scale']['description']}")
