"""S4 on the twin, as the lab's protocol ``cilia``: the die's force–voltage curves and its brushings.

Paper mode (as the published simulation loads the pillars: a tip force perpendicular to each axis) at
``points`` equal steps up to ``force_max_mN``, and balance mode (as the measurement was made: the die
lowered step by step onto a plate on a balance, to 70 % of the pillars' height past first contact), each
repeated ``trials`` times. Every reading goes through the computed readout (Johnson, 1/f and meter noise,
the meter's quantisation; :mod:`softtip.sensors.gmr`) and the bench's repeatability, both sensors read at
each step, tared by a reading at zero force. The twin's truth is the die file with the protocol's moment,
tip diameter and, where given, height and Young's modulus (:func:`softtip.systems.cilia.study.twin_model`).

Then the brushings (:mod:`softtip.systems.cilia.roughness`): the die held ``brush_engagement_um`` past first
contact and moved over ``brush_strips`` strips of each of the four surfaces, every strip at
``brush_speed_mm_s`` and at every one of ``brush_speeds_mm_s``, at ``brush_rate_hz``, and the first strip at ``brush_speed_mm_s`` at every one of
``brush_rates_hz``: one trial (one recording) each, both sensors read as published (the meter across the
sensor) or, with ``brush_bridge``, through a bridge (the rest voltage taken off before the meter).

Channels: ``gmr_x_V``, ``gmr_y_V`` (each sensor's voltage change from its tare; in a brushing, from its
rest voltage; a die with one sensor direction records its own only). Label: ``force_N`` (the total force on the die: the load applied in paper mode,
the balance's vertical reading in balance mode and under the surface in a brushing). Conditions: ``mode``
(paper, balance, brushing), ``repeat`` (the loading's repeat; in a brushing, which strip of the surface),
``tare_x_V``, ``tare_y_V`` (the tare readings; in a brushing, the rest voltage),
``surface`` (none in a loading), ``roughness_um`` (the surface's rms roughness), ``speed_mm_s`` (the
stage's speed; 0 in a loading) and ``rate_hz`` (readings per second).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from softtip._core.config import PositiveNumber, schema
from softtip._core.progress import Progress
from softtip._core.units import MM, UM
from softtip.data import Dataset, DatasetMetadata, TrialWriter
from softtip.lab.bench import RealismTable, SeededBench
from softtip.lab.protocols import BenchKind, Protocol, protocol_file_schema
from softtip.mechanics.viscoelastic import PronySeries
from softtip.systems.cilia.fit import MeasuredCurve
from softtip.systems.cilia.layout import MEMU, DieError, pillar_problem, placement_problem, read_die
from softtip.systems.cilia.model import CiliaModel, ForceCurve
from softtip.systems.cilia.roughness import Recording, brush_surfaces
from softtip.systems.cilia.study import (
    DWELL_S,
    CiliaSettings,
    balance_contact,
    balance_descent,
    balance_plate,
    die_path,
    measure,
    paper_forces,
    twin_model,
)

SENSORS = ("X", "Y")
LABELS = {"force_N": "N"}
CONDITIONS = {"mode": "1", "repeat": "1", "surface": "1", "roughness_um": "um", "speed_mm_s": "mm/s", "rate_hz": "Hz"}


def channel(sensor: str) -> str:
    """The dataset channel of ``sensor``'s voltage."""
    return f"gmr_{sensor.lower()}_V"


def tare(sensor: str) -> str:
    """The dataset condition of ``sensor``'s tare."""
    return f"tare_{sensor.lower()}_V"
MODES = ("paper", "balance")
BRUSHING = "brushing"


@schema(section="realism")
class CiliaRealism(RealismTable):
    """The bench beyond the readout's computed noise (the repeatability is the protocol's parameter)."""

    dwell_s: PositiveNumber = DWELL_S  # per load step: the time axis of the dataset


@schema(section="viscoelastic")
class NoRelaxation:
    """PDMS pillars at quasi-static load steps: the study models no relaxation."""


CiliaProtocolFile = protocol_file_schema(CiliaRealism, NoRelaxation)


@dataclass(frozen=True)
class CiliaDie:
    """The die a protocol runs on: its file, checked when the protocol is read."""

    name: str
    path: Path

    @property
    def spec(self) -> dict:
        return {"name": self.name, "die_file": self.path.name}


@dataclass
class CiliaBench(SeededBench):
    model: CiliaModel  # the twin's die with the protocol's truth


def _device(file: CiliaProtocolFile, parameters: CiliaSettings, source: str, base: Path | None) -> CiliaDie:
    """The die file, resolved from the protocol file's folder and read through (a bad one is refused here,
    before any work)."""
    path = die_path(parameters.die, base if parameters.die != "shipped" else None)
    if not path.is_file() and parameters.die != "shipped":
        path = Path(parameters.die)  # relative to the working folder, as a command-line path would be
    die = read_die(path)
    height = die.pillars.rod.length if parameters.height_mm is None else parameters.height_mm * MM
    if parameters.brush_engagement_um * UM >= 0.7 * height:  # the balance-mode response reaches 70 % of the height
        raise DieError(f"{source}: parameters.brush_engagement_um = {parameters.brush_engagement_um:g}: expected "
                       f"less than 70 % of the pillars' height ({0.7 * height / UM:g} um)")
    # the twin's pillars: the die's with the protocol's truth (tip diameter, taper kept, moment) and height
    rod = die.pillars.rod
    tip = parameters.truth_diameter_um * UM
    base = rod.base_diameter / rod.tip_diameter * tip
    problem = pillar_problem(height, tip, base, parameters.truth_moment_memu * MEMU)
    if problem:
        key = {"moment_memu": "truth_moment_memu"}.get(problem[0], "truth_diameter_um")
        raise DieError(f"{source}: parameters.{key} = {getattr(parameters, key):g}: {problem[1]}")
    placed = placement_problem(die.pillars.positions, base, die.size)
    if placed:
        raise DieError(f"{source}: parameters.truth_diameter_um = {parameters.truth_diameter_um:g}: the base it gives "
                       f"({base / UM:g} um, the die's taper kept): {placed}")
    spread = float(np.ptp(die.pillars.positions[:, 0]))
    if parameters.brush_length_mm * MM <= spread + 4 * UM:
        raise DieError(f"{source}: parameters.brush_length_mm = {parameters.brush_length_mm:g}: expected a stroke "
                       f"longer than the pillars' spread along it ({spread / MM:g} mm)")
    return CiliaDie(name=f"gmr-cilia:{parameters.die}", path=path)


def _setup(protocol: Protocol, progress: Progress, timings: dict) -> tuple[CiliaBench, dict, str]:
    p = replace(protocol.parameters, die=str(protocol.design.path))
    model = twin_model(p)
    bench = CiliaBench(prony=PronySeries((), ()), realism=protocol.realism, rng=np.random.default_rng(protocol.seed),
                       rate_hz=1.0 / protocol.realism.dwell_s, model=model)
    return bench, {"die_file": str(protocol.design.path.name)}, (
        f"{protocol.name}: {p.trials} x paper and balance curves of {p.points} steps, and the brushings, on "
        f"{protocol.design.name}")


def _curves(model: CiliaModel, p: CiliaSettings, sensors: tuple[str, ...]) -> dict[str, tuple[ForceCurve, ...]]:
    """The twin's noise-free curves, per mode: one per sensor."""
    forces, descent, contact = paper_forces(p), balance_descent(model, p), balance_contact(p)
    return {"paper": model.curves(forces, sensors),
            "balance": model.balance_curves(descent, contact, sensors, balance_plate(p))}


def cilia(bench: CiliaBench, p: CiliaSettings, seed: int, record: dict) -> Dataset:
    """``trials`` repeats of the paper-mode and the balance-mode curve, every sensor of the die read at every
    step; then the brushings of the four surfaces."""
    model, rng = bench.model, bench.rng
    sensors = tuple(m.name for m in model.die.meanders)
    writer = TrialWriter({channel(s): "V" for s in sensors}, LABELS, CONDITIONS | {tare(s): "V" for s in sensors},
                         DatasetMetadata(
        description="GMR cilia die: voltage change of each sensor against the force on the die, and brushings "
                    "across four surfaces",
        design={"die_file": record.get("die_file", ""), "moment_memu": p.truth_moment_memu,
                "tip_diameter_um": p.truth_diameter_um},
        sensor_settings={"current_A": model.die.meanders[0].readout.current}, protocol=record, seed=seed))
    curves = _curves(model, p, sensors)
    loading = {"surface": "none", "roughness_um": 0.0, "speed_mm_s": 0.0, "rate_hz": bench.rate_hz}
    for repeat in range(p.trials):
        for mode in MODES:
            truth = curves[mode]
            measured = [measure(model, curve, p.repeatability, rng) for curve in truth]
            writer.add({"time_s": np.arange(truth[0].force.size) * bench.realism.dwell_s,
                        **{channel(s): m.change for s, m in zip(sensors, measured)}, "force_N": truth[0].force},
                       {"mode": mode, "repeat": repeat, **loading,
                        **{tare(s): curve.volts[0] - curve.change[0] for s, curve in zip(sensors, truth)}})
    rests = {tare(s): model.rest_volts(s) for s in sensors}
    for brushing in brush_surfaces(model, balance_contact(p), p.brush_engagement_um * UM, p.brush_length_mm * MM,
                                   p.brush_speed_mm_s * MM, p.brush_rate_hz, tuple(v * MM for v in p.brush_speeds_mm_s),
                                   tuple(p.brush_rates_hz), p.brush_strips, rng, p.brush_bridge):
        recording = brushing.recording
        writer.add({"time_s": np.arange(recording.readings.size) / recording.rate,
                    **{channel(s): r for s, r in zip(sensors, brushing.readings)}, "force_N": brushing.force},
                   {"mode": BRUSHING, "repeat": recording.strip, **rests, "surface": recording.surface,
                    "roughness_um": recording.roughness / UM, "speed_mm_s": recording.speed / MM,
                    "rate_hz": recording.rate})
    return writer.to_dataset()


BENCH = BenchKind(
    protocol_file=CiliaProtocolFile, parameters={"cilia": CiliaSettings}, runners={"cilia": cilia},
    device=_device, setup=_setup,
    realism_sources={"dwell_s": "chosen: a load step every 2 s (the publication gives no rate)"},
    viscoelastic_sources={})


def curve_of(dataset: Dataset, mode: str, repeat: int, sensor: str) -> MeasuredCurve:
    """One measured curve of a ``cilia`` dataset."""
    if mode not in MODES or sensor not in SENSORS:
        raise DieError(f"curve: expected a mode of {MODES} and a sensor of {SENSORS}, got {mode!r}, {sensor!r}")
    rows = (dataset.column("mode") == mode) & (dataset.column("repeat") == repeat)
    if not rows.any():
        raise DieError(f"dataset: no {mode} curve of repeat {repeat}")
    part = dataset.select(rows=rows)
    return MeasuredCurve(part.column("force_N"), part.column(channel(sensor)), sensor)


BRUSHING_CONDITIONS = ("mode", "surface", "roughness_um", "repeat", "speed_mm_s", "rate_hz")
BRUSHING_LABELS = ("roughness_um", "speed_mm_s", "rate_hz")  # and optionally "strip": an imported log's


def recordings_of(dataset: Dataset, channel: str = "gmr_x_V") -> list[Recording]:
    """The brushings of a dataset, read from ``channel``: a ``cilia`` dataset's (trials of mode ``brushing``,
    a lab run's or a user's own, with the conditions ``surface``, ``roughness_um``, ``repeat`` (the strip),
    ``speed_mm_s`` and ``rate_hz``), or a log brought in by ``softtip import`` with the labels
    ``roughness_um``, ``speed_mm_s``, ``rate_hz`` and optionally ``strip`` on every reading (a recording is a
    run of a trial's readings with the same values; a surface is named by its roughness)."""
    if channel not in dataset.channels:
        raise DieError(f"dataset: expected the channel {channel}; its channels: {', '.join(dataset.channels)}")
    if all(name in dataset.labels for name in BRUSHING_LABELS):
        values = {name: dataset.column(name) for name in (*BRUSHING_LABELS, "strip") if name in dataset.labels}
        roughness = values["roughness_um"]
        return recordings_in_runs(f"dataset {channel}", [f"{value:g} um" for value in roughness],
                                  values.get("strip", np.zeros(len(dataset))), values["speed_mm_s"],
                                  values["rate_hz"], roughness, dataset.column(channel), dataset.column("trial"))
    missing = [name for name in BRUSHING_CONDITIONS if name not in dataset.conditions]
    if missing:
        raise DieError(f"dataset: expected brushings: the conditions {', '.join(BRUSHING_CONDITIONS)} (missing "
                       f"{', '.join(missing)}), or, for a log brought in by softtip import, the labels "
                       f"{', '.join(BRUSHING_LABELS)} on every reading (import them with --label roughness_um=COLUMN:um "
                       "--label speed_mm_s=COLUMN:mm/s --label rate_hz=COLUMN:Hz)")
    brushing = dataset.select(rows=dataset.column("mode") == BRUSHING)
    if len(brushing) == 0:
        raise DieError("dataset: no brushing trials (mode = brushing)")
    conditions = brushing.trial_conditions
    readings = brushing.column(channel)
    trials = brushing.column("trial")
    recordings = []
    for index, trial in enumerate(brushing.trials):
        recordings.append(Recording(str(conditions["surface"][index]), float(conditions["roughness_um"][index]) * UM,
                                    int(conditions["repeat"][index]), float(conditions["speed_mm_s"][index]) * MM,
                                    float(conditions["rate_hz"][index]), np.array(readings[trials == trial])))
    return recordings


BRUSHING_COLUMNS = ("surface", "roughness_um", "speed_mm_s", "rate_hz")  # and optionally "strip"


def recordings_from_csv(path: Path, channel: str) -> list[Recording]:
    """The brushings of a CSV table, one row per reading: the columns ``surface`` (a name), ``roughness_um``
    (its rms roughness, µm; 0 for the flat one), ``speed_mm_s``, ``rate_hz``, optionally ``strip`` (which
    strip of the surface; 0 when absent), and ``channel`` (the reading, V). A recording is a run of
    consecutive rows with the same surface, strip, speed and rate."""
    from softtip.data.csvload import parse_numbers, read_csv_table
    from softtip.data.dataset import require_columns

    numeric = [*BRUSHING_COLUMNS[1:], channel]
    table = read_csv_table(path, numeric)
    require_columns(path, [*BRUSHING_COLUMNS, channel], table.column_names)
    if "strip" in table.column_names:
        numeric.append("strip")
        table = read_csv_table(path, numeric)
    if table.num_rows == 0:
        raise DieError(f"{path}: no readings")
    values = {name: parse_numbers(path, name, table.column(name)) for name in numeric}
    surface = np.array([str(v) for v in table.column("surface").to_pylist()])
    strip = values.get("strip", np.zeros(table.num_rows))
    return recordings_in_runs(str(path), surface, strip, values["speed_mm_s"], values["rate_hz"],
                              values["roughness_um"], values[channel], np.zeros(len(surface)))


def recordings_in_runs(source: str, surface: list[str] | NDArray, strip: NDArray, speed: NDArray, rate: NDArray,
                       roughness: NDArray, readings: NDArray, trial: NDArray) -> list[Recording]:
    """Brushings from per-reading columns (speeds mm/s, rates /s, roughnesses µm): a recording is a run of
    consecutive readings of one ``trial`` with the same surface, strip, speed, rate and roughness."""
    if not (np.all(np.isfinite(readings)) and np.all(strip >= 0) and np.all(strip == np.round(strip))):
        raise DieError(f"{source}: expected finite readings and whole strip numbers >= 0")
    for name, column in (("speed_mm_s", speed), ("rate_hz", rate)):
        if not np.all(column > 0):
            raise DieError(f"{source}: {name}: expected positive numbers")
    if not np.all(roughness >= 0):
        raise DieError(f"{source}: roughness_um: expected roughnesses >= 0 um")
    keys = list(zip(trial, surface, strip, speed, rate, roughness))
    starts = [0] + [row for row in range(1, len(keys)) if keys[row] != keys[row - 1]] + [len(keys)]
    recordings = []
    for start, end in zip(starts[:-1], starts[1:]):
        _, name, number, speed_mm_s, rate_hz, roughness_um = keys[start]
        recordings.append(Recording(str(name), float(roughness_um) * UM, int(number), float(speed_mm_s) * MM,
                                    float(rate_hz), np.asarray(readings[start:end], dtype=np.float64)))
    return recordings


FORCE_UNITS = {"N": 1.0, "mN": 1e-3, "g": 9.80665e-3}  # a balance reads grams: times standard gravity


def curve_from_csv(path: Path, force_column: str, voltage_column: str, force_unit: str, sensor: str,
                   tare: bool) -> MeasuredCurve:
    """A measured force–voltage curve from a CSV table: ``force_column`` in ``force_unit`` (N, mN or g, a
    balance's mass) and ``voltage_column`` (V), the change from the unloaded reading, or with ``tare`` the
    sensor's voltage, from which the mean of the rows at zero force is taken."""
    from softtip.data.csvload import parse_numbers, read_csv_table
    from softtip.data.dataset import require_columns

    if force_unit not in FORCE_UNITS:
        raise DieError(f"force unit {force_unit!r}: expected one of {', '.join(FORCE_UNITS)}")
    table = read_csv_table(path, [force_column, voltage_column])
    require_columns(path, [force_column, voltage_column], table.column_names)
    force = parse_numbers(path, force_column, table.column(force_column)) * FORCE_UNITS[force_unit]
    volts = parse_numbers(path, voltage_column, table.column(voltage_column))
    return _tared_curve(path, force, volts, sensor, tare, force_column, voltage_column)


VOLTAGE_UNITS = {"V": 1.0, "mV": 1e-3, "uV": 1e-6}


def curve_from_dataset(path: Path, dataset: Dataset, force_label: str, channel: str, sensor: str, tare: bool,
                       trial: int | None) -> MeasuredCurve:
    """A measured force–voltage curve from a dataset (``softtip import``'s, or any other): the label
    ``force_label`` in its declared unit (N, mN or g) against the channel ``channel`` (V, mV or µV), of its
    one trial or of ``trial``; ``tare`` as :func:`curve_from_csv`."""
    if force_label not in dataset.labels:
        raise DieError(f"{path}: no label {force_label!r} (--force-column); its labels: "
                       f"{', '.join(dataset.labels) or 'none'}")
    if channel not in dataset.channels:
        raise DieError(f"{path}: no channel {channel!r} (--voltage-column); its channels: {', '.join(dataset.channels)}")
    force_unit, voltage_unit = dataset.labels[force_label], dataset.channel_units[channel]
    if force_unit not in FORCE_UNITS or voltage_unit not in VOLTAGE_UNITS:
        raise DieError(f"{path}: {force_label} in {force_unit!r} and {channel} in {voltage_unit!r}: expected a force "
                       f"in {', '.join(FORCE_UNITS)} and a voltage in {', '.join(VOLTAGE_UNITS)}")
    trials = dataset.trials
    if trial is None and len(trials) > 1:
        raise DieError(f"{path}: {len(trials)} trials (0 to {len(trials) - 1}): expected one curve; choose it with --trial")
    if trial is not None and trial not in trials:
        raise DieError(f"{path}: --trial = {trial}: expected one of its trials, 0 to {len(trials) - 1}")
    part = dataset if trial is None else dataset.select(trials=[trial])
    force = np.asarray(part.column(force_label), dtype=np.float64) * FORCE_UNITS[force_unit]
    volts = np.asarray(part.column(channel), dtype=np.float64) * VOLTAGE_UNITS[voltage_unit]
    return _tared_curve(path, force, volts, sensor, tare, force_label, channel)


def _tared_curve(path: Path, force: NDArray, volts: NDArray, sensor: str, tare: bool, force_column: str,
                 voltage_column: str) -> MeasuredCurve:
    if tare:
        unloaded = force == 0
        if not unloaded.any():
            raise DieError(f"{path}: no row at zero force in {force_column!r} to tare {voltage_column!r} by")
        volts = volts - volts[unloaded].mean()
    try:
        return MeasuredCurve(force, volts, sensor)
    except DieError as problem:
        raise DieError(f"{path}: {problem}") from None
