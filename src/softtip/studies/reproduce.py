"""Reproduce a published study: run it, and report it as the publication's tables beside softtip's,
with its protocol and provenance; an index of every study in a report directory.

``reproduce_study("pushing")`` returns a :class:`StudyReport`: it renders in Jupyter, writes one
self-contained HTML file and a JSON of its results, and heads one row of ``index.html``.
:func:`reproduce_studies` runs several, each in a process of its own when given workers: every study
is seeded on its own and runs with single-threaded native pools in either way, so a parallel run's
results are the serial run's.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import platform
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from softtip import __version__
from softtip._core.files import atomic_write
from softtip._core.progress import SILENT, Progress
from softtip._core.systems import Study, load, studies
from softtip._core.systems import study as registered_study
from softtip._core.threads import single_threaded
from softtip.lab import Protocol, load_protocol
from softtip.lab.protocols import shipped_protocol_path
from softtip.lab.trials import processes_for_trials
from softtip.published import OUTSIDE, published_procedure
from softtip.report.document import Report, Section
from softtip.report.index import index_report
from softtip.report.procedure import (PROCEDURE_COLUMN, ProcedureDifference, procedure_caption, procedure_cell,
                                      procedure_differences, shown)
from softtip.report.tables import Table
from softtip.studies.outcome import StudyOutcome

REPORT_FORMAT = "softtip-study-report"
QUICK_TRIALS = {"calibration_trials": 2, "validation_trials": 2, "trials": 2, "untrained_trials": 1}
_UNITS = (("_mm_per_N", "mm/N"), ("_K_per_sqrt_s", "K/√s"), ("_mm_s", "mm/s"), ("_percent", "%"), ("_mm", "mm"),
          ("_deg", "deg"), ("_hz", "Hz"), ("_s", "s"), ("_N", "N"), ("_sd", "fraction"))


def parameter_unit(key: str) -> str:
    """The unit a parameter's name carries (``speed_mm_s`` -> ``mm/s``); '' for counts and switches."""
    return next((unit for suffix, unit in _UNITS if key.endswith(suffix)), "")


def _rounded(value, digits=3):
    """Results as JSON: floats to ``digits`` decimals, numpy values as Python ones, keys as text."""
    if isinstance(value, dict):
        return {str(k): _rounded(v, digits) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_rounded(v, digits) for v in value]
    if isinstance(value, (float, np.floating)):
        return round(float(value), digits) if np.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def protocol_table(protocol: Protocol, source: str, quick_keys: set[str], study: Study) -> Table:
    """Every setting of the run: value, unit, default or changed, where the value comes from, and the
    publication's value where it states one (a difference marked)."""
    rows, cells = [], {}
    procedure = published_procedure(protocol.name)

    def add(section: str, key: str, value, default, origin: str) -> None:
        row = f"{section}.{key}"
        rows.append(row)
        changed = value != default
        where = ("--quick (a smoke run)" if key in quick_keys and section == "parameters"
                 else f"set by the study: {study.because}" if key in study.sets and section == "parameters"
                 else f"changed in {source}" if changed else origin)
        cells.update({(row, "value"): shown(value), (row, "unit"): parameter_unit(key),
                      (row, "default or changed"): f"changed (default {shown(default)})" if changed else "default",
                      (row, "where from"): where,
                      (row, PROCEDURE_COLUMN): procedure_cell(procedure, key, value) if section == "parameters" else None})

    bench = protocol.bench
    defaults = bench.defaults(protocol.name)
    for key, value in asdict(protocol.parameters).items():
        add("parameters", key, value, defaults[key], f"softtip's {protocol.name} protocol, after the publication's "
                                                    "procedure")
    defaults = asdict(type(protocol.realism)())
    for key, value in protocol.realism.to_dict().items():
        add("realism", key, value, defaults[key], bench.realism_sources[key])
    defaults = asdict(type(protocol.viscoelastic)())
    for key, value in asdict(protocol.viscoelastic).items():
        add("viscoelastic", key, value, defaults[key], bench.viscoelastic_sources[key])
    differences = procedure_differences(procedure, "parameters", asdict(protocol.parameters))
    return Table("Protocol", "setting", rows, ["value", "unit", "default or changed", "where from", PROCEDURE_COLUMN],
                 cells, caption="Every setting of this run; realism effects are set to 0 to switch them off. "
                                + procedure_caption(procedure, differences))


@dataclass
class StudyReport:
    """One reproduced study: its outcome, the protocol it ran and how it was run."""

    study: Study
    outcome: StudyOutcome
    protocol_table: Table
    provenance: dict[str, str]
    seconds: float
    procedure_differences: list[ProcedureDifference] = field(default_factory=list)

    @property
    def name(self) -> str:
        return self.study.name

    def comparisons(self) -> list[dict]:
        """Each published figure beside softtip's, with their difference and verdict."""
        return [c.to_dict() for table in self.outcome.tables for c in table.comparisons()]

    def to_json(self, report_file: str | None = None) -> dict:
        comparisons = self.comparisons()
        return {"format": REPORT_FORMAT, "study": self.name, "follows": self.study.follows,
                "headline": self.outcome.headline.to_dict(), "comparisons": comparisons,
                "outside": sum(c["verdict"] == OUTSIDE for c in comparisons),
                "procedure_differences": [difference.to_dict() for difference in self.procedure_differences],
                "results": _rounded(self.outcome.results), "seconds": round(self.seconds, 1),
                "provenance": self.provenance, "report": report_file}

    def report(self) -> Report:
        headline = self.outcome.headline
        smoke = self.provenance.get("quick (smoke run)", "no") != "no"
        lead = ("A smoke run (--quick): fewer trials than the study, so its figures are not the study's. "
                if smoke else "") + f"{self.study.follows}. Headline: {headline.label} = " + (
            "n/a" if headline.value is None else f"{headline.value:.3g} {headline.unit}".strip())
        if headline.comparison is not None:
            lead += f" (published {headline.comparison.published.text}; {headline.comparison.verdict})"
        provenance = Table("Provenance", "item", list(self.provenance), ["value"],
                           {(k, "value"): v for k, v in self.provenance.items()})
        return Report(f"softtip reproduce {self.name}", lead, [
            Section("softtip beside the publication", self.outcome.notes, self.outcome.tables),
            Section("Figures", figures=self.outcome.figures),
            Section("Protocol and provenance", tables=[self.protocol_table, provenance])])

    def _repr_html_(self) -> str:
        return self.report()._repr_html_()

    def write(self, directory: str | Path) -> Path:
        """``NAME.html`` (the report) and ``NAME.json`` (what the index reads) in ``directory``."""
        html, results = report_files(self.name)
        path = self.report().write(Path(directory) / html)
        atomic_write(Path(directory) / results, json.dumps(self.to_json(path.name), indent=2))
        return path


def report_files(name: str) -> tuple[str, str]:
    """The files study ``name``'s report writes in its folder: its HTML and the JSON the index reads."""
    return f"{name}.html", f"{name}.json"


def quick_cuts(protocol: Protocol, study: Study | None = None) -> dict[str, object]:
    """The parameters a smoke run of ``protocol`` changes: every trial count cut to its minimum, and
    what ``study``'s ``quick`` names."""
    parameters = asdict(protocol.parameters)
    cuts = {key: count for key, count in QUICK_TRIALS.items() if parameters.get(key, 0) > count}
    return cuts | {key: value for key, value in (study.quick if study else {}).items() if parameters.get(key) != value}


def reproduce_study(name: str, seed: int = 1, quick: bool = False, protocol_path: str | Path | None = None,
                    progress: Progress = SILENT, command: str | None = None) -> StudyReport:
    """Run study ``name`` on its shipped protocol or on ``protocol_path``; ``quick`` cuts every trial
    count to a minimum and sets what the study's ``quick`` names (a smoke run, not the study)."""
    study = registered_study(name)
    protocol = load_protocol(protocol_path or study.protocol).changed(seed=seed, **study.sets)
    cuts = quick_cuts(protocol, study) if quick else {}
    protocol, quick_keys = protocol.changed(**cuts), set(cuts)
    started = datetime.now(timezone.utc)
    start = time.perf_counter()
    source = str(protocol_path) if protocol_path else f"the shipped protocol {shipped_protocol_path(study.protocol).name}"
    table = protocol_table(protocol, source, quick_keys, study)
    analysis = load(study.analysis)
    outcome = analysis(protocol, seed, progress)
    seconds = time.perf_counter() - start
    provenance = {
        "softtip version": __version__, "study": f"{name}: {study.follows}", "protocol": source,
        "design(s)": ", ".join(outcome.designs or [protocol.design.name]), "seed": str(seed),
        "quick (smoke run)": ("no" if not quick else "yes: fewer trials than the study" +
                              (", a coarse protocol" if study.quick else "")),
        "command": command or f"softtip.studies.reproduce.reproduce_study({name!r}, seed={seed}, quick={quick})",
        "started (UTC)": started.strftime("%Y-%m-%d %H:%M:%S"), "run time": f"{seconds:.1f} s",
        "python / platform": f"{platform.python_version()} / {platform.platform(terse=True)}"}
    differences = procedure_differences(published_procedure(protocol.name), "parameters", asdict(protocol.parameters))
    return StudyReport(study, outcome, table, provenance, seconds, differences)


def reproduce_into(directory: str | Path, name: str, seed: int = 1, quick: bool = False,
                   progress: Progress = SILENT, command: str | None = None, trial_processes: int | None = None) -> dict:
    """Study ``name`` reproduced and its report written in ``directory``: the report's JSON (what the
    index reads), its ``report`` the HTML file's path. Native thread pools are kept to one thread: the
    studies' fits are small and thin, and a pool of processes already takes every core. The protocols'
    trials run in ``trial_processes`` processes (default one per core)."""
    with single_threaded(), processes_for_trials(trial_processes or default_workers()):
        study = reproduce_study(name, seed=seed, quick=quick, progress=progress, command=command)
    path = study.write(directory)
    return study.to_json(str(path))


def default_workers() -> int:
    """One process per core."""
    return os.cpu_count() or 1


def reproduce_studies(names: Sequence[str], directory: str | Path, seed: int = 1, quick: bool = False,
                      workers: int = 1, progress: Progress = SILENT, command: str | None = None,
                      finished: Callable[[str, dict], None] | None = None,
                      trial_processes: int | None = None) -> dict[str, dict]:
    """Studies ``names`` reproduced into ``directory``, serially (``workers`` = 1) or in a pool of
    ``workers`` processes; each report's JSON by name, in the order of ``names``. ``finished(name, json)``
    is called as each study ends (in the order they end). The workers are started afresh (not forked
    from this process, whose threads may hold locks), inherit the environment and so the cache, and
    report nothing but the JSON: their progress is one bar here, a step per study. The protocols' trials
    run in ``trial_processes`` processes (1: in the study's own; default: one per core, shared among the
    pool's processes)."""
    if workers < 1:
        raise ValueError(f"workers = {workers}: expected at least 1")
    results = {}
    if workers == 1 or len(names) == 1:
        for name in names:
            with progress.task(f"reproducing {name}"):
                results[name] = reproduce_into(directory, name, seed, quick, progress, command, trial_processes)
            if finished:
                finished(name, results[name])
    else:
        with (progress.task(f"reproducing {len(names)} studies in {min(workers, len(names))} processes",
                            total=len(names)) as task,
              ProcessPoolExecutor(min(workers, len(names)), mp_context=multiprocessing.get_context("spawn")) as pool):
            # the pool's processes already share the cores: each runs its trials on its own share of them
            shared = trial_processes or max(1, default_workers() // min(workers, len(names)))
            running = {pool.submit(reproduce_into, directory, name, seed, quick, SILENT, command, shared): name
                       for name in names}
            try:
                for future in as_completed(running):
                    name = running[future]
                    results[name] = future.result()
                    task.advance(note=f"last: {name}")
                    if finished:
                        finished(name, results[name])
            except BaseException:  # a study that failed (or Ctrl-C) stops the ones not yet started
                pool.shutdown(cancel_futures=True)
                raise
    return {name: results[name] for name in names}


INDEX_FILE = "index.html"


def write_index(directory: str | Path) -> Path:
    """``index.html`` of every study report (``*.json``) in ``directory``, in the registry's order."""
    directory = Path(directory)
    entries, order = [], list(studies())
    for path in sorted(directory.glob("*.json")):
        try:
            entry = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError):
            continue
        if isinstance(entry, dict) and entry.get("format") == REPORT_FORMAT and entry.get("study") in order:
            entries.append(entry)
    entries.sort(key=lambda e: order.index(e["study"]))
    return index_report(entries).write(directory / INDEX_FILE)
