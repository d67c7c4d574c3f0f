"""The systems built on softtip's toolkit, each described once by a :class:`System` record.

A system - a sensor or a device with the publications it follows - lives in one package and
registers one record. softtip finds the records through the Python entry-point group
``softtip.systems`` (a lab's own system is a separate package declaring one entry point, as pytest
and Gymnasium take plug-ins), or through :func:`register` at run time. The command line, the lab,
the studies, the live path and the reports loop over :func:`systems`; no toolkit module names a
system.

What is heavy to import is named as ``"module:attribute"`` and imported only when used
(:func:`load`), so listing the systems loads none of their models. A system's files sit in its
package: shipped designs in ``designs/``, protocol files in ``protocols/`` and the publications'
figures in ``published.toml``.
"""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from importlib import metadata, resources
from importlib.resources.abc import Traversable
from typing import Any

from softtip._core.channels import MAGNETIC, Reading

ENTRY_POINT_GROUP = "softtip.systems"


class NotRegistered(LookupError, ValueError):
    """A name no registered system has."""


class SystemSkipped(UserWarning):
    """An installed system that failed to load, or whose names clash with a registered system's: left
    out, so that every other system works."""


@dataclass(frozen=True)
class Study:
    """A published study a system reproduces: the lab protocol it runs, the analysis that turns its
    dataset into the publication's figures (``"module:function"``), and what it follows."""

    name: str
    protocol: str
    analysis: str
    follows: str
    # protocol parameters the study sets over the protocol file's, and why (printed in the report)
    sets: Mapping[str, object] = field(default_factory=dict)
    because: str = ""
    # protocol parameters ``--quick`` sets besides cutting the trial counts: a coarse smoke run of
    # what the analysis computes beyond the protocol's trials (sweeps, reruns)
    quick: Mapping[str, object] = field(default_factory=dict)


@dataclass(frozen=True)
class System:
    """One system's registration: everything of it the toolkit's commands loop over.

    ``benches``: bench kind -> ``"module:attribute"`` of its :class:`softtip.lab.protocols.BenchKind`;
    ``protocols``: protocol name -> the bench kind it runs on (its file is ``protocols/NAME.toml``);
    ``scenarios``: ``softtip live --emulate --scenario NAME`` -> ``"module:function"``,
    ``function(progress, check)`` returning a :class:`softtip.realtime.scenario.LiveScenario` (see
    that module for ``check``); ``demos``: ``softtip demo NAME`` -> a command function;
    ``bench_commands``: ``softtip bench NAME``; ``commands``: command groups of its own (a Typer app).
    """

    name: str
    title: str
    label: str  # how the specification and the published tables name it (S1 ...)
    package: str  # the package its files are read from
    publications: tuple[str, ...] = ()
    readings: tuple[Reading, ...] = ()
    benches: Mapping[str, str] = field(default_factory=dict)
    protocols: Mapping[str, str] = field(default_factory=dict)
    studies: tuple[Study, ...] = ()
    scenarios: Mapping[str, str] = field(default_factory=dict)
    demos: Mapping[str, str] = field(default_factory=dict)
    # what it offers as the toolkit's defaults, by use (DEFAULT_USES); taken when it is softtip's own
    # or the user's settings choose it (softtip._core.user)
    defaults: Mapping[str, str] = field(default_factory=dict)
    bench_commands: Mapping[str, str] = field(default_factory=dict)
    commands: Mapping[str, str] = field(default_factory=dict)
    # the chips it reads: name -> "module:attribute" of a softtip.sensors.registry.SensorKind
    sensors: Mapping[str, str] = field(default_factory=dict)
    # the wire formats softtip live --port --driver NAME reads: "module:attribute" of a softtip.hardware.drivers.Driver
    drivers: Mapping[str, str] = field(default_factory=dict)
    # kinds of body its designs may be (simulate, optimize): "module:attribute" of a softtip.design.model.BodyKind
    bodies: Mapping[str, str] = field(default_factory=dict)

    def files(self) -> Traversable:
        return resources.files(self.package)

    def protocol_file(self, name: str) -> Traversable:
        return self.files() / "protocols" / f"{name}.toml"

    def designs(self) -> dict[str, Traversable]:
        """Its shipped designs by name."""
        folder = self.files() / "designs"
        if not folder.is_dir():
            return {}
        return {entry.name.removesuffix(".toml"): entry for entry in sorted(folder.iterdir(), key=lambda e: e.name)
                if entry.name.endswith(".toml")}

    def published(self) -> Traversable | None:
        """Its publications' figures (``published.toml``), if it has them."""
        path = self.files() / "published.toml"
        return path if path.is_file() else None


# what a system may offer as a default (System.defaults), and what each use takes
DEFAULT_USES = {"simulate": "a shipped design of its own (softtip simulate --design)",
                "bench": "a shipped design of its own (softtip bench twin --design)",
                "scenario": "one of its scenarios (softtip live --emulate --scenario)",
                "demo": '"module:function", the command plain softtip demo runs'}

_REGISTERED: dict[str, System] = {}
_INSTALLED_BY: dict[str, str] = {}  # system name -> "distribution version" of the package that declared it
_entry_points = "unread"  # "reading" while they load: a plug-in that registers itself on import reads none again

# the names that must be unique over all systems, and how to list them from a record
_UNIQUE = {"protocol": lambda s: s.protocols, "study": lambda s: [study.name for study in s.studies],
           "scenario": lambda s: s.scenarios, "demo": lambda s: s.demos, "bench": lambda s: s.bench_commands,
           "command": lambda s: s.commands, "reading": lambda s: [r.quantity for r in s.readings],
           "sensor": lambda s: s.sensors, "driver": lambda s: s.drivers,
           "body": lambda s: s.bodies}
_FIELDS = {"sensor": "sensors", "driver": "drivers", "body": "bodies"}  # the record's field of a kind of name


def register(system: System) -> System:
    """Adds ``system`` to the registry; a name it shares with a registered system is refused."""
    _read_entry_points()
    return _add(system)


def _add(system: object) -> System:
    if not isinstance(system, System):
        raise TypeError(f"a softtip system must be a System record, got {type(system).__name__}")
    if unknown := set(system.defaults) - set(DEFAULT_USES):
        raise ValueError(f"system {system.name!r}: defaults.{sorted(unknown)[0]}: expected one of "
                         f"{', '.join(DEFAULT_USES)}")
    if "scenario" in system.defaults and system.defaults["scenario"] not in system.scenarios:
        raise ValueError(f"system {system.name!r}: defaults.scenario = {system.defaults['scenario']!r}: expected "
                         f"{DEFAULT_USES['scenario']}")
    if system.name in _REGISTERED and _REGISTERED[system.name] is not system:
        raise ValueError(f"system {system.name!r} is registered twice")
    for what, names in _UNIQUE.items():
        for other in _REGISTERED.values():
            if other.name != system.name and (clash := set(names(system)) & set(names(other))):
                raise ValueError(f"system {system.name!r}: {what} {sorted(clash)[0]!r} is also system "
                                 f"{other.name!r}'s")
    _REGISTERED[system.name] = system
    return system


def unregister(name: str) -> None:
    """Removes a system registered at run time (a test's own)."""
    _REGISTERED.pop(name, None)


def _package(entry: metadata.EntryPoint) -> str:
    """The installed package (distribution) that declares an entry point, as a user would install it."""
    return entry.dist.name if entry.dist is not None else entry.module.partition(".")[0]


def failure_line(error: BaseException) -> str:
    """What a system's code raised, on one line: its type and the first line of its message."""
    reason = str(error).strip().splitlines()
    return type(error).__name__ + (f": {reason[0]}" if reason else "")


def _skip(entry: metadata.EntryPoint, error: Exception) -> None:
    warnings.warn(f"softtip system {entry.name!r} of package {_package(entry)!r} skipped: {failure_line(error)}",
                  SystemSkipped, stacklevel=4)


def is_own(system: System) -> bool:
    """Whether ``system`` is one of softtip's own (a package inside softtip)."""
    return system.package.partition(".")[0] == "softtip"


def _registration_order(loaded: tuple[metadata.EntryPoint, object]) -> tuple:
    entry, system = loaded
    if isinstance(system, System) and is_own(system):
        return (0, system.label, system.name)
    return (1, _package(entry), entry.name)


def _read_entry_points() -> None:
    """Registers every installed system: softtip's own first, in the order the specification numbers
    them, then the others by package, so that a name an installed package shares with softtip's is
    that package's to lose. A system that fails to load or clashes is skipped with a warning."""
    global _entry_points
    if _entry_points != "unread":
        return
    _entry_points = "reading"
    try:
        loaded = []
        for entry in metadata.entry_points(group=ENTRY_POINT_GROUP):
            try:  # a broken plug-in must not take the toolkit down with it
                loaded.append((entry, entry.load()))
            except Exception as error:
                _skip(entry, error)
        for entry, system in sorted(loaded, key=_registration_order):
            try:
                _add(system)
            except (TypeError, ValueError) as error:
                _skip(entry, error)
            else:
                if entry.dist is not None:
                    _INSTALLED_BY[system.name] = f"{entry.dist.name} {entry.dist.version}"
        _entry_points = "read"
    finally:
        if _entry_points == "reading":  # interrupted: read them again next time rather than not at all
            _entry_points = "unread"


def systems() -> dict[str, System]:
    """Every registered system, by name, in the order they registered."""
    _read_entry_points()
    return dict(_REGISTERED)


def provenance(system: System) -> dict[str, str | None]:
    """Where a system's code comes from, for the keys of its cached artefacts: its top-level package
    (whose source the key hashes beside softtip's) and the installed distribution that declared it, with
    its version (None for a record registered at run time)."""
    return {"package": system.package.partition(".")[0], "installed": _INSTALLED_BY.get(system.name)}


def load(reference: str) -> Any:
    """The object a ``"module:attribute"`` reference names (imported now)."""
    module, _, attribute = reference.partition(":")
    target: Any = importlib.import_module(module)
    for part in attribute.split("."):
        target = getattr(target, part)
    return target


def owner(kind: str, name: str) -> System:
    """The system that registered ``name`` as a ``kind`` (protocol, study, scenario, demo, bench,
    command); a name no system registered is refused with the registered ones."""
    for system in systems().values():
        if name in _UNIQUE[kind](system):
            return system
    raise NotRegistered(f"{kind} {name!r}: expected one of {', '.join(names(kind)) or '(none registered)'}")


def declared(kind: str, name: str, expected: type) -> Any:
    """What the system that registered ``name`` as a ``kind`` (sensor, driver, body) names for it,
    imported now: an ``expected`` whose ``.name`` is ``name``, else refused naming the record's key; a
    name no system registered is refused with the registered ones."""
    system = owner(kind, name)
    reference = _UNIQUE[kind](system)[name]
    found = load(reference)
    if not isinstance(found, expected) or found.name != name:
        raise TypeError(f"system {system.name!r}: {_FIELDS[kind]}.{name} = {reference!r}: expected a "
                        f"{expected.__name__} named {name!r}")
    return found


def beside_own(kind: str, own: Mapping[str, Any]) -> list[str]:
    """The names of a kind softtip has its own of (drivers, body kinds): its own, then every registered
    system's not named as one of them (softtip's keep their names)."""
    return [*own, *(name for name in names(kind) if name not in own)]


def own_or_declared(kind: str, name: str, own: Mapping[str, Any], expected: type, what: str) -> Any:
    """softtip's own ``name`` of a kind, or the ``expected`` a registered system declares for it (imported
    now); another name is refused in one line with the known ones (``what`` names the kind there)."""
    if name in own:
        return own[name]
    try:
        return declared(kind, name, expected)
    except NotRegistered:
        raise NotRegistered(f"{what} {name!r}: expected one of {', '.join(beside_own(kind, own))}") from None


def names(kind: str) -> list[str]:
    """Every registered name of a kind, system by system."""
    return [n for system in systems().values() for n in _UNIQUE[kind](system)]


def study(name: str) -> Study:
    """The registered study ``name``; a name no system registered is refused with the registered ones."""
    registered = studies()
    if name not in registered:
        raise NotRegistered(f"study {name!r}: expected one of {', '.join(registered) or '(none registered)'}")
    return registered[name]


def default(use: str) -> str | None:
    """What the toolkit's commands default to for ``use`` (one of :data:`DEFAULT_USES`): the offer of
    the system the user's settings choose, else of softtip's own systems (the first that offers one).
    An installed system's offer is never taken unless chosen, whatever its label or package."""
    from softtip._core.user import chosen_system

    if use not in DEFAULT_USES:
        raise ValueError(f"default {use!r}: expected one of {', '.join(DEFAULT_USES)}")
    registered = systems()
    chosen = chosen_system(list(registered))
    candidates = ([registered[chosen]] if chosen else []) + [s for s in registered.values() if is_own(s)]
    return next((system.defaults[use] for system in candidates if use in system.defaults), None)


def studies() -> dict[str, Study]:
    """Every registered study, by name."""
    return {study.name: study for system in systems().values() for study in system.studies}


def readings() -> tuple[Reading, ...]:
    """The readings the registered systems stream, beyond the toolkit's own."""
    return tuple(reading for system in systems().values() for reading in system.readings)


def known_readings() -> tuple[Reading, ...]:
    """The toolkit's reading and every registered system's."""
    return (MAGNETIC, *readings())


def reading_of(channels: Iterable[str]) -> Reading:
    """The reading whose channels ``channels`` all are."""
    channels = list(channels)
    READINGS = known_readings()
    for reading in READINGS:
        if channels and all(reading.is_channel(name) for name in channels):
            return reading
    strangers = [name for name in channels if not any(r.is_channel(name) for r in READINGS)]
    if strangers or not channels:
        raise ValueError(f"input channel {strangers[0] if strangers else None!r}: expected a channel name like "
                         + " or ".join(r.channel_name(0, "x") for r in READINGS))
    raise ValueError(f"input channels {channels}: expected channels of one sensor kind, not "
                     + " and ".join(r.quantity for r in READINGS if any(r.is_channel(n) for n in channels)))
