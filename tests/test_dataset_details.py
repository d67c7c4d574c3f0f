"""Every refusal of the dataset module, word for word: a one-line message names the parameter, column or
trial at fault and what was expected (the reference: the message as the module's notes state it,
written out by hand); and the baseline subtraction, the access helpers and the metadata of joined
datasets against hand-computed values."""

from __future__ import annotations

import json
import time
import types
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from softtip import __version__
from softtip.data import Dataset, DatasetError, DatasetMetadata, TrialWriter, concat
from softtip.data.dataset import (
    UnverifiedDatasetWarning,
    column_to_numpy,
    first_line,
    require_columns,
    subtract_trial_baseline,
)


def small() -> Dataset:
    return Dataset({"trial": [3, 3, 8], "time_s": [0.0, 0.1, 0.0], "s0_bz_uT": [1.0, 2.0, 3.0],
                    "s0_bx_uT": [4.0, 5.0, 6.0], "fz_N": [0.1, 0.2, 0.3], "state": ["a", "b", "c"],
                    "phi_deg": [10, 10, 20]},
                   labels={"fz_N": "N", "state": "1"}, conditions={"phi_deg": "deg"})


def bare() -> Dataset:
    return Dataset({"trial": [0], "time_s": [0.0], "s0_bz_uT": [1.0]})


CASES = {
    "baseline of zero samples": (lambda: subtract_trial_baseline(np.zeros((2, 1)), np.zeros(2, int), 0),
                                 "baseline: expected a number of samples >= 1, got 0"),
    "baseline of True samples": (lambda: subtract_trial_baseline(np.zeros((2, 1)), np.zeros(2, int), True),
                                 "baseline: expected a number of samples >= 1, got True"),
    "baseline of 2.5 samples": (lambda: subtract_trial_baseline(np.zeros((5, 1)), np.zeros(5, int), 2.5),
                                "baseline: expected a number of samples >= 1, got 2.5"),
    "baseline longer than a trial": (lambda: subtract_trial_baseline(np.zeros((5, 1)), np.array([0, 0, 0, 7, 7]), 3),
                                     "trial 7 has 2 samples, fewer than the 3 of its baseline"),
    "no such column": (lambda: small().column("nope"),
                       "no column 'nope' (columns: trial, time_s, s0_bx_uT, s0_bz_uT, fz_N, state, phi_deg)"),
    "X of no channels": (lambda: small().X([]), "X: no channels asked for"),
    "X of a label": (lambda: small().X(["fz_N"]),
                     "X: 'fz_N' is not a channel of this dataset (channels: s0_bx_uT, s0_bz_uT)"),
    "y of nothing": (lambda: small().y([]), "y: no labels asked for"),
    "y of text among numbers": (lambda: small().y(["fz_N", "state"]), "y: state holds <U1 values; ask for it alone"),
    "y of an unknown name": (lambda: small().y("nope"),
                             "y: 'nope' is not a label or condition (labels: fz_N, state; conditions: phi_deg)"),
    "y of a channel": (lambda: bare().y(["s0_bz_uT"]),
                       "y: 's0_bz_uT' is not a label or condition (labels: none; conditions: none)"),
    "y of an unknown name among two conditions": (lambda: Dataset(
        {"trial": [0], "time_s": [0.0], "s0_bz_uT": [1.0], "a": [1.0], "b": [2.0]}, conditions={"a": "1", "b": "1"}
    ).y("nope"), "y: 'nope' is not a label or condition (labels: none; conditions: a, b)"),
    "a condition not an identifier": (lambda: Dataset({"trial": [0], "time_s": [0.0], "s0_bz_uT": [1.0]},
                                                      conditions={"f z": "1"}),
                                      "conditions: 'f z' is not a valid column name (letters, digits, underscores)"),
    "columns of three lengths": (lambda: Dataset({"trial": [0, 0], "time_s": [0.0, 1.0], "s0_bz_uT": [1.0, 2.0],
                                                  "a": [1.0, 2.0, 3.0], "z": [1.0]}, labels={"a": "1", "z": "1"}),
                                 "columns differ in length: a has 3 rows, z has 1"),
    "a 2-D label": (lambda: Dataset({"trial": [0], "time_s": [0.0], "s0_bz_uT": [1.0], "f": [[1.0]]},
                                    labels={"f": "N"}),
                    "column f: expected a 1-D array, got shape (1, 1)"),
    "a softtip version of no text": (lambda: DatasetMetadata(softtip_version=3),
                                     "metadata softtip_version = 3: expected a non-empty string"),
    "a trial split, not the first": (lambda: Dataset({"trial": [0, 5, 6, 5], "time_s": [0.0, 0.0, 0.0, 1.0],
                                                     "s0_bz_uT": np.zeros(4)}),
                                     "the rows of trial 5 are not contiguous"),
    "a 2-D trial column": (lambda: Dataset({"trial": [[0]], "time_s": [0.0], "s0_bz_uT": [1.0]}),
                           "column trial: expected a 1-D array, got shape (1, 1)"),
    "select of both": (lambda: small().select([0], trials=[3]), "select: give either rows or trials"),
    "select of neither": (lambda: small().select(), "select: give either rows or trials"),
    "select of a short mask": (lambda: small().select(np.array([True, False])),
                               "select: a row mask needs 3 entries, got shape (2,)"),
    "select past the end": (lambda: small().select(np.array([0, 3])),
                            "select: row indices must be in [0, 3), got 0..3"),
    "select before the start": (lambda: small().select(np.array([-1, 2])),
                                "select: row indices must be in [0, 3), got -1..2"),
    "select by floats": (lambda: small().select(np.array([0.0])),
                         "select: rows must be a boolean mask or 1-D integer indices, got float64"),
    "select by 2-D indices": (lambda: small().select(np.array([[0]])),
                              "select: rows must be a boolean mask or 1-D integer indices, got int64"),
    "a 2-D column": (lambda: Dataset({"trial": [0], "time_s": [[0.0]], "s0_bz_uT": [1.0]}),
                     "column time_s: expected a 1-D array, got shape (1, 1)"),
    "text trial ids": (lambda: Dataset({"trial": ["a"], "time_s": [0.0], "s0_bz_uT": [1.0]}),
                       "column trial: expected integer trial ids, got <U1"),
    "text channel": (lambda: Dataset({"trial": [0], "time_s": [0.0], "s0_bz_uT": ["x"]}),
                     "column s0_bz_uT: expected numbers, got <U1"),
    "complex label": (lambda: Dataset({"trial": [0], "time_s": [0.0], "s0_bz_uT": [1.0], "z": [1j]},
                                      labels={"z": "1"}),
                      "column z: dtype complex128 cannot be stored (expected bool, integer, float32, float64 or string)"),
    "float16 label": (lambda: Dataset({"trial": [0], "time_s": [0.0], "s0_bz_uT": [1.0],
                                       "z": np.zeros(1, np.float16)}, labels={"z": "1"}),
                      "column z: dtype float16 cannot be stored (expected bool, integer, float32, float64 or string)"),
    "labels not a mapping": (lambda: Dataset({"trial": [0], "time_s": [0.0], "s0_bz_uT": [1.0]}, labels=["z"]),
                             "labels: expected a mapping of name to unit, got list"),
    "a label not an identifier": (lambda: TrialWriter(1, {"f z": "N"}),
                                  "labels: 'f z' is not a valid column name (letters, digits, underscores)"),
    "a condition named time_s": (lambda: TrialWriter(1, None, {"time_s": "s"}),
                                 "conditions: 'time_s' is reserved for the trial id, the time or a channel"),
    "a label named as a channel": (lambda: TrialWriter(1, {"s0_bx_uT": "uT"}),
                                   "labels: 's0_bx_uT' is reserved for the trial id, the time or a channel"),
    "a unit of spaces": (lambda: TrialWriter(1, None, {"phi": "  "}),
                         'conditions: phi has no unit (give a unit string; "1" if dimensionless)'),
    "a magnetic channel in mT": (lambda: TrialWriter({"s0_bx_uT": "mT"}),
                                 "channels: s0_bx_uT [mT] is a magnetic channel, in uT"),
    "design not a dict": (lambda: DatasetMetadata(design=[1]),
                          "metadata design: expected a JSON object (a dict), got list"),
    "protocol with NaN": (lambda: DatasetMetadata(protocol={"gain": float("nan")}),
                          "metadata protocol: not representable as JSON (Out of range float values are not JSON "
                          "compliant)"),
    "creation time not ISO": (lambda: DatasetMetadata(created_utc="yesterday"),
                              "metadata created_utc: expected an ISO 8601 time, got 'yesterday'"),
    "a channel also a label": (lambda: Dataset({"trial": [0], "time_s": [0.0], "f": [1.0]}, labels={"f": "N"},
                                               channel_units={"f": "N"}),
                               "f is declared both as a channel and as a label or condition"),
    "metadata not DatasetMetadata": (lambda: Dataset({"trial": [0], "time_s": [0.0], "s0_bz_uT": [1.0]},
                                                     metadata={"description": "x"}),
                                     "metadata: expected a DatasetMetadata, got dict"),
    "no trial column": (lambda: Dataset({"time_s": [0.0], "s0_bz_uT": [1.0]}), "missing column trial"),
    "no time column": (lambda: Dataset({"trial": [0], "s0_bz_uT": [1.0]}), "missing column time_s"),
    "no channel": (lambda: Dataset({"trial": [0], "time_s": [0.0]}),
                   "no channel columns (expected names like s0_bx_uT, or channels declared with units)"),
    "an undeclared column": (lambda: Dataset({"trial": [0], "time_s": [0.0], "s0_bz_uT": [1.0], "f": [1.0]}),
                             "column 'f' is neither a channel (s<k>_b<x|y|z>_uT, or declared with its unit) nor a "
                             "declared label or condition"),
    "a declared label missing": (lambda: Dataset({"trial": [0], "time_s": [0.0], "s0_bz_uT": [1.0]},
                                                 labels={"f": "N"}),
                                 "missing column f (declared as a label)"),
    "a declared channel missing": (lambda: Dataset({"trial": [0], "time_s": [0.0], "s0_bz_uT": [1.0]},
                                                   channel_units={"f": "N"}),
                                   "missing column f (declared as a channel)"),
    "a declared condition missing": (lambda: Dataset({"trial": [0], "time_s": [0.0], "s0_bz_uT": [1.0]},
                                                     conditions={"f": "N"}),
                                     "missing column f (declared as a condition)"),
    "a NaN channel": (lambda: Dataset({"trial": [0, 0], "time_s": [0.0, 1.0], "s0_bz_uT": [1.0, np.nan]}),
                      "column s0_bz_uT: row 1 is not finite"),
    "columns of two lengths": (lambda: Dataset({"trial": [0, 0], "time_s": [0.0, 1.0], "s0_bz_uT": [1.0]}),
                               "columns differ in length: trial has 2 rows, s0_bz_uT has 1"),
    "time standing still": (lambda: Dataset({"trial": [5, 5, 5], "time_s": [0.0, 1.0, 1.0], "s0_bz_uT": np.zeros(3)}),
                            "column time_s: time does not increase within trial 5 at row 2"),
    "an infinite time": (lambda: Dataset({"trial": [5, 5], "time_s": [0.0, np.inf], "s0_bz_uT": np.zeros(2)}),
                         "column time_s: row 1 is not finite"),
    "a condition that changes": (lambda: Dataset({"trial": [1, 1, 2, 2], "time_s": [0.0, 1.0, 0.0, 1.0],
                                                  "s0_bz_uT": np.zeros(4), "c": [1.0, 1.0, np.nan, 2.0]},
                                                 conditions={"c": "1"}),
                                 "condition c changes within trial 2: conditions are constant over a trial"),
    "text in a unit": (lambda: Dataset({"trial": [0], "time_s": [0.0], "s0_bz_uT": [1.0], "c": ["x"]},
                                       conditions={"c": "mm"}),
                       'column c holds text but is declared in mm: text columns are categories, declared with unit "1"'),
    "concat of nothing": (lambda: concat([]), "concat: no datasets given"),
    "concat of other conditions": (lambda: concat(
        [small(), Dataset({"trial": [9], "time_s": [0.0], "s0_bz_uT": [1.0], "s0_bx_uT": [1.0], "fz_N": [0.1],
                           "state": ["a"], "phi_deg": [1.0]}, {"fz_N": "N", "state": "1"}, {"phi_deg": "mm"})]),
        "concat: dataset 1 has conditions {'phi_deg': 'mm'}, dataset 0 has {'phi_deg': 'deg'}"),
    "concat of other channels": (lambda: concat([bare(), Dataset({"trial": [9], "time_s": [0.0], "s0_bx_uT": [1.0]})]),
                                 "concat: dataset 1 has channels {'s0_bx_uT': 'uT'}, dataset 0 has {'s0_bz_uT': 'uT'}"),
    "concat of another design": (lambda: concat([bare(), Dataset({"trial": [9], "time_s": [0.0], "s0_bz_uT": [1.0]},
                                                                 metadata=DatasetMetadata(design={"name": "B"}))]),
                                 "concat: dataset 1 has a different design from dataset 0"),
    "concat of other sensor settings": (lambda: concat([bare(), Dataset(
        {"trial": [9], "time_s": [0.0], "s0_bz_uT": [1.0]}, metadata=DatasetMetadata(sensor_settings={"gain": 1}))]),
        "concat: dataset 1 has a different sensor settings from dataset 0"),
    "concat of text and numbers": (lambda: concat([
        Dataset({"trial": [0], "time_s": [0.0], "s0_bz_uT": [1.0], "c": [1.0]}, conditions={"c": "1"}),
        Dataset({"trial": [1], "time_s": [0.0], "s0_bz_uT": [1.0], "c": ["x"]}, conditions={"c": "1"})]),
        "concat: column c holds string values in dataset 1 and numeric values in dataset 0"),
    "concat of booleans and numbers": (lambda: concat([
        Dataset({"trial": [0], "time_s": [0.0], "s0_bz_uT": [1.0], "c": [1]}, conditions={"c": "1"}),
        Dataset({"trial": [1], "time_s": [0.0], "s0_bz_uT": [1.0], "c": [True]}, conditions={"c": "1"})]),
        "concat: column c holds boolean values in dataset 1 and numeric values in dataset 0"),
    "concat of one trial twice": (lambda: concat([bare(), bare()]),
                                  "concat: trial 0 occurs in more than one dataset (pass renumber_trials=True to number "
                                  "the trials afresh)"),
    "concat of a trial twice, not the first": (lambda: concat([
        Dataset({"trial": [1, 4], "time_s": [0.0, 0.0], "s0_bz_uT": [1.0, 1.0]}),
        Dataset({"trial": [4], "time_s": [0.0], "s0_bz_uT": [1.0]})]),
        "concat: trial 4 occurs in more than one dataset (pass renumber_trials=True to number the trials afresh)"),
    "a writer of no channels": (lambda: TrialWriter([]), "channels: expected distinct channel names, at least one"),
    "a writer of one channel twice": (lambda: TrialWriter(["s0_bx_uT", "s0_bx_uT"]),
                                      "channels: expected distinct channel names, at least one"),
    "a writer of a channel not a name": (lambda: TrialWriter([3]),
                                         "channels: 3 is not a channel name (s<k>_b<x|y|z>_uT)"),
    "a trial id of True": (lambda: TrialWriter(1).add({}, trial=True), "trial: expected an integer id, got True"),
    "a trial id of 1.0": (lambda: TrialWriter(1).add({}, trial=1.0), "trial: expected an integer id, got 1.0"),
    "a trial of no samples": (lambda: TrialWriter(1).add({"time_s": [], "s0_bx_uT": [], "s0_by_uT": [],
                                                          "s0_bz_uT": []}),
                              "trial 0: no samples"),
    "a trial lacking two columns": (lambda: TrialWriter(1).add({"time_s": [0.0], "s0_bx_uT": [0.0]}),
                                    "trial 0: samples lack s0_by_uT, s0_bz_uT"),
    "a trial holding two more": (lambda: TrialWriter(1).add({"time_s": [0.0], "s0_bx_uT": [0.0], "s0_by_uT": [0.0],
                                                             "s0_bz_uT": [0.0], "b": [0.0], "a": [0.0]}),
                                 "trial 0: samples hold undeclared a, b"),
    "a trial holding a number as a name": (lambda: TrialWriter(1).add({"time_s": [0.0], "s0_bx_uT": [0.0],
                                                                        "s0_by_uT": [0.0], "s0_bz_uT": [0.0],
                                                                        "b": [0.0], 3: [0.0]}),
                                           "trial 0: samples hold undeclared 3, b"),
    "a trial's condition of two values": (lambda: TrialWriter(1, None, {"c": "1"}).add(
        {"time_s": [0.0], "s0_bx_uT": [0.0], "s0_by_uT": [0.0], "s0_bz_uT": [0.0]}, {"c": [1, 2]}, trial=4),
        "trial 4: condition c must be one value, got shape (2,)"),
    "a trial of a NaN time": (lambda: TrialWriter(1).add({"time_s": [np.nan], "s0_bx_uT": [0.0], "s0_by_uT": [0.0],
                                                          "s0_bz_uT": [0.0]}, trial=2),
                              "trial 2: column time_s: row 0 is not finite"),
    "a writer of no trials": (lambda: TrialWriter(1).to_dataset(), "no trials were added"),
    "a column missing from a file": (lambda: require_columns("run.csv", ["a"], ["b", "c"]),
                                     "run.csv: no column 'a' (columns: b, c)"),
    "a column twice in a file": (lambda: require_columns("run.csv", ["b"], ["b", "c", "b"]),
                                 "run.csv: column 'b' appears more than once"),
}


@pytest.mark.parametrize("case", CASES)
def test_each_refusal_is_one_line_word_for_word(case):
    call, message = CASES[case]
    with pytest.raises(DatasetError) as refusal:
        call()
    assert str(refusal.value) == message


def test_the_trial_baseline_is_the_mean_of_each_trials_first_rows():
    values = np.array([[1.0, 10.0], [3.0, 20.0], [5.0, 60.0], [2.0, 4.0], [4.0, 8.0]])
    trial = np.array([0, 0, 0, 1, 1])
    # by hand: trial 0's first two rows average (2, 15), trial 1's (3, 6)
    np.testing.assert_array_equal(subtract_trial_baseline(values, trial, 2),
                                  [[-1.0, -5.0], [1.0, 5.0], [3.0, 45.0], [-1.0, -2.0], [1.0, 2.0]])
    # one sample: each trial's first row
    np.testing.assert_array_equal(subtract_trial_baseline(values, trial, 1),
                                  [[0.0, 0.0], [2.0, 10.0], [4.0, 50.0], [0.0, 0.0], [2.0, 4.0]])
    np.testing.assert_array_equal(subtract_trial_baseline(values, trial, np.int64(1)),
                                  subtract_trial_baseline(values, trial, 1))


def test_a_column_given_exactly_once_is_found():
    require_columns("run.csv", ["b", "c"], ["c", "b"])  # no refusal


def test_repr_counts_samples_and_trials_and_names_the_columns():
    assert repr(small()) == ("Dataset(3 samples, 2 trials, channels ['s0_bx_uT', 's0_bz_uT'], labels {'fz_N': 'N', "
                             "'state': '1'}, conditions {'phi_deg': 'deg'})")


def test_joined_datasets_keep_the_metadata_they_share_and_list_what_differs():
    design, settings = {"name": "B", "p": [1, 2]}, {"gain_sel": 7}

    def part(trial: int, protocol: dict, seed: int, description: str) -> Dataset:
        return Dataset({"trial": [trial], "time_s": [0.0], "s0_bz_uT": [1.0]}, metadata=DatasetMetadata(
            description=description, design=design, sensor_settings=settings, protocol=protocol, seed=seed,
            softtip_version="0.9", created_utc="2025-01-02T03:04:05Z"))

    same = concat([part(0, {"grasp_mm": 4}, 11, "a"), part(1, {"grasp_mm": 4}, 11, "a")]).metadata
    assert same == DatasetMetadata(description="a", design=design, sensor_settings=settings,
                                   protocol={"grasp_mm": 4}, seed=11, softtip_version="0.9",
                                   created_utc="2025-01-02T03:04:05Z")
    other = concat([part(0, {"grasp_mm": 4}, 11, "a"), part(1, {"grasp_mm": 5}, 12, "b")]).metadata
    assert (other.description, other.design, other.sensor_settings, other.protocol, other.seed) == (
        "a; b", design, settings, {"concatenated": [{"grasp_mm": 4}, {"grasp_mm": 5}]}, None)
    assert (other.softtip_version, other.created_utc) == ("0.9", "2025-01-02T03:04:05Z")  # the same in both
    later = part(1, {"grasp_mm": 4}, 11, "a")
    object.__setattr__(later.metadata, "created_utc", "2025-06-07T08:09:10Z")
    joined = concat([part(0, {"grasp_mm": 4}, 11, "a"), later]).metadata
    # two creation times: the joined dataset is made now, by this softtip
    assert joined.softtip_version == __version__ and joined.created_utc not in (
        "2025-01-02T03:04:05Z", "2025-06-07T08:09:10Z")


def written(tmp_path: Path) -> Path:
    return small().write(tmp_path / "trials.parquet")


def with_document(path: Path, edit) -> Path:
    """``path`` rewritten by pyarrow with its metadata document edited by ``edit`` (a dict -> dict or bytes)."""
    document = edit(json.loads(pq.read_schema(path).metadata[b"softtip"]))
    raw = document if isinstance(document, bytes) else json.dumps(document).encode()
    pq.write_table(pq.read_table(path).replace_schema_metadata({b"softtip": raw}), path)
    return path


def with_table(path: Path, edit) -> Path:
    table = pq.read_table(path)
    pq.write_table(edit(table).replace_schema_metadata(table.schema.metadata), path)
    return path


FILE_CASES = {
    "metadata not JSON": (lambda d: b"{not json", "the softtip metadata is not valid JSON"),
    "metadata a list": (lambda d: [1], "not a softtip dataset (format None, expected 'softtip-dataset')"),
    "another format": (lambda d: d | {"format": "other"},
                       "not a softtip dataset (format 'other', expected 'softtip-dataset')"),
    "another version": (lambda d: d | {"schema_version": 2},
                        "schema version 2 is not supported (this softtip reads version 1)"),
    "no seed field": (lambda d: {k: v for k, v in d.items() if k != "seed"}, "metadata field 'seed' is missing"),
    "a field more": (lambda d: d | {"colour": "red"}, "unknown metadata field 'colour'"),
    "channels not a list": (lambda d: d | {"channels": {"s0_bz_uT": "uT"}},
                            "metadata channels: expected a list of {name, unit} objects"),
    "a label with a key more": (lambda d: d | {"labels": [{"name": "fz_N", "unit": "N", "scale": 1}]},
                                "metadata labels: expected a list of {name, unit} objects"),
    "a condition named by a number": (lambda d: d | {"conditions": [{"name": 3, "unit": "deg"}]},
                                      "metadata conditions: expected a list of {name, unit} objects"),
    "a magnetic channel in mT": (lambda d: d | {"channels": [{"name": "s0_bx_uT", "unit": "mT"},
                                                             {"name": "s0_bz_uT", "unit": "uT"}]},
                                 "metadata channels: s0_bx_uT [mT] is a magnetic channel, in uT"),
    "a checksum not text": (lambda d: d | {"sha256": 5}, "metadata sha256: expected a hex digest, got 5"),
    "a checksum too short": (lambda d: d | {"sha256": "abc"},
                             "checksum mismatch: the file was altered or damaged after it was written"),
    "a label declared with no column": (lambda d: d | {"labels": [*d["labels"], {"name": "fx_N", "unit": "N"}]},
                                        "missing column fx_N"),
}


@pytest.mark.parametrize("case", FILE_CASES)
def test_each_refusal_of_a_file_names_it_word_for_word(tmp_path, case):
    edit, message = FILE_CASES[case]
    path = with_document(written(tmp_path), edit)
    with pytest.raises(DatasetError) as refusal:
        Dataset.read(path)
    assert str(refusal.value) == f"{path}: {message}"


def test_a_files_columns_must_be_those_it_declares_once_each_without_gaps(tmp_path):
    path = with_table(written(tmp_path), lambda table: table.append_column("extra", pa.array([0.0, 0.0, 0.0])))
    with pytest.raises(DatasetError) as refusal:
        Dataset.read(path)
    assert str(refusal.value) == f"{path}: column 'extra' is not declared in the metadata"
    path = with_table(written(tmp_path), lambda table: table.append_column("fz_N", table.column("fz_N")))
    with pytest.raises(DatasetError) as refusal:
        Dataset.read(path)
    assert str(refusal.value) == f"{path}: duplicate column names"
    path = with_table(written(tmp_path), lambda table: table.set_column(0, "trial", pa.array([3, None, 8])))
    with pytest.raises(DatasetError) as refusal:
        Dataset.read(path)
    assert str(refusal.value) == f"{path}: column trial: missing value at row 1"
    path = with_table(written(tmp_path), lambda table: table.drop_columns(["s0_bx_uT"]))
    with pytest.raises(DatasetError) as refusal:
        Dataset.read(path)
    assert str(refusal.value) == f"{path}: missing column s0_bx_uT"
    with pytest.raises(DatasetError) as refusal:
        small().write(tmp_path / "missing" / "trials.parquet")
    assert str(refusal.value) == (f"dataset file {tmp_path / 'missing' / 'trials.parquet'}: directory "
                                  f"{tmp_path / 'missing'} does not exist")


def test_a_trial_writer_declares_its_channels_with_units_and_keeps_its_metadata():
    assert TrialWriter(1).channel_units == {"s0_bx_uT": "uT", "s0_by_uT": "uT", "s0_bz_uT": "uT"}
    assert TrialWriter(["s1_bz_uT"]).channel_units == {"s1_bz_uT": "uT"}
    assert TrialWriter({"side_fz_N": "N"}).channel_units == {"side_fz_N": "N"}
    metadata = DatasetMetadata(description="two presses", seed=4)
    writer = TrialWriter(1, metadata=metadata)
    writer.add({"time_s": [0.0], "s0_bx_uT": [0.0], "s0_by_uT": [0.0], "s0_bz_uT": [0.0]})
    assert writer.to_dataset().metadata == metadata
    assert TrialWriter(1).metadata.description == ""


def test_select_takes_one_trial_any_iterable_of_trials_and_indices_from_zero():
    dataset = small()
    np.testing.assert_array_equal(dataset.select(trials=8).column("s0_bz_uT"), [3.0])
    np.testing.assert_array_equal(dataset.select(trials=iter([3])).column("s0_bz_uT"), [1.0, 2.0])
    np.testing.assert_array_equal(dataset.select(np.array([0, 2])).column("s0_bz_uT"), [1.0, 3.0])
    assert len(dataset.select(np.array([], dtype=int))) == 0


def test_three_datasets_renumbered_count_their_trials_in_order():
    joined = concat([small(), small(), small().select(trials=[8])], renumber_trials=True)
    np.testing.assert_array_equal(joined.groups, [0, 0, 1, 2, 2, 3, 4])


def test_an_arrow_column_to_numpy_by_hand():
    np.testing.assert_array_equal(column_to_numpy("s", pa.array(["a", "b", "a"]).dictionary_encode()), ["a", "b", "a"])
    np.testing.assert_array_equal(column_to_numpy("f", pa.array([1.0, None])), [1.0, np.nan])  # NaN where missing
    with pytest.raises(DatasetError) as refusal:
        column_to_numpy("i", pa.array([1, None]))
    assert str(refusal.value) == "column i: missing value at row 1"
    with pytest.raises(DatasetError) as refusal:
        column_to_numpy("i", pa.chunked_array([[1, 2], [None]]), row_word="sample", first_row=10)
    assert str(refusal.value) == "column i: missing value at sample 12"


def test_first_line_of_an_error_or_its_type_when_it_says_nothing():
    assert first_line(ValueError("one\ntwo")) == "one"
    assert first_line(ValueError("  \n ")) == "ValueError"
    assert first_line(KeyError()) == "KeyError"


def test_text_columns_of_either_arrow_string_type_come_back_as_text():
    for column in (pa.array(["a", "bc"]), pa.array(["a", "bc"], pa.large_string())):
        values = column_to_numpy("s", column)
        assert values.dtype == np.dtype("<U2") and values.tolist() == ["a", "bc"]


def test_a_file_that_is_no_parquet_is_refused_in_pyarrows_first_line(tmp_path):
    path = tmp_path / "notes.parquet"
    path.write_text("trial,time_s\n0,0\n")
    with pytest.raises(pa.ArrowException) as arrow:  # the reference: pyarrow's own refusal
        pq.read_schema(path)
    with pytest.raises(DatasetError) as refusal:
        Dataset.read(path)
    assert str(refusal.value) == f"{path}: not a Parquet file ({str(arrow.value).splitlines()[0]})"


def test_a_file_without_a_checksum_warns_in_full(tmp_path):
    path = written(tmp_path)
    with_document(path, lambda d: {k: v for k, v in d.items() if k != "sha256"} | {"softtip_version": "0.1.0"})
    with pytest.warns(UnverifiedDatasetWarning) as warned:
        Dataset.read(path)
    assert str(warned[0].message) == (f"{path}: no checksum (written by softtip 0.1.0, before datasets carried one): "
                                      "its content cannot be verified; write it again to add one")


def test_a_nan_put_into_the_metadata_after_its_checks_is_not_written(tmp_path):
    dataset = Dataset({"trial": [0], "time_s": [0.0], "s0_bz_uT": [1.0]},
                      metadata=DatasetMetadata(design={"gain": 1.0}))
    dataset.metadata.design["gain"] = float("nan")  # the metadata's objects are plain dicts
    with pytest.raises(ValueError, match="Out of range float values are not JSON compliant"):
        dataset.write(tmp_path / "nan.parquet")
    assert not (tmp_path / "nan.parquet").exists()


def test_magnetic_channels_are_ordered_by_sensor_number_and_text_labels_stored_as_text():
    dataset = Dataset({"trial": [0], "time_s": [0.0], "s10_bx_uT": [1.0], "s2_bz_uT": [2.0], "s2_bx_uT": [3.0],
                       "state": np.array(["ab"], dtype=object)}, labels={"state": "1"})
    assert dataset.channels == ("s2_bx_uT", "s2_bz_uT", "s10_bx_uT")  # 2 before 10, as numbers
    assert dataset.column("state").dtype == np.dtype("<U2")
    empty = Dataset({"trial": np.zeros(0, int), "time_s": [], "s0_bz_uT": [], "state": np.array([], dtype=str)},
                    labels={"state": "1"})
    assert empty.column("state").dtype == np.dtype("<U1") and empty.column("trial").dtype == np.int64
    assert empty.trial_lengths.dtype == np.intp and len(empty.trial_lengths) == len(empty.trials) == 0
    assert type(DatasetMetadata(seed=np.int64(7)).seed) is int



def test_a_condition_that_is_nan_over_a_whole_trial_is_constant_and_declarations_are_plain_dicts():
    dataset = Dataset({"trial": [0, 0], "time_s": [0.0, 1.0], "s0_bz_uT": [1.0, 2.0], "c": [np.nan, np.nan],
                       "f": [1.0, 2.0]},
                      labels=types.MappingProxyType({"f": "N"}), conditions=types.MappingProxyType({"c": "1"}))
    assert np.isnan(dataset.trial_conditions["c"]).all()
    assert (type(dataset.labels), type(dataset.conditions)) == (dict, dict)
    assert (dataset.labels, dataset.conditions) == ({"f": "N"}, {"c": "1"})


def test_the_creation_time_is_utc_whatever_the_machines_zone(monkeypatch):
    monkeypatch.setenv("TZ", "Asia/Tokyo")  # nine hours from UTC, no summer time
    time.tzset()
    try:
        created = datetime.fromisoformat(DatasetMetadata().created_utc.replace("Z", "+00:00"))
    finally:
        monkeypatch.undo()
        time.tzset()
    assert abs((datetime.now(timezone.utc) - created).total_seconds()) < 60
