"""The ``softtip`` command line: a thin layer over the library, every command registered here.

Each command lives in the module of its stage (:mod:`.twin`, :mod:`.importing`, :mod:`.lab`, :mod:`.optimize`,
:mod:`.live`, :mod:`.demo`, :mod:`.sysid`, :mod:`.bench`); they share only :mod:`.common`. ``softtip`` and
``python -m softtip`` run this same application.
"""

from __future__ import annotations

import functools
import sys
import warnings

import typer

from softtip import __version__
from softtip._core.stopping import stop_as_ctrl_c
from softtip._core.systems import SystemSkipped, default, load, systems
from softtip._core.user import chosen_system
from softtip.cli.common import Deferred, Toolkit, console, errors, printable

# read before any command module asks: an installed system skipped is one line, not a traceback
with warnings.catch_warnings(record=True) as _caught:
    warnings.simplefilter("always", SystemSkipped)
    _registered = tuple(systems().values())
for _warning in _caught:
    if issubclass(_warning.category, SystemSkipped):
        errors.print(f"warning: {printable(_warning.message)}", markup=False, highlight=False, soft_wrap=True)
    else:
        warnings.warn_explicit(_warning.message, _warning.category, _warning.filename, _warning.lineno)
try:  # the user's settings choose the commands' defaults: a mistake in them stops every command at once
    chosen_system([system.name for system in _registered])
except ValueError as _error:
    errors.print(f"error: {printable(_error)}", markup=False, highlight=False, soft_wrap=True)
    sys.exit(2)

from softtip.cli import importing, lab, live, optimize, plugin, recording, session, sysid, twin  # noqa: E402

DEMO_HELP = "Demonstrations on the built-in simulated sensors."
BENCH_HELP = "Benchmarks measured on this machine (ratios against baselines of the same run)."


def _typer_group(help_text: str, commands: dict, callback=None) -> typer.Typer:
    group = typer.Typer(help=help_text, no_args_is_help=callback is None)
    if callback is not None:
        group.callback(invoke_without_command=True)(callback)
    for command_name, function in commands.items():
        group.command(command_name)(function)
    return group


def _demos() -> typer.Typer:
    main_demo = load(reference) if (reference := default("demo")) else None
    return _typer_group(DEMO_HELP + (f"\n\nPlain softtip demo: {' '.join(main_demo.__doc__.split())}"
                                     if main_demo else ""),
                        {name: load(reference) for system in _registered for name, reference in system.demos.items()},
                        callback=main_demo)


def _benches() -> typer.Typer:
    from softtip.cli import bench

    return _typer_group(BENCH_HELP, {
        "twin": bench.bench_twin, "rom": bench.bench_rom, "live": bench.bench_live, "firmware": bench.bench_firmware,
        "magnetics": bench.bench_magnetics,
        "calibration": bench.bench_calibration, "sysid": bench.bench_sysid, "studies": bench.bench_studies,
        **{name: load(reference) for system in _registered for name, reference in system.bench_commands.items()}})


def _deferred(name: str, summary: str, build) -> Deferred:
    return Deferred(name, summary, lambda: typer.main.get_group(build()))


class Softtip(Toolkit):
    """The softtip command: the demos, the benchmarks and every system's command groups imported when used."""

    deferred = (_deferred("demo", DEMO_HELP, _demos), _deferred("bench", BENCH_HELP, _benches),
                *(_deferred(name, f"{system.label} ({system.name}): {system.title}.",
                            functools.partial(load, reference))
                  for system in _registered for name, reference in system.commands.items()))


app = typer.Typer(help="softtip: fingertip tactile sensing, from design to real-time estimates.\n\nSystems: " + "; ".join(
    f"{system.name} ({system.label}): {system.title}" for system in _registered),
    no_args_is_help=True, add_completion=False, pretty_exceptions_enable=False, cls=Softtip)


@app.callback(invoke_without_command=True)
def main(version: bool = typer.Option(False, "--version", help="Print the version and exit.")) -> None:
    stop_as_ctrl_c()  # a launch system's SIGTERM keeps finished work and closes recordings, as Ctrl-C does
    if version:
        console.print(f"softtip {__version__}")
        raise typer.Exit()


for command in (twin.designs, twin.simulate, live.live, live.convert, optimize.optimize, lab.reproduce,
                lab.calibrate, lab.evaluate, session.recalibrate):
    app.command()(command)
app.command("import")(importing.import_logs)
app.command("check-system")(plugin.check_system)
app.add_typer(_typer_group("The virtual lab: the published experiments on the twin, as datasets.",
                           {"run": lab.lab_run}), name="lab")
app.add_typer(_typer_group("System identification: transfer-function and state-space models from recordings.",
                           {"fit": sysid.sysid_fit, "orders": sysid.sysid_orders, "predict": sysid.sysid_predict}),
              name="sysid")
app.add_typer(_typer_group("MCAP recordings of the live stream.", {"repair": recording.recording_repair}),
              name="recording")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(app())
