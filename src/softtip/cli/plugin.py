"""``softtip check-system``: a registered system checked as the toolkit uses it."""

from __future__ import annotations

import json

import typer

from softtip.cli.common import console, fail, printable, progress_for


def check_system(
    name: str = typer.Argument(..., help="A registered system (softtip --help lists them)."),
    no_studies: bool = typer.Option(False, "--no-studies", help="Leave out the studies' quick reproductions "
                                                                "(the slowest checks)."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Check a registered system as softtip uses it: every reference of its record, each shipped protocol
    run at its quick size (its dataset's roles), each live scenario and each study's quick report.
    Prints every broken rule in one line naming the file or the record's key; exit code 1 if any."""
    from softtip._core.systems import systems
    from softtip.plugin import check_system as check

    if name not in systems():
        fail(f"NAME = {name!r}: expected one of {', '.join(systems())}")
    broken = check(name, progress_for(json_output), studies=not no_studies)
    if json_output:
        print(json.dumps({"system": name, "broken": broken}, indent=2))
    else:
        for line in broken:
            console.print(printable(line), markup=False, highlight=False, soft_wrap=True)
        if not broken:
            console.print(f"{name}: every rule holds", markup=False, highlight=False)
    if broken:
        raise typer.Exit(1)
