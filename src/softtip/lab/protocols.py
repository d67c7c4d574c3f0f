"""Protocol files: a validated TOML per experiment, reproducible from the file and its seed.

Every protocol belongs to a registered system (:mod:`softtip._core.systems`) and runs on one of its
benches (:class:`BenchKind`): what the file may hold beyond its name and seed (``[parameters]``,
``[realism]``, ``[viscoelastic]`` and the bench's own keys, each validated by the bench's schemas),
what the bench is built from, how it is set up for a run, and the trials each protocol runs on it.
A shipped protocol is ``protocols/NAME.toml`` in its system's package; any file with ``protocol =
"NAME"`` runs the same way. A run goes one way on every bench: the bench is set up from the
protocol, then the protocol's trials run on it.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field, make_dataclass, replace
from pathlib import Path
from typing import Any

from threadpoolctl import threadpool_limits

from softtip._core.cache import EntryPieces, artefact_key, cache_dir, code_hash, stored_or_made
from softtip._core.config import Text, integer, parse, read_toml, refused, schema
from softtip._core.progress import SILENT, Progress
from softtip._core.systems import NotRegistered, load, names, owner, provenance
from softtip.data import Dataset
from softtip.lab.trials import trials_kept_in

ProtocolName = Text  # the registry knows the names: protocol_from_dict refuses any other


def protocol_file_schema(realism: type, viscoelastic: type, **keys: type | tuple[type, Any]) -> type:
    """The schema of a bench's protocol files: ``protocol`` (a registered name), ``seed``, ``parameters``
    (checked against the protocol's own schema once the name is known), the ``[realism]`` and
    ``[viscoelastic]`` tables of these schemas, and the bench's own ``keys``: name -> its type (a key
    every file must give) or (type, default)."""
    given = [(name, kind) for name, kind in keys.items() if not isinstance(kind, tuple)]
    defaults = [(name, kind, field(default=default)) for name, (kind, default) in
                ((name, kind) for name, kind in keys.items() if isinstance(kind, tuple))]
    return schema(make_dataclass("ProtocolFile", [
        ("protocol", ProtocolName), *given, ("seed", integer(), field(default=0)),
        ("parameters", dict[str, Any], field(default_factory=dict)),
        ("realism", realism, field(default_factory=realism)),
        ("viscoelastic", viscoelastic, field(default_factory=viscoelastic)), *defaults], frozen=True))


@dataclass(frozen=True)
class Size:
    """An estimate of the work a protocol asks for, made from its parameters before any work: ``amount``
    of ``what`` (``formula`` says how it was counted), refused above ``limit`` unless asked for."""

    amount: float
    limit: float
    what: str
    formula: str


class ProtocolTooLarge(ValueError):
    """A protocol whose estimated work is above its bench's limit."""


@dataclass(frozen=True)
class BenchKind:
    """A bench protocols run on.

    ``protocol_file``: the schema of its protocol files (:func:`protocol_file_schema`); ``parameters``: each protocol's ``[parameters]``
    schema; ``runners``: each protocol's trials, ``runner(bench, parameters, seed, record) -> Dataset``
    (``parameters`` the schema's object, ``record`` what the dataset's metadata keeps of the protocol);
    ``device(file, parameters, source, folder)``: what the file describes the bench with;
    ``setup(protocol, progress, timings)``: the bench for one run, what the dataset records of it
    beyond the protocol's tables, and the description of the trials' stage (building what it needs is
    timed into ``timings``); ``realism_sources`` and ``viscoelastic_sources``: where each default of
    those tables comes from (the reports print them); ``size(protocol, parameters)``: an estimate of
    the work a protocol's trials ask for (:class:`Size`), checked before the bench is set up.
    """

    protocol_file: type
    parameters: Mapping[str, type]
    runners: Mapping[str, Callable[[Any, Any, int, dict], Dataset]]
    device: Callable[[Any, dict, str, Path | None], Any]
    setup: Callable[[Protocol, Progress, dict], tuple[Any, dict, str]]
    realism_sources: Mapping[str, str]
    viscoelastic_sources: Mapping[str, str]
    size: Callable[[str, Any], Size] | None = None

    def defaults(self, protocol: str) -> dict[str, Any]:
        """Protocol ``protocol``'s parameters as its schema gives them."""
        return asdict(self.parameters[protocol]())


def bench_of(protocol: str) -> BenchKind:
    """The bench a registered protocol runs on."""
    system = owner("protocol", protocol)
    return load(system.benches[system.protocols[protocol]])


@dataclass(frozen=True)
class Protocol:
    """A validated protocol: its tables are their schemas' objects, from the file to the bench."""

    name: str
    design: Any  # what the bench is built from (a design, a device)
    seed: int
    parameters: Any  # the protocol's [parameters] schema
    realism: Any
    viscoelastic: Any
    bench: BenchKind = field(repr=False, compare=False)
    files: tuple[Path, ...] = field(default=(), repr=False, compare=False)  # what the protocol file names

    def changed(self, seed: int | None = None, **parameters: Any) -> Protocol:
        """A copy with another ``seed`` and these ``[parameters]``, validated as a file's are."""
        table = asdict(self.parameters) | parameters
        return replace(self, seed=self.seed if seed is None else seed, parameters=parse(
            self.bench.parameters[self.name], table, f"protocol {self.name}", "parameters"))

    def to_dict(self) -> dict:
        return {"protocol": self.name, "design": self.design.name, "seed": self.seed,
                "parameters": asdict(self.parameters), "realism": self.realism.to_dict(),
                "viscoelastic": asdict(self.viscoelastic)}


def shipped_protocol_path(name: str) -> Path:
    return Path(str(owner("protocol", name).protocol_file(name)))


def protocol_from_dict(table: dict, source: str, base: Path | None = None) -> Protocol:
    name = table.get("protocol") if isinstance(table, dict) else None
    if not isinstance(name, str):
        raise refused("expected the name of a protocol: " + ", ".join(names("protocol")), source, "protocol",
                      value=name)
    try:
        bench = bench_of(name)
    except NotRegistered:
        raise refused(f"expected one of {', '.join(names('protocol'))}", source, "protocol", value=name) from None
    top = parse(bench.protocol_file, table, source)
    parameters = parse(bench.parameters[top.protocol], top.parameters, source, "parameters")
    return Protocol(name=top.protocol, design=bench.device(top, parameters, source, base), seed=top.seed,
                    parameters=parameters, realism=top.realism, viscoelastic=top.viscoelastic, bench=bench,
                    files=named_files(table, base))


def named_files(table: Any, base: Path | None) -> tuple[Path, ...]:
    """Every existing file a protocol's table names, in any key, as its bench would look for it: beside
    the protocol file (``base``) or from the working folder. They are the run's inputs, so no output of
    the run may replace them, whichever bench reads which key."""
    if isinstance(table, dict):
        return tuple(dict.fromkeys(path for value in table.values() for path in named_files(value, base)))
    if isinstance(table, list):
        return tuple(dict.fromkeys(path for value in table for path in named_files(value, base)))
    if not isinstance(table, str) or not table or "\0" in table:
        return ()
    candidates = [Path(table)] + ([base / table] if base is not None else [])
    try:
        return tuple(path for path in candidates if path.is_file())
    except OSError:  # a name too long to be a path is not one
        return ()


def load_protocol(path: str | Path) -> Protocol:
    """A protocol file, or the name of a registered system's shipped protocol (``pushing`` ...)."""
    path = Path(path)
    if not path.suffix and str(path) in names("protocol"):
        path = shipped_protocol_path(str(path))
    return protocol_from_dict(read_toml(path, "protocol"), str(path), path.parent)


def check_size(protocol: Protocol) -> None:
    """Refuses a protocol whose estimated work (its bench's :class:`Size`) is above the bench's limit."""
    if protocol.bench.size is None:
        return
    size = protocol.bench.size(protocol.name, protocol.parameters)
    if not size.amount <= size.limit:
        raise ProtocolTooLarge(f"protocol {protocol.name}: its [parameters] ask for some {size.amount:.3g} "
                               f"{size.what} ({size.formula}), above the limit of {size.limit:.3g}; "
                               "--force runs it all the same")


def run_protocol(protocol: Protocol, progress: Progress = SILENT, *, large: bool = False,
                 reuse: bool = True) -> tuple[Dataset, dict]:
    """Run one experiment; returns its dataset and timings (s). ``progress`` gets a task per stage.
    A protocol above its bench's size limit (:func:`check_size`) is refused before any work unless ``large``.
    The dataset is kept in the cache under :func:`protocol_key`: the same protocol run again (by another
    study, or a second ``reproduce``) reads it (timed as ``cache_read_s``) unless ``reuse`` is False.
    While it runs, each trial of a protocol whose trials draw from streams of their own
    (:func:`softtip.lab.trials.run_trials`) is kept as a piece of that entry: a run stopped part way keeps
    them and the next runs only the rest; the pieces go once the whole dataset is stored."""
    if not large:
        check_size(protocol)
    if not reuse:
        return _run_trials(protocol, progress)
    start = time.perf_counter()
    path, key = trials_path(protocol), protocol_key(protocol)
    pieces = EntryPieces(path, key, _TRIALS_KIND)

    def make() -> tuple[Dataset, dict]:
        with trials_kept_in(pieces):
            return _run_trials(protocol, progress)

    (dataset, timings), read = stored_or_made(path, key, _TRIALS_KIND, lambda path: (Dataset.read(path), {}), make,
                                              lambda made, path: made[0].write(path))
    if not read:
        pieces.clear()
    return dataset, {"cache_read_s": time.perf_counter() - start} if read else timings


def _run_trials(protocol: Protocol, progress: Progress) -> tuple[Dataset, dict]:
    """The bench set up for ``protocol`` and its trials run on it: the dataset and the timings (s)."""
    timings = {}
    bench, recorded, stage = protocol.bench.setup(protocol, progress, timings)
    start = time.perf_counter()
    # the trials' dense solves are small: a second BLAS thread only fights for a shared core
    with progress.task(stage), threadpool_limits(limits=1):
        record = {**asdict(protocol.parameters), "viscoelastic": asdict(protocol.viscoelastic), **recorded,
                  "realism": protocol.realism.to_dict()}
        dataset = protocol.bench.runners[protocol.name](bench, protocol.parameters, protocol.seed, record)
    timings["trials_s"] = time.perf_counter() - start
    return dataset, timings


_TRIALS_KIND = "protocol trials"


def protocol_key(protocol: Protocol) -> str:
    """The cache key of artefacts made from ``protocol``'s trials: the protocol, its design, the content
    of every file it names (a die, a table: edited under the same name, they make other trials), the
    source of the whole of softtip (the trials run through nearly every subpackage) and the package of
    the system that owns the protocol, its source and installed version (a lab's own, edited or upgraded,
    gets new artefacts)."""
    system = provenance(owner("protocol", protocol.name))
    files = [[path.name, hashlib.sha256(path.read_bytes()).hexdigest()] for path in protocol.files]
    return artefact_key({"protocol": protocol.to_dict(), "design": protocol.design.spec, "files": files,
                         "system": system}, code_hash("softtip", system["package"]), length=16)


def trained_model_path(protocol: Protocol, name: str, suffix: str = ".npz") -> Path:
    """Where an artefact made from ``protocol``'s trials (a trained model, a live scenario) is cached,
    under its :func:`protocol_key`."""
    return cache_dir() / "models" / f"{name}-{protocol_key(protocol)}{suffix}"


def trials_path(protocol: Protocol) -> Path:
    """Where the dataset of ``protocol``'s trials is cached (a Parquet file), under its :func:`protocol_key`."""
    return cache_dir() / "trials" / f"{protocol.name}-{protocol_key(protocol)}.parquet"
