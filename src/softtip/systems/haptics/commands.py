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
from softtip.cli.common import check_output, check_outputs, claimed, console, errors, fail, progress_for
from softtip.systems.haptics.limits import (
    DURATION_EXPECTED,
    LEVELS_EXPECTED,
    MAX_DURATION_S,
    MAX_FS_LEVELS,
    METHOD_ALIASES,
    SHORT_NAMES,
    USER_DATA_METHODS,
)

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


def bench_haptics_loop(
    seconds: float = typer.Option(5.0, "--seconds", help="Seconds each run of the loop renders."),
    record: bool = typer.Option(True, "--record/--no-record", help="Record each run to a temporary MCAP file, as "
                                                                   "`haptics render --record` does."),
    seed: int = typer.Option(1, "--seed", help="Seed of the table, the synthetic sensation and the noise."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """The 1 kHz render loop's lateness (each tick's start after its deadline) on this machine: idle, and
    with a spinning process on every other CPU; each with real-time priority asked for, beside the same
    run at normal priority as the baseline; with the load average around each run."""
    _finite_positive(seconds, "--seconds")
    if not 0.1 <= seconds <= 600:
        fail(f"--seconds = {seconds}: expected from 0.1 to 600")
    if seed < 0:
        fail(f"--seed = {seed}: expected an integer >= 0")
    from softtip.systems.haptics.live import bench_loop

    with progress_for(json_output).task("haptics loop: idle and loaded, real-time and baseline", total=1) as task:
        report = bench_loop(seconds, record, seed)
        task.advance()
    if json_output:
        print(json.dumps(report, indent=2))
        return
    table = Table(title=f"softtip bench haptics-loop ({seconds:g} s a run" + (", recorded" if record else "")
                        + f"; loaded: CPUs {report['loaded']['busy_cpus']} spinning)")
    for column in ("case", "run", "lateness p50/p99/max µs", "> 1 ms late", "p99 target", "load", "granted"):
        table.add_column(column, justify="right")
    for case in ("idle", "loaded"):
        for kind in ("real-time", "baseline"):
            run = report[case][kind]
            verdict = ("" if kind == "baseline" else
                       f"≤ {report['targets_p99_us'][case]:.0f} " + ("✓" if report[case]["meets_target"] else "✗"))
            table.add_row(case, kind, f"{run['lateness_p50_us']:.0f} / {run['lateness_p99_us']:.0f} / "
                                      f"{run['lateness_max_us']:.0f}", f"{run['late_ticks']} of {run['ticks']}",
                          verdict, f"{run['load_average_before'][0]:.2f}", run["timing"]["granted"])
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


METHOD_CHOICES = (*SHORT_NAMES, *METHOD_ALIASES)
METHOD_HELP = ("standard; A (data-driven: the user's table on the device model); B (geometric, for --fingertip's "
               "radius); B+ (B with the user's stiffness from five presses); A+ (A from an adaptive user table); "
               "data-driven and geometric name A and B")


def _check_choices(method: str, fs_levels: int, seed: int) -> None:
    if method not in METHOD_CHOICES:
        fail(f"--method = {method!r}: expected one of {', '.join(METHOD_CHOICES)}")
    if not 2 <= fs_levels <= MAX_FS_LEVELS:
        fail(f"--fs-levels = {fs_levels}: expected {LEVELS_EXPECTED}")
    if seed < 0:
        fail(f"--seed = {seed}: expected an integer >= 0")


def _table(table_file: Path | None, device, method: str):
    """The recorded table ``table_file`` (None without one), refused in one line naming it if the renderer
    cannot index it, or if ``method`` is A or A+ and it has no DS readings to personalise it by."""
    from softtip.systems.haptics.table_files import read_table

    if table_file is None:
        return None
    table = read_table(table_file, device)
    table.renderer()
    if method in ("A", "A+") and table.platform_wrenches is None:
        fail(f"--method {method} with --table {table_file}: {method} personalises the table by its DS readings "
             "(ds_fx_N .. ds_tz_Nm), which the file has none of")
    return table


def _renderer(device, motor_inputs, finger_wrenches, platform_wrenches, method: str, finger, seed: int, progress,
              drive=None):
    """The renderer on an FS table (its arrays) for ``finger``, personalised by ``method`` (the user's
    data driven by ``drive``, else on the device model), and how many entries the personalisation flagged."""
    from softtip.systems.haptics.live import personalised_renderer

    with progress.task(f"haptics: the table personalised ({method})", total=1) as task:
        made = personalised_renderer(device, method, finger, motor_inputs, finger_wrenches, platform_wrenches, seed,
                                     drive=drive)
        task.advance()
    return made


def _driven_on(servos, finger, paced: bool, progress):
    """How the user's data are driven on a real device: each batch of configurations through
    ``servos`` (a :class:`~.servos.SerialDevice`) with a progress bar of its own."""
    from softtip.systems.haptics.collection import CollectionSettings

    def drive(motor_inputs):
        with progress.task(f"haptics: {len(motor_inputs)} configurations driven on the device and read back",
                           total=len(motor_inputs)) as task:
            return servos.collect(finger, motor_inputs, CollectionSettings(), paced, task)
    return drive


def _fs_table(device, fs_levels: int, rng: np.random.Generator, progress):
    """A simulated FS table of ``fs_levels``³ configurations on ``device``, its saturated entries left out."""
    from softtip.systems.haptics.live import fs_collection

    with progress.task("haptics: FS table", total=1) as task:
        table = fs_collection(device, fs_levels, rng)
        task.advance()
    return table


@app.command("render")
def render(
    duration: float = typer.Option(None, "--duration", help="Seconds to render (default: a synthetic sensation "
                                                            "until Ctrl-C, or the whole --sensation file)."),
    sensation: Path = typer.Option(None, "--sensation", help="A recorded sensation (.csv or .parquet: time_s, fx_N, "
                                                             "fy_N, fz_N); default a synthetic one."),
    fingertip: str = typer.Option("FS cast (7.5 mm)", "--fingertip",
                                  help="The test fingertip in the device: a shipped one's name or a fingertip .toml "
                                       "file."),
    method: str = typer.Option("standard", "--method", help=METHOD_HELP + "."),
    device_file: Path = typer.Option(None, "--device", help="A device TOML file (default softtip's device)."),
    table_file: Path = typer.Option(None, "--table", help="A recorded lookup table (.csv or .parquet: fx_N, fy_N, "
                                                          "fz_N [, tx_Nm, ty_Nm, tz_Nm], motor1_rad.. or motor1_deg.. "
                                                          "[, ds_fx_N .. ds_tz_Nm for A and A+]) instead of a "
                                                          "simulated FS table."),
    fs_levels: int = typer.Option(13, "--fs-levels", help="Simulated FS table levels per servo (13: 13³ entries), "
                                                          "without --table."),
    seed: int = typer.Option(1, "--seed", help="Seed of the table collection, the synthetic sensation and the noise."),
    record: Path = typer.Option(None, "--record", help="Record the stream to this MCAP file."),
    foxglove_port: int = typer.Option(None, "--foxglove-port", help="Serve a Foxglove live view on this port."),
    ros2: bool = typer.Option(False, "--ros2", help="Publish on ROS 2 topics (pip install 'softtip[ros2]')."),
    realtime: bool = typer.Option(True, "--realtime/--fast", help="Pace the loop to its 1 kHz deadlines, or run "
                                                                  "it as fast as the machine allows."),
    priority: bool = typer.Option(True, "--priority/--no-priority", help="Run the paced loop at real-time priority "
                                                                         "(SCHED_FIFO) pinned to one CPU, where Linux "
                                                                         "permits it."),
    port: str = typer.Option(None, "--port", help="Drive a real device: its controller's serial port (a device path "
                                                  "or a pyserial URL), in the line protocol of "
                                                  "softtip.systems.haptics.servos; default the device model. "
                                                  "--method A, B+ and A+ drive the user's data on it first and read "
                                                  "them from its wrench reports (W lines, version 2)."),
    baud: int = typer.Option(115_200, "--baud", help="--port's baud rate (8N1)."),
    force: bool = typer.Option(False, "--force", help="Overwrite --record's file."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Stream a sensation through the renderer to the device model, or with --port to a real device: a
    loop on 1 kHz deadlines rendering a command at each of the servos' 50 Hz frames, out on the live
    sinks (MCAP, Foxglove) with each tick's measured start; Ctrl-C ends it, keeping the recording."""
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
    from softtip.realtime.sinks.foxglove import FoxgloveSink
    from softtip.realtime.sinks.ros2 import ros2_problem
    from softtip.systems.haptics.bench import device_from_file
    from softtip.systems.haptics.live import (
        LOOP_RATE_HZ,
        recorded_sensation,
        render_stream,
        synthetic_holds,
        synthetic_sensation,
    )
    from softtip.systems.haptics.servos import NoWrenchReports, SerialDevice, SimulatedDevice, check_baud

    method = METHOD_ALIASES.get(method, method)
    finger = _fingertip(fingertip, "--fingertip")
    if ros2 and (problem := ros2_problem()) is not None:
        fail(f"--ros2: {problem}")
    inputs = [p for p in (sensation, device_file, table_file, _file(fingertip)) if p is not None]
    if record is not None:
        record = check_output(record, "--record", inputs, force=force)
    device = device_from_file(device_file or "shipped").device
    check_baud(baud, device.servo.command_rate_hz, "--baud")
    table = _table(table_file, device, method)
    wanted = recorded_sensation(sensation, duration) if sensation is not None else None
    rng = np.random.default_rng(seed)
    progress = progress_for(json_output)
    with claimed(record, "--record"):  # a second render recording to the same file is refused
        # the port is the last check: opened before any work, released whatever happens next
        servos = (SimulatedDevice(device, finger, LOOP_RATE_HZ, rng) if port is None
                  else SerialDevice(port, device, baud, "--port", "--baud"))
        try:
            sinks = live_sinks(dashboard=False, record=record, foxglove_port=foxglove_port, ros2=ros2)
            fs = table if table is not None else _fs_table(device, fs_levels, rng, progress)
            # with --port, A, B+ and A+ drive the user's data on the device and read its wrench reports
            on_device = port is not None and method in USER_DATA_METHODS
            try:
                renderer, out_of_reach = _renderer(
                    device, fs.motor_inputs, fs.wrenches if table is not None else fs.finger_wrenches,
                    fs.platform_wrenches, method, finger, seed, progress,
                    _driven_on(servos, finger, realtime, progress) if on_device else None)
            except NoWrenchReports as problem:
                fail(f"--method {method} with --port: {problem}; {method} reads the user's fingertip by the device's "
                     "sensor (a device without one takes --method standard or B)")
            if wanted is None:
                wanted = (synthetic_holds(device, rng, batch=1) if duration is None else
                          synthetic_sensation(device, duration, rng))
        except BaseException:
            servos.close()
            raise
        for sink in sinks:
            if isinstance(sink, FoxgloveSink):
                errors.print(sink.where_to_open(), markup=False, highlight=False, soft_wrap=True)
        if duration is None and sensation is None:
            errors.print("rendering until Ctrl-C", highlight=False)
        source = str(table_file) if table_file else f"simulated FS table, {fs_levels}³"
        summary = render_stream(device, renderer, servos, wanted, sinks, metadata={
            "fingertip": finger.name, "method": method, "table": source, "seed": seed,
            "sensation": str(sensation) if sensation else "synthetic", "device": port or "simulated"},
            paced=realtime, realtime=priority).to_dict()
    summary |= {"fingertip": finger.name, "method": method, "table": source,
                "table_entries_flagged": out_of_reach, "device": port or "simulated",
                "user_data_read_by": None if method not in USER_DATA_METHODS else "device" if on_device
                else "device model",
                "record": str(record) if record else None}
    if json_output:
        print(json.dumps(summary, indent=2))
        return
    console.print(_render_line(summary, finger.name, record), highlight=False)


def _render_line(summary: dict, finger: str, record: Path | None) -> str:
    """What ``haptics render`` did, in words."""
    error = (f"median {summary['median_error_N']:.3f} N, p90 {summary['p90_error_N']:.3f} N (read by the "
             f"{summary['error_measured_by']})" if summary["median_error_N"] is not None
             else "not measured (the device reports no wrench)")
    lateness = ("not paced (--fast)" if summary["lateness_p50_us"] is None else
                f"p50 {summary['lateness_p50_us']:.0f} µs, p99 {summary['lateness_p99_us']:.0f} µs, max "
                f"{summary['lateness_max_us']:.0f} µs, {summary['late_ticks']} ticks over a period late "
                f"({summary['timing']['granted']})")
    return (f"{summary['ticks']} ticks at 1 kHz on {finger} ({summary['method']}, {summary['device']} device)"
            + (", ended by Ctrl-C" if summary["interrupted"] else "")
            + f"; {summary['renderings']} renderings, one per servo command: p99 {summary['latency_p99_us']:.1f} µs"
            + f"; ticks' start after their deadline: {lateness}"
            + f"; |F_wanted − F_rendered| {error}; {summary['outside_table']} renderings outside the table, "
            + f"{summary['table_entries_flagged']} table entries flagged"
            + (f"; recorded to {record}" if record else ""))


table_app = typer.Typer(help="Lookup tables: export one for a device's firmware.", no_args_is_help=True)
app.add_typer(table_app, name="table")


@table_app.command("export")
def export_table(
    header: Path = typer.Argument(..., help="The C header to write (.h): the table as const float arrays."),
    csv_file: Path = typer.Option(None, "--csv", help="Also write the same entries as a table file (.csv)."),
    fingertip: str = typer.Option("FS cast (7.5 mm)", "--fingertip", help="The user's fingertip (for a --method "
                                                                         "other than standard): a shipped one's name or a "
                                                                         "fingertip .toml file."),
    method: str = typer.Option("standard", "--method", help=METHOD_HELP + "."),
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
    from softtip.systems.haptics.table_files import c_header, write_fs_table_csv, write_table_csv

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
    method = METHOD_ALIASES.get(method, method)
    finger = _fingertip(fingertip, "--fingertip")
    device = device_from_file(device_file or "shipped").device
    table = _table(table_file, device, method)
    if table is not None and fs_table_file is not None and table.platform_wrenches is None:
        fail(f"--fs-table: the table file {table_file} has no DS readings (ds_fx_N ... ds_tz_Nm), which a protocol's "
             "fs_table needs")
    fs = table if table is not None else _study_fs_table(device, fs_levels, seed, progress_for(json_output))
    renderer, out_of_reach = _renderer(device, fs.motor_inputs, fs.wrenches if table is not None else
                                       fs.finger_wrenches, fs.platform_wrenches, method, finger, seed,
                                       progress_for(json_output))
    source = f"table file {table_file.name}" if table_file else f"simulated {fs_levels}³ FS table, seed {seed}"
    provenance = (f"{source} on {device.device.name}, {method}"
                  + (f" for {finger.name}" if method != "standard" else ""))
    atomic_write(header, c_header(renderer, "SOFTTIP_HAPTICS_TABLE_H", provenance.replace("*/", "* /")))
    if csv_file is not None:
        write_table_csv(csv_file, renderer)
    if fs_table_file is not None:
        write_fs_table_csv(fs_table_file, table.wrenches if table is not None else fs.finger_wrenches,
                           fs.platform_wrenches, fs.motor_inputs)
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
