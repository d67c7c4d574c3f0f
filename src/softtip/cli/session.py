"""``softtip recalibrate``: a saved model carried over to a new session from a few presses."""

from __future__ import annotations

import json
from enum import Enum
from pathlib import Path

import typer

from softtip.cli.common import FORCE, check_input, check_number, check_outputs, console, errors, fail, printable

MAX_PRESSES = 20  # more is a calibration, not a session correction


class GainGrouping(str, Enum):
    """Which inputs share a gain (calibration.session)."""

    chip = "chip"
    channel = "channel"
    common = "common"


def recalibrate(
    model_file: Path = typer.Argument(..., help="Saved model (.npz) from an earlier session."),
    dataset: Path = typer.Argument(..., help="The new session (.parquet): its readings as changes from its own rest "
                                             "(re-zeroed), its loads as labels, rows in time order."),
    presses: int = typer.Option(5, "--presses", help=f"Presses of the new session to re-calibrate from (1-"
                                                     f"{MAX_PRESSES}); the rows after the last are scored."),
    press_above: float = typer.Option(None, "--press-above", help="A press is a run of rows whose largest "
                                      "|target| exceeds this, in the targets' unit (default: a tenth of the "
                                      "largest)."),
    gains: GainGrouping = typer.Option(GainGrouping.chip, "--gains", help="One gain per chip (its magnet and "
                                       "sensitivity scale its three axes alike), per channel, or one for all."),
    output: Path = typer.Option(None, "--output", "-o", help="Save the model re-calibrated from the --presses "
                                                              "presses here (.npz)."),
    plot: Path = typer.Option(None, "--plot", help="Save the error against the number of presses to this PNG."),
    force: bool = FORCE,
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Carry a saved model over to a new session: its readings re-zeroed at rest, each chip's gain
    re-fitted from the first presses of a known or measured load, the model kept. Prints the error on
    the rest of the session after 0, 1, ... presses, beside predicting zero."""
    import numpy as np

    from softtip.calibration import load_model, save_model
    from softtip.calibration.session import SessionGains, gain_groups, session_curve
    from softtip.cli.lab import check_model_data
    from softtip.data import Dataset

    check_number(presses, "--presses", minimum=1, maximum=MAX_PRESSES)
    check_number(press_above, "--press-above", above=0, maximum=1e12)
    check_input(model_file, "MODEL_FILE")
    check_input(dataset, "DATASET")
    if plot is not None and plot.suffix.lower() != ".png":
        fail(f"--plot {plot}: expected a file name ending in .png")
    check_outputs([("--output", output), ("--plot", plot)], [model_file, dataset], force=force)
    estimator, meta = load_model(model_file)
    if hasattr(estimator, "predict_proba"):
        fail(f"MODEL_FILE = {model_file}: a classifier; a session is re-calibrated for a regression model")
    data = Dataset.read(dataset)
    check_model_data(meta, data, dataset)
    targets = list(meta.target_names)
    X = data.X(list(meta.input_channels))
    y = np.column_stack([np.asarray(data.column(t), dtype=float) for t in targets])
    largest = float(np.nanmax(np.abs(y))) if y.size else 0.0
    above = largest / 10 if press_above is None else press_above
    if not above > 0:
        fail(f"{dataset}: the targets are 0 throughout: no press to re-calibrate from")
    groups = gain_groups(list(meta.input_channels), gains.value)
    curve = session_curve(estimator, X, y, data.groups, presses=presses, above=above, groups=groups)
    summary = {
        "model": str(model_file), "dataset": str(dataset), "targets": targets,
        "target_units": [data.labels[t] for t in targets], "press_above": above, "gains": gains.value,
        "presses_found": len(curve.press_ends), "scored_rows": curve.scored_rows,
        "zero_rmse": curve.zero_rmse.tolist(),
        "rmse_by_presses": [{"presses": k, "rmse": row.tolist()} for k, row in enumerate(curve.rmse)],
        "gains_after_last_press": dict(zip(meta.input_channels, curve.gains[-1].tolist(), strict=True)),
    }
    if curve.at_bound[-1]:
        errors.print(printable(f"warning: gain group(s) {list(curve.at_bound[-1])} reached the bound 1/20 or 20: "
                               "the presses do not determine them"), markup=False, highlight=False, soft_wrap=True)
    if output is not None:
        fitted = SessionGains(estimator, groups).fit(X[: curve.press_ends[presses - 1]],
                                                     y[: curve.press_ends[presses - 1]])
        save_model(output, fitted.corrected_model(), input_channels=list(meta.input_channels),
                   input_units=list(meta.input_units), target_names=targets, target_units=list(meta.target_units),
                   extra={**meta.extra, "session": {"dataset": str(dataset), "presses": presses,
                                                   "gains": fitted.gains_.tolist(), "grouping": gains.value}})
        summary["output"] = str(output)
    if plot is not None:
        summary["plot"] = str(_plot_curve(curve, targets, [data.labels[t] for t in targets], plot))
    if json_output:
        print(json.dumps(summary, indent=2))
        return
    unit = data.labels[targets[0]]
    console.print(f"{dataset}: {len(curve.press_ends)} presses above {above:.4g} {unit}; scored on the "
                  f"{curve.scored_rows} rows after press {presses}")
    console.print(f"  predicting zero: RMSE {curve.zero_rmse[0]:.4g} {unit}")
    for k, row in enumerate(curve.rmse):
        console.print(f"  after {k} press{'es' if k != 1 else ''}: RMSE {row[0]:.4g} {unit}")
    if output is not None:
        console.print(f"re-calibrated model: {output}")


def _plot_curve(curve, targets: list[str], units: list[str], path: Path) -> Path:
    import numpy as np
    from matplotlib.figure import Figure

    from softtip._core.files import save_figure

    figure = Figure(figsize=(5.5, 3.6), layout="constrained")
    axes = figure.add_subplot()
    presses = np.arange(len(curve.rmse))
    for k, (name, unit) in enumerate(zip(targets, units, strict=True)):
        line, = axes.plot(presses, curve.rmse[:, k], "o-", label=f"{name}: re-calibrated")
        axes.axhline(curve.zero_rmse[k], color=line.get_color(), ls=":", label=f"{name}: predicting zero")
    axes.set_xlabel("presses of the new session used")
    axes.set_ylabel(f"RMSE ({units[0]})" if len(set(units)) == 1 else "RMSE")
    axes.set_xticks(presses)
    axes.set_yscale("log")  # predicting zero is often ten times worse than any re-calibration
    axes.legend(fontsize="small")
    axes.set_title(f"A saved model on a new session ({curve.scored_rows} rows scored)", fontsize="medium")
    return save_figure(figure, path, dpi=120)
