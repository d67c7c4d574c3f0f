"""``softtip bench``: speeds on this machine, each beside a baseline measured in the same run."""

from __future__ import annotations

import json
from enum import Enum
from pathlib import Path

import typer

from softtip.cli.common import FORCE, LONGEST_S, check_number, check_output, console, fail, progress_for
from softtip._core.systems import default


MAX_BATCH = 10_000_000  # samples or poses in one batch: some 1 GB of float64 field per sensor and magnet
MAX_CALLS = 10_000_000  # timed calls: minutes at the slowest single-sample latency measured


class RomFriction(str, Enum):  # contact on footprint cells adds Coulomb's law
    none = "none"
    stick = "stick"
    coulomb = "coulomb"



def bench_twin(
    design: str = typer.Option(default("bench"), help="Design to benchmark."),
    mesh_size: float = typer.Option(1.0, "--mesh-size", help="Mesh size (mm)."),
    poses: int = typer.Option(200_000, help="Batch size of magnet poses for the magnetics + sensor stage."),
    skip_neo_hookean: bool = typer.Option(False, "--skip-neo-hookean", help="Leave out the 3 mm neo-Hookean push."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Time the twin: mesh (built, and read from the cache), 1 mm board push with contact (vs one
    fixed-area linear solve), neo-Hookean 3 mm push, and magnetics + sensor readings per second (vs magpylib)."""
    from softtip.bench.twin import bench_twin as run
    from softtip.cli.twin import check_mesh_work
    from softtip.design.model import load_design

    check_number(mesh_size, "--mesh-size", above=0, maximum=1000, unit="mm")
    check_number(poses, "--poses", minimum=1, maximum=MAX_BATCH)
    check_mesh_work(load_design(design), mesh_size, force=False)

    report = run(design, mesh_size, poses, include_neo_hookean=not skip_neo_hookean,
                 log=None if json_output else console.print)
    if json_output:
        print(json.dumps(report, indent=2))


def bench_rom(
    design: str = typer.Option(default("bench"), help="Design to reduce."),
    samples: int = typer.Option(None, help="Exact contact samples to fit the interpolator on (default: 8000)."),
    holdout: int = typer.Option(12, help="Held-out finite-element solves for the error report."),
    save: Path = typer.Option(None, help="Save the reduced twin (npz + json) to this .npz file."),
    force: bool = FORCE,
    contact_layer_mm: float = typer.Option(None, "--contact-layer-mm",
                                           help="Element size (mm) in the layer indenters reach (default: 1.5 mm)."),
    friction: RomFriction = typer.Option(
        RomFriction.stick, help="Board friction: stick (the loads it holds at mu = 0.7) or coulomb (mu = 0.7)."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Build a reduced-order twin and measure its held-out FE error, batch speed and speed-up over FE."""
    from softtip.bench.twin import bench_rom as run

    check_number(samples, "--samples", minimum=50, maximum=1_000_000)
    check_number(holdout, "--holdout", minimum=2, maximum=10_000)
    if save is not None:
        if save.suffix.lower() != ".npz":  # the reduced twin's file is written as NAME.npz whatever was typed
            fail(f"--save {save}: expected a file name ending in .npz")
        check_output(save, "--save", [design] if Path(design).is_file() else [], force=force)
    if contact_layer_mm is not None and not 0.2 <= contact_layer_mm <= 1.5:
        fail(f"--contact-layer-mm = {contact_layer_mm}: expected an element size of 0.2 to 1.5 mm")
    report = run(design, samples, holdout, save=str(save) if save else None, contact_layer_mm=contact_layer_mm,
                 friction=friction.value, log=None if json_output else console.print, progress=progress_for(json_output))
    if json_output:
        print(json.dumps(report, indent=2))


def bench_live(
    duration: float = typer.Option(20.0, "--duration", help="Seconds of streaming (the full soak: 600)."),
    rate: int = typer.Option(500, "--rate", help="Frames per second."),
    chips: int = typer.Option(4, "--chips", help="Chips per frame."),
    faults: bool = typer.Option(False, "--faults", help="Inject corrupt and dropped bytes, stalls, chip errors."),
    start: bool = typer.Option(False, "--start", help="First time the start of live --emulate --scenario push "
                               "to its first frame, cold (an empty cache) then warm, before the soak."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Soak: emulator -> driver -> baseline -> a 12-20-4 network -> MCAP recorder; every frame counted,
    latency from arrival to estimate, CPU of the pipeline's process (emulator in another process)."""
    from softtip.hardware import FaultPlan
    from softtip.bench.live import soak, start_times
    from softtip.cli.live import MAX_CHIPS, MAX_RATE_HZ

    check_number(duration, "--duration", above=0, maximum=LONGEST_S, unit="s")
    check_number(rate, "--rate", minimum=1, maximum=MAX_RATE_HZ, unit="Hz")
    check_number(chips, "--chips", minimum=1, maximum=MAX_CHIPS)

    plan = FaultPlan(corrupt_every=97, drop_byte_every=131, stall_every=211, stall_ms=3, chip_error_every=53,
                     seed=1) if faults else None
    progress = progress_for(json_output)
    starts = {"start": start_times(progress=progress)} if start else {}
    with progress.task(f"soaking for {duration:g} s"):
        report = starts | soak(duration, rate, chips, plan)
    if json_output:
        print(json.dumps(report, indent=2, default=float))
    else:
        console.print(report)



def _check_firmware_folder(firmware: Path) -> None:
    """``--firmware``'s folder, refused in one line unless it holds the firmware's Makefile."""
    if firmware.exists() and not firmware.is_dir():
        fail(f"--firmware = {firmware}: expected a folder (the firmware folder of a softtip source checkout)")
    if not (firmware / "Makefile").is_file():
        fail(f"--firmware = {firmware}: expected the firmware folder of a softtip source checkout (its Makefile); "
             "a wheel does not install the firmware's sources")


def bench_firmware(
    chips: int = typer.Option(4, "--chips", help="Chips of the largest build (each count from 1 is measured)."),
    seconds: float = typer.Option(2.0, "--seconds", help="Simulated seconds of streaming per chip count."),
    fields: Path = typer.Option(None, "--fields", help="Text file of fields fed to the chips: one row per "
                                "conversion, x y z (µT) of each chip (default: the twin's, the default live "
                                "scenario's, computed once and cached as live --emulate caches them)."),
    export_fields: Path = typer.Option(None, "--export-fields", help="Write the fields the bench would feed its "
                                       "--chips chips to this file, in --fields' format, and stop (no build, no "
                                       "run)."),
    firmware: Path = typer.Option(None, "--firmware", help="The firmware folder of a softtip source checkout (its "
                                  "Makefile and sketch; default: the checkout softtip runs from, else ./firmware)."),
    force: bool = FORCE,
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """The firmware's own AVR build run in simavr with an emulated TCA9548A and MLX90393s, streaming to
    the host driver over a pseudo-terminal at 1,000,000 baud: frames per second per chip count, frames
    lost or damaged, latency from conversion to decoded frame, the fields read back, and the firmware's
    answer to each host command, to bad input and to bus faults. The chips read the twin's fields
    (the default live scenario's) unless --fields names a file."""
    from softtip.bench.firmware import (FIRMWARE_DIR, MAX_CHIPS, bench_firmware as run, file_fields, toolchain_missing,
                                        twin_fields, write_fields)
    from softtip.cli.common import check_input

    check_number(chips, "--chips", minimum=1, maximum=MAX_CHIPS)
    check_number(seconds, "--seconds", above=0, maximum=LONGEST_S, unit="s")
    fed = None if fields is None else file_fields(check_input(fields, "--fields"), chips)
    if firmware is not None:  # checked when given, even when only exporting: a mistake is named, not ignored
        _check_firmware_folder(firmware)
    progress = progress_for(json_output)
    if export_fields is not None:
        check_output(export_fields, "--export-fields", [fields] if fields is not None else [], force=force)
        fed = twin_fields(chips, progress) if fed is None else fed
        write_fields(export_fields, fed.fields_uT)
        written = {"export_fields": str(export_fields), "rows": len(fed.fields_uT), "chips": chips,
                   "source": fed.source}
        if json_output:
            print(json.dumps(written, indent=2))
        else:
            console.print(f"{written['rows']} rows of {chips} chip{'s' * (chips > 1)}' fields written to "
                          f"{export_fields}: {fed.source}", highlight=False, markup=False)
        return
    if firmware is None:
        firmware = FIRMWARE_DIR if FIRMWARE_DIR.is_dir() else Path("firmware")
        _check_firmware_folder(firmware)
    missing = toolchain_missing()
    if missing is not None:
        fail(f"bench firmware: {missing}")
    report = run(chips, seconds, progress=progress, fields=fed, firmware_dir=firmware)
    if json_output:
        print(json.dumps(report, indent=2))
        return
    console.print(f"fields fed to the chips: {report['fields']['source']}", highlight=False, markup=False)
    console.print(f"load average {', '.join(f'{v:.2f}' for v in report['load_average_before'])} before, "
                  f"{', '.join(f'{v:.2f}' for v in report['load_average_after'])} after; {report['cpus']} CPUs")
    for s in report["streams"]:
        latency, simulated, host = s["latency_oldest_chip"], s["latency_simulated_part"], s["latency_host_part"]
        console.print(f"{s['chips']} chip{'s' * (s['chips'] > 1)}: {s['frames_per_s']:.1f} frames/s (bus and "
                      f"conversion alone: {s['frames_per_s_bus_and_conversion_bound']:.0f}); "
                      f"{s['frames_received']}/{s['frames_sent']} frames received, {s['frames_lost']} lost, "
                      f"{s['crc_errors'] + s['malformed']} damaged, {s['frames_not_as_fed']} not as fed; latency "
                      f"p50 {latency['p50_ms']:.2f} / p99 {latency['p99_ms']:.2f} / max {latency['max_ms']:.2f} ms "
                      f"(on the board {simulated['p50_ms']:.2f} ms, host p99 {host['p99_ms']:.2f} ms; simulation at "
                      f"{s['realtime_factor']:.2f}x real time)")
    for answer in report["commands"]:
        mark = "[green]ok[/]" if answer["ok"] else "[red]WRONG[/]"
        console.print(f"  {answer['case']}: {answer['answer']} ({mark})", highlight=False)
    for fault in report["faults"]:
        console.print(f"  {fault['case']}: " + ", ".join(
            f"{k.replace('_', ' ')} {f'{v:.2f}' if isinstance(v, float) else v}" for k, v in fault.items() if k != "case"),
            highlight=False)



def bench_magnetics(
    poses: list[int] = typer.Option([100_000, 1_000_000], "--poses", help="Pose sets per batch (repeatable)."),
    sensors: list[int] = typer.Option([1, 2], "--sensors", help="Sensors (repeatable)."),
    magnets: int = typer.Option(4, "--magnets", help="Magnets per pose set."),
    repeats: int = typer.Option(3, "--repeats", help="Runs per batch; the fastest counts."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Readings per second of the exact field kernel, beside magpylib's on the same poses."""
    from softtip.bench.magnetics import bench_magnetics as run

    for option, values, most in (("--poses", poses, MAX_BATCH), ("--sensors", sensors, 1000), ("--magnets", [magnets], 1000),
                                 ("--repeats", [repeats], 1000)):
        for value in values:
            check_number(value, option, minimum=1, maximum=most)
    results = [run(n, magnets, s, repeats) for n in poses for s in sensors]
    if json_output:
        print(json.dumps(results, indent=2))
        return
    for r in results:
        console.print(f"{r['n_poses']:>9,} poses x {r['n_sensors']} sensor(s), {r['n_magnets']} magnets: "
                      f"{r['readings_per_second']:,.0f} readings/s; magpylib {r['magpylib_readings_per_second']:,.0f}; "
                      f"ratio {r['speedup_vs_magpylib']:.1f}x")


def bench_calibration(
    calls: int = typer.Option(20_000, "--calls", help="Single-sample calls timed."),
    batch: int = typer.Option(1_000_000, "--batch", help="Samples in the batch."),
    train: int = typer.Option(20_000, "--train", help="Training samples."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """One-sample estimate, batch throughput and Levenberg-Marquardt training time of a 6-20-2
    network, beside scikit-learn's MLPRegressor, the published polynomial and the published times."""
    from softtip.bench.calibration import bench_calibration as run

    check_number(calls, "--calls", minimum=100, maximum=MAX_CALLS)
    check_number(batch, "--batch", minimum=100, maximum=MAX_BATCH)
    check_number(train, "--train", minimum=100, maximum=1_000_000)
    with progress_for(json_output).task("timing the calibration models"):
        report = run(calls, batch, train)
    if json_output:
        print(json.dumps(report, indent=2))
        return
    console.print(f"{report['network']}; {report['machine']['cpus']} CPUs")
    for name, figures in report["single_sample_latency"].items():
        console.print(f"  {name:28s} median {figures['median_us']:8.2f} µs   p99 {figures['p99_us']:8.2f} µs")
    for name, rate in report["batch_samples_per_s"].items():
        console.print(f"  batch {name:22s} {rate / 1e6:8.2f} M samples/s")
    training = report["training"]
    console.print(f"  LM training on {training['samples']} samples: {training['seconds']:.2f} s, "
                  f"{training['epochs']} epochs, stop: {training['stop_reason']}")
    for name, ratio in report["ratios"].items():
        console.print(f"  {name:50s} {ratio:12.1f}x")


def bench_sysid(
    calls: int = typer.Option(20_000, "--calls", help="Streaming steps timed per model."),
    seed: int = typer.Option(0, "--seed", help="Seed of the synthetic recordings."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Fit times and validation fit % of a 3x3 transfer function (order 6) and state-space model (order 8)
    on 1,500 samples beside nfoursid and SIPPY (pip install 'softtip[bench]'), and streaming-step latency beside a
    numpy step."""
    from softtip._core.extras import require
    from softtip.bench.sysid import bench_sysid as run

    check_number(calls, "--calls", minimum=100, maximum=MAX_CALLS)
    check_number(seed, "--seed", minimum=0)
    require("softtip bench sysid (its baselines)", "bench", "nfoursid", "sippy_unipi")
    with progress_for(json_output).task("identifying and timing"):
        report = run(calls, seed)
    if json_output:
        print(json.dumps(report, indent=2))
        return
    console.print(f"{report['data']['estimation_samples']} estimation samples, {report['data']['validation_samples']} "
                  f"validation samples at {report['data']['ts']:g} s; {report['machine']['cpus']} CPUs")
    for name in ("transfer_function_order_6", "state_space_order_8", "state_space_order_8_refined", "nfoursid_order_8"):
        figures = report[name]
        fits = ", ".join(f"{v:.1f}" for v in figures["validation_fit_percent"])
        console.print(f"  {name:30s} {figures['seconds']:7.3f} s   validation fit % {fits}")
    console.print(f"  SIPPY: {report['sippy']['note']}")
    for name, figures in report["streaming_step_us"].items():
        console.print(f"  step {name:42s} median {figures['median_us']:6.2f} µs   p99 {figures['p99_us']:6.2f} µs")
    start = report["start"]
    console.print(f"  start (best of {start['repeats']} processes, load average "
                  f"{', '.join(f'{v:.2f}' for v in start['load_average'])}): python alone "
                  f"{start['interpreter_s']:.2f} s, import softtip.sysid {start['import_sysid_s']:.2f} s, sysid --help "
                  f"{start['help_s']:.2f} s, a 200-sample sysid fit {start['fit_s']:.2f} s (CSV), "
                  f"{start['fit_parquet_s']:.2f} s (Parquet)")
    for name, met in report["targets_met"].items():
        console.print(f"  target {name} <= {report['targets'][name]:g}: {'met' if met else '[red]missed[/]'}")
    for name, ratio in report["ratios"].items():
        console.print(f"  {name:45s} {ratio:10.2f}")


def bench_studies(
    studies: list[str] = typer.Argument(None, help="Studies to time (default: all of them)."),
    jobs: int = typer.Option(None, "--jobs", "-j", help="Processes of the parallel run (default: one per core)."),
    seed: int = typer.Option(1, "--seed", help="Seed of the experiments and the models."),
    quick: bool = typer.Option(False, "--quick", help="Each study's smoke run (reproduce --quick)."),
    cold: bool = typer.Option(False, "--cold", help="Each run on an empty cache of its own (default: the cache as "
                                                    "it is; an empty one is filled by the serial run)."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Reproduce the studies one after another, then in a pool of processes, in one call: wall and CPU
    time of each run, each study's time, the load average, and the parallel run's speed-up."""
    from softtip.bench.studies import bench_studies as run
    from softtip.cli.lab import MAX_JOBS, chosen_studies
    from softtip.studies.reproduce import default_workers

    names = chosen_studies(studies)
    check_number(jobs, "--jobs", minimum=1, maximum=MAX_JOBS)
    check_number(seed, "--seed", minimum=0)
    report = run(names, jobs or default_workers(), seed=seed, quick=quick, cold=cold,
                 progress=progress_for(json_output))
    if json_output:
        print(json.dumps(report, indent=2))
        return
    for name in ("serial", "parallel"):
        timed = report[name]
        console.print(f"{name:8s} ({timed['workers']} process{'es' if timed['workers'] > 1 else ''}): wall "
                      f"{timed['wall_s']:.1f} s, CPU {timed['cpu_s']:.1f} s; load average before "
                      f"{', '.join(f'{v:.2f}' for v in timed['load_average_before'])}, after "
                      f"{', '.join(f'{v:.2f}' for v in timed['load_average_after'])}")
    console.print(f"speed-up of the parallel run: {report['speedup']:.2f}x on {report['cpus']} CPUs")
