"""Protocol files: a validated TOML per experiment, reproducible from the file and its seed.

Each protocol runs on a bench (:data:`BENCHES`): the magnetic fingertip's (S1: a design's
mechanics on the twin) or the wearable's (S2: a person's finger with a chip on the side of the
nail, :mod:`softtip.lab.wearable`). A fingertip protocol file names the experiment, the design, the
seed, and overrides any of the protocol's parameters (every key and its default is in
:data:`DEFAULTS`; the shipped files under ``softtip/lab/protocols/`` list them all, with units in
their names)::

    protocol = "pushing"
    design = "cylindrical-A"     # a shipped design or a design TOML file
    seed = 1

    [parameters]
    angles_deg = [0, 15, 30, 45, 60, 75, 90]

    [realism]                    # see softtip.lab.realism; all on by default
    position_sd_mm = 0.2

    [viscoelastic]               # the material's relaxation, set from one published cycle
    rest_s = 1.0

A wearable protocol file has no design: its ``[parameters]``, ``[realism]`` and ``[viscoelastic]``
are the wearable bench's (:class:`~softtip.lab.wearable.WearableParameters`,
:class:`~softtip.lab.realism.WearableRealism`, :class:`~softtip.lab.wearable.PadViscoelastic`).

Every protocol's ``[parameters]`` table has a schema (:data:`PARAMETER_SCHEMAS`); a fingertip
protocol's follows from its defaults. A run goes the same way on either bench: the bench is set up
from the protocol (:data:`BENCHES`), then the protocol's trials run on it (:data:`RUNNERS`).
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import time
from dataclasses import asdict, dataclass, field
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Callable

import numpy as np
from pydantic import Field
from threadpoolctl import threadpool_limits

from softtip._core.config import (Flag, NonNegativeNumber, Numbers, PositiveNumber, Real, Text, choice, expect, integer,
                                  parse, read_toml, refused, schema)
from softtip._core.progress import SILENT, Progress
from softtip._core.units import MM
from softtip.data import Dataset
from softtip.design.model import Design, load_design
from softtip.lab import experiments, wearable
from softtip.lab.realism import Realism, WearableRealism
from softtip.published import published_table
from softtip.twin.influence import InfluenceEngine

GEN1 = {"rate_hz": 20.0, "mesh_size_mm": 1.5, "curvature_points": 10, "reach_mm": 4.5, "pre_contact_s": 0.5,
        "board_thickness_mm": 1.6}
GEN2 = {"rate_hz": 50.0, "mesh_size_mm": 2.5, "curvature_points": 3, "reach_mm": 3.5, "pre_contact_s": 0.2}

PointsMM = Annotated[list[Annotated[list[Real], Field(min_length=2, max_length=2)]], Field(min_length=1),
                     expect("a list of [x, y] pairs in mm")]


def _parameter_type(key: str, default: Any) -> Any:
    """What a fingertip protocol's parameter may be, from its default: true/false, an integer >= 0, a
    number >= 0 (the rate > 0), a list of numbers or a list of [x, y] pairs."""
    if isinstance(default, bool):
        return Flag
    if isinstance(default, int):
        return integer()
    if isinstance(default, float):
        return PositiveNumber if key == "rate_hz" else NonNegativeNumber
    return PointsMM if isinstance(default[0], list) else Numbers


def _parameters_schema(defaults: dict[str, Any]) -> type:
    """The schema of a ``[parameters]`` table whose keys are those of ``defaults``, each typed by its default."""
    fields = [(key, _parameter_type(key, default), field(default_factory=functools.partial(copy.deepcopy, default)))
              for key, default in defaults.items()]
    return schema(dataclasses.make_dataclass("ProtocolParameters", fields, frozen=True))


# the fingertip protocols' parameters and their defaults
_FINGERTIP_DEFAULTS: dict[str, dict[str, Any]] = {
    "pushing": {**GEN1, "angles_deg": [0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0], "calibration_trials": 10,
                "validation_trials": 5, "depth_mm": 3.0, "speed_mm_s": 1.0},
    "force3": {**GEN1, "calibration_trials": 10, "validation_trials": 5, "normal_depth_mm": 3.0,
               "shear_depth_mm": 2.0, "shear_mm": 2.0, "speed_mm_s": 0.5},
    "hysteresis": {**GEN1, "rate_hz": 50.0, "speeds_mm_s": [0.25, 0.5, 1.0], "trials": 10, "depth_mm": 3.0,
                   "rest_s": 1.0},
    "grasp-two": {**GEN1, "trained_angles_deg": [0.0, 10.0, 20.0, 30.0],
                  "untrained_angles_deg": [5.0, 15.0, 25.0], "calibration_trials": 7, "validation_trials": 3,
                  "untrained_trials": 3, "grasp_displacement_mm": 4.0, "grasp_speed_mm_s": 5.0, "hold_s": 1.0},
    "grasp-positions": {**GEN2, "rate_hz": 20.0, "positions_mm": [-9.0, -6.0, -3.0, 0.0, 3.0, 6.0, 9.0],
                        "angles_deg": [0.0, 10.0, 20.0, 30.0], "untrained_angles_deg": [5.0, 15.0, 25.0],
                        "calibration_trials": 7, "validation_trials": 3, "board_thickness_mm": 1.7,
                        "other_thicknesses_mm": [1.0, 2.0, 4.0, 8.0], "grasp_displacement_mm": 4.0,
                        "grasp_speed_mm_s": 5.0, "hold_s": 0.5},
    "contact-states": {**GEN2, "phi_deg": [10.0, 20.0, 30.0], "psi_deg": [5.0, 10.0, 15.0],
                       "untrained_phi_deg": [15.0, 25.0, 35.0], "untrained_psi_deg": [7.0, 12.0, 17.0],
                       "approach_inclines_deg": [45.0, 60.0], "approach_phi_deg": 20.0,
                       "positions_mm": [[0.0, 0.0], [5.0, 5.0], [-5.0, 5.0], [-5.0, -5.0], [5.0, -5.0]],
                       "calibration_trials": 5, "validation_trials": 3, "untrained_trials": 1,
                       "grip_depth_mm": 1.0, "board_thickness_mm": 1.7, "board_width_mm": 80.0,
                       "stick_out_mm": 60.0, "travel_mm": 3.0, "speed_mm_s": 5.0},
    "inverter": {**GEN2, "calibration_trials": 7, "validation_trials": 3, "untrained_trials": 3,
                 "tilt_y_deg": 10.0, "untrained_tilt_y_deg": 15.0, "untrained_tilt_x_deg": 5.0,
                 "untrained_offsets_mm": [-5.0, 5.0], "grip_depth_mm": 1.0, "part_thickness_mm": 3.0,
                 "clip_spacing_mm": 60.0, "part_depth_mm": 50.0, "travel_mm": 1.5, "speed_mm_s": 5.0,
                 "seat_compliance_mm_per_N": 1.0, "rim_compliance_mm_per_N": 0.2},
}
FINGERTIP, WEARABLE = "fingertip", "wearable"
PROTOCOL_BENCHES: dict[str, str] = {**dict.fromkeys(_FINGERTIP_DEFAULTS, FINGERTIP), "wearable": WEARABLE}
PARAMETER_SCHEMAS: dict[str, type] = {**{name: _parameters_schema(defaults) for name, defaults in
                                         _FINGERTIP_DEFAULTS.items()}, "wearable": wearable.WearableParameters}
DEFAULTS: dict[str, dict[str, Any]] = {name: asdict(kind()) for name, kind in PARAMETER_SCHEMAS.items()}
RUNNERS: dict[str, Callable] = {
    "pushing": experiments.pushing, "force3": experiments.force3, "hysteresis": experiments.hysteresis,
    "grasp-two": experiments.grasp_two, "grasp-positions": experiments.grasp_positions,
    "contact-states": experiments.contact_states, "inverter": experiments.inverter,
    "wearable": wearable.wearable,
}


_HYSTERESIS = published_table("hysteresis")
PUBLISHED_HYSTERESIS_PERCENT = _HYSTERESIS.value("hysteresis", "calibration cycle").low


@schema(section="viscoelastic")
class Viscoelastic:
    """The material's relaxation: set so one centred board cycle shows this hysteresis (default: the
    published figure)."""

    hysteresis_percent: NonNegativeNumber = PUBLISHED_HYSTERESIS_PERCENT
    depth_mm: NonNegativeNumber = 3.0
    speed_mm_s: NonNegativeNumber = 0.25
    rest_s: NonNegativeNumber = 1.0


# each bench's [viscoelastic] table and where its defaults come from (the reports print it)
VISCOELASTIC_SOURCES: dict[str, tuple[type, dict[str, str]]] = {
    FINGERTIP: (Viscoelastic, {
        "hysteresis_percent": f"published: {_HYSTERESIS.source} ({_HYSTERESIS.system})",
        **{key: "the calibration cycle: the article's hysteresis test" for key in ("depth_mm", "speed_mm_s",
                                                                                   "rest_s")}}),
    WEARABLE: (wearable.PadViscoelastic, {
        "g": "assumed weights (softtip.mechanics.fingerpad)",
        "tau_s": "time constants of Pawluk & Howe 1999 (softtip.mechanics.fingerpad)"}),
}


@dataclass
class Protocol:
    name: str
    design: Design | wearable.WearableDevice  # what the bench is built from
    seed: int
    parameters: dict[str, Any]
    realism: Realism | WearableRealism = field(default_factory=Realism)
    viscoelastic: dict[str, Any] = field(default_factory=lambda: asdict(Viscoelastic()))

    @property
    def bench(self) -> str:
        return PROTOCOL_BENCHES[self.name]

    def to_dict(self) -> dict:
        return {"protocol": self.name, "design": self.design.name, "seed": self.seed, "parameters": self.parameters,
                "realism": self.realism.to_dict(), "viscoelastic": self.viscoelastic}


def shipped_protocol_path(name: str) -> Path:
    return Path(str(resources.files("softtip.lab") / "protocols" / f"{name}.toml"))


ProtocolName = choice(*sorted(RUNNERS))  # any protocol: its name chose the file's schema (protocol_from_dict)


@schema
class _FingertipProtocolFile:
    protocol: ProtocolName
    design: Text  # a shipped design or a design TOML file
    seed: integer() = 0
    parameters: dict[str, Any] = field(default_factory=dict)  # checked against the protocol's own
    realism: Realism = Realism()
    viscoelastic: Viscoelastic = Viscoelastic()


@schema
class _WearableProtocolFile:
    protocol: ProtocolName
    seed: integer() = 0
    parameters: dict[str, Any] = field(default_factory=dict)  # checked against WearableParameters
    realism: WearableRealism = WearableRealism()
    viscoelastic: wearable.PadViscoelastic = wearable.PadViscoelastic()


def protocol_from_dict(table: dict, source: str, base: Path | None = None) -> Protocol:
    name = table.get("protocol") if isinstance(table, dict) else None
    # the name chooses the bench; a missing or unknown name is refused by the fingertip file's schema
    bench = BENCHES[PROTOCOL_BENCHES.get(name, FINGERTIP) if isinstance(name, str) else FINGERTIP]
    top = parse(bench.protocol_file, table, source)
    parameters = asdict(parse(PARAMETER_SCHEMAS[top.protocol], top.parameters, source, "parameters"))
    return Protocol(name=top.protocol, design=bench.device(top, parameters, source, base), seed=top.seed,
                    parameters=parameters, realism=top.realism, viscoelastic=asdict(top.viscoelastic))


def load_protocol(path: str | Path) -> Protocol:
    """A protocol file, or the name of a shipped protocol (``pushing``, ``inverter`` ...)."""
    path = Path(path)
    if not path.suffix and str(path) in RUNNERS:
        path = shipped_protocol_path(str(path))
    return protocol_from_dict(read_toml(path, "protocol"), str(path), path.parent)


_FINGERTIPS: dict[tuple, InfluenceEngine] = {}


def fingertip_for(design: Design, parameters: dict, progress: Progress = SILENT) -> InfluenceEngine:
    """The design's lab mechanics, built once per process for each design and mesh."""
    key = (repr(design.spec), parameters["mesh_size_mm"], parameters["curvature_points"], parameters["reach_mm"])
    if key not in _FINGERTIPS:
        _FINGERTIPS[key] = InfluenceEngine.build(design, parameters["mesh_size_mm"] * MM, parameters["reach_mm"] * MM,
                                                 curvature_points=parameters["curvature_points"], progress=progress)
    return _FINGERTIPS[key]


# ---------------------------------------------------------------------------------------------- benches


@dataclass(frozen=True)
class BenchKind:
    """A bench protocols run on: the schema of their files, what the bench is built from and how it is set up.

    ``device(file, parameters, source, folder)``: what the protocol file describes the bench with;
    ``setup(protocol, progress, timings)``: the bench for one run, what the dataset records of it beyond
    the protocol's tables, and the description of the trials' stage (building what it needs is timed
    into ``timings``).
    """

    protocol_file: type
    device: Callable[[Any, dict, str, Path | None], Design | wearable.WearableDevice]
    setup: Callable[[Protocol, Progress, dict], tuple[Any, dict, str]]


def _design(file: _FingertipProtocolFile, parameters: dict, source: str, base: Path | None) -> Design:
    """The file's design: a shipped one or a design file, found beside the protocol file first."""
    try:
        return load_design(file.design if base is None or not (base / file.design).is_file() else base / file.design)
    except ValueError as error:
        raise refused(str(error), source, "design", value=file.design) from None


def _fingertip_bench(protocol: Protocol, progress: Progress, timings: dict) -> tuple[experiments.Bench, dict, str]:
    """The design's mechanics (``mechanics_s``) and its material's relaxation, set from the ``[viscoelastic]``
    cycle; the dataset records that relaxation."""
    start = time.perf_counter()
    fingertip = fingertip_for(protocol.design, protocol.parameters, progress)
    timings["mechanics_s"] = time.perf_counter() - start
    v = protocol.viscoelastic
    prony = experiments.material_prony(fingertip, v["hysteresis_percent"], v["depth_mm"] * MM, v["speed_mm_s"] * MM,
                                       v["rest_s"])
    bench = experiments.Bench(fingertip=fingertip, prony=prony, realism=protocol.realism,
                              rng=np.random.default_rng(protocol.seed), rate_hz=protocol.parameters["rate_hz"])
    return (bench, {"prony": {"g": list(prony.g), "tau_s": list(prony.tau)}},
            f"{protocol.name}: trials on {protocol.design.name}")


def _wearable_device(file: _WearableProtocolFile, parameters: dict, source: str,
                     base: Path | None) -> wearable.WearableDevice:
    return wearable.WearableDevice.from_parameters(parameters)


def _wearable_bench(protocol: Protocol, progress: Progress, timings: dict) -> tuple[wearable.WearableBench, dict, str]:
    """The finger tissue's relaxation, given by the ``[viscoelastic]`` table."""
    p = protocol.parameters
    bench = wearable.WearableBench(prony=wearable.PadViscoelastic(**protocol.viscoelastic).prony(),
                                   realism=protocol.realism, rng=np.random.default_rng(protocol.seed),
                                   rate_hz=p["rate_hz"])
    return bench, {}, f"{protocol.name}: {p['participants']} participants x {p['runs']} runs on {protocol.design.name}"


BENCHES: dict[str, BenchKind] = {FINGERTIP: BenchKind(_FingertipProtocolFile, _design, _fingertip_bench),
                                 WEARABLE: BenchKind(_WearableProtocolFile, _wearable_device, _wearable_bench)}


def run_protocol(protocol: Protocol, progress: Progress = SILENT) -> tuple[Dataset, dict]:
    """Run one experiment; returns its dataset and timings (s). ``progress`` gets a task per stage."""
    timings = {}
    bench, recorded, stage = BENCHES[protocol.bench].setup(protocol, progress, timings)
    start = time.perf_counter()
    # the trials' dense solves are small: a second BLAS thread only fights for a shared core
    with progress.task(stage), threadpool_limits(limits=1):
        dataset = RUNNERS[protocol.name](bench, {**protocol.parameters, "viscoelastic": protocol.viscoelastic,
                                                 **recorded, "realism": protocol.realism.to_dict()}, protocol.seed)
    timings["trials_s"] = time.perf_counter() - start
    return dataset, timings
