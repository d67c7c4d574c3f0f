"""The dataset format, the CSV loader and the trial-wise splits.

References: pyarrow reading the files directly, hand-computed unit conversions, counts and
baselines, and scikit-learn's GroupKFold for the folds.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.linear_model import Ridge
from sklearn.model_selection import GroupKFold, cross_val_score

from softtip import __version__
from softtip.data import (
    Dataset,
    DatasetError,
    DatasetMetadata,
    LeakageWarning,
    TrialKFold,
    TrialWriter,
    channel_columns,
    channel_names,
    concat,
    kfold_by_trial,
    leave_condition_out,
    read_csv_recording,
    split_by_sample,
    split_by_trial,
)

TRAINED_DEG = (0.0, 10.0, 20.0, 30.0)
UNTRAINED_DEG = (5.0, 15.0, 25.0)
LABELS = {"angle_deg": "deg", "fz_N": "N", "state": "1"}
CONDITIONS = {"board_angle_deg": "deg", "trained": "1", "position_x_mm": "mm"}
METADATA = DatasetMetadata(description="grasping test, two fingertips", design={"name": "cylindrical-A", "p": [9, 5.5]},
                           sensor_settings={"gain_sel": 7, "res_xyz": [0, 0, 0]}, protocol={"grasp_mm": 4}, seed=11)


def grasp_trial(rng: np.random.Generator, angle: float, n: int) -> dict[str, np.ndarray]:
    field = rng.normal(size=(n, 2, 3)) * 50 + angle
    return {"time_s": np.arange(n) / 20.0, **channel_columns(field), "angle_deg": np.full(n, angle),
            "fz_N": field[:, 0, 2].astype(np.float32) / 100, "state": np.where(np.arange(n) < n // 2, "air", "grip")}


@pytest.fixture(scope="module")
def grasps() -> Dataset:
    """The published grasping test: 10 trials per trained angle, 3 per untrained angle, in recording order."""
    rng = np.random.default_rng(0)
    writer = TrialWriter(2, LABELS, CONDITIONS, METADATA)
    for angle, count in [*((a, 10) for a in TRAINED_DEG), *((a, 3) for a in UNTRAINED_DEG)]:
        for repeat in range(count):
            writer.add(grasp_trial(rng, angle, 8 + repeat % 4),
                       {"board_angle_deg": angle, "trained": angle in TRAINED_DEG, "position_x_mm": repeat % 3 - 1})
    return writer.to_dataset()


# --------------------------------------------------------------------------
# Layout and access
# --------------------------------------------------------------------------


def test_channel_names_follow_sensor_then_axis():
    assert channel_names(2) == ("s0_bx_uT", "s0_by_uT", "s0_bz_uT", "s1_bx_uT", "s1_by_uT", "s1_bz_uT")
    field = np.arange(24.0).reshape(4, 2, 3)
    columns = channel_columns(field)
    assert list(columns) == list(channel_names(2))
    np.testing.assert_array_equal(columns["s1_bz_uT"], [5.0, 11.0, 17.0, 23.0])


def test_x_y_groups_and_trial_conditions(grasps):
    assert len(grasps.trials) == 4 * 10 + 3 * 3
    np.testing.assert_array_equal(grasps.trials, np.arange(49))
    assert grasps.channels == channel_names(2)
    X = grasps.X()
    assert X.shape == (len(grasps), 6) and X.dtype == np.float64
    np.testing.assert_array_equal(X[:, 5], grasps.column("s1_bz_uT"))
    np.testing.assert_array_equal(grasps.X(["s1_bx_uT", "s0_bx_uT"]), X[:, [3, 0]])
    both = grasps.y(["angle_deg", "fz_N"])
    assert both.shape == (len(grasps), 2) and both.dtype == np.float64
    assert grasps.y("state").dtype.kind == "U"
    np.testing.assert_array_equal(grasps.groups, grasps.column("trial"))
    table = grasps.trial_conditions
    assert set(table) == {"trial", *CONDITIONS}
    # trial 13 is the 4th of the 10° trials (position 3 % 3 - 1); trial 42 the 3rd of the 5° trials
    assert table["board_angle_deg"][13] == 10.0 and table["position_x_mm"][13] == -1 and table["trained"][13]
    assert table["board_angle_deg"][42] == 5.0 and not table["trained"][42]
    np.testing.assert_array_equal(grasps.trial_lengths[:5], [8, 9, 10, 11, 8])


def test_columns_are_read_only_copies():
    time = np.arange(3.0)
    dataset = Dataset({"trial": [0, 0, 0], "time_s": time, "s0_bz_uT": [1.0, 2.0, 3.0]})
    time[0] = 99.0
    assert dataset.column("time_s")[0] == 0.0
    with pytest.raises(ValueError):
        dataset.column("s0_bz_uT")[0] = 5.0


def test_select_by_trials_and_by_mask(grasps):
    chosen = grasps.select(trials=[3, 41])
    np.testing.assert_array_equal(chosen.trials, [3, 41])
    assert len(chosen) == grasps.trial_lengths[3] + grasps.trial_lengths[41]
    by_mask = grasps.select(np.isin(grasps.groups, [3, 41]))
    np.testing.assert_array_equal(by_mask.X(), chosen.X())
    with pytest.raises(DatasetError, match="no trial 99"):
        grasps.select(trials=[99])


# --------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------


def every_dtype() -> Dataset:
    n = 6
    return Dataset(
        {"trial": [4, 4, 4, 9, 9, 9], "time_s": [0.0, 0.05, 0.1, 0.0, 0.02, 0.5],
         "s1_bz_uT": np.linspace(-3, 3, n), "s0_bx_uT": np.arange(n), "s0_by_uT": np.ones(n), "s0_bz_uT": np.zeros(n),
         "s1_bx_uT": np.zeros(n), "s1_by_uT": np.zeros(n),
         "fz_N": np.array([0.1, np.nan, 0.3, 0.4, 0.5, 0.6]), "fx_N": np.arange(n, dtype=np.float32),
         "state": np.array(["air", "edge", "point A", "air", "air", "edge"]), "code": np.arange(n, dtype=np.int8),
         "count": np.arange(n, dtype=np.uint16),
         "trained": [True, True, True, False, False, False], "phi_deg": np.array([10, 10, 10, 20, 20, 20], np.int32),
         "surface": ["acrylic"] * 3 + ["pcb"] * 3},
        labels={"fz_N": "N", "fx_N": "N", "state": "1", "code": "1", "count": "1"},
        conditions={"trained": "1", "phi_deg": "deg", "surface": "1"}, metadata=METADATA)


def test_round_trip_preserves_every_column_dtype_and_the_metadata(tmp_path):
    original = every_dtype()
    path = original.write(tmp_path / "trials.parquet")
    back = Dataset.read(path)
    assert list(back.columns) == list(original.columns)
    for name, values in original.columns.items():
        assert back.columns[name].dtype == values.dtype, name
        np.testing.assert_array_equal(back.columns[name], values)  # NaN compares equal here
    assert back.labels == original.labels and back.conditions == original.conditions
    assert back.metadata == original.metadata
    # the channels are stored sensor by sensor whatever order they were given in
    assert back.channels == channel_names(2)


def test_file_read_by_pyarrow_alone(tmp_path):
    path = every_dtype().write(tmp_path / "trials.parquet")
    table = pq.read_table(path)
    assert table.column_names[:3] == ["trial", "time_s", "s0_bx_uT"]
    assert table.schema.field("trial").type == pa.int64() and table.schema.field("fx_N").type == pa.float32()
    assert table.schema.field("state").type == pa.string()
    np.testing.assert_array_equal(table.column("s1_bz_uT").to_numpy(), np.linspace(-3, 3, 6))
    document = json.loads(table.schema.metadata[b"softtip"])
    assert document["format"] == "softtip-dataset" and document["schema_version"] == 1
    assert document["channels"][0] == {"name": "s0_bx_uT", "unit": "uT"}
    assert {"name": "phi_deg", "unit": "deg"} in document["conditions"]
    assert document["design"] == {"name": "cylindrical-A", "p": [9, 5.5]}
    assert document["softtip_version"] == __version__ and document["seed"] == 11
    assert document["created_utc"].endswith("Z")


def rewrite(path, document=None, drop=None, add=None):
    """The file at ``path`` rewritten with another metadata document or one column dropped or added."""
    table = pq.read_table(path)
    meta = table.schema.metadata
    if drop:
        table = table.drop_columns([drop])
    if add:
        table = table.append_column(add, pa.array(np.zeros(table.num_rows)))
    if document is not None:
        meta = {b"softtip": json.dumps(document).encode()}
    pq.write_table(table.replace_schema_metadata(meta), path)


@pytest.mark.parametrize("damage, message", [
    ({"document": {}}, "format None, expected 'softtip-dataset'"),
    ({"document": "version 2"}, "schema version 2 is not supported .this softtip reads version 1."),
    ({"drop": "s1_by_uT"}, "missing column s1_by_uT"),
    ({"add": "extra"}, "column 'extra' is not declared"),
])
def test_damaged_files_are_refused_with_one_line(tmp_path, damage, message):
    path = every_dtype().write(tmp_path / "trials.parquet")
    if damage.get("document") == "version 2":
        document = json.loads(pq.read_schema(path).metadata[b"softtip"])
        damage = {"document": {**document, "schema_version": 2}}
    rewrite(path, **damage)
    with pytest.raises(DatasetError, match=message) as refusal:
        Dataset.read(path)
    assert str(path) in str(refusal.value) and "\n" not in str(refusal.value)


def test_foreign_and_unreadable_files_are_refused(tmp_path):
    foreign = tmp_path / "foreign.parquet"
    pq.write_table(pa.table({"x": [1.0, 2.0]}), foreign)
    with pytest.raises(DatasetError, match=r"foreign.parquet: not a softtip dataset \(no 'softtip' entry"):
        Dataset.read(foreign)
    text = tmp_path / "notes.parquet"
    text.write_text("trial,time_s\n0,0\n")
    with pytest.raises(DatasetError, match="notes.parquet: not a Parquet file"):
        Dataset.read(text)
    with pytest.raises(DatasetError, match="missing.parquet does not exist"):
        Dataset.read(tmp_path / "missing.parquet")
    bad_json = tmp_path / "bad.parquet"
    pq.write_table(pa.table({"x": [1.0]}).replace_schema_metadata({b"softtip": b"{not json"}), bad_json)
    with pytest.raises(DatasetError, match="bad.parquet: the softtip metadata is not valid JSON"):
        Dataset.read(bad_json)


# --------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------


def one_trial(**changes):
    samples = {"time_s": [0.0, 0.05, 0.1], **channel_columns(np.zeros((3, 1, 3))), "fz_N": [0.0, 0.1, 0.2]}
    return {**samples, **changes}


@pytest.mark.parametrize("samples, conditions, message", [
    (one_trial(fz_N=[0.0, 0.1]), {"phi_deg": 10}, "trial 0: columns differ in length"),
    (one_trial(time_s=[0.0, np.nan, 0.1]), {"phi_deg": 10}, "trial 0: column time_s: row 1 is not finite"),
    (one_trial(time_s=[0.0, 0.1, 0.1]), {"phi_deg": 10}, "trial 0: column time_s: time does not increase"),
    (one_trial(s0_bz_uT=[0.0, np.inf, 0.0]), {"phi_deg": 10}, "trial 0: column s0_bz_uT: row 1 is not finite"),
    ({k: v for k, v in one_trial().items() if k != "s0_by_uT"}, {"phi_deg": 10}, "trial 0: samples lack s0_by_uT"),
    (one_trial(s0_bw_uT=[1, 2, 3]), {"phi_deg": 10}, "trial 0: samples hold undeclared s0_bw_uT"),
    (one_trial(), {}, "trial 0: conditions lack phi_deg"),
    (one_trial(), {"phi_deg": [10, 20]}, "condition phi_deg must be one value"),
    (one_trial(fz_N=np.array(["a", 1, 2.0], dtype=object)), {"phi_deg": 10},
     "column fz_N: expected numbers, booleans or strings"),
    (one_trial(fz_N=["0", "0.1", "x"]), {"phi_deg": 10}, "column fz_N holds text but is declared in N"),
])
def test_trial_writer_refuses_bad_trials(samples, conditions, message):
    writer = TrialWriter(1, {"fz_N": "N"}, {"phi_deg": "deg"})
    with pytest.raises(DatasetError, match=message):
        writer.add(samples, conditions)
    assert writer.n_trials == 0


def test_trial_writer_declarations_and_ids():
    with pytest.raises(DatasetError, match="labels: fz_N has no unit"):
        TrialWriter(1, {"fz_N": ""})
    with pytest.raises(DatasetError, match="channels: 's0_bx_mT' is not a channel name"):
        TrialWriter(["s0_bx_mT"])
    writer = TrialWriter(1, {"fz_N": "N"})
    assert writer.add(one_trial(), trial=7) == 7
    assert writer.add(one_trial()) == 8
    with pytest.raises(DatasetError, match="trial 7 was already added"):
        writer.add(one_trial(), trial=7)
    with pytest.raises(DatasetError, match="no trials were added"):
        TrialWriter(1).to_dataset()


def test_dataset_refuses_broken_trial_structure():
    base = {"trial": [0, 0, 1, 1], "time_s": [0.0, 0.1, 0.0, 0.1], "s0_bz_uT": np.zeros(4)}
    with pytest.raises(DatasetError, match="rows of trial 0 are not contiguous"):
        Dataset({**base, "trial": [0, 1, 0, 1]})
    with pytest.raises(DatasetError, match="condition phi_deg changes within trial 1"):
        Dataset({**base, "phi_deg": [10, 10, 10, 20]}, conditions={"phi_deg": "deg"})
    with pytest.raises(DatasetError, match="column 'fz_N' is neither a channel"):
        Dataset({**base, "fz_N": np.zeros(4)})
    with pytest.raises(DatasetError, match="fz_N is declared both as a label and as a condition"):
        Dataset({**base, "fz_N": np.zeros(4)}, labels={"fz_N": "N"}, conditions={"fz_N": "N"})
    with pytest.raises(DatasetError, match="column trial: expected integer trial ids"):
        Dataset({**base, "trial": [0.0, 0.0, 1.0, 1.0]})
    with pytest.raises(DatasetError, match="metadata design: expected a JSON object"):
        DatasetMetadata(design=[1, 2])
    with pytest.raises(DatasetError, match=r"^metadata seed = 1\.5: expected an integer or None$"):
        DatasetMetadata(seed=1.5)
    with pytest.raises(DatasetError, match=r"^metadata description = 3: expected a string$"):
        DatasetMetadata(description=3)
    assert DatasetMetadata(seed=np.int64(7)).seed == 7


# --------------------------------------------------------------------------
# concat
# --------------------------------------------------------------------------


def test_concat_refuses_clashing_trial_ids_unless_renumbered(grasps):
    first, second = grasps.select(trials=[0, 1]), grasps.select(trials=[45, 46])
    assert np.array_equal(concat([first, second]).trials, [0, 1, 45, 46])
    with pytest.raises(DatasetError, match="trial 0 occurs in more than one dataset"):
        concat([first, first])
    twice = concat([first, first], renumber_trials=True)
    np.testing.assert_array_equal(twice.trials, [0, 1, 2, 3])
    np.testing.assert_array_equal(twice.X(), np.vstack([first.X(), first.X()]))
    assert twice.metadata == grasps.metadata


def test_concat_refuses_different_declarations(grasps):
    other = Dataset({"trial": [100], "time_s": [0.0], **channel_columns(np.zeros((1, 2, 3)))})
    with pytest.raises(DatasetError, match="dataset 1 has labels"):
        concat([grasps, other])


# --------------------------------------------------------------------------
# Channels of other sensors
# --------------------------------------------------------------------------

FORCE_CHANNELS = {"side_fx_N": "N", "side_fy_N": "N", "side_fz_N": "N"}


def chip_trial(n: int = 4, **changes) -> dict:
    return {"time_s": np.arange(n) / 10.0, **{name: np.linspace(0, k + 1, n) for k, name in enumerate(FORCE_CHANNELS)},
            "fz_N": np.linspace(0, 2, n), **changes}


def test_channels_of_another_sensor_keep_their_units_through_a_file(tmp_path):
    writer = TrialWriter(FORCE_CHANNELS, {"fz_N": "N"}, {"participant": "1"}, METADATA)
    writer.add(chip_trial(), {"participant": 0})
    writer.add(chip_trial(6), {"participant": 1})
    path = tmp_path / "wearable.parquet"
    writer.write(path)
    back = Dataset.read(path)
    assert back.channels == tuple(FORCE_CHANNELS) and back.channel_units == FORCE_CHANNELS
    np.testing.assert_array_equal(back.X(), writer.to_dataset().X())
    # the document lists them as it always listed channels: name and unit, no new schema version
    document = json.loads(pq.read_schema(path).metadata[b"softtip"])
    assert document["schema_version"] == 1
    assert document["channels"] == [{"name": name, "unit": "N"} for name in FORCE_CHANNELS]
    assert back.select(trials=[1]).channel_units == FORCE_CHANNELS
    assert concat([back, back], renumber_trials=True).channel_units == FORCE_CHANNELS


def test_magnetic_channels_come_first_then_the_declared_ones_in_their_order():
    columns = {"trial": [0, 0], "time_s": [0.0, 0.1], "side_fz_N": [1.0, 2.0], "s0_bz_uT": [0.0, 1.0],
               "s0_bx_uT": [0.0, 0.0], "s0_by_uT": [0.0, 0.0], "side_fx_N": [0.0, 0.5]}
    dataset = Dataset(columns, channel_units={"side_fz_N": "N", "side_fx_N": "N"})
    assert dataset.channels == ("s0_bx_uT", "s0_by_uT", "s0_bz_uT", "side_fz_N", "side_fx_N")
    assert dataset.channel_units["s0_bz_uT"] == "uT" and dataset.channel_units["side_fx_N"] == "N"
    # an old dataset of Hall sensors declares nothing and reads as before
    assert Dataset({k: v for k, v in columns.items() if not k.startswith("side")}).channel_units == dict.fromkeys(
        ("s0_bx_uT", "s0_by_uT", "s0_bz_uT"), "uT")


@pytest.mark.parametrize("build, message", [
    (lambda: Dataset({"trial": [0], "time_s": [0.0], "s0_bz_uT": [0.0], "side_fz_N": [1.0]}),
     "column 'side_fz_N' is neither a channel"),
    (lambda: Dataset({"trial": [0], "time_s": [0.0], "side_fz_N": [1.0]}), "no channel columns"),
    (lambda: Dataset({"trial": [0], "time_s": [0.0]}, channel_units={"side_fz_N": "N"}),
     "missing column side_fz_N .declared as a channel."),
    (lambda: Dataset({"trial": [0], "time_s": [0.0], "s0_bz_uT": [1.0]}, channel_units={"s0_bz_uT": "mT"}),
     "channels: s0_bz_uT .mT. is a magnetic channel, in uT"),
    (lambda: Dataset({"trial": [0], "time_s": [0.0], "side_fz_N": [1.0]}, labels={"side_fz_N": "N"},
                     channel_units={"side_fz_N": "N"}), "side_fz_N is declared both as a channel and as a label"),
    (lambda: Dataset({"trial": [0], "time_s": [0.0], "side_fz_N": [1.0]}, channel_units={"side_fz_N": ""}),
     "channels: side_fz_N has no unit"),
    (lambda: Dataset({"trial": [0], "time_s": [0.0], "side_fz_N": [np.nan]}, channel_units={"side_fz_N": "N"}),
     "column side_fz_N: row 0 is not finite"),
    (lambda: TrialWriter({"side fz": "N"}), "channels: 'side fz' is not a valid column name"),
])
def test_declared_channels_are_checked_like_every_column(build, message):
    with pytest.raises(DatasetError, match=message):
        build()


def test_concat_refuses_the_same_channel_in_another_unit():
    one = Dataset({"trial": [0], "time_s": [0.0], "side_fz_N": [1.0]}, channel_units={"side_fz_N": "N"})
    other = Dataset({"trial": [1], "time_s": [0.0], "side_fz_N": [1.0]}, channel_units={"side_fz_N": "mN"})
    with pytest.raises(DatasetError, match="dataset 1 has channels {'side_fz_N': 'mN'}"):
        concat([one, other])


def test_a_file_declaring_a_magnetic_channel_in_another_unit_is_refused(tmp_path):
    path = every_dtype().write(tmp_path / "trials.parquet")
    document = json.loads(pq.read_schema(path).metadata[b"softtip"])
    document["channels"][0]["unit"] = "mT"
    rewrite(path, document)
    with pytest.raises(DatasetError, match="metadata channels: s0_bx_uT .mT. is a magnetic channel, in uT"):
        Dataset.read(path)


# --------------------------------------------------------------------------
# Splits
# --------------------------------------------------------------------------


def assert_disjoint_cover(dataset, *parts):
    """No trial on two sides (no leakage) and every row exactly once."""
    trials = np.concatenate([part.trials for part in parts])
    assert len(np.unique(trials)) == len(trials)
    assert sum(len(part) for part in parts) == len(dataset)
    np.testing.assert_array_equal(np.sort(trials), np.sort(dataset.trials))


def per_condition_counts(dataset, column):
    values, counts = np.unique(dataset.trial_conditions[column], return_counts=True)
    return dict(zip(values.tolist(), counts.tolist(), strict=True))


def test_split_by_trial_takes_the_first_k_of_each_condition(grasps):
    trained, _ = leave_condition_out(grasps, "board_angle_deg", UNTRAINED_DEG)
    calibration, validation = split_by_trial(trained, 7, ["board_angle_deg"])
    assert_disjoint_cover(trained, calibration, validation)
    assert per_condition_counts(calibration, "board_angle_deg") == dict.fromkeys(TRAINED_DEG, 7)
    assert per_condition_counts(validation, "board_angle_deg") == dict.fromkeys(TRAINED_DEG, 3)
    # trials were recorded angle by angle, 10 each: the first 7 of each block calibrate
    np.testing.assert_array_equal(calibration.trials, [b * 10 + i for b in range(4) for i in range(7)])
    # 0.7 of 10 trials is the same split
    by_fraction, _ = split_by_trial(trained, 0.7, ["board_angle_deg"])
    np.testing.assert_array_equal(by_fraction.trials, calibration.trials)


def test_split_by_trial_at_random_is_reproducible(grasps):
    calibration, validation = split_by_trial(grasps, 2, ["board_angle_deg"], seed=3)
    assert_disjoint_cover(grasps, calibration, validation)
    assert per_condition_counts(calibration, "board_angle_deg") == dict.fromkeys(TRAINED_DEG + UNTRAINED_DEG, 2)
    again, _ = split_by_trial(grasps, 2, ["board_angle_deg"], seed=3)
    other, _ = split_by_trial(grasps, 2, ["board_angle_deg"], seed=4)
    np.testing.assert_array_equal(again.trials, calibration.trials)
    assert not np.array_equal(other.trials, calibration.trials)
    with pytest.raises(DatasetError, match="condition board_angle_deg=5.0 has 3 trials, fewer than the 7"):
        split_by_trial(grasps, 7, ["board_angle_deg"])


@pytest.mark.parametrize("per_condition, calibration, validation", [(15, 10, 5), (10, 7, 3), (8, 5, 3)])
def test_published_split_sizes(per_condition, calibration, validation):
    """The papers' splits: 10 + 5 of 15, 7 + 3 of 10, 5 + 3 of 8, both as counts and as fractions."""
    rng = np.random.default_rng(1)
    writer = TrialWriter(1, conditions={"state": "1"})
    for state in ("point A", "point B", "edge"):
        for _ in range(per_condition):
            writer.add({"time_s": [0.0, 0.02], **channel_columns(rng.normal(size=(2, 1, 3)))}, {"state": state})
    dataset = writer.to_dataset()
    for k in (calibration, calibration / per_condition):
        cal, val = split_by_trial(dataset, k, ["state"])
        assert per_condition_counts(cal, "state") == dict.fromkeys(("point A", "point B", "edge"), calibration)
        assert per_condition_counts(val, "state") == dict.fromkeys(("point A", "point B", "edge"), validation)


@settings(max_examples=40, deadline=None)
@given(sizes=st.lists(st.integers(1, 6), min_size=1, max_size=5), k=st.integers(1, 6),
       seed=st.one_of(st.none(), st.integers(0, 2**32 - 1)))
def test_split_by_trial_never_leaks(sizes, k, seed):
    writer = TrialWriter(1, conditions={"group": "1"})
    for group, size in enumerate(sizes):
        for _ in range(size):
            writer.add({"time_s": [0.0], **channel_columns(np.zeros((1, 1, 3)))}, {"group": group})
    dataset = writer.to_dataset()
    if k > min(sizes):
        with pytest.raises(DatasetError, match="fewer than"):
            split_by_trial(dataset, k, ["group"], seed=seed)
        return
    calibration, validation = split_by_trial(dataset, k, ["group"], seed=seed)
    assert_disjoint_cover(dataset, calibration, validation)
    assert per_condition_counts(calibration, "group") == dict.fromkeys(range(len(sizes)), k)


def test_kfold_without_seed_is_group_kfold(grasps):
    ours = list(kfold_by_trial(grasps, 5))
    reference = list(GroupKFold(n_splits=5).split(grasps.X(), groups=grasps.groups))
    assert len(ours) == len(reference) == 5
    for (train, test), (ref_train, ref_test) in zip(ours, reference, strict=True):
        np.testing.assert_array_equal(train, ref_train)
        np.testing.assert_array_equal(test, ref_test)


def test_seeded_kfold_keeps_trials_whole(grasps):
    folds = list(kfold_by_trial(grasps, 4, seed=2))
    tested = np.concatenate([np.unique(grasps.groups[test]) for _, test in folds])
    np.testing.assert_array_equal(np.sort(tested), grasps.trials)  # every trial tested exactly once
    for train, test in folds:
        assert np.intersect1d(grasps.groups[train], grasps.groups[test]).size == 0
        assert len(train) + len(test) == len(grasps)
    trials_per_fold = [len(np.unique(grasps.groups[test])) for _, test in folds]
    assert max(trials_per_fold) - min(trials_per_fold) <= 1
    again = list(kfold_by_trial(grasps, 4, seed=2))
    assert all(np.array_equal(a[1], b[1]) for a, b in zip(folds, again, strict=True))


def test_trial_kfold_in_cross_val_score_equals_group_kfold(grasps):
    X, y = grasps.X(), grasps.y("fz_N")
    ours = cross_val_score(Ridge(), X, y, cv=TrialKFold.for_dataset(grasps, 5))
    reference = cross_val_score(Ridge(), X, y, cv=GroupKFold(n_splits=5), groups=grasps.groups)
    np.testing.assert_allclose(ours, reference, rtol=0, atol=0)
    with pytest.raises(DatasetError, match="X has 10 rows"):
        next(TrialKFold.for_dataset(grasps, 5).split(X[:10]))
    with pytest.raises(DatasetError, match="n_splits: expected an integer from 2 to the number of trials .49."):
        TrialKFold.for_dataset(grasps, 50)


def test_leave_condition_out_holds_out_the_untrained_angles(grasps):
    trained, untrained = leave_condition_out(grasps, "board_angle_deg", UNTRAINED_DEG)
    assert_disjoint_cover(grasps, trained, untrained)
    assert per_condition_counts(untrained, "board_angle_deg") == dict.fromkeys(UNTRAINED_DEG, 3)
    assert np.all(trained.trial_conditions["trained"]) and not np.any(untrained.trial_conditions["trained"])
    with pytest.raises(DatasetError, match="no trial has board_angle_deg = 35"):
        leave_condition_out(grasps, "board_angle_deg", [5, 35])
    with pytest.raises(DatasetError, match="'fz_N' is not a condition"):
        leave_condition_out(grasps, "fz_N", [1.0])


def test_split_by_sample_warns_about_leakage(grasps):
    with pytest.warns(LeakageWarning, match="trials have samples on both sides"):
        first, second = split_by_sample(grasps, 0.8, seed=0)
    assert len(first) == round(0.8 * len(grasps)) and len(first) + len(second) == len(grasps)
    assert np.intersect1d(first.trials, second.trials).size > 0  # the leakage it warns about
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        split_by_trial(grasps, 0.5)  # trial-wise splits do not warn


# --------------------------------------------------------------------------
# CSV recordings
# --------------------------------------------------------------------------

CSV = """run,t_ms,Bx,By,Bz,Fz,angle,contact
3,1000,0.0,0,0,0.0,15,air
3,1050,1.5,2,0.000012,0.5,15,air
3,1100,-0.25,-1,0.000001,1.0,15,edge
4,20,0.1,10,-0.000002,0.0,30,air
4,70,0.2,20,0.0,0.25,30,edge
"""
MAPPING = {"Bx": "s0_bx_uT", "By": "s0_by_uT", "Bz": "s0_bz_uT", "Fz": "fz_N", "angle": "board_angle_deg",
           "contact": "state"}
CSV_OPTIONS = dict(trial_column="run", time_column="t_ms", time_unit="ms", units={"Bx": "mT", "By": "G", "Bz": "T"},
                   labels={"fz_N": "N", "state": "1"}, conditions={"board_angle_deg": "deg"})


@pytest.fixture
def recording(tmp_path):
    path = tmp_path / "recording.csv"
    path.write_text(CSV)
    return path


def test_csv_recording_with_unit_conversion(recording):
    dataset = read_csv_recording(recording, MAPPING, **CSV_OPTIONS)
    np.testing.assert_array_equal(dataset.trials, [3, 4])
    # 1 mT = 1000 µT, 1 G = 100 µT, 1 T = 1e6 µT
    np.testing.assert_allclose(dataset.column("s0_bx_uT"), [0.0, 1500.0, -250.0, 100.0, 200.0])
    np.testing.assert_allclose(dataset.column("s0_by_uT"), [0.0, 200.0, -100.0, 1000.0, 2000.0])
    np.testing.assert_allclose(dataset.column("s0_bz_uT"), [0.0, 12.0, 1.0, -2.0, 0.0])
    # milliseconds to seconds, counted from each trial's first sample
    np.testing.assert_allclose(dataset.column("time_s"), [0.0, 0.05, 0.1, 0.0, 0.05])
    np.testing.assert_array_equal(dataset.column("state"), ["air", "air", "edge", "air", "edge"])
    np.testing.assert_array_equal(dataset.trial_conditions["board_angle_deg"], [15, 30])
    assert dataset.labels == {"fz_N": "N", "state": "1"}


def test_csv_mapping_from_toml_equals_the_dict(recording, tmp_path):
    toml = tmp_path / "mapping.toml"
    toml.write_text("""
trial_column = "run"
time_column = "t_ms"
time_unit = "ms"
[columns]
Bx = "s0_bx_uT"
By = "s0_by_uT"
Bz = "s0_bz_uT"
Fz = "fz_N"
angle = "board_angle_deg"
contact = "state"
[units]
Bx = "mT"
By = "G"
Bz = "T"
[labels]
fz_N = "N"
state = "1"
[conditions]
board_angle_deg = "deg"
""")
    from_toml = read_csv_recording(recording, toml)
    from_dict = read_csv_recording(recording, MAPPING, **CSV_OPTIONS)
    for name in from_dict.columns:
        np.testing.assert_array_equal(from_toml.column(name), from_dict.column(name))
    with pytest.raises(DatasetError, match="mapping.toml: time_unit is also given as an argument"):
        read_csv_recording(recording, toml, time_unit="s")


def test_csv_baseline_and_fixed_rate(tmp_path):
    path = tmp_path / "raw.csv"
    path.write_text("Bz;F;run\n100;0;1\n102;1;1\n110;2;1\n5;0;2\n7;1;2\n")
    dataset = read_csv_recording(path, {"Bz": "s0_bz_uT", "F": "fz_N"}, trial_column="run", labels={"fz_N": "N"},
                                 rate_hz=20, units="mT", baseline_samples=2, delimiter=";")
    # baselines (100 + 102) / 2 and (5 + 7) / 2 mT, then 1 mT = 1000 µT
    np.testing.assert_allclose(dataset.column("s0_bz_uT"), [-1000.0, 1000.0, 9000.0, -1000.0, 1000.0])
    np.testing.assert_allclose(dataset.column("time_s"), [0.0, 0.05, 0.1, 0.0, 0.05])
    np.testing.assert_array_equal(dataset.trials, [1, 2])
    with pytest.raises(DatasetError, match="raw.csv: trial 2 has 2 samples, fewer than the 3 of its baseline"):
        read_csv_recording(path, {"Bz": "s0_bz_uT"}, trial_column="run", rate_hz=20, baseline_samples=3,
                           delimiter=";")


@pytest.mark.parametrize("text, changes, message", [
    (CSV.replace("Bz,", "Bq,"), {}, r"recording.csv: no column 'Bz'"),
    (CSV.replace("0.5,15", "half,15"), {}, r"recording.csv: column 'Fz', line 3: 'half' is not a number"),
    (CSV.replace("1.5,2", "1.5mT,2"), {}, r"recording.csv: column 'Bx', line 3: '1.5mT' is not a number"),
    (CSV.replace("-0.25,-1", ",-1"), {}, r"recording.csv: column 'Bx', line 4: empty"),
    (CSV, {"units": "kG"}, r"read_csv_recording: units = 'kG': expected a magnetic unit"),
    (CSV, {"units": {"Bx": "mT"}}, r"mapping: units: no unit for magnetic column 'By'"),
    (CSV, {"labels": {"fz_N": "N"}}, r"mapping: columns: 'contact' = 'state' is neither a channel"),
    (CSV, {"conditions": {"board_angle_deg": "deg", "phi_deg": "deg"}}, "phi_deg is declared but no CSV column"),
    (CSV.replace("4,70", "4.5,70"), {}, r"trial column 'run' holds values that are not integers"),
    (CSV.replace("0.25,30", "0.25,35"), {}, "condition board_angle_deg changes within trial 4"),
    (CSV.replace("1100", "1040"), {}, "time does not increase within trial 3"),
])
def test_csv_refusals_name_the_file_and_column(tmp_path, text, changes, message):
    path = tmp_path / "recording.csv"
    path.write_text(text)
    with pytest.raises(DatasetError, match=message) as refusal:
        read_csv_recording(path, MAPPING, **{**CSV_OPTIONS, **changes})
    assert "\n" not in str(refusal.value)


@pytest.mark.parametrize("kind", [pa.float64(), pa.float32(), pa.int64(), pa.int16(), pa.uint8(), pa.bool_()])
def test_arrow_numbers_equal_arrows_own_conversion_across_chunks_offsets_and_nulls(kind):
    """The buffer reader gives what pyarrow's to_numpy gives: two chunks, the second sliced (a non-zero
    offset into its buffers, not a multiple of 8 bits), with a null in a float column read as NaN."""
    from softtip.data.dataset import arrow_numbers

    values = [1, 0, 3, 4, 5, 0, 7, 8, 9, 10, 11, 1]
    if pa.types.is_boolean(kind):
        values = [bool(v % 2) for v in values]
    with_null = values[:9] + [None] + values[10:] if pa.types.is_floating(kind) else values
    column = pa.chunked_array([pa.array(values[:3], kind), pa.array(with_null, kind).slice(5)])
    found = arrow_numbers(column)
    expected = column.to_numpy()
    assert found.dtype == expected.dtype and found.flags.writeable
    np.testing.assert_array_equal(found, expected)
    if pa.types.is_floating(kind):
        assert np.flatnonzero(np.isnan(found)).tolist() == [3 + 4]
    assert arrow_numbers(pa.chunked_array([], kind)).shape == (0,)
