"""``softtip lab run``, ``softtip reproduce``, ``softtip calibrate``, ``softtip evaluate``.

"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from softtip._core.systems import names, studies

if TYPE_CHECKING:
    import numpy as np
from softtip.cli.common import (FORCE, check_distinct, check_number, check_output, check_output_folder, console, errors,
                                fail, printable, progress_for)

STUDY_NAMES = tuple(studies())
MODEL_KINDS = ("polynomial", "network", "classifier")
MAX_HIDDEN = 10_000  # neurons in a layer: beyond, the Levenberg-Marquardt Jacobian outgrows memory
# softtip.calibration.validation's early-stopping rules and defaults, mirrored (and tested equal) so that
# --help does not import the calibration stack
STOPPING_RULES = ("auto", "trials", "blocks")
MIN_TRIALS_HELD_OUT = 10
DEFAULT_BLOCK_S = 5.0
MAX_BLOCK_S = 7 * 86_400.0  # a week, as --duration: a longer block is one block per trial
MAX_JOBS = 256  # processes of reproduce --jobs: beyond, more than any machine's cores


def lab_run(
    protocol: str = typer.Argument(..., help=f"A protocol file, or a shipped one: {', '.join(names('protocol'))}."),
    output: Path = typer.Option(None, "--output", "-o", help="Dataset file (.parquet); default PROTOCOL.parquet."),
    seed: int = typer.Option(None, "--seed", help="Override the protocol's seed."),
    force: bool = typer.Option(False, "--force", help="Replace an output file that exists, and run a protocol "
                                                      "whose estimated work is above its bench's limit."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Run one experiment protocol on the twin and write its dataset (Parquet + metadata)."""
    from softtip.lab import load_protocol, run_protocol

    if seed is not None and seed < 0:
        fail(f"--seed = {seed}: expected an integer >= 0")
    loaded = load_protocol(protocol).changed(seed=seed)
    target = check_output(output or Path(f"{loaded.name}.parquet"), "--output",
                          [*([protocol] if Path(protocol).is_file() else []), *loaded.files], force=force)
    dataset, timings = run_protocol(loaded, progress_for(json_output), large=force)
    path = dataset.write(target)
    summary = {"protocol": loaded.name, "design": loaded.design.name, "seed": loaded.seed, "dataset": str(path),
               "trials": len(dataset.trials), "samples": int(len(dataset.groups)), "channels": list(dataset.channels),
               "labels": dict(dataset.labels), "timings_s": {k: round(v, 2) for k, v in timings.items()}}
    if json_output:
        print(json.dumps(summary, indent=2))
    else:
        console.print(f"{summary['trials']} trials, {summary['samples']} samples -> {path}")


def chosen_studies(studies: list[str] | None) -> tuple[str, ...]:
    """The registered studies named on the command line, each once (``all`` or none: every one); a name
    not registered is a user error."""
    names = STUDY_NAMES if not studies or studies == ["all"] else tuple(dict.fromkeys(studies))
    unknown = [name for name in names if name not in STUDY_NAMES]
    if unknown:
        fail(f"STUDIES = {unknown[0]!r}: expected one of {', '.join(STUDY_NAMES)}, or all")
    return names


def reproduce(
    studies: list[str] = typer.Argument(..., help=f"One or more of {', '.join(STUDY_NAMES)}, or all."),
    output: Path = typer.Option(Path("reports"), "--output", "-o", help="Directory for the HTML reports and index.html."),
    seed: int = typer.Option(1, "--seed", help="Seed of the experiments and the models."),
    quick: bool = typer.Option(False, "--quick",
                               help="Two trials per condition and each study's coarse protocol: a smoke run, "
                                    "not the study."),
    force: bool = typer.Option(False, "--force", help="Replace the reports and index.html that --output holds."),
    jobs: int = typer.Option(None, "--jobs", "-j",
                             help="Studies run at once, each in a process of its own (default: one per core; 1 runs "
                                  "them one after another). The results are the same either way."),
    json_output: bool = typer.Option(False, "--json", help="Print each study's results beside the published figures as JSON."),
) -> None:
    """Run published studies end to end (experiments on the twin -> models -> metrics); write one
    self-contained HTML report per study, the publication's tables beside softtip's, and index.html."""
    import sys

    from softtip.studies.reproduce import INDEX_FILE, default_workers, report_files, reproduce_studies, write_index

    names = chosen_studies(studies)
    if seed < 0:
        fail(f"--seed = {seed}: expected an integer >= 0")
    check_number(jobs, "--jobs", minimum=1, maximum=MAX_JOBS)
    check_output_folder(output, "--output", [*(file for name in names for file in report_files(name)), INDEX_FILE],
                        force=force)
    command = "softtip " + " ".join(sys.argv[1:])

    def finished(name: str, report: dict) -> None:
        if not json_output:
            headline = report["headline"]
            published = f", published {headline['published']} ({headline['verdict']})" if headline["published"] else ""
            value = "n/a" if headline["softtip"] is None else f"{headline['softtip']:.4g}"
            console.print(f"{name}: {headline['label']} = {value} {headline['unit']}{published}; "
                          f"{report['report']} ({report['seconds']:.0f} s)")

    everything = reproduce_studies(names, output, seed=seed, quick=quick, workers=jobs or default_workers(),
                                   progress=progress_for(json_output), command=command, finished=finished)
    index = write_index(output)
    if json_output:
        print(json.dumps({"index": str(index), "studies": everything}, indent=2))
    else:
        console.print(f"index: {index}")


def calibrate(
    dataset: Path = typer.Argument(..., help="Dataset (.parquet) from softtip lab run or softtip convert."),
    target: list[str] = typer.Option(..., "--target", "-t", help="Label column(s) to estimate."),
    model: str = typer.Option("network", "--model", help=f"One of {', '.join(MODEL_KINDS)}."),
    hidden: list[str] = typer.Option(["10"], "--hidden",
                                     help="Hidden layer sizes, e.g. 20 or 10,10,10,10. Given more than once (with "
                                          "--cv), the candidates are cross-validated by trial and the best is fitted."),
    min_force: float = typer.Option(None, "--min-label", help="Use only samples whose first target is above this."),
    early_stopping: str = typer.Option(
        "auto", "--early-stopping",
        help="What the network holds out to stop training: trials (whole trials), blocks (every trial cut into "
             "--block-s pieces, whole pieces held out: right with few, different trials), or auto (trials from "
             f"{MIN_TRIALS_HELD_OUT} calibration trials, else blocks)."),
    block_s: float = typer.Option(DEFAULT_BLOCK_S, "--block-s", help="Length of the early-stopping blocks, seconds."),
    cv: int = typer.Option(None, "--cv", help="Also cross-validate by trial: K folds of whole calibration trials "
                                             "(2 to their number), for the model, each --hidden candidate and "
                                             "every baseline."),
    baseline: bool = typer.Option(False, "--baseline", help="Also fit and score scikit-learn's ridge, gradient "
                                                            "boosting and MLP on the same samples, as a reference."),
    output: Path = typer.Option(Path("model.npz"), "--output", "-o", help="Saved model (.npz)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the training."),
    force: bool = FORCE,
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Fit a model on the calibration trials of a dataset, score it on its validation trials, save it.

    The network's early stopping holds out whole trials or blocks of trials (--early-stopping); with --baseline,
    scikit-learn references are scored beside it; a validation set outside the calibration range is warned of.
    """
    import numpy as np

    from softtip.calibration import save_model
    from softtip.calibration.validation import CalibrationRange, stopping_groups
    from softtip.data import Dataset
    from softtip.data.splits import by_role
    from softtip.sensors.registry import check_changes

    if model not in MODEL_KINDS:
        fail(f"--model = {model!r}: expected one of {', '.join(MODEL_KINDS)}")
    if early_stopping not in STOPPING_RULES:
        fail(f"--early-stopping = {early_stopping!r}: expected one of {', '.join(STOPPING_RULES)}")
    check_number(block_s, "--block-s", above=0, maximum=MAX_BLOCK_S, unit="s")
    if model == "classifier" and (baseline or cv is not None):
        fail(f"{'--baseline' if baseline else '--cv'}: scores regression models; --model classifier is not one")
    check_distinct(target, "--target", "each label is estimated once")
    if seed < 0:
        fail(f"--seed = {seed}: expected an integer >= 0")
    if cv is not None and cv < 2:
        fail(f"--cv = {cv}: expected a number of folds >= 2")
    candidates = [_layer_sizes(text) for text in hidden]
    if len(set(candidates)) < len(candidates):
        fail("--hidden: a candidate is given twice; each is cross-validated once")
    if len(candidates) > 1 and (cv is None or model != "network"):
        fail(f"--hidden given {len(candidates)} times: choosing between candidates needs --cv K and --model network")
    check_output(output, "--output", [dataset], force=force)
    data = Dataset.read(dataset)
    unknown = [t for t in target if t not in data.labels]
    if unknown:
        fail(f"--target {unknown[0]!r}: {dataset} has labels {', '.join(data.labels)}")
    _check_label_units(data, dataset, target)
    check_changes(data.columns, data.metadata.sensor_settings, str(dataset))
    _check_finite(data, dataset, target)
    X, y = data.X(), _targets(data, target, model)
    keep = np.ones(len(X), dtype=bool) if min_force is None else (np.asarray(y if y.ndim == 1 else y[:, 0], float) > min_force)
    calibration, _ = by_role(data)
    train, test = keep & calibration, keep & ~calibration
    if not train.any():
        fail(f"{dataset}: no calibration samples (role = calibration) to fit on")
    trial, time_s = data.groups[train], data.column("time_s")[train]
    n_trials = np.unique(trial).size
    if cv is not None and cv > n_trials:
        fail(f"--cv = {cv}: {dataset} has {n_trials} calibration trials, fewer than the folds asked for")
    groups, rule = stopping_groups(trial, time_s, early_stopping, block_s)
    names = tuple(target)
    sizes = candidates[0]
    if cv is not None:
        cross = _cross_validation(X[train], y[train], trial, time_s, cv, model, candidates, seed, early_stopping,
                                  block_s, baseline, names, json_output)
        sizes = candidates[[_label(model, c) for c in candidates].index(cross["selected"])]
    estimator = _make_model(model, sizes, seed, rule)
    start = time.perf_counter()
    estimator.fit(X[train], y[train], groups=groups)
    seconds = time.perf_counter() - start
    report = _score(estimator, model, X[test], y[test], names) if test.any() else {}
    warned = []
    if not test.any():
        warned.append(f"{dataset} has no validation samples (role = validation): the model is saved unscored")
    summary = {"model": str(output), "kind": model, "label": _label(model, sizes), "hidden": list(sizes),
               "targets": list(target), "fit_s": round(seconds, 2), "calibration_samples": int(train.sum()),
               "calibration_trials": int(n_trials), "validation_samples": int(test.sum()), "validation": report}
    if model != "polynomial":
        summary["early_stopping"] = {"rule": rule, "block_s": block_s if rule == "blocks" else None,
                                     "groups": int(np.unique(groups).size), "stop_reason": estimator.stop_reason_,
                                     "best_epoch": int(estimator.best_epoch_)}
    calibration_range = CalibrationRange.of(X[train], y[train]) if model != "classifier" else None
    if test.any() and calibration_range is not None:
        shift = calibration_range.shift(X[test], y[test])
        summary["shift"] = shift.to_json(data.channels)
        if shift.shifted:
            warned.append(shift.warning(data.channels, names))
    if baseline and test.any():
        from softtip.calibration.validation import baselines

        with progress_for(json_output).task("fitting the scikit-learn baselines"):
            references = baselines((X[train], y[train]), (X[test], y[test]), names, seed)
        summary["baselines"] = {reference.name: reference.to_json() for reference in references}
        warned += [f"baseline {reference.name} stopped at its iteration cap without converging"
                   for reference in references if not reference.converged]
    elif baseline:
        warned.append("--baseline: no validation samples to score the baselines on")
    if cv is not None:
        summary["cross_validation"] = cross
        warned += [cross["warning"]] if cross["warning"] else []
    summary["warnings"] = warned
    save_model(output, estimator, input_channels=list(data.channels),
               input_units=[data.channel_units[c] for c in data.channels],
               target_names=list(target) if model != "classifier" else [target[0]],
               target_units=[data.labels[t] for t in target][: 1 if model == "classifier" else None],
               extra={"dataset": str(dataset), "validation": report,
                      "early_stopping": summary.get("early_stopping"),
                      "calibration_range": calibration_range and calibration_range.to_json()})
    for warning in warned:
        errors.print(printable(f"warning: {warning}"), markup=False, highlight=False, soft_wrap=True)
    if json_output:
        print(json.dumps(summary, indent=2))
    else:
        console.print(_calibration_table(summary, data.labels))
        console.print(f"model saved: {output}")


def _layer_sizes(text: str) -> tuple[int, ...]:
    """The hidden layer sizes of one --hidden value, or a one-line refusal."""
    try:
        sizes = tuple(int(v) for v in text.split(","))
    except ValueError:
        sizes = ()
    if not sizes or min(sizes) < 1 or max(sizes) > MAX_HIDDEN:
        fail(f"--hidden = {text!r}: expected sizes from 1 to {MAX_HIDDEN} separated by commas, e.g. 10,10")
    return sizes


def _label(kind: str, sizes: tuple[int, ...]) -> str:
    """A model's name in tables: its kind, and its hidden layers if it has any."""
    return kind if kind == "polynomial" else f"{kind} {','.join(map(str, sizes))}"


def _cross_validation(X, y, trial, time_s, folds: int, kind: str, candidates: list[tuple[int, ...]], seed: int,
                      early_stopping: str, block_s: float, with_baselines: bool, targets: tuple[str, ...],
                      json_output: bool) -> dict:
    """The RMSE per target of every candidate of softtip's model (and of the baselines) on held-out
    calibration trials, and the candidate selected."""
    from softtip.calibration.validation import BASELINES, Candidate, baseline, cross_validate_by_trial, selected

    models = [Candidate(_label(kind, sizes), lambda rule, sizes=sizes: _make_model(kind, sizes, seed, rule), True)
              for sizes in candidates]
    if with_baselines:
        models += [Candidate(name, lambda rule, name=name: baseline(name, seed), False) for name in BASELINES]
    with progress_for(json_output).task(f"cross-validating by trial ({folds} folds)"):
        cross = cross_validate_by_trial(models, X, y, trial, time_s, folds, early_stopping, block_s)
    own = {model.name: cross.rmse[model.name] for model in models[:len(candidates)]}
    shifted = [f"trials {', '.join(map(str, trials))} ({100 * shift.input_share:.0f} % of samples)"
               for trials, shift in zip(cross.held_out_trials, cross.held_out_shifts, strict=True) if shift.shifted]
    return {"folds": folds, "selected": selected(own, y),
            "rmse": {name: dict(zip(targets, map(float, values), strict=True)) for name, values in cross.rmse.items()},
            "held_out": [{"trials": list(trials), "input_share": shift.input_share, "target_share": shift.target_share}
                         for trials, shift in zip(cross.held_out_trials, cross.held_out_shifts, strict=True)],
            "warning": (f"cross-validation holds out trials beyond the range of the others: {'; '.join(shifted)}; "
                        "their errors measure extrapolation") if shifted else ""}


def _calibration_table(summary: dict, units: dict[str, str]):
    """The validation scores of the model and its references, one row per model and target."""
    from rich.table import Table

    stopping = summary.get("early_stopping")
    title = f"{summary['label']} on {summary['calibration_samples']} calibration samples"
    if stopping:
        title += f", early stopping by {stopping['rule']} ({stopping['stop_reason']} at epoch {stopping['best_epoch']})"
    table = Table(title=title, caption="\n".join(f"warning: {warning}" for warning in summary["warnings"]) or None,
                  caption_justify="left")
    cross = summary.get("cross_validation")
    for column in ("model", "target", "RMSE", "MAE", "R²", *(["CV RMSE by trial"] if cross else [])):
        table.add_column(column, justify="left" if column in ("model", "target") else "right")
    rows = [(summary["label"], summary["validation"])]
    rows += [(name, reference["validation"]) for name, reference in summary.get("baselines", {}).items()]
    for name, scores in rows:
        for label, score in scores.items():
            if not isinstance(score, dict):  # a classifier's report: accuracy and probability
                table.add_row(name, label, f"{score:.4g}", "", "")
                continue
            unit = units.get(label, "")
            cells = [f"{score['rmse']:.4g} {unit}", f"{score['mean_abs_error']:.4g} {unit}", f"{score['r2']:.4f}"]
            if cross:
                cells.append(f"{cross['rmse'][name][label]:.4g} {unit}")
            table.add_row(name, label, *cells)
    scored = {name for name, scores in rows if scores}
    for name, scores in (cross or {}).get("rmse", {}).items():  # cross-validated only: not chosen, or no validation
        if name not in scored:
            for label, rmse in scores.items():
                table.add_row(name, label, "", "", "", f"{rmse:.4g} {units.get(label, '')}")
    return table


def evaluate(
    model_file: Path = typer.Argument(..., help="Saved model (.npz)."),
    dataset: Path = typer.Argument(..., help="Dataset (.parquet)."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Score a saved model on every sample of a dataset (its validation report, by condition).

    A regression model saved with its calibration range is checked against the dataset: "shift" holds the
    out-of-range shares, and "warnings" (also on stderr) says when the dataset lies outside that range.
    """
    from softtip.calibration import load_model
    from softtip.calibration.validation import CalibrationRange
    from softtip.data import Dataset

    estimator, meta = load_model(model_file)
    data = Dataset.read(dataset)
    kind = "classifier" if hasattr(estimator, "predict_proba") else "regression"
    targets = list(meta.target_names)
    check_model_data(meta, data, dataset)
    X = data.X(list(meta.input_channels))
    y = _targets(data, targets, kind)
    report = _score(estimator, kind, X, y, targets)
    stored = meta.extra.get("calibration_range")
    if kind == "regression" and stored is not None:
        shift = CalibrationRange.from_json(stored, len(meta.input_channels), len(targets)).shift(X, y)
        report["shift"] = shift.to_json(tuple(meta.input_channels))
        report["warnings"] = [shift.warning(tuple(meta.input_channels), tuple(targets))] if shift.shifted else []
        for warning in report["warnings"]:
            errors.print(printable(f"warning: {warning}"), markup=False, highlight=False, soft_wrap=True)
    if json_output:
        print(json.dumps(report, indent=2))
    else:
        console.print(json.dumps(report, indent=2))


# The units softtip's label names end in (SI or the tables' mm, degrees, mN, mT, µT), by that ending.
NAMED_UNITS = ("N", "mN", "m", "mm", "deg", "rad", "s", "Pa", "kPa", "T", "mT", "uT")


def check_model_data(meta, data, dataset: Path) -> None:
    """A dataset a saved model (``meta``: its metadata) can be scored on: the model's input channels
    and targets, labels in the units their names state, readings within the chip's range."""
    from softtip.sensors.registry import check_changes

    missing = [c for c in meta.input_channels if c not in data.channels]
    if missing:
        fail(f"{dataset}: lacks the model's input channel {missing[0]!r}")
    absent = [t for t in meta.target_names if t not in data.labels]
    if absent:
        fail(f"{dataset}: lacks the model's target {absent[0]!r}")
    _check_label_units(data, dataset, list(meta.target_names))
    check_changes(data.columns, data.metadata.sensor_settings, str(dataset))
    _check_finite(data, dataset, list(meta.target_names))


def _check_finite(data, dataset: Path, targets: list[str]) -> None:
    """Every target value finite, refused by file and column before any fit (scikit-learn's own refusal
    names neither)."""
    from softtip.data import DatasetError

    try:
        data.require_finite(targets)
    except DatasetError as problem:
        fail(f"{dataset}: {problem}")


def _check_label_units(data, dataset: Path, targets: list[str]) -> None:
    """A label whose name states its unit (``fz_N``) must be declared in that unit: a label of "furlongs",
    or of kN, named in newtons would be scored in a unit it is not in."""
    for name in targets:
        named = name.rsplit("_", 1)[-1] if "_" in name else None
        declared = data.labels[name]
        if named in NAMED_UNITS and declared != named:
            fail(f"{dataset}: label {name!r} is declared in {declared!r}, but its name says {named!r}")


def _make_model(kind: str, sizes: tuple[int, ...], seed: int, rule: str):
    """An unfitted model of ``kind``; a network's early stopping as the applied ``rule`` (trials or blocks) asks."""
    from softtip.calibration import LMNetwork, PolynomialFit, SoftmaxClassifier
    from softtip.calibration.validation import min_progress

    if kind == "polynomial":
        return PolynomialFit()
    if kind == "network":
        return LMNetwork(sizes, min_progress=min_progress(rule), random_state=seed)
    return SoftmaxClassifier(sizes, random_state=seed)


def _targets(data, target: list[str], kind: str) -> np.ndarray:
    import numpy as np

    if kind == "classifier":
        return data.column(target[0])
    columns = [np.asarray(data.column(t), dtype=float) for t in target]
    return columns[0] if len(columns) == 1 else np.column_stack(columns)


def _score(estimator, kind: str, X: np.ndarray, y: np.ndarray, target: tuple[str, ...] | list[str]) -> dict:
    import numpy as np

    from softtip import metrics
    from softtip.calibration.validation import regression_scores

    if kind == "classifier":
        predicted = estimator.predict(X)
        return {"accuracy": float(np.mean(predicted == y)),
                "mean_probability_of_true_class": metrics.mean_probability_of_true_class(
                    estimator.predict_proba(X), y, estimator.classes_)}
    return regression_scores(y, estimator.predict(X), tuple(target))
