"""``softtip lab run``, ``softtip reproduce``, ``softtip calibrate``, ``softtip evaluate``.

"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import typer

from softtip._core.systems import names, studies
from softtip.cli.common import (FORCE, check_distinct, check_output, check_output_folder, console, errors, fail,
                                printable, progress_for)

STUDY_NAMES = tuple(studies())
MODEL_KINDS = ("polynomial", "network", "classifier")
MAX_HIDDEN = 10_000  # neurons in a layer: beyond, the Levenberg-Marquardt Jacobian outgrows memory


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
                          [protocol] if Path(protocol).is_file() else [], force=force)
    dataset, timings = run_protocol(loaded, progress_for(json_output), large=force)
    path = dataset.write(target)
    summary = {"protocol": loaded.name, "design": loaded.design.name, "seed": loaded.seed, "dataset": str(path),
               "trials": len(dataset.trials), "samples": int(len(dataset.groups)), "channels": list(dataset.channels),
               "labels": dict(dataset.labels), "timings_s": {k: round(v, 2) for k, v in timings.items()}}
    if json_output:
        print(json.dumps(summary, indent=2))
    else:
        console.print(f"{summary['trials']} trials, {summary['samples']} samples -> {path}")


def reproduce(
    studies: list[str] = typer.Argument(..., help=f"One or more of {', '.join(STUDY_NAMES)}, or all."),
    output: Path = typer.Option(Path("reports"), "--output", "-o", help="Directory for the HTML reports and index.html."),
    seed: int = typer.Option(1, "--seed", help="Seed of the experiments and the models."),
    quick: bool = typer.Option(False, "--quick",
                               help="Two trials per condition and each study's coarse protocol: a smoke run, "
                                    "not the study."),
    json_output: bool = typer.Option(False, "--json", help="Print each study's results beside the published figures as JSON."),
) -> None:
    """Run published studies end to end (experiments on the twin -> models -> metrics); write one
    self-contained HTML report per study, the publication's tables beside softtip's, and index.html."""
    import sys

    from softtip.studies.reproduce import reproduce_study, write_index

    names = STUDY_NAMES if studies == ["all"] else tuple(dict.fromkeys(studies))
    unknown = [name for name in names if name not in STUDY_NAMES]
    if unknown:
        fail(f"STUDIES = {unknown[0]!r}: expected one of {', '.join(STUDY_NAMES)}, or all")
    if seed < 0:
        fail(f"--seed = {seed}: expected an integer >= 0")
    check_output_folder(output, "--output")
    command = "softtip " + " ".join(sys.argv[1:])
    everything = {}
    progress = progress_for(json_output)
    for name in names:
        with progress.task(f"reproducing {name}"):
            study = reproduce_study(name, seed=seed, quick=quick, progress=progress, command=command)
        report = study.write(output)
        everything[name] = study.to_json(str(report))
        if not json_output:
            headline = everything[name]["headline"]
            published = f", published {headline['published']} ({headline['verdict']})" if headline["published"] else ""
            value = "n/a" if headline["softtip"] is None else f"{headline['softtip']:.4g}"
            console.print(f"{name}: {headline['label']} = {value} {headline['unit']}{published}; "
                          f"{report} ({study.seconds:.0f} s)")
    index = write_index(output)
    if json_output:
        print(json.dumps({"index": str(index), "studies": everything}, indent=2))
    else:
        console.print(f"index: {index}")


def calibrate(
    dataset: Path = typer.Argument(..., help="Dataset (.parquet) from softtip lab run or softtip convert."),
    target: list[str] = typer.Option(..., "--target", "-t", help="Label column(s) to estimate."),
    model: str = typer.Option("network", "--model", help=f"One of {', '.join(MODEL_KINDS)}."),
    hidden: str = typer.Option("10", "--hidden", help="Hidden layer sizes, e.g. 20 or 10,10,10,10."),
    min_force: float = typer.Option(None, "--min-label", help="Use only samples whose first target is above this."),
    output: Path = typer.Option(Path("model.npz"), "--output", "-o", help="Saved model (.npz)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the training."),
    force: bool = FORCE,
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Fit a model on the calibration trials of a dataset, score it on its validation trials, save it."""
    from softtip.calibration import save_model
    from softtip.data import Dataset
    from softtip.data.splits import by_role

    if model not in MODEL_KINDS:
        fail(f"--model = {model!r}: expected one of {', '.join(MODEL_KINDS)}")
    check_distinct(target, "--target", "each label is estimated once")
    if seed < 0:
        fail(f"--seed = {seed}: expected an integer >= 0")
    check_output(output, "--output", [dataset], force=force)
    data = Dataset.read(dataset)
    unknown = [t for t in target if t not in data.labels]
    if unknown:
        fail(f"--target {unknown[0]!r}: {dataset} has labels {', '.join(data.labels)}")
    _check_label_units(data, dataset, target)
    _check_readings(data, dataset)
    try:
        sizes = tuple(int(v) for v in hidden.split(","))
    except ValueError:
        sizes = ()
    if not sizes or min(sizes) < 1 or max(sizes) > MAX_HIDDEN:
        fail(f"--hidden = {hidden!r}: expected sizes from 1 to {MAX_HIDDEN} separated by commas, e.g. 10,10")
    estimator = _make_model(model, sizes, seed)
    X, y = data.X(), _targets(data, target, model)
    keep = np.ones(len(X), dtype=bool) if min_force is None else (np.asarray(y if y.ndim == 1 else y[:, 0], float) > min_force)
    calibration, _ = by_role(data)
    train, test = keep & calibration, keep & ~calibration
    if not train.any():
        fail(f"{dataset}: no calibration samples (role = calibration) to fit on")
    start = time.perf_counter()
    estimator.fit(X[train], y[train], groups=data.groups[train])
    seconds = time.perf_counter() - start
    report = _score(estimator, model, X[test], y[test], target) if test.any() else {}
    if not test.any():
        errors.print(printable(f"warning: {dataset} has no validation samples (role = validation): the model is "
                               "saved unscored"), markup=False, highlight=False, soft_wrap=True)
    save_model(output, estimator, input_channels=list(data.channels),
               input_units=[data.channel_units[c] for c in data.channels],
               target_names=list(target) if model != "classifier" else [target[0]],
               target_units=[data.labels[t] for t in target][: 1 if model == "classifier" else None],
               extra={"dataset": str(dataset), "validation": report})
    summary = {"model": str(output), "kind": model, "hidden": list(sizes), "targets": list(target),
               "fit_s": round(seconds, 2), "calibration_samples": int(train.sum()),
               "validation_samples": int(test.sum()), "validation": report}
    if json_output:
        print(json.dumps(summary, indent=2))
    else:
        console.print(json.dumps(summary, indent=2))


def evaluate(
    model_file: Path = typer.Argument(..., help="Saved model (.npz)."),
    dataset: Path = typer.Argument(..., help="Dataset (.parquet)."),
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Score a saved model on every sample of a dataset (its validation report, by condition)."""
    from softtip.calibration import load_model
    from softtip.data import Dataset

    estimator, meta = load_model(model_file)
    data = Dataset.read(dataset)
    kind = "classifier" if hasattr(estimator, "predict_proba") else "regression"
    targets = list(meta.target_names)
    check_model_data(meta, data, dataset)
    X = data.X(list(meta.input_channels))
    y = _targets(data, targets, kind)
    report = _score(estimator, kind, X, y, targets)
    if json_output:
        print(json.dumps(report, indent=2))
    else:
        console.print(json.dumps(report, indent=2))


# The units softtip's label names end in (SI or the tables' mm, degrees, mN, mT, µT), by that ending.
NAMED_UNITS = ("N", "mN", "m", "mm", "deg", "rad", "s", "Pa", "kPa", "T", "mT", "uT")


def check_model_data(meta, data, dataset: Path) -> None:
    """A dataset a saved model (``meta``: its metadata) can be scored on: the model's input channels
    and targets, labels in the units their names state, readings within the chip's range."""
    missing = [c for c in meta.input_channels if c not in data.channels]
    if missing:
        fail(f"{dataset}: lacks the model's input channel {missing[0]!r}")
    absent = [t for t in meta.target_names if t not in data.labels]
    if absent:
        fail(f"{dataset}: lacks the model's target {absent[0]!r}")
    _check_label_units(data, dataset, list(meta.target_names))
    _check_readings(data, dataset)


def _check_label_units(data, dataset: Path, targets: list[str]) -> None:
    """A label whose name states its unit (``fz_N``) must be declared in that unit: a label of "furlongs",
    or of kN, named in newtons would be scored in a unit it is not in."""
    for name in targets:
        named = name.rsplit("_", 1)[-1] if "_" in name else None
        declared = data.labels[name]
        if named in NAMED_UNITS and declared != named:
            fail(f"{dataset}: label {name!r} is declared in {declared!r}, but its name says {named!r}")


def _check_readings(data, dataset: Path) -> None:
    """Magnetic readings (changes from a baseline, µT) within what an MLX90393 can output: a change between
    two readings in range is at most twice the range, at the dataset's sensor settings or, without them,
    at the chip's widest (GAIN_SEL 0, RES 3)."""
    from softtip._core.channels import MAGNETIC
    from softtip.sensors.mlx90393 import MLX90393Settings, full_scale_uT

    stated = data.metadata.sensor_settings
    settings = MLX90393Settings.from_dict(stated) if stated else MLX90393Settings(gain_sel=0, res_xyz=(3, 3, 3))
    where = "the dataset's sensor settings" if stated else "its widest setting"
    limit = 2 * full_scale_uT(settings)
    for channel in filter(MAGNETIC.is_channel, data.channels):
        values = data.columns[channel]
        largest = float(np.nanmax(np.abs(values))) if len(values) else 0.0
        bound = limit[MAGNETIC.channel_order(channel)[1]]
        if not largest <= bound:
            fail(f"{dataset}: channel {channel} reaches {largest:.4g} µT, beyond twice the MLX90393's "
                 f"{bound / 2:.4g} µT range at {where}")


def _make_model(kind: str, sizes: tuple[int, ...], seed: int):
    from softtip.calibration import LMNetwork, PolynomialFit, SoftmaxClassifier

    if kind == "polynomial":
        return PolynomialFit()
    if kind == "network":
        return LMNetwork(sizes, random_state=seed)
    return SoftmaxClassifier(sizes, random_state=seed)


def _targets(data, target: list[str], kind: str) -> np.ndarray:
    if kind == "classifier":
        return data.column(target[0])
    columns = [np.asarray(data.column(t), dtype=float) for t in target]
    return columns[0] if len(columns) == 1 else np.column_stack(columns)


def _score(estimator, kind: str, X: np.ndarray, y: np.ndarray, target: list[str]) -> dict:
    from softtip import metrics

    if kind == "classifier":
        predicted = estimator.predict(X)
        return {"accuracy": float(np.mean(predicted == y)),
                "mean_probability_of_true_class": metrics.mean_probability_of_true_class(
                    estimator.predict_proba(X), y, estimator.classes_)}
    estimate = estimator.predict(X).reshape(len(X), -1)
    truth = y.reshape(len(y), -1)
    return {name: {"mean_abs_error": float(metrics.mean_abs_error(truth[:, k], estimate[:, k])),
                   "rmse": float(metrics.rmse(truth[:, k], estimate[:, k])),
                   "r2": float(metrics.r2(truth[:, k], estimate[:, k]))} for k, name in enumerate(target)}
