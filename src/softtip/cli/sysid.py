"""``softtip sysid fit``, ``softtip sysid orders``, ``softtip sysid predict``: system identification from
recordings (CSV, Parquet or softtip datasets)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from enum import Enum
from pathlib import Path

import typer
from rich.markup import escape
from rich.table import Table

from softtip._core.files import atomic_write, save_figure
from softtip.cli.common import FORCE, check_distinct, check_number, check_output, check_outputs, console, errors, fail


class Kind(str, Enum):
    tf = "tf"
    ss = "ss"


class Detrend(str, Enum):
    none = "none"
    mean = "mean"
    linear = "linear"
    estimate = "estimate"


class InitialState(str, Enum):
    zero = "zero"
    estimate = "estimate"


class Intervals(str, Enum):
    sandwich = "sandwich"
    white = "white"


class Method(str, Enum):
    n4sid = "n4sid"
    moesp = "moesp"
    cva = "cva"


DATA = typer.Option(..., "--data", help="Recording: .csv, .parquet, or a softtip dataset (.parquet).")
INPUTS = typer.Option(..., "--input", "-u", help="Input column (repeat, or separate by commas).")
OUTPUTS = typer.Option(..., "--output", "-y", help="Output column (repeat, or separate by commas).")
TS = typer.Option(None, "--ts", help="Sample time (s); default from the time column.")
TIME_COLUMN = typer.Option(None, "--time-column", help="Time column (s) of a plain file (default: time_s if present).")
TRIAL_COLUMN = typer.Option(None, "--trial-column", help="Trial id column of a plain file (default: trial if present).")
VALIDATE = typer.Option(None, "--validate", help="Recording to validate on (same columns).")
FULL_SCALE = typer.Option(None, "--full-scale", help="Rated full-scale range of each output, in its unit "
                                                     "(repeat; default: the measured range max - min).")
JSON = typer.Option(False, "--json", help="Print JSON.")
DETREND = typer.Option(Detrend.none, "--detrend",
                       help="Levels to take out before identifying: mean or linear trend of the estimation data, "
                            "or estimate (input means, output levels estimated with the model); saved with the "
                            "model and taken out of validation and live data the same way.")
DELAY = typer.Option("0", "--delay", help="Input delay in samples: one for all inputs, one per input (2,0,5), "
                                          "or 'estimate' (searched up to --max-delay).")
MAX_DELAY = typer.Option(40, "--max-delay", help="Longest delay (samples) --delay estimate searches.")


COLUMNS = typer.Option(None, "--columns", help="Names of the columns of a text file without a header (.csv, "
                                                "whitespace .dat/.txt), in order, separated by commas (.dat/.txt "
                                                "default: 1, 2 ... by position).")
MISSING = typer.Option(None, "--missing", help="The value the logger writes for 'no reading' (like -1): rows "
                                               "holding it in an input or output are dropped (then --resample).")
UNIT = typer.Option(None, "--unit", help="A column's unit as NAME=UNIT (repeat; e.g. heater=V): carried into every "
                                         "table, plot and the saved model.")
RESAMPLE = typer.Option(None, "--resample", help="Interpolate irregular time stamps linearly onto an even grid of "
                                                 "this sample time (s), trial by trial; what it did is printed.")
VALIDATE_INPUT = typer.Option(None, "--validate-input",
                              help="The validation record's input columns, one per --input (default: the same "
                                   "names); without --validate they are read from --data, as in a file with uEst, "
                                   "uVal, yEst, yVal side by side.")
VALIDATE_OUTPUT = typer.Option(None, "--validate-output",
                               help="The validation record's output columns, one per --output (see "
                                    "--validate-input).")


@dataclass(frozen=True)
class Reading:
    """How to read a recording's file: what the command line says beyond its columns."""

    ts: float | None
    time_column: str | None
    trial_column: str | None
    columns: list[str] | None
    units: dict[str, str]
    resample: float | None
    missing: float | None


def _reading(ts, time_column, trial_column, columns, units, resample, missing) -> Reading:
    check_number(ts, "--ts", above=0, unit="s")
    check_number(resample, "--resample", above=0, unit="s")
    if resample is not None and ts is not None:
        fail("--resample and --ts: give one sample time (--resample for irregular time stamps)")
    names = None if columns is None else _names([columns])
    if names is not None:
        _distinct(names, "--columns")
    pairs = {}
    for text in units or ():
        name, equals, unit = text.partition("=")
        if not equals or not name.strip() or not unit.strip() or not unit.strip().isprintable():
            fail(f"--unit {text!r}: expected NAME=UNIT, like heater=V")
        if name.strip() in pairs:
            fail(f"--unit: {name.strip()!r} given more than once")
        pairs[name.strip()] = unit.strip()
    if missing is not None and not math.isfinite(missing):
        fail(f"--missing = {missing}: expected a finite number (the value written for 'no reading')")
    return Reading(ts, time_column, trial_column, names, pairs, resample, missing)


def _names(values: list[str]) -> list[str]:
    return [name.strip() for value in values for name in value.split(",") if name.strip()]


def _read(path: Path, inputs: list[str], outputs: list[str], reading: Reading, units: dict[str, str] | None = None):
    from softtip.sysid import read_recording

    units = reading.units if units is None else units
    unknown = [name for name in units if name not in (*inputs, *outputs)]
    if unknown:
        fail(f"--unit {unknown[0]}=...: {unknown[0]!r} is not an --input or --output")
    recording = read_recording(path, inputs, outputs, ts=reading.ts, time_column=reading.time_column,
                               trial_column=reading.trial_column, units=units or None, names=reading.columns,
                               resample=reading.resample, missing=reading.missing)
    if recording.resampled is not None:
        errors.print(f"[yellow]note:[/] {path}: {escape(recording.resampled.describe())}")
    return recording


def _records(data: Path, validate: Path | None, inputs: list[str], outputs: list[str], validate_inputs,
             validate_outputs, reading: Reading):
    """The estimation record and the validation record (None without one), the latter under the estimation
    columns' names whatever its own columns are called."""
    from dataclasses import replace

    val_inputs = inputs if not validate_inputs else _names(validate_inputs)
    val_outputs = outputs if not validate_outputs else _names(validate_outputs)
    for option, names, matched in (("--validate-input", val_inputs, inputs), ("--validate-output", val_outputs,
                                                                              outputs)):
        if len(names) != len(matched):
            fail(f"{option}: {len(names)} columns for {len(matched)} {option.split('-')[-1]}s: expected one each")
    recording = _read(data, inputs, outputs, reading)
    if validate is None and not (validate_inputs or validate_outputs):
        return recording, None
    renamed = dict(zip((*inputs, *outputs), (*val_inputs, *val_outputs), strict=True))
    units = {renamed[name]: unit for name, unit in reading.units.items() if name in renamed}
    path = data if validate is None else validate
    validation = _read(path, val_inputs, val_outputs, reading, units)
    label = str(path) if renamed == {name: name for name in renamed} else \
        f"{path} ({', '.join(val_inputs)} → {', '.join(val_outputs)})"
    return recording, replace(validation, inputs=tuple(inputs), outputs=tuple(outputs), source=label)


def _full_scale(values: list[float] | None):
    from softtip.sysid import MEASURED, rated

    for value in values or ():
        check_number(value, "--full-scale", above=0)
    return rated(values) if values else MEASURED


def _level_note(recording, detrend: Detrend) -> str | None:
    """A hint when no trend is taken out of a recording whose levels exceed its variation: a model of
    deviations from zero spends itself on the levels."""
    import numpy as np

    if detrend is not Detrend.none:
        return None
    signals = np.vstack([np.hstack([trial.u, trial.y]) for trial in recording.trials])
    names = (*recording.inputs, *recording.outputs)
    high = [f"{name} {level:.4g} (± {spread:.3g})" for name, level, spread in
            zip(names, signals.mean(axis=0), signals.std(axis=0)) if abs(level) > spread]
    if not high:
        return None
    return ("levels larger than their variation and not taken out: " + ", ".join(high) +
            "; a model from rest cannot follow them: try --detrend mean")


def _order(kind: Kind, order: str, validated: bool) -> int | str:
    if order == "auto" and (validated or kind is Kind.ss):
        return order
    try:
        value = int(order)
    except ValueError:
        value = 0
    if value < 1:
        fail(f"--order = {order!r}: expected a positive integer or auto (a transfer function's auto order needs a "
             "validation record: --validate or --validate-output)")
    return value


def _delay(text: str) -> int | list[int] | str:
    text = text.strip()
    if text in ("estimate", "auto"):
        return "estimate"
    try:
        values = [int(part) for part in text.split(",")]
    except ValueError:
        values = [-1]
    if min(values) < 0:
        fail(f"--delay = {text!r}: expected 'estimate', a number of samples >= 0, or one per input (like 2,0,5)")
    return values[0] if len(values) == 1 else values


def _model(kind: Kind, order: int | str, zeros: int | None, method: Method, refine: bool | None, continuous: bool,
           detrend: Detrend, delay: str, max_delay: int, initial_state: InitialState, intervals: Intervals):
    from softtip.sysid import StateSpaceModel, TransferFunctionModel

    common = {"detrend": detrend.value, "delay": _delay(delay), "max_delay": max_delay,
              "initial_state": initial_state.value}
    common |= {} if refine is None else {"refine": refine}
    if kind is Kind.tf:
        if continuous:
            fail("--continuous: a transfer function is continuous already (it runs discretised)")
        return TransferFunctionModel(order, zeros, intervals=intervals.value, **common)
    if zeros is not None:
        fail("--zeros: only for --kind tf")
    if intervals is not Intervals.sandwich:
        fail("--intervals: only for --kind tf (a state-space model's come from its Kalman predictor's white "
             "prediction errors)")
    return StateSpaceModel(order, method.value, domain="continuous" if continuous else "discrete", **common)


def _scores_table(title: str, scores: dict, warnings: list[str] = ()) -> Table:
    table = Table(title=title)
    for heading in ("output", "R²", "r", "RMSE", "RMSE % FS", "MAE % FS", "fit %", "full scale"):
        table.add_column(heading, justify="left" if heading == "output" else "right")
    for name, row in scores["outputs"].items():
        table.add_row(name, *(f"{row[key]:.3f}" if row[key] is not None else "—" for key in ("r2", "r")),
                      f"{row['rmse']:.4g} {row['unit']}".strip(),
                      *(f"{row[key]:.2f}" for key in ("rmse_fs_percent", "mae_fs_percent")),
                      f"{row['fit_percent']:.1f}" if row["fit_percent"] is not None else "—",
                      f"{row['full_scale']:.4g} {row['unit']}".strip())
    table.caption = (f"full scale: {scores['full_scale']['description']}; {scores['samples']} samples; "
                     f"initial state: {scores['initial_state']}" +
                     "".join(f"\n[yellow]warning:[/] {escape(text)}" for text in warnings))
    return table


FIGURE_SUFFIXES = (".png", ".pdf", ".svg")
STABILITY = {"stable": "stable", "unstable": "[red]unstable[/]",
             "uncertain": "[yellow]stability uncertain[/] (a pole's interval reaches the boundary)"}


def _print_residual_tests(tests: dict) -> None:
    table = Table(title=f"residual tests on {tests['data']} ({tests['lags']} lags, {100 * tests['confidence']:g} %)")
    for heading in ("output", "white", "N Σρ²", "limit", "input", "independent", "Σ(ρ/σ)²", "limit "):
        table.add_column(heading, justify="left" if heading in ("output", "input") else "right")
    for name, row in tests["outputs"].items():
        white = row["whiteness"]
        for k, (source, test) in enumerate(row["input_independence"].items()):
            table.add_row(*((name, "yes" if white["passed"] else "[red]no[/]", f"{white['statistic']:.1f}",
                             f"{white['limit']:.1f}") if k == 0 else ("", "", "", "")),
                          source, "yes" if test["passed"] else "[red]no[/]", f"{test['statistic']:.1f}",
                          f"{test['limit']:.1f}")
    table.caption = (f"{tests['test']}; residuals: one-step prediction errors (an output-error model's are its "
                     "simulation errors, which need not be white)")
    console.print(table)


def _print_uncertainty(uncertainty: dict, inputs: list[str], outputs: list[str]) -> None:
    """A transfer function's coefficients and poles with their intervals, and what the intervals assume."""
    z, level = uncertainty["z"], f"± {100 * uncertainty['confidence']:g} %"
    table = Table(title=f"coefficients (descending powers of s) and poles, {level} intervals")
    for heading in ("entry", "denominator", "numerator", "poles (rad/s)"):
        table.add_column(heading)

    def ranges(values):
        return ", ".join(f"{v['value']:.4g} ± {z * v['std']:.2g}" for v in values)

    for entry in uncertainty["entries"]:
        poles = ", ".join(f"{p['real']:.4g}{p['imag']:+.4g}j (± {z * p['real_std']:.2g}, {z * p['imag_std']:.2g}j)"
                          for p in entry["poles"])
        table.add_row(f"{inputs[entry['input']]} → {outputs[entry['output']]}", "1, " + ranges(entry["denominator"]),
                      ranges(entry["numerator"]), poles)
    table.caption = f"intervals: {uncertainty['method']}: {uncertainty['assumption']}"
    console.print(table)


def _print_state_space_uncertainty(uncertainty: dict, inputs: list[str], outputs: list[str]) -> None:
    z, level = uncertainty["z"], f"± {100 * uncertainty['confidence']:g} %"
    unit = " (rad/s)" if uncertainty["poles_domain"] == "continuous" else ""
    console.print(f"{uncertainty['poles_domain']} poles{unit}, {level} intervals: " + ", ".join(
        f"{p['real']:.4g}{p['imag']:+.4g}j (± {z * p['real_std']:.2g}, {z * p['imag_std']:.2g}j)"
        for p in uncertainty["poles"]))
    console.print(f"DC gains, {level} intervals: " + ", ".join(
        f"{inputs[g['input']]} → {outputs[g['output']]} {g['value']:.4g} ± {z * g['std']:.2g}"
        for g in uncertainty["dc_gains"]))
    console.print(f"intervals: {uncertainty['assumption']}")


def _print_summary(summary: dict) -> None:
    console.print(f"[bold]{summary['kind']}[/] model, {summary['states']} states, {summary['parameters']} parameters, "
                  f"ts = {summary['ts']:g} s, {STABILITY[summary['stability']]}; "
                  f"fitted in {summary['fit_seconds']:.2f} s on {summary['data']['trials']} trials "
                  f"({summary['data']['samples']} samples)")
    console.print("fit % on the estimation data (simulated from rest): " +
                  ", ".join(f"{name} {value:.1f}" for name, value in summary["fit_percent"].items()))
    trend = summary["trend"]
    if trend["kind"] != "none":
        def values(key):
            return ", ".join(f"{v:.5g}" for v in trend[key])

        console.print(f"trend taken out ({trend['kind']}, saved with the model): input levels {values('input_offset')}, "
                      f"output levels {values('output_offset')}" +
                      (f"; slopes per s {values('input_slope')} and {values('output_slope')}"
                       if trend["kind"] == "linear" else ""))
    if any(delay["samples"] for delay in summary["delays"].values()):
        console.print("input delays: " + ", ".join(f"{name} {delay['samples']} samples ({delay['seconds']:g} s)"
                                                   for name, delay in summary["delays"].items()))
    report = summary.get("report") or summary.get("refinement")
    if report is not None:
        console.print(f"estimation: {'converged' if report.get('converged') else '[red]not converged[/]'}: "
                      f"{report['message']}")


def sysid_fit(
    data: Path = DATA,
    input: list[str] = INPUTS,
    output: list[str] = OUTPUTS,
    kind: Kind = typer.Option(..., "--kind", help="tf: transfer-function matrix; ss: state space."),
    order: str = typer.Option(..., "--order", help="Poles per entry (tf) or states (ss), or auto: with a validation "
                                                   "record the order that validates best (from estimated initial "
                                                   "states; tf 2-8, ss 2-12), else (ss) the singular values' "
                                                   "largest drop."),
    zeros: int = typer.Option(None, "--zeros", help="Zeros per entry (tf; default order - 1)."),
    method: Method = typer.Option(Method.moesp, "--method", help="Subspace method (ss; MOESP validates best on the benchmark cases)."),
    refine: bool = typer.Option(None, "--refine/--no-refine",
                                help="Prediction-error refinement (default: tf yes, ss no)."),
    continuous: bool = typer.Option(False, "--continuous", help="A continuous state-space model (ss)."),
    detrend: Detrend = DETREND,
    initial_state: InitialState = typer.Option(InitialState.zero, "--initial-state",
                                               help="zero: every trial starts at rest; estimate: each trial's "
                                                    "initial state estimated with the model (--detrend estimate "
                                                    "estimates them too)."),
    delay: str = DELAY,
    max_delay: int = MAX_DELAY,
    ts: float = TS,
    time_column: str = TIME_COLUMN,
    trial_column: str = TRIAL_COLUMN,
    columns: str = COLUMNS,
    unit: list[str] = UNIT,
    resample: float = RESAMPLE,
    missing: float = MISSING,
    validate: Path = VALIDATE,
    validate_input: list[str] = VALIDATE_INPUT,
    validate_output: list[str] = VALIDATE_OUTPUT,
    full_scale: list[float] = FULL_SCALE,
    model_file: Path = typer.Option(None, "--model", "-o", help="Save the model here (.npz)."),
    bode: Path = typer.Option(None, "--bode", help="Save the Bode plot here (.png, .pdf, .svg), with its "
                                                   "confidence band, beside the recording's empirical transfer "
                                                   "function."),
    residuals: Path = typer.Option(None, "--residuals", help="Save the residual tests' plot here (.png, .pdf, "
                                                             ".svg): on --validate, else on the estimation data."),
    compare: Path = typer.Option(None, "--compare", help="Save the measured against the simulated outputs here (.png, "
                                                         ".pdf, .svg), per output with its fit %, each trial from its "
                                                         "estimated initial state: on the validation record if "
                                                         "given, else on the estimation data."),
    step: Path = typer.Option(None, "--step", help="Save every input's step response here (.png, .pdf, .svg), "
                                                   "with its confidence band."),
    impulse: Path = typer.Option(None, "--impulse", help="Save every input's impulse response (a pulse of unit "
                                                         "area) here (.png, .pdf, .svg), with its confidence band."),
    confidence: float = typer.Option(0.95, "--confidence", help="Confidence of the intervals and the Bode band."),
    intervals: Intervals = typer.Option(Intervals.sandwich, "--intervals",
                                        help="tf: the coefficients' covariance: sandwich (Newey-West; honest for "
                                             "coloured output errors) or white (σ² (JᵀJ)⁻¹, white errors "
                                             "assumed)."),
    lags: int = typer.Option(25, "--lags", help="Lags of the residual tests."),
    force: bool = FORCE,
    json_output: bool = JSON,
) -> None:
    """Identify a model of the outputs from the inputs; print its summary and, with --validate, per output
    R², r, RMSE, RMSE and MAE in % of full scale and the fit % (simulated from rest, and from each trial's
    estimated initial state), and the residual tests (whiteness, independence of the inputs)."""
    from softtip.sysid import save_model, validated_order
    from softtip.sysid.models import DEFAULT_ORDERS
    from softtip.sysid.verdicts import fit_warnings

    if not 0 < confidence < 1:
        fail(f"--confidence = {confidence}: expected a fraction between 0 and 1")
    check_number(lags, "--lags", minimum=1, maximum=100_000)
    check_number(max_delay, "--max-delay", minimum=0, maximum=100_000)
    reading = _reading(ts, time_column, trial_column, columns, unit, resample, missing)
    scale = _full_scale(full_scale)
    figures = (("--bode", bode), ("--residuals", residuals), ("--compare", compare), ("--step", step),
               ("--impulse", impulse))
    for option, path in figures:
        if path is not None and path.suffix.lower() not in FIGURE_SUFFIXES:
            fail(f"{option} {path}: expected a .png, .pdf or .svg file")
    sources = [data] + ([validate] if validate is not None else [])
    check_outputs([("--model", model_file), *figures], sources, force=force)
    inputs, outputs = _names(input), _names(output)
    _distinct(inputs, "--input")
    _distinct(outputs, "--output")
    validated = validate is not None or bool(validate_input or validate_output)
    chosen_order = _order(kind, order, validated)
    cross_validate = chosen_order == "auto" and validated
    # an auto order by validation is set once chosen; the options are checked now, on the smallest
    estimator = _model(kind, min(DEFAULT_ORDERS[kind.value]) if cross_validate else chosen_order, zeros, method,
                       refine, continuous, detrend, delay, max_delay, initial_state, intervals)
    recording, validation = _records(data, validate, inputs, outputs, validate_input, validate_output, reading)
    selection = None
    if cross_validate:
        order_name = "n_poles" if kind is Kind.tf else "order"
        params = {name: value for name, value in estimator.get_params().items()
                  if name not in (order_name, "estimate_covariance")}
        best, rows = validated_order(recording, validation, kind.value, **params)
        estimator.set_params(**{order_name: best})
        selection = {"method": f"validation on {validation.source}, each fit from its estimated initial states: "
                               "the best mean fit %, a smaller order within 0.5 points preferred",
                     "order": best, "fit_percent": {row["order"]: row["fit_percent"] for row in rows}}
        errors.print(f"order {best} chosen by validation: " + ", ".join(
            f"{row['order']}: {row['fit_percent']:.1f} %" for row in rows))
    estimator.fit(recording)
    result = {"model": estimator.summary(confidence), "note": _level_note(recording, detrend),
              "order_selection": selection}
    checked = recording if validation is None else validation
    # a short record takes fewer lags: four samples a lag at least
    usable = min(lags, checked.n_samples // 4)
    tests = estimator.residual_tests(checked, lags=usable) if usable >= 1 else None
    result["residual_tests"] = None if tests is None else \
        tests.to_dict() | {"data": checked.source}
    fitted = [estimator.evaluate(recording, full_scale=scale, initial_state=state) for state in ("zero", "estimate")]
    result["estimation_estimated_initial_state"] = fitted[1].to_dict()
    warnings = {"model": result["model"]["warnings"],
                "estimation": fit_warnings(estimator.outputs_, *fitted, str(data))}
    if validation is not None:
        validated = [estimator.evaluate(validation, full_scale=scale, initial_state=state)
                     for state in ("zero", "estimate")]
        result["validation"], result["validation_estimated_initial_state"] = (s.to_dict() for s in validated)
        warnings["validation"] = fit_warnings(estimator.outputs_, *validated, validation.source, fitted[1])
    result["warnings"] = [text for texts in warnings.values() for text in texts]
    for text in result["warnings"]:
        errors.print(f"[yellow]warning:[/] {escape(text)}")
    if model_file is not None:
        result["saved"] = str(save_model(model_file, estimator))
    if bode is not None:
        save_figure(estimator.bode(confidence=confidence, recording=checked), bode)
        result["bode"] = str(bode)
    if residuals is not None:
        if tests is None:
            fail(f"--residuals: {checked.n_samples} samples are too few for residual tests")
        save_figure(tests.figure(), residuals)
        result["residuals"] = str(residuals)
    if compare is not None:
        save_figure(estimator.compare(checked), compare)
        result["compare"] = str(compare)
    for name, path in (("step", step), ("impulse", impulse)):
        if path is not None:
            save_figure(estimator.response_figure(name, confidence), path)
            result[name] = str(path)
    if json_output:
        print(json.dumps(result, indent=2))
        return
    _print_summary(result["model"])
    if result["note"]:
        console.print(f"[yellow]note:[/] {result['note']}")
    if kind is Kind.tf:
        _print_uncertainty(result["model"]["uncertainty"], inputs, outputs)
    elif result["model"]["uncertainty"] is not None:
        _print_state_space_uncertainty(result["model"]["uncertainty"], inputs, outputs)
    else:
        console.print(f"parameter covariance {result['model']['uncertainty_note']}")
    for text in warnings["model"]:
        console.print(f"[yellow]warning:[/] {escape(text)}")
    console.print(_scores_table(f"estimation on {escape(recording.source)} (simulated from each trial's estimated "
                                "initial state)", result["estimation_estimated_initial_state"],
                                warnings["estimation"]))
    if validation is not None:
        console.print(_scores_table(f"validation on {escape(validation.source)} (simulated from rest)",
                                    result["validation"]))
        console.print(_scores_table(f"validation on {escape(validation.source)} (simulated from each trial's "
                                    "estimated initial state)",
                                    result["validation_estimated_initial_state"], warnings["validation"]))
    if result["residual_tests"] is not None:
        _print_residual_tests(result["residual_tests"])
    for name in ("saved", "bode", "residuals", "compare", "step", "impulse"):
        if name in result:
            console.print(f"{name} -> {result[name]}")


def _distinct(names: list[str], option: str) -> None:
    if not names:
        fail(f"{option}: expected at least one column name")
    check_distinct(names, option)


def _order_range(text: str) -> list[int]:
    try:
        if "-" in text:
            first, last = (int(part) for part in text.split("-"))
            orders = list(range(first, last + 1))
        else:
            orders = [int(part) for part in text.split(",")]
    except ValueError:
        orders = []
    if not orders or min(orders) < 1 or len(set(orders)) < len(orders):
        fail(f"--orders = {text!r}: expected a range like 2-8 or a list like 2,4,6 of different positive integers")
    return orders


def sysid_orders(
    data: Path = DATA,
    input: list[str] = INPUTS,
    output: list[str] = OUTPUTS,
    kind: Kind = typer.Option(..., "--kind", help="tf: transfer-function matrix; ss: state space."),
    orders: str = typer.Option(None, "--orders", help="Orders, e.g. 2-8 or 2,4,6 (default: tf 2-8, ss 2-12)."),
    method: Method = typer.Option(Method.moesp, "--method", help="Subspace method (ss; MOESP validates best on the benchmark cases)."),
    detrend: Detrend = DETREND,
    delay: str = DELAY,
    max_delay: int = MAX_DELAY,
    ts: float = TS,
    time_column: str = TIME_COLUMN,
    trial_column: str = TRIAL_COLUMN,
    columns: str = COLUMNS,
    unit: list[str] = UNIT,
    resample: float = RESAMPLE,
    missing: float = MISSING,
    validate: Path = VALIDATE,
    validate_input: list[str] = VALIDATE_INPUT,
    validate_output: list[str] = VALIDATE_OUTPUT,
    initial_state: InitialState = typer.Option(InitialState.zero, "--initial-state",
                                               help="Score each fit from rest (zero) or from each trial's "
                                                    "estimated initial state (estimate)."),
    json_output: bool = JSON,
) -> None:
    """Fit every order and tabulate fit %, AIC, BIC and time (fit % on --validate if given; AIC and BIC on the
    estimation data: N ln det Σ + 2p (AIC) or + p ln N (BIC), + N ny (ln 2π + 1), Σ the residual covariance)."""
    from softtip.sysid import order_table

    check_number(max_delay, "--max-delay", minimum=0, maximum=100_000)
    reading = _reading(ts, time_column, trial_column, columns, unit, resample, missing)
    delay_per_input = _delay(delay)
    chosen = None if orders is None else _order_range(orders)
    inputs, outputs = _names(input), _names(output)
    _distinct(inputs, "--input")
    _distinct(outputs, "--output")
    recording, validation = _records(data, validate, inputs, outputs, validate_input, validate_output, reading)
    params = {"detrend": detrend.value, "delay": delay_per_input, "max_delay": max_delay}
    params |= {"method": method.value} if kind is Kind.ss else {}
    rows = order_table(recording, kind.value, chosen, validation,
                       initial_state.value, **params)
    note = _level_note(recording, detrend)
    if json_output:
        print(json.dumps(rows, indent=2))
        return
    where = (f"on {escape(validation.source)}" if validation is not None else "on the estimation data") + \
        (" from rest" if initial_state is InitialState.zero else " from the estimated initial states")
    table = Table(title=f"{'transfer functions (poles per entry)' if kind is Kind.tf else 'state space (states)'}: "
                        f"fit % {where}")
    for heading in ("order", "parameters", "fit %", *outputs, "AIC", "BIC", "stable", "seconds"):
        table.add_column(heading, justify="right")
    best_bic = min(rows, key=lambda row: row["bic"])["order"]
    for row in rows:
        table.add_row(f"{row['order']}{' *' if row['order'] == best_bic else ''}", str(row["parameters"]),
                      f"{row['fit_percent']:.1f}", *(f"{row['fit_percent_per_output'][name]:.1f}" for name in outputs),
                      f"{row['aic']:.1f}", f"{row['bic']:.1f}", "yes" if row["stable"] else "no",
                      f"{row['seconds']:.2f}")
    table.caption = "* lowest BIC"
    console.print(table)
    if note:
        console.print(f"[yellow]note:[/] {note}")


def sysid_predict(
    model_file: Path = typer.Argument(..., help="Saved model (.npz) from softtip sysid fit."),
    data: Path = DATA,
    horizon: int = typer.Option(None, "--horizon", "-k",
                                help="Predict k steps ahead from the measured outputs (default: simulate)."),
    ts: float = TS,
    time_column: str = TIME_COLUMN,
    trial_column: str = TRIAL_COLUMN,
    columns: str = COLUMNS,
    resample: float = RESAMPLE,
    missing: float = MISSING,
    full_scale: list[float] = FULL_SCALE,
    out: Path = typer.Option(None, "--out", "-o", help="Write trial, time_s and the predicted outputs (.parquet)."),
    force: bool = FORCE,
    initial_state: InitialState = typer.Option(InitialState.zero, "--initial-state",
                                               help="zero: from rest; estimate: each trial's initial state from "
                                                    "its measured outputs."),
    json_output: bool = JSON,
) -> None:
    """Run a saved model on a recording; score it where the recording has the model's outputs."""
    from softtip.sysid import load_model
    from softtip.sysid.recording import file_columns

    check_number(horizon, "--horizon", minimum=1, maximum=10_000_000)
    reading = _reading(ts, time_column, trial_column, columns, None, resample, missing)
    scale = _full_scale(full_scale)
    if out is not None:
        check_output(out, "--out", [model_file, data], force=force)
    model = load_model(model_file)
    present = file_columns(data, reading.columns)
    measured = all(name in present for name in model.outputs_)
    if horizon is not None and not measured:
        fail(f"{data}: --horizon needs the measured outputs {', '.join(model.outputs_)}")
    if initial_state is InitialState.estimate and not measured:
        fail(f"{data}: --initial-state estimate needs the measured outputs {', '.join(model.outputs_)}")
    recording = _read(data, list(model.inputs_), list(model.outputs_) if measured else [], reading)
    predicted = model.predict(recording, horizon, initial_state.value) if measured else model.simulate(recording)
    scores = None
    if measured:
        scores = replace(model.evaluate_predictions(recording, predicted, scale),
                         initial_state="estimated" if initial_state is InitialState.estimate else "zero")
    result = {"model": str(model_file), "horizon": horizon, "trials": len(recording.trials),
              "samples": recording.n_samples, "scores": None if scores is None else scores.to_dict()}
    if out is not None:
        result["written"] = str(_write_predictions(out, recording, predicted, model.outputs_, model_file, horizon))
    if json_output:
        print(json.dumps(result, indent=2))
        return
    what = "simulated" if horizon is None else f"{horizon}-step-ahead predictions"
    if measured:
        console.print(_scores_table(f"{model_file} on {data} ({what})", result["scores"]))
    else:
        console.print(f"{data} has no measured outputs: {what} only")
    if out is not None:
        console.print(f"{recording.n_samples} samples -> {result['written']}")


def _write_predictions(path: Path, recording, predicted, outputs, model_file: Path, horizon: int | None) -> Path:
    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq

    columns = {"trial": np.concatenate([np.full(len(trial), trial.id) for trial in recording.trials]),
               "time_s": np.concatenate([recording.time(k) for k in range(len(recording.trials))])}
    stacked = np.vstack(predicted)
    for k, name in enumerate(outputs):
        columns[f"{name}_predicted"] = stacked[:, k]
    note = {"model": str(model_file), "horizon": horizon, "data": recording.source}
    table = pa.table(columns).replace_schema_metadata({b"softtip-sysid": json.dumps(note).encode()})
    return atomic_write(path, lambda handle: pq.write_table(table, handle))
