"""``softtip import``: a rig's delimited text logs into a softtip dataset, as a mapping file says."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import typer

from softtip.cli.common import FORCE, check_input, check_number, check_output, console, errors, fail, printable

LONGEST_TOLERANCE_S = 3600.0  # a join across more than an hour pairs readings that have nothing to do with each other


def _trial_numbers(text: str) -> list[int]:
    try:
        numbers = [int(part) for part in text.split(",")]
    except ValueError:
        numbers = []
    if not numbers or min(numbers) < 0:
        fail(f"--validate-trials = {text!r}: expected trial numbers >= 0 separated by commas, e.g. 0,3")
    return numbers


def import_logs(
    sources: list[Path] = typer.Argument(..., help="Log files (labels in them) or folders (holding the mapping's "
                                                   "sensor and label files), one or more trials each."),
    mapping: Path = typer.Option(..., "--mapping", "-m", help="TOML mapping: which columns are which chip, axis "
                                                              "and label, in what unit; trials, validation, baseline."),
    output: Path = typer.Option(..., "--output", "-o", help="Dataset to write (.parquet)."),
    validate_last: int = typer.Option(None, "--validate-last", help="The last N trials validate (overrides the "
                                                                     "mapping's trials.validation)."),
    validate_fraction: float = typer.Option(None, "--validate-fraction",
                                            help="The last fraction of the trials validates, rounded half up."),
    validate_trials: str = typer.Option(None, "--validate-trials", help="These trials validate, e.g. 0,3 "
                                                                         "(numbered from 0 in the sources' order)."),
    baseline_samples: int = typer.Option(None, "--baseline-samples",
                                         help="Each trial's zero is the mean of its first N sensor samples."),
    baseline_seconds: float = typer.Option(None, "--baseline-seconds",
                                           help="Each trial's zero is the mean of its first S seconds."),
    tolerance: float = typer.Option(None, "--tolerance", help="Largest time (s) between a sensor row and the "
                                                              "label row joined to it."),
    force: bool = FORCE,
    json_output: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Turn delimited text logs (CSV, whitespace, with or without a header) into a checksummed softtip dataset
    that calibrate, evaluate and sysid read."""
    from softtip.lab.importing import Baseline, Validation, load_mapping
    from softtip.lab.importing import import_logs as read_logs

    check_input(mapping, "--mapping")
    given = [name for name, value in (("--validate-last", validate_last), ("--validate-fraction", validate_fraction),
                                      ("--validate-trials", validate_trials)) if value is not None]
    if len(given) > 1:
        fail(f"{given[0]} and {given[1]}: give one way of choosing the validation trials")
    if baseline_samples is not None and baseline_seconds is not None:
        fail("--baseline-samples and --baseline-seconds: give one baseline rule")
    if validate_last is not None and validate_last < 1:
        fail(f"--validate-last = {validate_last}: expected a number of trials >= 1")
    if baseline_samples is not None and baseline_samples < 1:
        fail(f"--baseline-samples = {baseline_samples}: expected a number of samples >= 1")
    if validate_fraction is not None and not 0 < validate_fraction < 1:
        fail(f"--validate-fraction = {validate_fraction:g}: expected a fraction of the trials, between 0 and 1")
    check_number(baseline_seconds, "--baseline-seconds", above=0, maximum=LONGEST_TOLERANCE_S, unit="s")
    check_number(tolerance, "--tolerance", above=0, maximum=LONGEST_TOLERANCE_S, unit="s")
    chosen = _trial_numbers(validate_trials) if validate_trials is not None else None
    loaded = load_mapping(mapping)
    trials = loaded.trials
    if given:
        trials = replace(trials, validation=Validation(last=validate_last, fraction=validate_fraction, trials=chosen))
    if baseline_samples is not None or baseline_seconds is not None:
        trials = replace(trials, baseline=Baseline(samples=baseline_samples, seconds=baseline_seconds))
    labels = loaded.labels
    if tolerance is not None:
        if labels is None or labels.file is None:
            fail(f"--tolerance = {tolerance:g}: {mapping} joins no label log (labels are in the sensor log or absent)")
        labels = replace(labels, tolerance_s=tolerance)
    loaded = replace(loaded, trials=trials, labels=labels)
    inputs = [mapping, *sources]
    inputs += [source / name for source in sources if source.is_dir()
               for name in (loaded.sensor.file, labels.file if labels else None) if name]
    check_output(output, "--output", inputs, force=force)
    dataset, report = read_logs(sources, loaded)
    path = dataset.write(output)
    saturated = {channel: count for channel, count in report.saturated.items() if count}
    summary = {"dataset": str(path), "trials": report.trials, "samples": report.samples,
               "validation_trials": report.validation_trials, "channels": dict(dataset.channel_units),
               "labels": {name: unit for name, unit in dataset.labels.items()},
               "sensor_settings": dataset.metadata.sensor_settings,
               "unlabelled_rows_dropped": report.unlabelled_dropped,
               "largest_join_offset_s": report.join_offset_s, "saturated_samples": saturated}
    if saturated:
        errors.print(printable(f"warning: saturated readings at the declared sensor settings: "
                               f"{', '.join(f'{name} {count}' for name, count in saturated.items())} samples "
                               "(label 'saturated' marks them)"), markup=False, highlight=False, soft_wrap=True)
    if json_output:
        print(json.dumps(summary, indent=2))
    else:
        console.print(printable(f"{report.trials} trials ({len(report.validation_trials)} validating), "
                                f"{report.samples} samples, {len(dataset.channels)} channels -> {path}"),
                      markup=False, highlight=False)
