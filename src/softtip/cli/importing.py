"""``softtip import``: a rig's delimited text logs into a softtip dataset, as a mapping file or the options say."""

from __future__ import annotations

import copy
import json
import re
import warnings
from pathlib import Path

import typer

from softtip.cli.common import FORCE, check_input, check_number, check_output, console, errors, fail, printable

LONGEST_SPAN_S = 3600.0  # a join tolerance or a baseline over an hour pairs readings that do not belong together


def _trial_numbers(text: str) -> list[int]:
    try:
        numbers = [int(part) for part in text.split(",")]
    except ValueError:
        numbers = []
    if not numbers or min(numbers) < 0:
        fail(f"--validate-trials = {text!r}: expected trial numbers >= 0 separated by commas, e.g. 0,3")
    return numbers


def _column(text: str) -> int | str:
    """A column as typed: its number (from 1), or its header name."""
    return int(text) if re.fullmatch(r"[+-]?[0-9]+", text.strip()) else text.strip()


def _chips(text: str) -> list[list[int | str]]:
    return [[_column(part) for part in chip.split(",")] for chip in text.split(";")]


def _labels(entries: list[str]) -> dict[str, dict[str, int | str]]:
    labels = {}
    for entry in entries:
        match = re.fullmatch(r"([^=]+)=([^:]+):(.+)", entry)
        if match is None:
            fail(f"--label {entry!r}: expected NAME=COLUMN:UNIT, e.g. fz_N=5:g")
        name, column, unit = (part.strip() for part in match.groups())
        if name in labels:
            fail(f"--label {entry!r}: {name} is given twice")
        labels[name] = {"column": _column(column), "unit": unit}
    return labels


def _set(document: dict, table: str, key: str, value) -> None:
    """``document[table][key] = value``; a ``table`` that is not a table is left for the mapping's check."""
    part = document.setdefault(table, {})
    if isinstance(part, dict):
        part[key] = value


def import_logs(
    sources: list[Path] = typer.Argument(..., help="Log files (labels in them) or folders (holding the mapping's "
                                                   "sensor and label files), one or more trials each."),
    mapping: Path = typer.Option(None, "--mapping", "-m", help="TOML mapping: which columns are which chip, axis "
                                                               "and label, in what unit; trials, validation, baseline. "
                                                               "The options below override it, or replace it."),
    output: Path = typer.Option(..., "--output", "-o", help="Dataset to write (.parquet)."),
    chips: str = typer.Option(None, "--chips", help="Each chip's x, y, z columns (numbers from 1, or header names), "
                                                    "chips separated by ';', e.g. '2,3,4;5,6,7'."),
    time: str = typer.Option(None, "--time", help="The time column (seconds, unless the mapping says otherwise)."),
    unit: str = typer.Option(None, "--unit", help="The chips' unit: uT, mT, G, T, or counts (with the mapping's "
                                                  "gain_sel and res_xyz)."),
    label: list[str] = typer.Option([], "--label", help="A label in the sensor log, NAME=COLUMN:UNIT (fz_N=load:kN: "
                                                        "stored in the unit its name ends in)."),
    no_header: bool = typer.Option(False, "--no-header", help="The sensor log has no header row: columns are "
                                                              "numbered from 1."),
    delimiter: str = typer.Option(None, "--delimiter", help="One character between the cells, or 'whitespace'."),
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
    from softtip._core.config import read_toml
    from softtip.data import DatasetError
    from softtip.lab.importing import import_logs as read_logs
    from softtip.lab.importing import DeprecatedMappingKey, log_files, mapping_from

    if mapping is not None:
        check_input(mapping, "--mapping")
    elif chips is None:
        fail("--mapping or --chips: give a mapping file, or at least the chips' columns")
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
    check_number(baseline_seconds, "--baseline-seconds", above=0, maximum=LONGEST_SPAN_S, unit="s")
    check_number(tolerance, "--tolerance", above=0, maximum=LONGEST_SPAN_S, unit="s")
    document = {} if mapping is None else read_toml(mapping, "import mapping", DatasetError)
    as_written = copy.deepcopy(document)
    options = {"chips": None if chips is None else _chips(chips), "time": None if time is None else _column(time),
               "unit": unit, "delimiter": delimiter, "header": False if no_header else None}
    for key, value in options.items():
        if value is not None:
            _set(document, "sensor", key, value)
    if label:
        _set(document, "labels", "columns", _labels(label))
    if tolerance is not None:
        _set(document, "labels", "tolerance_s", tolerance)
    if given:
        chosen = {"last": validate_last, "fraction": validate_fraction,
                  "trials": None if validate_trials is None else _trial_numbers(validate_trials)}
        _set(document, "trials", "validation", {key: value for key, value in chosen.items() if value is not None})
    if baseline_samples is not None or baseline_seconds is not None:
        _set(document, "trials", "baseline", {"samples": baseline_samples} if baseline_samples is not None
             else {"seconds": baseline_seconds})
    source = ("the options" if mapping is None else str(mapping) if document == as_written
              else f"{mapping} with the options")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DeprecatedMappingKey)
        loaded = mapping_from(document, source)
    for warning in caught:  # an old key still read: one line, not a traceback's location
        errors.print(printable(f"warning: {warning.message}"), markup=False, highlight=False, soft_wrap=True)
    inputs = [*([] if mapping is None else [mapping]), *sources]
    inputs += [path for source in sources if source.is_dir()
               for files in log_files(source, loaded) for path in files or []]
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
