"""A study's result files: a CSV and a JSON of every design, and a map of the objective."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np

from softtip._core.files import atomic_write, save_figure
from softtip.optimize.study import OK, StudyResult


OUTPUT_FILES = {"csv": "results.csv", "json": "results.json", "plot": "objective.png"}


def write_outputs(result: StudyResult, directory: Path) -> dict[str, str]:
    """Write ``results.csv``, ``results.json`` and ``objective.png`` into ``directory``; return their paths."""
    directory.mkdir(parents=True, exist_ok=True)
    paths = {key: directory / name for key, name in OUTPUT_FILES.items()}
    atomic_write(paths["csv"], _csv_text(result))
    atomic_write(paths["json"], json.dumps(result.to_json(), indent=2))
    plot_objective(result, paths["plot"])
    return {key: str(path) for key, path in paths.items()}


def _csv_text(result: StudyResult) -> str:
    names = [p.name for p in result.config.parameters]
    stream = io.StringIO(newline="")
    writer = csv.writer(stream)
    writer.writerow(["evaluation", "index", *names, "status", f"objective_{result.config.objective.unit}",
                     "cached", "fe_seconds", "reason"])
    for r in result.table:
        writer.writerow([r.evaluation or "", r.index, *(r.params[n] for n in names), r.status,
                         "" if r.objective is None else repr(r.objective), r.cached,
                         "" if r.fe_seconds is None else f"{r.fe_seconds:.3f}", r.reason])
    return stream.getvalue()


def plot_objective(result: StudyResult, path: Path) -> Path:
    """The objective over the first two parameters (others held at the best design's values) as a
    heat map - or over the only parameter as a curve; grey: infeasible, failed or not evaluated."""
    from matplotlib.figure import Figure as PlotFigure

    config, best = result.config, result.best
    objective = config.objective
    label = f"{objective.name} ({objective.unit})" if objective.unit else objective.name
    parameters = config.parameters
    fixed = {p.name: best.params[p.name] for p in parameters[2:]} if best else {}
    on_slice = [r for r in result.records if all(r.params[n] == v for n, v in fixed.items())]
    figure = PlotFigure(figsize=(7.5, 5.0))
    axes = figure.subplots()
    title = f"{config.name}: {label}, goal {objective.goal}"
    if fixed:
        title += "\n" + ", ".join(f"{n} = {v:g}" for n, v in fixed.items())
    if len(parameters) == 1:
        xs = np.array(parameters[0].values, dtype=float)
        ys = np.full(len(xs), np.nan)
        for r in on_slice:
            if r.status == OK:
                ys[list(parameters[0].values).index(r.params[parameters[0].name])] = r.objective
        axes.plot(xs, ys, "o-")
        axes.set_xlabel(parameters[0].name)
        axes.set_ylabel(label)
        if best:
            axes.plot([best.params[parameters[0].name]], [best.objective], "r*", markersize=14, label="best")
            axes.legend()
    else:
        px, py = parameters[0], parameters[1]
        xs, ys = list(px.values), list(py.values)
        grid = np.full((len(ys), len(xs)), np.nan)
        for r in on_slice:
            if r.status == OK:
                grid[ys.index(r.params[py.name]), xs.index(r.params[px.name])] = r.objective
        axes.set_facecolor("0.85")
        if np.isnan(grid).any():
            figure.text(0.01, 0.01, "grey: infeasible, failed or not evaluated", fontsize=7, color="0.4")
        mesh = axes.pcolormesh(_edges(xs), _edges(ys), np.ma.masked_invalid(grid), cmap="viridis", shading="flat")
        figure.colorbar(mesh, ax=axes, label=label)
        if config.method == "bayes":  # where the search went, in order
            for r in on_slice:
                if r.evaluation is not None:
                    axes.annotate(str(r.evaluation), (r.params[px.name], r.params[py.name]), ha="center",
                                  va="center", fontsize=7, color="white")
        if best:
            axes.plot([best.params[px.name]], [best.params[py.name]], marker="*", color="red", markersize=16,
                      markeredgecolor="white", linestyle="none", label=f"best: {best.objective:.4g}")
            axes.legend(loc="upper right", fontsize=8)
        axes.set_xlabel(px.name)
        axes.set_ylabel(py.name)
    axes.set_title(title, fontsize=10)
    figure.tight_layout()
    return save_figure(figure, path, dpi=120)


def _edges(values: list[float]) -> np.ndarray:
    """Cell edges around grid values, so each design is one cell centred on its value."""
    centres = np.asarray(values, dtype=float)
    if len(centres) == 1:
        return np.array([centres[0] - 0.5, centres[0] + 0.5])
    middle = (centres[1:] + centres[:-1]) / 2
    return np.concatenate([[2 * centres[0] - middle[0]], middle, [2 * centres[-1] - middle[-1]]])
