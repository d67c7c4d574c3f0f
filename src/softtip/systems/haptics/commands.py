"""S3's commands: ``softtip bench haptics`` and ``softtip haptics render``."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np
import typer
from rich.table import Table

from softtip._core.files import atomic_write
from softtip.cli.common import check_output, check_outputs, claimed, console, fail, progress_for
from softtip.systems.haptics.limits import DURATION_EXPECTED, LEVELS_EXPECTED, MAX_DURATION_S, MAX_FS_LEVELS

app = typer.Typer(help="S3: personalised haptic rendering with the 3-cable fingertip device.", no_args_is_help=True)

RENDER_P99_TARGET_S, TABLE_BUILD_TARGET_S, REPRODUCE_TARGET_S = 50e-6, 0.1, 30.0


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


def _fingertip(value: str, option: str):
    """A shipped test fingertip's name, or a fingertip TOML file (refused in one line)."""
    from softtip.systems.haptics.bench import FINGERTIP_NAMES
    from softtip.systems.haptics.fingertip_file import load_fingertip
    from softtip.systems.haptics.fingertips import TEST_FINGERTIPS

    if value in FINGERTIP_NAMES:
        return next(f for f in TEST_FINGERTIPS if f.name == value)
    if not value.endswith(".toml"):
        fail(f"{option} = {value!r}: expected one of {', '.join(FINGERTIP_NAMES)}, or a fingertip .toml file")
    return load_fingertip(value)


def _file(fingertip: str) -> Path | None:
    return Path(fingertip) if fingertip.endswith(".toml") else None


def _check_choices(method: str, fs_levels: int, seed: int) -> None:
    if method not in ("standard", "geometric"):
        fail(f"--method = {method!r}: expected standard or geometric")
    if not 2 <= fs_levels <= MAX_FS_LEVELS:
        fail(f"--fs-levels = {fs_levels}: expected {LEVELS_EXPECTED}")
    if seed < 0:
        fail(f"--seed = {seed}: expected an integer >= 0")


def _renderer(device, renderer, fs_levels: int, rng: np.random.Generator, method: str, finger, progress):
    """The renderer for ``finger``: ``renderer`` (a recorded table's), or one on a simulated FS table of
    ``fs_levels``³ configurations, personalised by ``method``; and how many entries the geometric
    method could not reach."""
    from softtip.systems.haptics.fingertips import FINGERTIP_SENSOR
    from softtip.systems.haptics.live import fs_renderer
    from softtip.systems.haptics.personalisation import personalise_geometric
    from softtip.systems.haptics.rendering import NearestNeighbourRenderer

    if renderer is None:
        with progress.task("haptics: FS table", total=1) as task:
            renderer = fs_renderer(device, fs_levels, rng)
            task.advance()
    if method != "geometric":
        return renderer, 0
    personal = personalise_geometric(device, renderer.motor_inputs_, FINGERTIP_SENSOR.radius, finger.radius)
    personalised = NearestNeighbourRenderer(**renderer.get_params()).fit(renderer.features_, personal.motor_inputs)
    return personalised, int(personal.outside.sum())


@app.command("render")
def render(
    duration: float = typer.Option(None, "--duration", help="Seconds to render (default: 5 s synthetic, or the "
                                                            "whole file)."),
    sensation: Path = typer.Option(None, "--sensation", help="A recorded sensation (.csv or .parquet: time_s, fx_N, "
                                                             "fy_N, fz_N); default a synthetic one."),
    fingertip: str = typer.Option("FS cast (7.5 mm)", "--fingertip",
                                  help="The test fingertip in the device: a shipped one's name or a fingertip .toml "
                                       "file."),
    method: str = typer.Option("standard", "--method", help="standard or geometric (B, for --fingertip's radius)."),
    device_file: Path = typer.Option(None, "--device", help="A device TOML file (default softtip's device)."),
    table_file: Path = typer.Option(None, "--table", help="A recorded lookup table (.csv or .parquet: fx_N, fy_N, "
                                                          "fz_N [, tx_Nm, ty_Nm, tz_Nm], motor1_rad.. or motor1_deg..) "
                                                          "instead of a simulated FS table."),
    fs_levels: int = typer.Option(13, "--fs-levels", help="Simulated FS table levels per servo (13: 13³ entries), "
                                                          "without --table."),
    seed: int = typer.Option(1, "--seed", help="Seed of the table collection, the synthetic sensation and the noise."),
    record: Path = typer.Option(None, "--record", help="Record the stream to this MCAP file."),
    foxglove_port: int = typer.Option(None, "--foxglove-port", help="Serve a Foxglove live view on this port."),
    ros2: bool = typer.Option(False, "--ros2", help="Publish on ROS 2 topics (pip install 'softtip[ros2]')."),
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
        fail(f"--duration = {duration}: expected {DURATION_EXPECTED}")
    _check_choices(method, fs_levels, seed)
    if foxglove_port is not None and not 0 < foxglove_port < 65536:
        fail(f"--foxglove-port = {foxglove_port}: expected a port from 1 to 65535")
    if port is not None and not port.isprintable():
        fail(f"--port = {port!r}: expected a serial device path or a pyserial URL")
    from softtip.realtime.sinks.factory import live_sinks
    from softtip.realtime.sinks.ros2 import ros2_problem
    from softtip.systems.haptics.bench import device_from_file
    from softtip.systems.haptics.live import LOOP_RATE_HZ, recorded_sensation, render_stream, synthetic_sensation
    from softtip.systems.haptics.servos import SerialDevice, SimulatedDevice, check_baud
    from softtip.systems.haptics.table_files import read_table

    finger = _fingertip(fingertip, "--fingertip")
    if ros2 and (problem := ros2_problem()) is not None:
        fail(f"--ros2: {problem}")
    inputs = [p for p in (sensation, device_file, table_file, _file(fingertip)) if p is not None]
    if record is not None:
        record = check_output(record, "--record", inputs, force=force)
    device = device_from_file(device_file or "shipped").device
    check_baud(baud, device.servo.command_rate_hz, "--baud")
    table = read_table(table_file, device) if table_file else None
    recorded = table.renderer() if table else None
    wanted = recorded_sensation(sensation, duration) if sensation is not None else None
    rng = np.random.default_rng(seed)
    with claimed(record, "--record"):  # a second render recording to the same file is refused
        # the port is the last check: opened before any work, released whatever happens next
        servos = (SimulatedDevice(device, finger, LOOP_RATE_HZ, rng) if port is None
                  else SerialDevice(port, device, baud, "--port", "--baud"))
        try:
            sinks = live_sinks(dashboard=False, record=record, foxglove_port=foxglove_port, ros2=ros2)
            renderer, out_of_reach = _renderer(device, recorded, fs_levels, rng, method, finger,
                                               progress_for(json_output))
            if wanted is None:
                wanted = synthetic_sensation(device, 5.0 if duration is None else duration, rng)
        except BaseException:
            servos.close()
            raise
        source = str(table_file) if table_file else f"simulated FS table, {fs_levels}³"
        summary = render_stream(device, renderer, servos, wanted, sinks, metadata={
            "fingertip": finger.name, "method": method, "table": source, "seed": seed,
            "sensation": str(sensation) if sensation else "synthetic", "device": port or "simulated"},
            paced=realtime).to_dict()
    summary |= {"fingertip": finger.name, "method": method, "table": source,
                "table_entries_out_of_reach": out_of_reach, "device": port or "simulated",
                "record": str(record) if record else None}
    if json_output:
        print(json.dumps(summary, indent=2))
        return
    error = ("not measured (a serial device reports no wrench)" if summary["median_error_N"] is None else
             f"median {summary['median_error_N']:.3f} N, p90 {summary['p90_error_N']:.3f} N")
    console.print(f"{summary['ticks']} ticks at 1 kHz on {finger.name} ({method}, {summary['device']} device), "
                  f"{summary['servo_frames']} servo commands, {summary['late_ticks']} late: rendering p99 "
                  f"{summary['latency_p99_us']:.1f} µs; |F_wanted − F_rendered| {error}; {summary['outside_table']} "
                  f"ticks outside the table, {out_of_reach} table entries out of reach"
                  + (f"; recorded to {record}" if record else ""))


table_app = typer.Typer(help="Lookup tables: export one for a device's firmware.", no_args_is_help=True)
app.add_typer(table_app, name="table")


@table_app.command("export")
def export_table(
    header: Path = typer.Argument(..., help="The C header to write (.h): the table as const float arrays."),
    csv_file: Path = typer.Option(None, "--csv", help="Also write the same entries as a table file (.csv)."),
    fingertip: str = typer.Option("FS cast (7.5 mm)", "--fingertip", help="The user's fingertip (for --method "
                                                                         "geometric): a shipped one's name or a "
                                                                         "fingertip .toml file."),
    method: str = typer.Option("standard", "--method", help="standard or geometric (B, for --fingertip's radius)."),
    device_file: Path = typer.Option(None, "--device", help="A device TOML file (default softtip's device)."),
    table_file: Path = typer.Option(None, "--table", help="A recorded lookup table (.csv or .parquet) instead of a "
                                                          "simulated FS table."),
    fs_levels: int = typer.Option(13, "--fs-levels", help="Simulated FS table levels per servo, without --table."),
    seed: int = typer.Option(1, "--seed", help="Seed of the simulated table collection (the study's at that seed)."),
    fs_table_file: Path = typer.Option(None, "--fs-table", help="Also write the FS table as collected, one row per "
                                                                "configuration (.csv): the FS's wrench, the DS's "
                                                                "(ds_*) and the motor inputs in rad, what a haptics "
                                                                "protocol's fs_table reads (--method standard)."),
    force: bool = typer.Option(False, "--force", help="Replace output files that exist."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Write a lookup table for a device's firmware: the renderer's entries (forces in N, motor inputs
    in degrees) as a C header of const arrays with its settings as macros, and with --csv as a CSV;
    with --fs-table, the FS table itself for a protocol's ``fs_table``."""
    _check_choices(method, fs_levels, seed)
    from softtip.systems.haptics.bench import device_from_file
    from softtip.systems.haptics.rendering import NearestNeighbourRenderer
    from softtip.systems.haptics.table_files import c_header, read_table, write_fs_table_csv, write_table_csv

    inputs = [p for p in (device_file, table_file, _file(fingertip)) if p is not None]
    if header.suffix != ".h":
        fail(f"header = {header}: expected a C header file name ending in .h")
    for option, path in (("--csv", csv_file), ("--fs-table", fs_table_file)):
        if path is not None and path.suffix.lower() != ".csv":
            fail(f"{option} = {path}: expected a file name ending in .csv")
    if fs_table_file is not None and method != "standard":
        fail(f"--fs-table with --method = {method!r}: expected --method standard (a protocol's fs_table is the FS's "
             "own collection, which the study personalises)")
    check_outputs([("header", header), ("--csv", csv_file), ("--fs-table", fs_table_file)], inputs, force=force)
    finger = _fingertip(fingertip, "--fingertip")
    device = device_from_file(device_file or "shipped").device
    table = read_table(table_file, device) if table_file else None
    if table is not None and fs_table_file is not None and table.platform_wrenches is None:
        fail(f"--fs-table: the table file {table_file} has no DS readings (ds_fx_N ... ds_tz_Nm), which a protocol's "
             "fs_table needs")
    collected = None if table else _study_fs_table(device, fs_levels, seed, progress_for(json_output))
    indexed = (table.renderer() if table else
               NearestNeighbourRenderer().fit(collected.finger_wrenches, collected.motor_inputs))
    renderer, out_of_reach = _renderer(device, indexed, fs_levels, np.random.default_rng(seed), method, finger,
                                       progress_for(json_output))
    source = f"table file {table_file.name}" if table_file else f"simulated {fs_levels}³ FS table, seed {seed}"
    provenance = (f"{source} on {device.device.name}, {method}"
                  + (f" for {finger.name}" if method == "geometric" else ""))
    atomic_write(header, c_header(renderer, "SOFTTIP_HAPTICS_TABLE_H", provenance.replace("*/", "* /")))
    if csv_file is not None:
        write_table_csv(csv_file, renderer)
    if fs_table_file is not None:
        write_fs_table_csv(fs_table_file, *((table.wrenches, table.platform_wrenches, table.motor_inputs) if table
                                            else (collected.finger_wrenches, collected.platform_wrenches,
                                                  collected.motor_inputs)))
    summary = {"header": str(header), "csv": str(csv_file) if csv_file else None,
               "fs_table": str(fs_table_file) if fs_table_file else None, "entries": len(renderer.features_),
               "file_rows_merged": table.merged if table is not None else 0,
               "entries_out_of_reach": out_of_reach, "provenance": provenance}
    if json_output:
        print(json.dumps(summary, indent=2))
        return
    console.print(f"{summary['entries']} entries (those without contact as one) written to {header}"
                  + (f" and {csv_file}" if csv_file else "") + (f"; the FS table to {fs_table_file}" if fs_table_file
                                                                else "") + f": {provenance}")


def _study_fs_table(device, fs_levels: int, seed: int, progress):
    """The FS table the study collects on ``device`` at ``seed`` (its own noise stream, the protocol's
    default hold and window): a protocol reading it as its fs_table renders as one simulating it."""
    from softtip.systems.haptics.collection import CollectionSettings
    from softtip.systems.haptics.study import fs_table

    with progress.task("haptics: FS table", total=1) as task:
        collected = fs_table(device, fs_levels, CollectionSettings(), seed)
        task.advance()
    return collected
