"""What a system of a lab's own needs from softtip, in one public module, and the checker of a
registered system (as scikit-learn's ``check_estimator`` and Gymnasium's ``env_checker`` are).

A system is a package that defines one :class:`System` and declares it as an entry point of the group
``softtip.systems`` (docs/architecture.md, "How to add a system"). Everything it hands the toolkit is
named here, by what the toolkit does with it: the interfaces below are the rules the toolkit relies on,
and :func:`check_system` (``softtip check-system NAME``) finds every one a system breaks, one line each,
naming the file or the record's key and what was expected.

Importing this module is light: the record (:class:`System`, :class:`Study`) and the readings
(:class:`Reading`, :data:`MAGNETIC`) come with it, so that a system's ``__init__`` imports them from here
and listing the systems stays light; every other name loads the toolkit's stage it comes from when it
is first used.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

from softtip._core.channels import MAGNETIC, Reading
from softtip._core.systems import DEFAULT_USES, Study, System, failure_line, known_readings, load, systems

if TYPE_CHECKING:
    from softtip._core.progress import Progress
    from softtip.lab.protocols import Protocol as LabProtocol
    from softtip.realtime.scenario import LiveScenario
    from softtip.studies.outcome import StudyOutcome

# every other name of the contract, by where it lives: imported on first use (PEP 562)
_ELSEWHERE = {
    "softtip._core.config": ("NonNegativeNumber", "PositiveNumber", "choice", "integer", "schema"),
    "softtip._core.progress": ("SILENT",),
    "softtip.data": ("DatasetMetadata", "TrialWriter"),
    "softtip.design.model": ("BodyKind", "BodyMaterial", "DesignSpec", "MagnetSizes", "PoissonRatio", "magnets_at",
                             "ring_of_magnets"),
    "softtip.hardware": ("PacedSource", "Sample"),
    "softtip.hardware.drivers": ("Driver", "PortRequest"),
    "softtip.lab": ("BenchKind", "run_protocol"),
    "softtip.lab.bench": ("SeededBench",),
    "softtip.lab.protocols": ("protocol_file_schema",),
    "softtip.mechanics.mesh": ("BodySolid",),
    "softtip.mechanics.viscoelastic": ("PronySeries",),
    "softtip.published": ("published_table",),
    "softtip.realtime.scenario": ("LiveScenario",),
    "softtip.report.document": ("Figure",),
    "softtip.report.tables": ("Table",),
    "softtip.sensors.contract": ("Acquisition",),
    "softtip.sensors.registry": ("ChipSettings", "SensorKind"),
    "softtip.studies.outcome": ("Headline", "StudyOutcome"),
}
_RENAMED = {"SensorModel": "softtip.sensors.contract:Sensor"}  # the sensor contract, named apart from SensorKind
_REFERENCES = {**{name: f"{module}:{name}" for module, names in _ELSEWHERE.items() for name in names}, **_RENAMED}


def __getattr__(name: str) -> Any:
    if name not in _REFERENCES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = globals()[name] = load(_REFERENCES[name])
    return value


__all__ = [
    "MAGNETIC", "SILENT", "Acquisition", "Analysis", "BenchKind", "BodyKind", "BodyMaterial", "BodySolid",
    "ChipSettings", "DatasetMetadata", "DesignSpec", "Device", "Driver", "Figure", "Headline", "LiveScenario",
    "MagnetSizes", "NonNegativeNumber", "PacedSource", "PoissonRatio", "PortRequest", "PositiveNumber",
    "PronySeries", "Reading", "RealismTable", "Sample", "Scenario", "SeededBench", "SensorKind", "SensorModel",
    "Study", "StudyOutcome", "System", "Table", "TrialWriter", "check_system", "choice", "integer", "magnets_at",
    "protocol_file_schema", "published_table", "ring_of_magnets", "run_protocol", "schema",
]



@runtime_checkable
class Device(Protocol):
    """What a bench's ``device(...)`` returns: the protocol's ``design``, named in reports and keys."""

    name: str
    spec: dict


@runtime_checkable
class RealismTable(Protocol):
    """A protocol file's ``[realism]`` table, recorded in every dataset's metadata; its bench's
    ``realism_sources`` names the source of every key."""

    def to_dict(self) -> dict: ...


class Analysis(Protocol):
    """A study's analysis (``Study.analysis``): the protocol's dataset into the publication's figures."""

    def __call__(self, protocol: LabProtocol, seed: int, progress: Progress) -> StudyOutcome: ...


class Scenario(Protocol):
    """A live scenario (``System.scenarios``): it calls ``check(chips, rate_hz)`` before any long work."""

    def __call__(self, progress: Progress, check: Any) -> LiveScenario: ...


def _references(system: System) -> list[tuple[str, str, type | None]]:
    """Every ``"module:attribute"`` of the record: (its key in the record, the reference, what it must be)."""
    import typer

    from softtip.design.model import BodyKind
    from softtip.hardware.drivers import Driver
    from softtip.lab import BenchKind
    from softtip.sensors.registry import SensorKind

    named = [(f"benches.{k}", v, BenchKind) for k, v in system.benches.items()]
    named += [(f"scenarios.{k}", v, None) for k, v in system.scenarios.items()]
    named += [(f"demos.{k}", v, None) for k, v in system.demos.items()]
    named += [(f"bench_commands.{k}", v, None) for k, v in system.bench_commands.items()]
    named += [(f"commands.{k}", v, typer.Typer) for k, v in system.commands.items()]
    named += [(f"sensors.{k}", v, SensorKind) for k, v in system.sensors.items()]
    named += [(f"drivers.{k}", v, Driver) for k, v in system.drivers.items()]
    named += [(f"bodies.{k}", v, BodyKind) for k, v in system.bodies.items()]
    named += [(f"studies.{s.name}.analysis", s.analysis, None) for s in system.studies]
    return named + [("defaults.demo", system.defaults["demo"], None)] if "demo" in system.defaults else named


def check_system(name: str, progress: Progress | None = None, studies: bool = True) -> list[str]:
    """Every rule the registered system ``name`` breaks, one line each (none: it holds). Resolves every
    reference of its record, loads and runs each shipped protocol at its quick size and checks its
    dataset's roles, runs each live scenario and, with ``studies``, each
    study's quick reproduction (its report); ``progress`` shows that work (none: silent)."""
    from softtip._core.progress import SILENT
    from softtip.design.model import OWN_BODY_KINDS, BodyKind
    from softtip.hardware.drivers import OWN as OWN_DRIVERS
    from softtip.hardware.drivers import Driver
    from softtip.published import published_tables
    from softtip.sensors.registry import SensorKind
    from softtip.studies.outcome import StudyOutcome
    from softtip.studies.reproduce import reproduce_study

    progress = SILENT if progress is None else progress
    system = systems().get(name)
    if system is None:
        raise ValueError(f"system {name!r}: expected one of {', '.join(systems())}")
    record = f"{system.package} (System {system.name!r})"
    broken = []
    for key, reference, kind in _references(system):
        try:
            target = load(reference)
        except Exception as error:  # any failure to import is the plug-in's to fix: reported, not raised
            broken.append(f"{record}: {key} = {reference!r}: cannot be loaded ({failure_line(error)})")
            continue
        if kind is not None and not isinstance(target, kind):
            broken.append(f"{record}: {key} = {reference!r}: expected a {kind.__name__}, got {type(target).__name__}")
        elif kind in (SensorKind, Driver, BodyKind) and target.name != key.partition(".")[2]:
            broken.append(f"{record}: {key} = {reference!r}: the {kind.__name__} is named {target.name!r}, expected "
                          f"{key.partition('.')[2]!r}")
        elif kind is None and not callable(target):
            broken.append(f"{record}: {key} = {reference!r}: expected a function, got {type(target).__name__}")
        elif kind is SensorKind:
            broken += _check_sensor_model(record, key, target)
    for what, names, own in (("drivers", system.drivers, OWN_DRIVERS), ("bodies", system.bodies, OWN_BODY_KINDS)):
        for key in sorted(set(names) & set(own)):
            broken.append(f"{record}: {what}.{key}: softtip's own is named so: expected another name")
    for use in ("simulate", "bench"):
        if use in system.defaults and system.defaults[use] not in system.designs():
            broken.append(f"{record}: defaults.{use} = {system.defaults[use]!r}: expected {DEFAULT_USES[use]}")
    if broken:  # the protocols and scenarios run through these references
        return broken
    for protocol_name, bench in system.protocols.items():
        broken += _check_protocol(system, record, protocol_name, bench, progress)
    for scenario_name, reference in system.scenarios.items():
        broken += _check_scenario(record, scenario_name, load(reference), progress)
    if system.studies:
        try:
            published_tables()
        except ValueError as error:
            broken.append(str(error))
    for study in system.studies if studies and not broken else ():
        try:
            report = reproduce_study(study.name, quick=True, progress=progress)
        except Exception as error:  # the study's analysis is the plug-in's code: its failure is a finding
            broken.append(f"{record}: study {study.name!r}: its quick reproduction failed ({failure_line(error)})")
            continue
        if not isinstance(report.outcome, StudyOutcome):
            broken.append(f"{record}: studies.{study.name}.analysis: expected a StudyOutcome, got "
                          f"{type(report.outcome).__name__}")
    return broken


def _check_protocol(system: System, record: str, name: str, bench: str, progress: Progress) -> list[str]:
    from softtip.data.splits import CALIBRATION, VALIDATION
    from softtip.lab import run_protocol
    from softtip.lab.protocols import load_protocol
    from softtip.studies.reproduce import quick_cuts

    roles = (CALIBRATION, VALIDATION)  # what a trial's "role" condition may be: calibrate splits by it
    if bench not in system.benches:
        return [f"{record}: protocols.{name} = {bench!r}: expected one of its benches ({', '.join(system.benches)})"]
    path = Path(str(system.protocol_file(name)))
    if not path.is_file():
        return [f"{path}: missing: expected the protocol file of {name!r} in the package's protocols/ folder"]
    kind = load(system.benches[bench])
    missing = [what for what, table in (("parameters", kind.parameters), ("runners", kind.runners)) if name not in table]
    if missing:
        return [f"{record}: bench {bench!r}: {missing[0]} has nothing for protocol {name!r}"]
    try:
        protocol = load_protocol(path)
    except ValueError as error:
        return [str(error)]
    broken = []
    if not isinstance(protocol.design, Device):
        broken.append(f"{record}: bench {bench!r}: device(...) returned {type(protocol.design).__name__}, expected "
                      "an object with .name and .spec")
    if not isinstance(protocol.realism, RealismTable):
        broken.append(f"{record}: bench {bench!r}: its [realism] schema has no to_dict()")
        return broken
    for table, sources, what in ((protocol.realism.to_dict(), kind.realism_sources, "realism_sources"),
                                 (asdict(protocol.viscoelastic), kind.viscoelastic_sources, "viscoelastic_sources")):
        if unnamed := [key for key in table if key not in sources]:
            broken.append(f"{record}: bench {bench!r}: {what} names no source for {unnamed[0]!r}")
    if broken:
        return broken
    try:
        dataset, _ = run_protocol(protocol.changed(**quick_cuts(protocol)), progress)
    except Exception as error:  # the runner is the plug-in's code: its failure is a finding
        return [f"{path}: its quick run failed ({failure_line(error)})"]
    strangers = sorted(set(map(str, dataset.column("role"))) - set(roles)) if "role" in dataset.conditions else []
    if strangers:
        broken.append(f"{path}: its dataset's role {strangers[0]!r}: expected {' or '.join(roles)}")
    return broken


def _check_sensor_model(record: str, key: str, kind: Any) -> list[str]:
    """A sensor's acquisition model, if it has one: at its widest settings, zero true values give an
    :class:`Acquisition` of one value per axis."""
    import numpy as np

    from softtip.sensors.contract import Acquisition

    if kind.model is None:
        return []
    try:
        read = kind.model(kind.widest).acquire(np.zeros(kind.axes))
    except Exception as error:  # the model is the plug-in's code: its failure is a finding
        return [f"{record}: {key}: its model failed to read zeros at its widest settings ({failure_line(error)})"]
    if not isinstance(read, Acquisition) or np.shape(read.values) != (kind.axes,):
        return [f"{record}: {key}: its model read {type(read).__name__}: expected an Acquisition of {kind.axes} "
                "values"]
    return []


def _check_scenario(record: str, name: str, scenario: Scenario, progress: Progress) -> list[str]:
    from softtip.hardware import PacedSource
    from softtip.realtime.scenario import LiveScenario

    asked = []
    try:
        stream = scenario(progress, lambda chips, rate_hz: asked.append((chips, rate_hz)))
    except Exception as error:  # the scenario is the plug-in's code: its failure is a finding
        return [f"{record}: scenarios.{name}: failed ({failure_line(error)})"]
    if not isinstance(stream, LiveScenario):
        return [f"{record}: scenarios.{name}: expected a LiveScenario, got {type(stream).__name__}"]
    broken = [] if asked else [f"{record}: scenarios.{name}: never called check(chips, rate_hz) before its work"]
    if isinstance(stream.source, PacedSource) and stream.source.reading not in known_readings():
        broken.append(f"{record}: scenarios.{name}: streams {stream.source.reading.quantity}, expected a reading "
                      "of a registered system")
    return broken
