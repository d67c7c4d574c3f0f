"""S3's commands: ``softtip bench haptics`` and ``softtip haptics render``."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np
import typer
from rich.table import Table

from softtip.cli.common import check_output, console, fail, progress_for

app = typer.Typer(help="S3: personalised haptic rendering with the 3-cable fingertip device.", no_args_is_help=True)

RENDER_P99_TARGET_S, TABLE_BUILD_TARGET_S, REPRODUCE_TARGET_S = 50e-6, 0.1, 30.0
MAX_DURATION_S = 3600.0
MAX_FS_LEVELS = 31  # 29,791 configurations: a real collection of about nine hours


def _finite_positive(value: float | None, option: str) -> None:
    if value is not None and not (math.isfinite(value) and value > 0):
        fail(f"{option} = {value}: expected a finite number > 0")


def _percentile_us(samples: np.ndarray, q: float) -> float:
    return float(np.percentile(samples, q) * 1e6)


def bench_haptics(
    queries: int = typer.Option(5000, "--queries", help="Renderings timed (one wanted wrench each)."),
    repeats: int = typer.Option(5, "--repeats", help="Personalised 13³ tables built (the median is reported)."),
    reproduce: bool = typer.Option(True, "--reproduce/--no-reproduce", help="Also time the whole reproduce haptics."),
    seed: int = typer.Option(1, "--seed", help="Seed of the simulated collection."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """S3's speeds on this machine, each beside a baseline of the same run: one rendering (query +
    weighting, p99; baseline: a bare scipy cKDTree query of the same 8 neighbours), a personalised 13³
    table built (geometric and data-driven, with the renderer's index; baseline: indexing the FS table
    alone) and the whole ``softtip reproduce haptics``."""
    for option, value, most in (("--queries", queries, 1_000_000), ("--repeats", repeats, 100)):
        if not 1 <= value <= most:
            fail(f"{option} = {value}: expected an integer from 1 to {most}")
    if seed < 0:
        fail(f"--seed = {seed}: expected an integer >= 0")
    from scipy.spatial import cKDTree

    from softtip.systems.haptics.collection import CollectionSettings, motor_grid, sensed_contact
    from softtip.systems.haptics.device import load_device
    from softtip.systems.haptics.fingertips import FINGERTIP_SENSOR, TEST_FINGERTIPS
    from softtip.systems.haptics.personalisation import personalise_data_driven, personalise_geometric
    from softtip.systems.haptics.rendering import NearestNeighbourRenderer

    rng = np.random.default_rng(seed)
    device = load_device()
    progress = progress_for(json_output)
    with progress.task("haptics: FS and user tables", total=1) as task:
        fs = sensed_contact(device, FINGERTIP_SENSOR, motor_grid(device, 13), CollectionSettings(), rng).unsaturated()
        user_finger = TEST_FINGERTIPS[-1]
        user = sensed_contact(device, user_finger, motor_grid(device, 7), CollectionSettings(), rng).unsaturated()
        task.advance()
    renderer = NearestNeighbourRenderer().fit(fs.finger_wrenches, fs.motor_inputs)
    wanted = fs.finger_wrenches[rng.integers(0, len(fs.motor_inputs), queries)] + rng.normal(0, 0.05, (queries, 6))
    render_s, query_s = np.empty(queries), np.empty(queries)
    tree = cKDTree(renderer.features_)
    for k, wrench in enumerate(wanted):
        start = time.perf_counter()
        renderer.render_one(wrench)
        render_s[k] = time.perf_counter() - start
        start = time.perf_counter()
        tree.query(wrench[:3], k=renderer.n_neighbours)
        query_s[k] = time.perf_counter() - start

    def timed(build) -> float:
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            build()
            times.append(time.perf_counter() - start)
        return float(np.median(times))

    standard = renderer.get_params()
    geometric_s = timed(lambda: NearestNeighbourRenderer(**standard).fit(
        fs.finger_wrenches, personalise_geometric(device, fs.motor_inputs, FINGERTIP_SENSOR.radius,
                                                  user_finger.radius).motor_inputs))
    data_driven_s = timed(lambda: NearestNeighbourRenderer(**standard).fit(
        fs.finger_wrenches, personalise_data_driven(device, fs.motor_inputs, fs.platform_wrenches, user.motor_inputs,
                                                    user.platform_wrenches, renderer.n_neighbours,
                                                    renderer.contact_threshold).motor_inputs))
    index_s = timed(lambda: NearestNeighbourRenderer(**standard).fit(fs.finger_wrenches, fs.motor_inputs))
    report = {
        "rendering": {"p50_us": _percentile_us(render_s, 50), "p99_us": _percentile_us(render_s, 99),
                      "target_p99_us": RENDER_P99_TARGET_S * 1e6,
                      "baseline_cKDTree_query_p99_us": _percentile_us(query_s, 99),
                      "ratio_p99": float(np.percentile(render_s, 99) / np.percentile(query_s, 99)),
                      "queries": queries, "table_entries": len(renderer.features_)},
        "personalised_table_13^3": {"geometric_ms": geometric_s * 1e3, "data_driven_ms": data_driven_s * 1e3,
                                    "target_ms": TABLE_BUILD_TARGET_S * 1e3, "baseline_index_fs_table_ms": index_s * 1e3,
                                    "entries": len(fs.motor_inputs), "repeats": repeats},
    }
    if reproduce:
        from softtip.studies.reproduce import reproduce_study

        start = time.perf_counter()
        reproduce_study("haptics", seed=seed, progress=progress)
        report["reproduce_haptics"] = {"s": time.perf_counter() - start, "target_s": REPRODUCE_TARGET_S}
    if json_output:
        print(json.dumps(report, indent=2))
        return
    table = Table(title="softtip bench haptics (this machine)")
    for column in ("measure", "softtip", "baseline (same run)", "target"):
        table.add_column(column, justify="right")
    r, t = report["rendering"], report["personalised_table_13^3"]
    table.add_row("one rendering, p99", f"{r['p99_us']:.1f} µs", f"cKDTree query {r['baseline_cKDTree_query_p99_us']:.1f} µs",
                  f"≤ {r['target_p99_us']:.0f} µs")
    table.add_row("personalised 13³ table, geometric", f"{t['geometric_ms']:.1f} ms",
                  f"index FS table {t['baseline_index_fs_table_ms']:.1f} ms", f"≤ {t['target_ms']:.0f} ms")
    table.add_row("personalised 13³ table, data-driven", f"{t['data_driven_ms']:.1f} ms",
                  f"index FS table {t['baseline_index_fs_table_ms']:.1f} ms", f"≤ {t['target_ms']:.0f} ms")
    if reproduce:
        table.add_row("reproduce haptics", f"{report['reproduce_haptics']['s']:.1f} s", "", f"≤ {REPRODUCE_TARGET_S:.0f} s")
    console.print(table)


@app.command("render")
def render(
    duration: float = typer.Option(None, "--duration", help="Seconds to render (default: 5 s synthetic, or the "
                                                            "whole file)."),
    sensation: Path = typer.Option(None, "--sensation", help="A recorded sensation (.csv or .parquet: time_s, fx_N, "
                                                             "fy_N, fz_N); default a synthetic one."),
    fingertip: str = typer.Option("FS cast (7.5 mm)", "--fingertip", help="The test fingertip in the device."),
    method: str = typer.Option("standard", "--method", help="standard or geometric (B, for --fingertip's radius)."),
    device_file: Path = typer.Option(None, "--device", help="A device TOML file (default softtip's device)."),
    fs_levels: int = typer.Option(13, "--fs-levels", help="FS table levels per servo (13: 13³ entries)."),
    seed: int = typer.Option(1, "--seed", help="Seed of the table collection, the synthetic sensation and the noise."),
    record: Path = typer.Option(None, "--record", help="Record the stream to this MCAP file."),
    foxglove_port: int = typer.Option(None, "--foxglove-port", help="Serve a Foxglove live view on this port."),
    ros2: bool = typer.Option(False, "--ros2", help="Publish on ROS 2 topics (needs rclpy, a sourced ROS 2)."),
    realtime: bool = typer.Option(True, "--realtime/--fast", help="Pace the loop to the wall clock at 1 kHz, or run "
                                                                  "it as fast as the machine allows."),
    port: str = typer.Option(None, "--port", help="Drive a real device: its controller's serial port (a device path "
                                                  "or a pyserial URL), in the line protocol of "
                                                  "softtip.systems.haptics.servos; default the device model."),
    baud: int = typer.Option(115_200, "--baud", help="--port's baud rate (8N1)."),
    force: bool = typer.Option(False, "--force", help="Overwrite --record's file."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Stream a sensation through the renderer to the device model, or with --port to a real device: a
    1 kHz loop, the servos' 50 Hz commands, the commanded motor inputs and the rendered wrench out on
    the live sinks (MCAP, Foxglove)."""
    # every option checked before the renderer's modules load (they take seconds on a busy machine)
    _finite_positive(duration, "--duration")
    if duration is not None and duration > MAX_DURATION_S:
        fail(f"--duration = {duration}: expected at most {MAX_DURATION_S:g} s (the sequence is built in memory)")
    if method not in ("standard", "geometric"):
        fail(f"--method = {method!r}: expected standard or geometric")
    if not 2 <= fs_levels <= MAX_FS_LEVELS:
        fail(f"--fs-levels = {fs_levels}: expected an integer from 2 to {MAX_FS_LEVELS} (a table of levels³ "
             "configurations)")
    if seed < 0:
        fail(f"--seed = {seed}: expected an integer >= 0")
    if foxglove_port is not None and not 0 < foxglove_port < 65536:
        fail(f"--foxglove-port = {foxglove_port}: expected a port from 1 to 65535")
    if port is not None and not port.isprintable():
        fail(f"--port = {port!r}: expected a serial device path or a pyserial URL")
    from softtip.realtime.sinks.factory import live_sinks
    from softtip.realtime.sinks.ros2 import ros2_available
    from softtip.systems.haptics.bench import FINGERTIP_NAMES, device_from_file
    from softtip.systems.haptics.fingertips import FINGERTIP_SENSOR, TEST_FINGERTIPS
    from softtip.systems.haptics.live import (LOOP_RATE_HZ, fs_renderer, recorded_sensation, render_stream,
                                              synthetic_sensation)
    from softtip.systems.haptics.personalisation import personalise_geometric
    from softtip.systems.haptics.rendering import NearestNeighbourRenderer
    from softtip.systems.haptics.servos import SerialDevice, SimulatedDevice, check_baud

    if fingertip not in FINGERTIP_NAMES:
        fail(f"--fingertip = {fingertip!r}: expected one of {', '.join(FINGERTIP_NAMES)}")
    if ros2 and not ros2_available():
        fail("--ros2: ROS 2 is not available (rclpy and the standard message packages do not import; source the "
             "ROS 2 setup script first)")
    inputs = [p for p in (sensation, device_file) if p is not None]
    if record is not None:
        record = check_output(record, "--record", inputs, force=force)
    device = device_from_file(device_file or "shipped").device
    check_baud(baud, device.servo.command_rate_hz, "--baud")
    wanted = recorded_sensation(sensation, duration) if sensation is not None else None
    rng = np.random.default_rng(seed)
    finger = next(f for f in TEST_FINGERTIPS if f.name == fingertip)
    # the port is the last check: opened before any work, released whatever happens next
    servos = (SimulatedDevice(device, finger, LOOP_RATE_HZ, rng) if port is None
              else SerialDevice(port, device, baud, "--port", "--baud"))
    try:
        sinks = live_sinks(dashboard=False, record=record, foxglove_port=foxglove_port, ros2=ros2)
        with progress_for(json_output).task("haptics: FS table", total=1) as task:
            renderer = fs_renderer(device, fs_levels, rng)
            task.advance()
        out_of_reach = 0
        if method == "geometric":
            personal = personalise_geometric(device, renderer.motor_inputs_, FINGERTIP_SENSOR.radius, finger.radius)
            renderer = NearestNeighbourRenderer(**renderer.get_params()).fit(renderer.features_, personal.motor_inputs)
            out_of_reach = int(personal.outside.sum())
        if wanted is None:
            wanted = synthetic_sensation(device, 5.0 if duration is None else duration, rng)
    except BaseException:
        servos.close()
        raise
    summary = render_stream(device, renderer, servos, wanted, sinks, metadata={
        "fingertip": fingertip, "method": method, "fs_levels": fs_levels, "seed": seed,
        "sensation": str(sensation) if sensation else "synthetic", "device": port or "simulated"},
        paced=realtime).to_dict()
    summary |= {"fingertip": fingertip, "method": method, "table_entries_out_of_reach": out_of_reach,
                "device": port or "simulated", "record": str(record) if record else None}
    if json_output:
        print(json.dumps(summary, indent=2))
        return
    error = ("not measured (a serial device reports no wrench)" if summary["median_error_N"] is None else
             f"median {summary['median_error_N']:.3f} N, p90 {summary['p90_error_N']:.3f} N")
    console.print(f"{summary['ticks']} ticks at 1 kHz on {fingertip} ({method}, {summary['device']} device), "
                  f"{summary['servo_frames']} servo commands, {summary['late_ticks']} late: rendering p99 "
                  f"{summary['latency_p99_us']:.1f} µs; |F_wanted − F_rendered| {error}; {summary['outside_table']} "
                  f"ticks outside the table, {out_of_reach} table entries out of reach"
                  + (f"; recorded to {record}" if record else ""))
