"""A researcher's lookup tables: a recorded table read from a file, and a table written for firmware.

**A recorded table** is a CSV or Parquet file, one row per configuration the device was driven to:
the motor inputs, ``motor1_rad``, ``motor2_rad``, ``motor3_rad`` (or ``motor1_deg`` ... in degrees),
and what the fingertip's sensor read, ``fx_N``, ``fy_N``, ``fz_N`` and, if it reads torques, ``tx_Nm``,
``ty_Nm``, ``tz_Nm``. The device-mounted sensor's readings, for personalisation A, may follow as
``ds_fx_N`` ... ``ds_tz_Nm`` (all six). A softtip dataset (``softtip import``'s, checksummed) is a table
file too: its labels of those names are the columns (each in the unit its name ends in), read and
verified as every dataset is. Values may be quantised (a servo's whole degrees, a sensor's
steps): a quantised sensor reads several configurations alike, so entries whose forces are equal are
merged into one, their motor inputs (and the rest of their readings) averaged; how many were merged
is reported. A missing column, a value that is not a finite number, or motor inputs beyond the
device's servos are refused in one line naming the file and the column.

**For firmware**, :func:`c_header` writes the renderer's own arrays (the table as
:class:`~.rendering.NearestNeighbourRenderer` indexed it: the entries without contact merged into one
at zero force) as C ``const`` arrays of ``float`` with their sizes and settings as macros, and
:func:`write_table_csv` the same entries as a table file this module reads back. :func:`write_fs_table_csv`
writes an FS table as collected (the FS's and the DS's readings with the motor inputs, every
configuration) for a haptics protocol's ``fs_table``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from softtip._core.files import atomic_write
from softtip.data import is_dataset_file
from softtip.systems.haptics.device import DeviceSpec
from softtip.systems.haptics.limits import MAX_FS_LEVELS, MAX_TABLE_ENTRIES
from softtip.systems.haptics.live import table_columns
from softtip.systems.haptics.rendering import NearestNeighbourRenderer, TableError

FORCES = ("fx_N", "fy_N", "fz_N")
TORQUES = ("tx_Nm", "ty_Nm", "tz_Nm")
MOTORS_RAD = ("motor1_rad", "motor2_rad", "motor3_rad")
MOTORS_DEG = ("motor1_deg", "motor2_deg", "motor3_deg")
DS = tuple(f"ds_{name}" for name in FORCES + TORQUES)


# how a softtip dataset (softtip import's) holds a table: its labels, named as a table file's columns
DATASET_FIX = ("; a softtip dataset holds them as labels of these names: softtip import ... --label fx_N=COLUMN:N "
               "--label motor1_deg=COLUMN:deg ... (its chips' channels are not read as forces)")


class TableFileError(ValueError):
    """A table file that cannot be read as a lookup table."""


@dataclass(frozen=True)
class RecordedTable:
    """A table read from the file ``source``: the sensor's wrenches (entries, 3 or 6: N, N·m), the motor inputs
    (entries, 3, rad), the DS's wrenches (entries, 6) if the file has them, and how many of the file's
    rows were merged into others (equal forces)."""

    source: str
    wrenches: np.ndarray
    motor_inputs: np.ndarray
    platform_wrenches: np.ndarray | None
    merged: int

    def renderer(self, **settings) -> NearestNeighbourRenderer:
        """The renderer on this table (``settings``: the renderer's); a table it cannot index (fewer
        distinct entries than neighbours ...) is refused naming the file."""
        try:
            return NearestNeighbourRenderer(**settings).fit(self.wrenches, self.motor_inputs)
        except TableError as problem:
            raise TableFileError(f"table file {self.source}: {problem}") from None


def _numbers(columns: dict, names: tuple[str, ...], path: Path) -> np.ndarray:
    values = []
    for name in names:
        try:
            column = np.asarray(columns[name], dtype=float)
        except (TypeError, ValueError):
            raise TableFileError(f"table file {path}: column {name}: expected numbers") from None
        bad = ~np.isfinite(column)
        if bad.any():
            raise TableFileError(f"table file {path}: column {name}, row {int(np.flatnonzero(bad)[0])}: expected a "
                                 "finite number")
        values.append(column)
    return np.column_stack(values)


def _merge_equal_forces(wrenches: np.ndarray, motor: np.ndarray,
                        platform: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The entries with one row per distinct force, each the mean of the rows that read it (in the
    order each force first appears)."""
    _, first, group = np.unique(wrenches[:, :3], axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)  # groups in the order they first appear
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    group = rank[group.ravel()]
    counts = np.bincount(group)[:, None]

    def mean(values: np.ndarray) -> np.ndarray:
        summed = np.zeros((len(counts), values.shape[1]))
        np.add.at(summed, group, values)
        return summed / counts

    return mean(wrenches), mean(motor), None if platform is None else mean(platform)


def read_table(path: str | Path, device: DeviceSpec | None = None) -> RecordedTable:
    """A recorded lookup table from a CSV or Parquet file (see the module's notes); with a ``device``,
    motor inputs beyond its servos' range are refused."""
    path = Path(path)
    columns = table_columns(path, "table file", TableFileError)
    missing = [name for name in FORCES if name not in columns]
    if missing:
        raise TableFileError(f"table file {path}: missing column {missing[0]} (expected {', '.join(FORCES)}, "
                             f"optionally {', '.join(TORQUES)})" + (DATASET_FIX if is_dataset_file(path) else ""))
    torques = [name in columns for name in TORQUES]
    if any(torques) and not all(torques):
        raise TableFileError(f"table file {path}: missing column {TORQUES[torques.index(False)]} (torques: all "
                             f"three of {', '.join(TORQUES)}, or none)")
    units = [all(name in columns for name in names) for names in (MOTORS_RAD, MOTORS_DEG)]
    if units[0] == units[1]:
        raise TableFileError(f"table file {path}: expected the motor inputs as {', '.join(MOTORS_RAD)} or as "
                             f"{', '.join(MOTORS_DEG)}" + (" (not both)" if units[0] else "")
                             + (DATASET_FIX if is_dataset_file(path) and not units[0] else ""))
    ds = [name in columns for name in DS]
    if any(ds) and not all(ds):
        raise TableFileError(f"table file {path}: missing column {DS[ds.index(False)]} (the DS's readings: all six "
                             f"of {', '.join(DS)}, or none)")
    rows = len(next(iter(columns.values())))
    if not 2 <= rows <= MAX_TABLE_ENTRIES:
        raise TableFileError(f"table file {path}: {rows} rows, expected 2 to {MAX_TABLE_ENTRIES} entries (the largest "
                             f"FS table, --fs-levels {MAX_FS_LEVELS})")
    wrenches = _numbers(columns, FORCES + (TORQUES if all(torques) else ()), path)
    motor = _numbers(columns, MOTORS_RAD if units[0] else MOTORS_DEG, path)
    if device is not None:
        limit = device.angle_max if units[0] else device.servo.angle_max_deg
        beyond = (motor < 0) | (motor > limit * (1 + 1e-12))
        if beyond.any():
            row, servo = map(int, np.argwhere(beyond)[0])
            name = (MOTORS_RAD if units[0] else MOTORS_DEG)[servo]
            raise TableFileError(f"table file {path}: column {name}, row {row}: {motor[row, servo]:g} is beyond the "
                                 f"device's servo range, 0 to {limit:g}")
    motor = motor if units[0] else np.radians(motor)
    platform = _numbers(columns, DS, path) if all(ds) else None
    merged_wrenches, merged_motor, merged_platform = _merge_equal_forces(wrenches, motor, platform)
    return RecordedTable(str(path), merged_wrenches, merged_motor, merged_platform, rows - len(merged_motor))


def _write_csv(path: str | Path, names: tuple[str, ...], rows: np.ndarray) -> None:
    """``rows`` under the header ``names``, every value at full precision (it reads back exactly)."""
    atomic_write(path, ",".join(names) + "\n" + "\n".join(",".join(repr(float(v)) for v in row) for row in rows) + "\n")


def write_table_csv(path: str | Path, renderer: NearestNeighbourRenderer) -> None:
    """The renderer's entries as a table file (forces and motor inputs in rad, full precision)."""
    if renderer.torque_length is not None:
        raise ValueError("renderer: a table for firmware searches forces only (no torque length)")
    _write_csv(path, FORCES + MOTORS_RAD, np.hstack([renderer.features_, renderer.motor_inputs_]))


def write_fs_table_csv(path: str | Path, wrenches, platform_wrenches, motor_inputs) -> None:
    """An FS table as collected, one row per configuration, as a haptics protocol's ``fs_table`` reads
    it: the FS's ``wrenches`` (entries, 6, or 3 forces), the DS's (entries, 6) and the motor inputs
    (entries, 3, rad), at full precision."""
    wrenches = np.asarray(wrenches, dtype=float)
    names = FORCES + (TORQUES if wrenches.shape[1] == 6 else ()) + DS + MOTORS_RAD
    _write_csv(path, names, np.hstack([wrenches, np.asarray(platform_wrenches, dtype=float),
                                       np.asarray(motor_inputs, dtype=float)]))


def _c_float(value: float) -> str:
    """A C float literal that reads back as the float32 nearest to ``value``."""
    text = f"{float(np.float32(value)):.9g}"
    return text + ("f" if any(mark in text for mark in ".en") else ".0f")


def _c_array(name: str, values: np.ndarray) -> str:
    rows = ",\n".join("    {" + ", ".join(map(_c_float, row)) + "}" for row in values)
    return f"static const float {name}[{len(values)}][{values.shape[1]}] = {{\n{rows}\n}};\n"


def c_header(renderer: NearestNeighbourRenderer, guard: str, provenance: str) -> str:
    """The renderer's table as a C header: its entries' forces (N) and motor inputs (degrees) as
    ``float`` arrays, its sizes, neighbours, weighting and out-of-range bounds as macros; ``guard``
    names the include guard, ``provenance`` (one line) says what made it."""
    if renderer.torque_length is not None:
        raise ValueError("renderer: a table for firmware searches forces only (no torque length)")
    if not guard.isidentifier() or not provenance.isprintable() or "*/" in provenance:
        raise ValueError(f"guard = {guard!r}, provenance: expected a C identifier and one line of text")
    entries = len(renderer.features_)
    low, high = renderer.lowest_.tolist(), renderer.highest_.tolist()
    return "\n".join([
        f"/* softtip haptic rendering table: {provenance}",
        " * Render a wanted force f (N): the SOFTTIP_TABLE_NEIGHBOURS entries of softtip_table_force_N nearest",
        " * to f (Euclidean), their softtip_table_motor_deg averaged with weights 1/d^SOFTTIP_TABLE_WEIGHTING_POWER",
        " * (an exact match: that entry). f beyond [lowest, highest] per component, or farther than",
        " * SOFTTIP_TABLE_WIDEST_GAP_N from its nearest entry, lies outside the table. */",
        f"#ifndef {guard}", f"#define {guard}", "",
        f"#define SOFTTIP_TABLE_ENTRIES {entries}",
        f"#define SOFTTIP_TABLE_NEIGHBOURS {renderer.n_neighbours}",
        f"#define SOFTTIP_TABLE_WEIGHTING_POWER {_c_float(renderer.weighting_power)}",
        f"#define SOFTTIP_TABLE_WIDEST_GAP_N {_c_float(renderer.widest_gap_)}", "",
        f"static const float softtip_table_lowest_N[3] = {{{', '.join(map(_c_float, low))}}};",
        f"static const float softtip_table_highest_N[3] = {{{', '.join(map(_c_float, high))}}};",
        _c_array("softtip_table_force_N", renderer.features_),
        _c_array("softtip_table_motor_deg", np.degrees(renderer.motor_inputs_)),
        f"#endif /* {guard} */", ""])
