"""The ``softtip`` command line: a thin layer over the library, every command registered here.

Each command lives in the module of its stage (:mod:`.twin`, :mod:`.importing`, :mod:`.lab`, :mod:`.optimize`,
:mod:`.live`, :mod:`.demo`, :mod:`.sysid`, :mod:`.bench`); they share only :mod:`.common`. ``softtip`` and
``python -m softtip`` run this same application.
"""

from __future__ import annotations

import sys

import typer

from softtip import __version__
from softtip._core.systems import load, systems
from softtip.cli import bench, importing, lab, live, optimize, recording, session, sysid, twin
from softtip.cli.common import Toolkit, console

app = typer.Typer(help="softtip: fingertip tactile sensing, from design to real-time estimates.\n\nSystems: " + "; ".join(
    f"{system.name} ({system.label}): {system.title}" for system in systems().values()),
    no_args_is_help=True, add_completion=False, pretty_exceptions_enable=False, cls=Toolkit)


@app.callback(invoke_without_command=True)
def main(version: bool = typer.Option(False, "--version", help="Print the version and exit.")) -> None:
    if version:
        console.print(f"softtip {__version__}")
        raise typer.Exit()


def _group(name: str, help_text: str, commands: dict, callback=None) -> None:
    group = typer.Typer(help=help_text, no_args_is_help=callback is None)
    if callback is not None:
        group.callback(invoke_without_command=True)(callback)
    for command_name, function in commands.items():
        group.command(command_name)(function)
    app.add_typer(group, name=name)


for command in (twin.designs, twin.simulate, live.live, live.convert, optimize.optimize, lab.reproduce,
                lab.calibrate, lab.evaluate, session.recalibrate):
    app.command()(command)
app.command("import")(importing.import_logs)
_group("lab", "The virtual lab: the published experiments on the twin, as datasets.", {"run": lab.lab_run})
_registered = systems().values()
_main_demo = next((load(system.main_demo) for system in _registered if system.main_demo), None)
_group("demo", "Demonstrations on the built-in simulated sensors."
       + (f"\n\nPlain softtip demo: {' '.join(_main_demo.__doc__.split())}" if _main_demo else ""),
       {name: load(reference) for system in _registered for name, reference in system.demos.items()},
       callback=_main_demo)
_group("sysid", "System identification: transfer-function and state-space models from recordings.",
       {"fit": sysid.sysid_fit, "orders": sysid.sysid_orders, "predict": sysid.sysid_predict})
_group("recording", "MCAP recordings of the live stream.", {"repair": recording.recording_repair})
_group("bench", "Benchmarks measured on this machine (ratios against baselines of the same run).",
       {"twin": bench.bench_twin, "rom": bench.bench_rom, "live": bench.bench_live,
        "magnetics": bench.bench_magnetics, "calibration": bench.bench_calibration, "sysid": bench.bench_sysid,
        "studies": bench.bench_studies,
        **{name: load(reference) for system in _registered for name, reference in system.bench_commands.items()}})
for _system in _registered:
    for _name, _reference in _system.commands.items():
        app.add_typer(load(_reference), name=_name)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(app())
