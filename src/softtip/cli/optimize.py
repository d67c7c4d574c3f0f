"""``softtip optimize``: run a design study (grid sweep or Bayesian search) from a TOML file.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import typer
from rich.table import Table

from softtip.cli.common import check_input, check_number, check_output_folder, console, fail, progress_for


def optimize(
    config: Path = typer.Option(..., "--config", help="Study file (TOML): design, parameters, objective, method."),
    scheduler: str = typer.Option(None, "--scheduler",
                                  help="Run on an existing Dask cluster, e.g. tcp://HOST:8786 "
                                       "(default: a local process pool)."),
    workers: int = typer.Option(2, "--workers", help="Local worker processes (1: in this process)."),
    output: Path = typer.Option(None, "--output", help="Directory for results.csv, results.json and "
                                                       "objective.png (default: the study's output)."),
    force: bool = typer.Option(False, "--force", help="Replace the results the output folder holds."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Sweep or search design parameters on the physics twin; FE results are cached, so a killed
    study resumes where it stopped."""
    from softtip.optimize.config import load_study
    from softtip.optimize.executors import make_executor
    from softtip.optimize.report import OUTPUT_FILES, write_outputs
    from softtip.optimize.study import run_study

    if scheduler is not None and not scheduler.strip():
        fail("--scheduler = '': expected the address of a Dask scheduler, e.g. tcp://HOST:8786")
    check_number(workers, "--workers", minimum=1, maximum=max(4 * (os.cpu_count() or 1), 8))
    if output is not None:
        check_output_folder(output, "--output", OUTPUT_FILES.values(), force=force)
    study = load_study(check_input(config, "--config"))
    directory = check_output_folder(output if output is not None else study.output, "--output",
                                    OUTPUT_FILES.values(), force=force)
    with make_executor(scheduler, workers) as executor:
        result = run_study(study, executor, progress=progress_for(json_output))
    files = write_outputs(result, directory)
    if json_output:
        report = result.to_json()
        print(json.dumps({key: report[key] for key in ("study", "method", "objective", "best", "evaluations",
                                                       "executor", "wall_seconds", "table")}
                         | {"outputs": files}, indent=2))
    else:
        print_study(result, files, console)


MAX_REASONS = 10  # why designs are infeasible or failed: the first few, the rest are in the CSV


def print_study(result, files: dict[str, str], console) -> None:
    config, best = result.config, result.best
    objective = config.objective
    table = Table(title=f"{config.name}: {config.method}, goal {objective.goal}")
    names = [p.name for p in config.parameters]
    rows = result.table
    table.add_column("#", justify="right", min_width=3)
    for name in names:  # long names fold in the header; the values stay on one line
        table.add_column(name, justify="right", overflow="fold", min_width=6)
    table.add_column(f"{objective.name} ({objective.unit})" if objective.unit else objective.name,
                     justify="right", overflow="fold", min_width=9)
    table.add_column("status", min_width=10)
    table.add_column("source", min_width=8)
    for r in rows:
        source = "cache" if r.cached else ("" if r.evaluation is None else "computed")
        value = "" if r.objective is None else f"{r.objective:.5f}"
        style = "bold green" if r is best else ("dim" if r.status != "ok" else None)
        table.add_row(str(r.evaluation or ""), *(f"{r.params[n]:g}" for n in names), value, r.status, source,
                      style=style)
    console.print(table)
    problems = [r for r in rows if r.reason]
    for r in problems[:MAX_REASONS]:
        console.print(f"[dim]{r.status}: {r.values}: {r.reason}[/]", highlight=False)
    if len(problems) > MAX_REASONS:
        console.print(f"[dim]... and {len(problems) - MAX_REASONS} more (see results.csv)[/]")
    counts = result.counts()
    if best is not None:
        console.print(f"best: {', '.join(f'{n} = {best.params[n]:g}' for n in names)} -> "
                      f"{objective.name} = {best.objective:.5f} {objective.unit} (evaluation {best.evaluation})")
    else:
        console.print("no feasible design was evaluated")
    console.print(f"evaluations: {counts['designs']} designs, {counts['fe_runs']} FE runs computed, "
                  f"{counts['cache_hits']} from the cache, {counts['infeasible']} infeasible, "
                  f"{counts['failed']} failed; stop: {counts['stop']}")
    console.print(f"{result.executor}; {result.wall_seconds:.1f} s")
    console.print("outputs: " + ", ".join(files.values()))
