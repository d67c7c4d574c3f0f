"""The ``softtip`` command line: a thin layer over the library."""

from __future__ import annotations

import contextlib
import json
import sys
from enum import Enum
from pathlib import Path

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from softtip import __version__

app = typer.Typer(help="softtip: soft magnetic tactile fingertips, from design to real-time estimates.",
                  no_args_is_help=True, add_completion=False, pretty_exceptions_enable=False)
bench_app = typer.Typer(help="Benchmarks measured on this machine (ratios against baselines of the same run).",
                        no_args_is_help=True)
app.add_typer(bench_app, name="bench")
console = Console()
errors = Console(stderr=True)


class IndenterKind(str, Enum):
    board = "board"
    plate = "plate"
    sphere = "sphere"


class Friction(str, Enum):
    none = "none"
    stick = "stick"


class RomFriction(str, Enum):  # contact on footprint cells adds Coulomb's law
    none = "none"
    stick = "stick"
    coulomb = "coulomb"


class Model(str, Enum):
    linear = "linear"
    neo_hookean = "neo-hookean"


class Switch(str, Enum):
    on = "on"
    off = "off"


def status(message: str, quiet: bool):
    """A spinner with ``message`` on the terminal, nothing when the output is JSON."""
    return contextlib.nullcontext() if quiet else console.status(message)


def fail(message: str) -> None:
    """A user mistake: one line, no traceback, exit code 2."""
    errors.print(f"[bold red]error:[/] {message}", highlight=False, soft_wrap=True)
    raise typer.Exit(2)


def user_errors(function):
    """Turn the library's validation errors into one-line messages."""
    import functools

    from softtip.design.model import DesignError

    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        try:
            return function(*args, **kwargs)
        except (DesignError, ValueError) as error:
            fail(str(error))

    return wrapper


@app.callback(invoke_without_command=True)
def main(version: bool = typer.Option(False, "--version", help="Print the version and exit.")) -> None:
    if version:
        console.print(f"softtip {__version__}")
        raise typer.Exit()


@app.command()
@user_errors
def designs(json_output: bool = typer.Option(False, "--json", help="Print JSON.")) -> None:
    """List the shipped fingertip designs."""
    from softtip.design.model import load_design, shipped_designs

    rows = [{"name": name, "kind": (d := load_design(name)).kind, "description": d.spec.get("description", ""),
             "magnets": len(d.magnets), "sensors": len(d.sensor_positions)} for name in shipped_designs()]
    if json_output:
        print(json.dumps(rows, indent=2))
        return
    table = Table(title="shipped designs")
    for column in ("name", "kind", "magnets", "sensors", "description"):
        table.add_column(column)
    for row in rows:
        table.add_row(*(str(row[c]) for c in ("name", "kind", "magnets", "sensors", "description")))
    console.print(table)


@app.command()
@user_errors
def simulate(
    design: str = typer.Option("cylindrical-A", help="Shipped design name or path to a design TOML file."),
    indenter: IndenterKind = typer.Option(IndenterKind.board, help="Rigid indenter."),
    depth: float = typer.Option(1.0, help="Normal travel after first touch (mm)."),
    angle: float = typer.Option(0.0, help="Board angle about the vertical axis (degrees)."),
    thickness: float = typer.Option(1.6, help="Board thickness (mm)."),
    radius: float = typer.Option(5.0, help="Sphere radius (mm)."),
    shear_x: float = typer.Option(0.0, "--shear-x", help="Tangential travel along x after the push (mm)."),
    shear_y: float = typer.Option(0.0, "--shear-y", help="Tangential travel along y after the push (mm)."),
    x: float = typer.Option(0.0, help="Contact position x on the fingertip (mm)."),
    y: float = typer.Option(0.0, help="Contact position y on the fingertip (mm)."),
    friction: Friction = typer.Option(Friction.stick, help="Contact friction: none, or stick (no slip)."),
    model: Model = typer.Option(Model.linear, help="Linear elasticity (fast) or neo-Hookean (large deformation)."),
    mesh_size: float = typer.Option(1.0, "--mesh-size", help="Largest element edge (mm)."),
    noise: Switch = typer.Option(Switch.on, help="Sensor noise and quantisation (off: the exact field)."),
    ambient: tuple[float, float, float] = typer.Option((0.0, 0.0, 0.0), help="Uniform ambient field x y z (µT)."),
    seed: int = typer.Option(0, help="Seed of the sensor noise."),
    plot: Path = typer.Option(None, help="Save a section of the deformed body to this PNG file."),
    deformed_mesh: Path = typer.Option(None, "--deformed-mesh",
                                       help="Save the mesh and its nodal displacements to this .npz file."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Run one load case on the physics twin and print magnet poses, sensor readings and force."""
    from softtip.design.model import MM, load_design
    from softtip.mechanics.contact import LoadCase
    from softtip.mechanics.indenters import make_indenter
    from softtip.twin import FingertipTwin

    for name, value in (("depth", depth), ("thickness", thickness), ("radius", radius), ("mesh-size", mesh_size)):
        if not np.isfinite(value) or value < 0 or (value == 0 and name != "depth"):
            fail(f"--{name} = {value}: expected a positive length in mm")
    if plot is not None and plot.suffix.lower() != ".png":
        fail(f"--plot {plot}: expected a file name ending in .png")
    if deformed_mesh is not None and deformed_mesh.suffix.lower() != ".npz":
        fail(f"--deformed-mesh {deformed_mesh}: expected a file name ending in .npz")
    twin = FingertipTwin(load_design(design), mesh_size=mesh_size * MM, ambient_field=np.array(ambient) * 1e-6)
    load = LoadCase(indenter=make_indenter(indenter.value, thickness=thickness * MM, angle_deg=angle,
                                           radius=radius * MM),
                    depth=depth * MM, tangential=(shear_x * MM, shear_y * MM), position=(x * MM, y * MM),
                    friction=friction.value)
    progress = None
    if model is Model.neo_hookean and not json_output:
        from rich.progress import Progress

        bar = Progress(console=errors, transient=True)
        bar.start()
        task = bar.add_task("Newton load steps", total=None)
        progress = lambda done, total: bar.update(task, completed=done, total=total)  # noqa: E731
    try:
        result = twin.simulate(load, model=model.value, noise=noise is Switch.on, rng=np.random.default_rng(seed))
    finally:
        if progress is not None:
            bar.stop()
    report = result_json(result, twin, angle, thickness, radius, mesh_size, noise is Switch.on)
    if plot is not None:
        from softtip.report.section import plot_section

        report["plot"] = str(plot_section(result, plot))
    if deformed_mesh is not None:
        vertices = len(twin.mesh.points)  # quadratic nodes: vertices first, then edge midpoints
        np.savez_compressed(deformed_mesh, points_m=twin.mesh.points, tetrahedra=twin.mesh.tets.T,
                            displacements_m=result.contact.displacements[:vertices],
                            quadratic_nodes_m=twin.body.space.nodes, quadratic_displacements_m=result.contact.displacements,
                            contact_nodes=result.contact.contact_nodes)
        report["deformed_mesh"] = str(deformed_mesh)
    if json_output:
        print(json.dumps(report, indent=2))
    else:
        print_result(report)


def _mm(vector) -> list[float]:
    return [round(float(v) * 1e3, 6) for v in vector]


def result_json(result, twin, angle: float, thickness: float, radius: float, mesh_size: float, noise: bool) -> dict:
    design = result.design
    saturated = twin.sensor.saturated(result.reading_counts)
    load = result.load
    return {
        "softtip": __version__,
        "design": design.name,
        "model": result.model,
        "load": {"indenter": type(load.indenter).__name__.lower(), "depth_mm": load.depth * 1e3,
                 "angle_deg": angle, "thickness_mm": thickness, "radius_mm": radius,
                 "tangential_mm": _mm(load.tangential), "position_mm": _mm(load.position),
                 "friction": load.friction},
        "magnets": [
            {"index": i, "position_mm": _mm(result.magnet_positions[i]),
             "rotvec": [round(float(v), 9) for v in result.magnet_rotvecs[i]],
             "feature_displacement_mm": _mm(result.feature_displacements[i]),
             "dimension_mm": _mm([m.diameter, m.height]),
             "polarization_T": [0.0, 0.0, m.polarization]}
            for i, m in enumerate(design.magnets)],
        "sensors": [
            {"index": j, "position_mm": _mm(design.sensor_positions[j]),
             "dB_uT": [round(float(v), 4) for v in result.reading_change_uT[j]],
             "dB_exact_uT": [round(float(v) * 1e6, 4) for v in result.field_change[j]],
             "counts": [int(c) for c in result.reading_counts[j]], "saturated": bool(saturated[j].any())}
            for j in range(len(design.sensor_positions))],
        "noise": noise,
        "sensor_model": sensor_summary(twin.sensor),
        "force_N": [round(float(f), 6) for f in result.force],
        "contact": {"nodes": int(len(result.contact.contact_nodes)), "iterations": result.contact.iterations,
                    "factorizations": result.contact.factorizations},
        "mesh": {"size_mm": mesh_size, "tetrahedra": int(twin.mesh.tets.shape[1]),
                 "unknowns": int(twin.body.size)},
        "timings_s": {k: round(v, 4) for k, v in result.timings.items()},
    }


def sensor_summary(sensor) -> dict:
    from softtip.sensors import conversion_time_s, lsb_uT, max_output_rate_hz, noise_rms_uT

    settings = sensor.settings
    return {"chip": "MLX90393", "settings": settings.to_dict(),
            "lsb_uT": [float(v) for v in lsb_uT(settings)], "noise_rms_uT": [float(v) for v in noise_rms_uT(settings)],
            "conversion_time_ms": conversion_time_s(settings) * 1e3, "max_rate_hz": max_output_rate_hz(settings)}


def print_result(report: dict) -> None:
    load = report["load"]
    console.print(f"[bold]{report['design']}[/] — {load['indenter']} {load['depth_mm']:.3g} mm, "
                  f"angle {load['angle_deg']:g}°, friction {load['friction']}, {report['model']} model")
    magnets = Table(title="magnets after loading")
    for column in ("#", "position (mm)", "feature displacement (mm)", "rotation vector (mrad)"):
        magnets.add_column(column, justify="right")
    for m in report["magnets"]:
        magnets.add_row(str(m["index"]), _fmt(m["position_mm"], 3), _fmt(m["feature_displacement_mm"], 4),
                        _fmt([v * 1e3 for v in m["rotvec"]], 2))
    console.print(magnets)
    sensors = Table(title="Hall sensors (change from the unloaded state)")
    for column in ("#", "position (mm)", "ΔB reading (µT)", "ΔB exact (µT)", "saturated"):
        sensors.add_column(column, justify="right")
    for s in report["sensors"]:
        sensors.add_row(str(s["index"]), _fmt(s["position_mm"], 2), _fmt(s["dB_uT"], 1), _fmt(s["dB_exact_uT"], 2),
                        "yes" if s["saturated"] else "no")
    console.print(sensors)
    force = report["force_N"]
    console.print(f"force on the indenter (N): Fx {force[0]:.4f}  Fy {force[1]:.4f}  Fz {force[2]:.4f}")
    console.print("timings (s): " + ", ".join(f"{k} {v:.3g}" for k, v in report["timings_s"].items()))
    chip = report["sensor_model"]
    console.print(f"MLX90393: LSB {_fmt(chip['lsb_uT'], 3)} µT, noise {_fmt(chip['noise_rms_uT'], 2)} µT RMS, "
                  f"{chip['conversion_time_ms']:.2f} ms per reading (≤ {chip['max_rate_hz']:.0f} Hz)")
    for key, label in (("plot", "section plot"), ("deformed_mesh", "deformed mesh")):
        if key in report:
            console.print(f"{label}: {report[key]}")


def _fmt(values, digits: int) -> str:
    return "  ".join(f"{v:+.{digits}f}" for v in values)


@bench_app.command("twin")
@user_errors
def bench_twin(
    design: str = typer.Option("cylindrical-D", help="Design to benchmark."),
    mesh_size: float = typer.Option(1.0, "--mesh-size", help="Mesh size (mm)."),
    poses: int = typer.Option(200_000, help="Batch size of magnet poses for the magnetics + sensor stage."),
    skip_neo_hookean: bool = typer.Option(False, "--skip-neo-hookean", help="Leave out the 3 mm neo-Hookean push."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Time the twin: mesh, 1 mm board push with contact (vs one fixed-area linear solve),
    neo-Hookean 3 mm push, and magnetics + sensor readings per second (vs magpylib)."""
    from softtip.bench import bench_twin as run

    report = run(design, mesh_size, poses, include_neo_hookean=not skip_neo_hookean,
                 log=None if json_output else console.print)
    if json_output:
        print(json.dumps(report, indent=2))


@bench_app.command("rom")
@user_errors
def bench_rom(
    design: str = typer.Option("cylindrical-D", help="Design to reduce."),
    samples: int = typer.Option(None, help="Exact contact samples to fit the interpolator on (default: 8000)."),
    holdout: int = typer.Option(12, help="Held-out finite-element solves for the error report."),
    save: Path = typer.Option(None, help="Save the reduced twin (npz + json) to this path."),
    contact_layer_mm: float = typer.Option(None, "--contact-layer-mm",
                                           help="Element size (mm) in the layer indenters reach (default: 1.5 mm)."),
    friction: RomFriction = typer.Option(
        RomFriction.stick, help="Board friction: stick (the loads it holds at mu = 0.7) or coulomb (mu = 0.7)."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Build a reduced-order twin and measure its held-out FE error, batch speed and speed-up over FE."""
    from softtip.bench import bench_rom as run

    if (samples is not None and samples < 50) or holdout < 2:
        fail(f"--samples = {samples}, --holdout = {holdout}: expected at least 50 samples and 2 held-out loads")
    if contact_layer_mm is not None and not 0.2 <= contact_layer_mm <= 1.5:
        fail(f"--contact-layer-mm = {contact_layer_mm}: expected an element size of 0.2 to 1.5 mm")
    report = run(design, samples, holdout, save=str(save) if save else None, contact_layer_mm=contact_layer_mm,
                 friction=friction.value, log=None if json_output else console.print)
    if json_output:
        print(json.dumps(report, indent=2))


demo_app = typer.Typer(help="Demonstrations on the built-in simulated sensor.")
app.add_typer(demo_app, name="demo")


@demo_app.callback(invoke_without_command=True)
@user_errors
def demo(
    context: typer.Context,
    seed: int = typer.Option(1, "--seed", help="Seed of the experiments, the fabricated unit and the training."),
    duration: float = typer.Option(20.0, "--duration", help="Seconds of live streaming."),
    record: Path = typer.Option(None, "--record", help="Also record the live stream to this MCAP file."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """The main job on the built-in simulated sensor: the twin runs the 3-axis force calibration, a
    network is fitted to it, and an emulated fingertip streams the twin's pushes through the live
    pipeline, whose estimates are scored against the twin's true force."""
    if context.invoked_subcommand is not None:
        return
    from softtip.studies.live_demo import run_main_demo

    say = (lambda message: None) if json_output else (lambda message: console.print(f"[bold]{message}[/]"))
    report = run_main_demo(seed=seed, duration_s=duration, dashboard=not json_output, record=record, say=say)
    if json_output:
        print(json.dumps(report, indent=2, default=float))
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
    console.print(f"{report['estimated_frames']} frames estimated live; model saved at {report['model']}; "
                  f"lost frames: {pipeline.get('lost_in_transit', 0)}")


@demo_app.command("insertion")
@user_errors
def demo_insertion(
    case: str = typer.Option("good", "--case", help="good, left-clip or right-clip."),
    seed: int = typer.Option(1, "--seed", help="Seed of the training data and the sensors' noise."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON (outcome, state_detected, "
                                                           "force_at_detection_N, every decision)."),
) -> None:
    """Feedback-controlled insertion of the inverter lid on the simulated arm: stop and retract when the
    fingertips see a clip on part B's rim (state 2 or 3), done when the target pose is reached."""
    from softtip.lab.insertion import CASES
    from softtip.studies.insertion import run_insertion

    if case not in CASES:
        fail(f"--case = {case!r}: expected one of {', '.join(CASES)}")
    with status(f"insertion, case {case}", json_output):
        outcome = run_insertion(case, seed, say=(lambda m: None) if json_output else console.print)
    if json_output:
        print(json.dumps(outcome, indent=2))
        return
    for decision in outcome["decisions"]:
        if decision["action"] != "approach" or decision["cycle"] % 25 == 0:
            console.print(f"t = {decision['time_s']:6.2f} s  height {decision['pose'][0] * 1e3:+.3f} mm  "
                          f"state {decision['state']}  force {decision['force_N']:.3f} N  -> {decision['action']}")
    estimated = outcome["force_at_detection_N"]
    console.print(f"[bold]{outcome['outcome']}[/]: state {outcome['state_detected']} at an estimated "
                  f"{'-' if estimated is None else f'{estimated:.3f}'} N "
                  f"(true {outcome['true_force_at_decision_N']:.3f} N)")


@app.command()
@user_errors
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
        with status("computing the twin's scenario", json_output):
            source = (pushing_scenario if scenario == "push" else insertion_scenario)(protocol, protocol.seed)
        settings = MLX90393Settings.from_dict(protocol.design.sensor_readout)
        chips = chips or source.field_uT.shape[1]
        if not model:  # the emulated fingertip comes with its calibration, trained on the twin once
            with status("calibrating the twin", json_output):
                if scenario == "push":
                    from softtip.studies.live_demo import calibrate_force_model

                    model = [calibrate_force_model(protocol.seed, say=lambda message: None, reuse=True)[0]]
                else:
                    from softtip.studies.insertion import trained_model_files

                    model = list(trained_model_files(protocol, say=lambda message: None))
    summary = run_live("emulator" if emulate else port, model,
                       live_sinks(dashboard=not json_output, record=record, foxglove_port=foxglove, ros2=ros2),
                       duration, rate_hz=rate, chips=chips, settings=settings, baseline_frames=baseline_frames,
                       drift_time_constant_s=drift_tau, emulator_source=source)
    if json_output:
        print(json.dumps(summary, indent=2, default=float))


@app.command()
@user_errors
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


@bench_app.command("live")
@user_errors
def bench_live(
    duration: float = typer.Option(20.0, "--duration", help="Seconds of streaming (the full soak: 600)."),
    rate: int = typer.Option(500, "--rate", help="Frames per second."),
    chips: int = typer.Option(4, "--chips", help="Chips per frame."),
    faults: bool = typer.Option(False, "--faults", help="Inject corrupt and dropped bytes, stalls, chip errors."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Soak: emulator -> driver -> baseline -> a 12-20-4 network -> MCAP recorder; every frame counted,
    latency from arrival to estimate, CPU of the pipeline's process (emulator in another process)."""
    from softtip.hardware import FaultPlan
    from softtip.realtime.bench import soak

    plan = FaultPlan(corrupt_every=97, drop_byte_every=131, stall_every=211, stall_ms=3, chip_error_every=53,
                     seed=1) if faults else None
    with status(f"soaking for {duration:g} s", json_output):
        report = soak(duration, rate, chips, plan)
    if json_output:
        print(json.dumps(report, indent=2, default=float))
    else:
        console.print(report)


from softtip.cli.optimize import optimize  # noqa: E402 - its own module; uses the helpers above

app.command()(user_errors(optimize))


if __name__ == "__main__":  # pragma: no cover
    sys.exit(app())

from softtip.cli.lab import register as register_lab  # noqa: E402

register_lab(app, user_errors)
