"""S3's study as a lab protocol: the simulated device, its FS table and user tables, the targets, and
every target rendered on every test fingertip by every method, written as one dataset.

One trial per target sensation (``trials`` of them: the publication's 100), in the order they were
recorded; within a trial one row per rendering, fingertip by fingertip and method by method
(:data:`~softtip.systems.haptics.study.METHODS`), at ``time_s`` = its place in that sequence times
``hold_s`` (each rendering held as a table entry is). The target's wrench is a condition of its
trial; each row holds what the method commanded and what the sensor under the test fingertip read.

Channels: ``rendered_f{x|y|z}_N`` and ``rendered_t{x|y|z}_Nm`` (the test fingertip's 6-axis
sensor). Labels: ``fingertip``, ``method``, ``motor{1|2|3}_rad`` (commanded), ``error_N``
(|F_target − F_rendered| over the three force components), ``flagged`` (the target lay outside the
table, or the sensor under the test fingertip saturated). Conditions: ``target_f{x|y|z}_N``,
``target_t{x|y|z}_Nm`` (the FS's reading of the target). The collection times and each fingertip's
personalisation figures are in the metadata's ``sensor_settings``.

The ``curve_*``, ``variations``, ``robustness_*`` and ``ablations`` parameters are not the dataset's: the
report (:mod:`.report`) reruns the simulated study over them (:mod:`.sensitivity`, :mod:`.ablation`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Annotated

import numpy as np
from pydantic import Field

from softtip._core.config import (Flag, PositiveNumber, Refusal, Text, choice, expect, integer, number, refused,
                                  schema)
from softtip._core.files import not_a_file
from softtip._core.progress import Progress
from softtip.data import Dataset, DatasetMetadata, TrialWriter
from softtip.lab.bench import RealismTable, SeededBench
from softtip.lab.protocols import BenchKind, Protocol, Size, protocol_file_schema
from softtip.mechanics.viscoelastic import PronySeries
from softtip.systems.haptics.collection import Collection, CollectionSettings, collection_duration
from softtip.systems.haptics.device import DEVICE_FILE, DeviceError, DeviceSpec, load_device
from softtip.systems.haptics.fingertip_file import load_fingertip
from softtip.systems.haptics.fingertips import TEST_FINGERTIPS, Fingertip
from softtip.systems.haptics.limits import (
    LEVELS_EXPECTED,
    MAX_FINGERTIP_FILES,
    MAX_FS_LEVELS,
    MAX_NEIGHBOURS,
    MAX_SIMULATED_PRESSES,
    MAX_TABLE_ENTRIES,
    MAX_TARGET_DRAWS,
    MAX_TARGETS,
)
from softtip.systems.haptics.personalisation import DATA_DRIVEN_VARIANTS, PRESS_DEPTHS
from softtip.systems.haptics.rendering import CONTACT_THRESHOLD, WeightingPower
from softtip.systems.haptics.sensitivity import CURVES, DEFAULT_VARIATIONS, VARIATION_NAMES, FingerVariation
from softtip.systems.haptics.study import METHODS, StudySettings, run_study
from softtip.systems.haptics.table_files import TableFileError, read_table

WRENCH_AXES = ("fx", "fy", "fz", "tx", "ty", "tz")
WRENCH_UNITS = ("N", "N", "N", "Nm", "Nm", "Nm")
RENDERED = tuple(f"rendered_{axis}_{unit}" for axis, unit in zip(WRENCH_AXES, WRENCH_UNITS))
TARGET = tuple(f"target_{axis}_{unit}" for axis, unit in zip(WRENCH_AXES, WRENCH_UNITS))
MOTORS = ("motor1_rad", "motor2_rad", "motor3_rad")
CHANNELS = {name: unit.replace("Nm", "N m") for name, unit in zip(RENDERED, WRENCH_UNITS)}
LABELS = {"fingertip": "1", "method": "1", **dict.fromkeys(MOTORS, "rad"), "error_N": "N", "flagged": "1"}
CONDITIONS = {name: unit.replace("Nm", "N m") for name, unit in zip(TARGET, WRENCH_UNITS)}
FINGERTIP_NAMES = tuple(f.name for f in TEST_FINGERTIPS)

Fingertips = Annotated[list[choice(*FINGERTIP_NAMES)], Field(min_length=1),
                       expect(f"a non-empty list of: {', '.join(FINGERTIP_NAMES)}")]
_STUDY, _COLLECTION = StudySettings(), CollectionSettings()
# the report's sweeps (softtip.systems.haptics.sensitivity); bounded so that no sweep runs for long
CURVE_SETTINGS = {"curve_n_neighbours": "n_neighbours", "curve_weighting_powers": "weighting_power",
                  "curve_fs_levels": "fs_levels", "curve_user_levels": "user_levels"}
_CURVES = dict(CURVES)
NeighbourCounts = Annotated[list[integer(1, MAX_NEIGHBOURS)], expect(f"a list of integers 1..{MAX_NEIGHBOURS}")]
WeightingPowers = Annotated[list[WeightingPower], expect("a list of numbers from 0 to 4")]
FsLevels = Annotated[list[integer(2, 21)], expect("a list of integers 2..21")]
UserLevels = Annotated[list[integer(2, 13)], expect("a list of integers 2..13")]
Variations = Annotated[list[choice(*VARIATION_NAMES)], expect(f"a list of: {', '.join(VARIATION_NAMES)}")]
RobustnessSeeds = Annotated[list[integer(0)], expect("a list of seeds (integers >= 0)")]


@schema(section="parameters")
class HapticsParameters:
    """The ``[parameters]`` table of the haptics protocol (S3; units in the names). ``trials``: the
    target sensations (one trial each); the table sizes are levels per servo (13 → 13³)."""

    trials: integer(2, MAX_TARGETS) = _STUDY.targets
    fs_levels: integer(2, MAX_FS_LEVELS, LEVELS_EXPECTED) = _STUDY.fs_levels
    user_levels: integer(2, MAX_FS_LEVELS, LEVELS_EXPECTED) = _STUDY.user_levels
    adaptive_budget: integer(27, MAX_TABLE_ENTRIES) = _STUDY.adaptive_budget
    n_neighbours: integer(1, MAX_NEIGHBOURS) = _STUDY.n_neighbours
    weighting_power: WeightingPower = _STUDY.weighting_power
    light_force_N: PositiveNumber = _STUDY.light_force
    contact_threshold_N: PositiveNumber = CONTACT_THRESHOLD
    target_draws: integer(1, MAX_TARGET_DRAWS) = _STUDY.target_draws
    data_driven: choice(*DATA_DRIVEN_VARIANTS) = _STUDY.data_driven
    ds_torque_length_m: PositiveNumber = _STUDY.torque_length
    hold_s: PositiveNumber = _COLLECTION.hold_s
    window_s: PositiveNumber = _COLLECTION.window_s
    fingertips: Fingertips = field(default_factory=lambda: list(FINGERTIP_NAMES))
    curve_n_neighbours: NeighbourCounts = field(default_factory=lambda: list(_CURVES["n_neighbours"]))
    curve_weighting_powers: WeightingPowers = field(default_factory=lambda: list(_CURVES["weighting_power"]))
    curve_fs_levels: FsLevels = field(default_factory=lambda: list(_CURVES["fs_levels"]))
    curve_user_levels: UserLevels = field(default_factory=lambda: list(_CURVES["user_levels"]))
    variations: Variations = field(default_factory=lambda: list(VARIATION_NAMES))
    robustness_seeds: RobustnessSeeds = field(default_factory=lambda: [2, 3])
    robustness_sigmas: number("a number of standard deviations from 0 to 3", ge=0, le=3) = 1.0
    ablations: Flag = True

    def __post_init__(self) -> None:
        for key in ("fingertips", *CURVE_SETTINGS, "variations", "robustness_seeds"):
            values = getattr(self, key)
            if len(set(values)) != len(values):
                raise Refusal(key, f"expected each {'fingertip' if key == 'fingertips' else 'value'} once")
        if self.target_draws < self.trials:
            raise Refusal("target_draws", f"expected at least trials = {self.trials}: each target is a random "
                                          "configuration that touches the FS")
        self.study_settings()
        self.collection_settings()

    def study_settings(self) -> StudySettings:
        return StudySettings(targets=self.trials, fs_levels=self.fs_levels, user_levels=self.user_levels,
                             adaptive_budget=self.adaptive_budget, n_neighbours=self.n_neighbours,
                             weighting_power=self.weighting_power, light_force=self.light_force_N,
                             contact_threshold=self.contact_threshold_N, target_draws=self.target_draws,
                             min_target_force=self.contact_threshold_N, data_driven=self.data_driven,
                             torque_length=self.ds_torque_length_m)

    def selected_fingertips(self) -> tuple[Fingertip, ...]:
        """The test fingertips ``fingertips`` names, in the study's order."""
        return tuple(f for f in TEST_FINGERTIPS if f.name in self.fingertips)

    def curves(self) -> tuple[tuple[str, tuple], ...]:
        """The report's sweeps: each study setting and the values it takes, those with any."""
        return tuple((setting, tuple(getattr(self, key))) for key, setting in CURVE_SETTINGS.items()
                     if getattr(self, key))

    def selected_variations(self) -> tuple[FingerVariation, ...]:
        return tuple(v for v in DEFAULT_VARIATIONS if v.name in self.variations)

    def collection_settings(self) -> CollectionSettings:
        try:
            return CollectionSettings(hold_s=self.hold_s, window_s=self.window_s)
        except ValueError:
            raise Refusal("window_s", f"expected at most hold_s = {self.hold_s} s") from None


@schema(section="realism")
class HapticsRealism(RealismTable):
    """The haptics bench has no realism switch of its own: the 6-axis sensors' noise and steps at 1 kHz,
    the servos' dead band and slew are part of the simulated procedure (softtip.sensors.wrench,
    softtip.systems.haptics.device)."""


@schema(section="viscoelastic")
class HapticsViscoelastic:
    """The casts are modelled elastic: a table entry is read at the end of a 1 s hold, after the rubber
    has settled (no relaxation table)."""


# ``device``: "shipped" or a device TOML file; ``fingertip_files``: a researcher's fingertips (TOML,
# .fingertip_file), tested after the named ones; ``fs_table``: "simulated" or a recorded FS table (CSV or
# Parquet with the DS's readings, .table_files) used instead of the simulated collection; paths relative
# to the protocol file
_HapticsProtocolFile = protocol_file_schema(HapticsRealism, HapticsViscoelastic, device=(Text, "shipped"),
                                            fingertip_files=(tuple[Text, ...], ()), fs_table=(Text, "simulated"))


@dataclass(frozen=True)
class HapticsDevice:
    """What the haptics protocol runs on: a device file, loaded and checked; the researcher's own
    fingertips (from files) and recorded FS table (None: simulated), if the protocol names any."""

    name: str
    source: str
    device: DeviceSpec
    fingertips: tuple[Fingertip, ...] = ()
    fingertip_sources: tuple[str, ...] = ()
    fs: Collection | None = None
    fs_source: str = "simulated"

    @property
    def spec(self) -> dict:
        return {"name": self.name, "file": self.source, **asdict(self.device),
                "fingertip_files": dict(zip((f.name for f in self.fingertips), self.fingertip_sources, strict=True)),
                "fs_table": self.fs_source}


def study_fingertips(parameters: HapticsParameters, setup: HapticsDevice) -> tuple[Fingertip, ...]:
    """The test fingertips a protocol names, then those of its fingertip files."""
    return parameters.selected_fingertips() + setup.fingertips


def recorded_fs_table(path: Path, device: DeviceSpec, parameters: HapticsParameters) -> Collection:
    """A recorded FS table for the study, checked before any work: its DS readings are needed
    (personalisation A) and the renderer must index it; its real collection time is that of its
    configurations on ``device``, each held as the protocol holds them."""
    table = read_table(path, device)
    if table.platform_wrenches is None:
        raise TableFileError(f"table file {path}: the study's personalisation A needs the DS's readings too "
                             "(ds_fx_N, ds_fy_N, ds_fz_N, ds_tx_Nm, ds_ty_Nm, ds_tz_Nm)")
    table.renderer(n_neighbours=parameters.n_neighbours, contact_threshold=parameters.contact_threshold_N)
    entries = len(table.motor_inputs)
    return Collection(table.motor_inputs, table.wrenches, table.platform_wrenches, np.zeros(entries, bool),
                      collection_duration(device, table.motor_inputs, parameters.hold_s))


def device_from_file(path: str | Path) -> HapticsDevice:
    """A device file (``"shipped"``: softtip's own), refused in one line if it is missing or breaks the
    kinematics."""
    path = DEVICE_FILE if str(path) == "shipped" else Path(path)
    problem = not_a_file(path)
    if problem:
        raise DeviceError(f"device file {path} {problem}")
    device = load_device(path)
    return HapticsDevice(device.device.name, "shipped" if path == DEVICE_FILE else str(path), device)


def _device(file: _HapticsProtocolFile, parameters: HapticsParameters, source: str, base: Path | None) -> HapticsDevice:
    def located(name: str) -> Path:
        path = Path(name)
        return path if path.is_absolute() or base is None else base / path

    if len(file.fingertip_files) > MAX_FINGERTIP_FILES:
        raise refused(f"expected at most {MAX_FINGERTIP_FILES} fingertip files (each a whole fingertip's tables and "
                      "renderings)", source, "fingertip_files", value=len(file.fingertip_files))
    setup = device_from_file("shipped" if file.device == "shipped" else located(file.device))
    fingertips = tuple(load_fingertip(located(name)) for name in file.fingertip_files)
    names = [*parameters.fingertips, *(f.name for f in fingertips)]
    repeated = next((name for k, name in enumerate(names) if name in names[:k]), None)
    if repeated is not None:
        raise refused(f"the fingertip name {repeated!r} is used twice: expected each test fingertip's name once",
                      source, "fingertip_files", value=list(file.fingertip_files))
    fs = None if file.fs_table == "simulated" else recorded_fs_table(located(file.fs_table), setup.device,
                                                                        parameters)
    return replace(setup, fingertips=fingertips, fingertip_sources=tuple(map(str, map(located, file.fingertip_files))),
                   fs=fs, fs_source=file.fs_table if fs is None else str(located(file.fs_table)))


@dataclass
class HapticsBench(SeededBench):
    """The device the protocol drives."""

    device: HapticsDevice


def haptics(bench: HapticsBench, p: HapticsParameters, seed: int, record: dict) -> Dataset:
    """S3's study: collect the tables, record the targets and render each on each fingertip by each method."""
    collection = p.collection_settings()
    study = run_study(p.study_settings(), seed, device=bench.device.device,
                      fingertips=study_fingertips(p, bench.device), collection=collection, fs=bench.device.fs)
    settings = {"sensor": asdict(collection.sensor), "hold_s": p.hold_s, "window_s": p.window_s,
                "fs_table": bench.device.fs_source,
                "fs_collection_s": study.fs_collection_s, "user_collection_s": study.user_collection_s,
                "max_contact_radius_over_layer": study.max_contact_to_layer,
                "fingertips": {o.fingertip.name: {
                    "radius_m": o.fingertip.radius, "fs_entries_flagged_A": o.user_table_flagged,
                    "fs_entries_out_of_reach_B": o.geometric_flagged, "fitted_modulus_Pa": o.fitted_modulus,
                    "adaptive_collection_s": o.adaptive_collection_s} for o in study.fingertips}}
    writer = TrialWriter(CHANNELS, LABELS, CONDITIONS, DatasetMetadata(
        description="haptic rendering: targets rendered on test fingertips by each method (simulated device)",
        design=bench.device.spec, sensor_settings=json_ready(settings), protocol=record, seed=seed))
    rows = [(o, m) for o in study.fingertips for m in range(len(METHODS))]
    times = np.arange(len(rows)) * p.hold_s
    for k, target in enumerate(study.target_wrenches):
        writer.add({"time_s": times,
                    **{name: np.array([o.rendered_wrenches[m, k, a] for o, m in rows]) for a, name in enumerate(RENDERED)},
                    "fingertip": np.array([o.fingertip.name for o, _ in rows]),
                    "method": np.array([METHODS[m] for _, m in rows]),
                    **{name: np.array([o.motor_inputs[m, k, a] for o, m in rows]) for a, name in enumerate(MOTORS)},
                    "error_N": np.array([o.errors[m, k] for o, m in rows]),
                    "flagged": np.array([bool(o.flagged[m, k]) for o, m in rows])},
                   dict(zip(TARGET, map(float, target), strict=True)))
    return writer.to_dataset()


def json_ready(value):
    """Settings as JSON values (tuples as lists, numpy numbers as Python ones)."""
    if isinstance(value, dict):
        return {str(k): json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _bench(protocol: Protocol, progress: Progress, timings: dict) -> tuple[HapticsBench, dict, str]:
    p = protocol.parameters
    bench = HapticsBench(prony=PronySeries((), ()), realism=protocol.realism,
                         rng=np.random.default_rng(protocol.seed), rate_hz=1.0 / p.hold_s, device=protocol.design)
    return bench, {}, (f"{protocol.name}: {p.trials} targets x {len(p.fingertips)} fingertips x {len(METHODS)} "
                       f"methods on {protocol.design.name}")


def haptics_size(protocol: str, p: HapticsParameters) -> Size:
    """The configurations the protocol's run drives and reads on the simulated device: the FS table, the
    random draws for targets, and per fingertip its user table, the adaptive table's candidates (the FS
    table's grid), its presses and every target rendered by every method."""
    fingertips = len(p.fingertips)
    presses = (p.fs_levels**3 + p.target_draws
               + fingertips * (p.user_levels**3 + p.fs_levels**3 + len(PRESS_DEPTHS) + p.trials * len(METHODS)))
    return Size(presses, MAX_SIMULATED_PRESSES, "simulated presses",
                f"fs_levels³ + target_draws + fingertips x (user_levels³ + fs_levels³ + {len(PRESS_DEPTHS)} presses "
                f"+ trials x {len(METHODS)} methods)")


BENCH = BenchKind(
    protocol_file=_HapticsProtocolFile, parameters={"haptics": HapticsParameters}, runners={"haptics": haptics},
    device=_device, setup=_bench, realism_sources={}, viscoelastic_sources={}, size=haptics_size)

