"""System-identification recordings: readers, sample time, detrending, splits, and one-line refusals."""

from __future__ import annotations

import hashlib
import struct
import warnings

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from softtip.data import DatasetError, DatasetMetadata, LeakageWarning, TrialWriter, channel_columns
from softtip.sysid.recording import Recording, read_recording
from softtip.sysid.splits import split_by_sample, split_by_time, split_by_trial

TS = 0.1


def _table(trials=3, length=50, seed=0) -> dict[str, np.ndarray]:
    """Columns of a 10 Hz recording: trial, time_s (starting at 2 s), two inputs and one output."""
    rng = np.random.default_rng(seed)
    n = trials * length
    return {"trial": np.repeat(np.arange(trials) + 10, length), "time_s": 2 + np.tile(np.arange(length), trials) * TS,
            "Fx_side": rng.normal(size=n), "Fz_side": rng.normal(size=n), "Fz": rng.normal(size=n)}


def _csv(path, columns: dict[str, np.ndarray]):
    names = list(columns)
    rows = zip(*(columns[name] for name in names), strict=True)
    path.write_text(",".join(names) + "\n" + "\n".join(",".join(repr(float(v)) if not isinstance(v, str) else v
                                                             for v in row) for row in rows) + "\n")
    return path


def _parquet(path, columns: dict[str, np.ndarray]):
    pq.write_table(pa.table(columns), path)
    return path


@pytest.mark.parametrize("writer, suffix", [(_csv, ".csv"), (_parquet, ".parquet")])
def test_a_plain_file_is_read_trial_by_trial_with_its_sample_time(tmp_path, writer, suffix):
    columns = _table()
    path = writer(tmp_path / f"record{suffix}", columns)
    recording = read_recording(path, ["Fx_side", "Fz_side"], ["Fz"], units={"Fz": "N"})
    assert recording.ts == pytest.approx(TS)
    assert [trial.id for trial in recording.trials] == [10, 11, 12]
    assert recording.output_units == ("N",) and recording.input_units == ("", "")
    np.testing.assert_array_equal(recording.trials[1].u[:, 1], columns["Fz_side"][50:100])
    np.testing.assert_array_equal(recording.trials[2].y[:, 0], columns["Fz"][100:])
    np.testing.assert_allclose(recording.time(0), np.arange(50) * TS)


@pytest.mark.parametrize("writer, suffix", [(_csv, ".csv"), (_parquet, ".parquet")])
def test_reading_a_recording_loads_no_pandas(tmp_path, writer, suffix):
    """Arrow's own to_numpy and pq.read_table import pandas, half a second of a command's start: a fresh
    interpreter reads a recording (and a softtip dataset) without it, to the same numbers."""
    import subprocess
    import sys
    from pathlib import Path

    path = writer(tmp_path / f"rec{suffix}", _table())
    dataset = TrialWriter(1, {"Fz": "N"}, metadata=DatasetMetadata(description="pandas-free"))
    dataset.add({"time_s": np.arange(4) * TS, **channel_columns(np.zeros((4, 1, 3))), "Fz": [0.0, 1.0, np.nan, 3.0]})
    dataset.write(tmp_path / "set.parquet")
    program = ("import sys; from softtip.sysid.recording import read_recording; from softtip.data import Dataset; "
               f"r = read_recording({str(path)!r}, ['Fx_side', 'Fz_side'], ['Fz'], trial_column='trial'); "
               f"d = Dataset.read({str(tmp_path / 'set.parquet')!r}); "
               "print(repr(float(r.trials[1].u[3, 1])), d.columns['Fz'].tolist(), 'pandas' in sys.modules)")
    source = Path(__file__).parents[1] / "src"
    found = subprocess.run([sys.executable, "-c", program], env={"PYTHONPATH": str(source), "PATH": ""},
                           capture_output=True, text=True, timeout=120)
    assert found.returncode == 0, found.stderr
    assert found.stdout.split() == [repr(float(_table()["Fz_side"][53])), "[0.0,", "1.0,", "nan,", "3.0]", "False"]


def test_a_softtip_dataset_gives_its_channels_and_labels_with_their_units(tmp_path):
    rng = np.random.default_rng(1)
    writer = TrialWriter(1, labels={"fz_N": "N"}, metadata=DatasetMetadata(seed=0))
    for _ in range(2):
        field = rng.normal(size=(40, 1, 3))
        writer.add({"time_s": np.arange(40) * 0.05, **channel_columns(field), "fz_N": rng.normal(size=40)})
    dataset = writer.write(tmp_path / "push.parquet")
    recording = read_recording(tmp_path / "push.parquet", ["s0_bx_uT", "s0_bz_uT"], ["fz_N"])
    assert recording.ts == pytest.approx(0.05) and len(recording.trials) == 2
    assert recording.input_units == ("uT", "uT") and recording.output_units == ("N",)
    np.testing.assert_array_equal(recording.trials[1].u[:, 1], dataset.column("s0_bz_uT")[40:])
    with pytest.raises(DatasetError, match="no channel or label 'angle'"):
        Recording.from_dataset(dataset, ["s0_bx_uT"], ["angle"])


def test_a_file_without_time_needs_the_sample_time(tmp_path):
    columns = _table(trials=1)
    del columns["time_s"], columns["trial"]
    path = _csv(tmp_path / "plain.csv", columns)
    with pytest.raises(DatasetError, match="no time column: give the sample time"):
        read_recording(path, ["Fx_side"], ["Fz"])
    recording = read_recording(path, ["Fx_side"], ["Fz"], ts=0.2)
    assert recording.ts == 0.2 and len(recording.trials) == 1 and recording.n_samples == 50


@pytest.mark.parametrize("edit, kwargs, message", [
    (lambda c: c["Fz"].__setitem__(7, np.nan), {}, r"trial 10: column 'Fz', sample 7: nan is not a finite number"),
    (lambda c: c["time_s"].__setitem__(20, c["time_s"][20] + 0.04), {},
     r"column 'time_s': irregular sample times in trial 10: a step of 0.14 s at row 20, the sample time is 0.1 s "
     r"\(tolerance 2 %\): resample it onto an even grid \(--resample SECONDS"),
    (lambda c: None, {"ts": 0.05}, r"the sample time given, 0.05 s, does not match the 0.1 s of column 'time_s'"),
    (lambda c: c.__setitem__("trial", np.r_[c["trial"][:140], np.full(10, 10)]), {},
     "the rows of trial 10 are not contiguous"),
])
def test_bad_recordings_are_refused_in_one_line_naming_the_file_and_column(tmp_path, edit, kwargs, message):
    columns = _table()
    edit(columns)
    path = _parquet(tmp_path / "bad.parquet", columns)
    with pytest.raises(DatasetError, match=message) as refusal:
        read_recording(path, ["Fx_side", "Fz_side"], ["Fz"], **kwargs)
    assert str(path) in str(refusal.value) and "\n" not in str(refusal.value)


def _daisy(path, columns: dict[str, np.ndarray], header: bool):
    """A whitespace text file as DaISy publishes them: numbers in columns separated by runs of spaces
    (and a tab), optionally a header of names."""
    rows = zip(*columns.values(), strict=True)
    lines = [*(["\t".join(columns)] if header else []),
             *("   " + "  \t ".join(f"{v:.16e}" for v in row) for row in rows)]
    path.write_text("\n".join(lines) + "\n\n")
    return path


@pytest.mark.parametrize("header", [True, False])
def test_a_whitespace_dat_file_is_read_with_or_without_its_header(tmp_path, header):
    columns = _table(trials=2)
    path = _daisy(tmp_path / "record.dat", columns, header)
    names = None if header else list(columns)
    recording = read_recording(path, ["Fx_side", "Fz_side"], ["Fz"], names=names, units={"Fz": "N"})
    assert recording.ts == pytest.approx(TS) and [trial.id for trial in recording.trials] == [10, 11]
    np.testing.assert_array_equal(recording.trials[1].y[:, 0], columns["Fz"][50:])
    np.testing.assert_array_equal(recording.trials[0].u[:, 1], columns["Fz_side"][:50])
    assert recording.output_units == ("N",)
    if not header:  # positions name the columns of a file without a header
        by_position = read_recording(path, ["3"], ["5"], time_column="2", trial_column="1")
        np.testing.assert_array_equal(by_position.trials[0].u[:, 0], columns["Fx_side"][:50])


@pytest.mark.parametrize("text, names, message", [
    ("1 2 3\n4 5\n", None, r"cannot be read as delimited text \(CSV parse error: Expected 3 columns, got 2: 4 5\)"),
    ("u y\n1 2\n3 x\n", None, r"column 'y', line 3: 'x' is not a number"),
    ("1 2\n3 4\n", ["u", "y", "z"], r"3 column names given for 2 columns \(its first line: 1 2\)"),
    ("u y\n1 2\n", ["a", "b"], r"the file names its columns in its first line \(u y\)"),
    ("u u\n1 2\n", None, r"column 'u' appears more than once"),
    ("\n\n", None, r"no rows of numbers"),
    ("u y\n", None, r"cannot be read as delimited text \(Could not skip initial 1 rows"),
])
def test_bad_whitespace_files_are_refused_naming_line_and_column(tmp_path, text, names, message):
    path = tmp_path / "bad.dat"
    path.write_text(text)
    with pytest.raises(DatasetError, match=message) as refusal:
        read_recording(path, ["1"], ["2"], ts=1.0, names=names)
    assert str(path) in str(refusal.value)


def test_resampling_interpolates_each_trial_linearly_and_says_what_it_did(tmp_path):
    """Irregular stamps of a signal that is linear between them: the resampled values are the line's
    (scipy's interp1d the reference), each trial from its own first stamp; the gaps are counted."""
    from scipy.interpolate import interp1d

    rng = np.random.default_rng(3)
    times = [np.cumsum(np.r_[0.0, rng.uniform(0.02, 0.04, 60), 1.1, rng.uniform(0.02, 0.04, 30)]),
             5 + np.cumsum(np.r_[0.0, rng.uniform(0.02, 0.04, 40)])]
    values = [np.sin(t) + t for t in times]
    columns = {"trial": np.concatenate([np.full(len(t), k) for k, t in enumerate(times)]),
               "time_s": np.concatenate(times), "u": np.concatenate(values), "y": -np.concatenate(values)}
    path = _csv(tmp_path / "serial.csv", columns)
    with pytest.raises(DatasetError, match=r"irregular sample times in trial 0.*resample it onto an even grid"):
        read_recording(path, ["u"], ["y"])
    recording = read_recording(path, ["u"], ["y"], resample=0.03)
    assert recording.ts == 0.03 and len(recording.trials) == 2
    for trial, t, v in zip(recording.trials, times, values, strict=True):
        grid = t[0] + 0.03 * np.arange(len(trial))
        assert grid[-1] <= t[-1] < grid[-1] + 0.03
        np.testing.assert_allclose(trial.u[:, 0], interp1d(t, v)(grid), rtol=0, atol=1e-12)
        np.testing.assert_allclose(trial.y[:, 0], -trial.u[:, 0])
    done = recording.resampled
    steps = np.concatenate([np.diff(t) for t in times])
    assert (done.before, done.after) == (len(columns["u"]), recording.n_samples)
    assert done.longest_step == pytest.approx(1.1) and done.gaps == 1
    assert done.median_step == pytest.approx(np.median(steps))
    assert "became" in done.describe() and recording.describe()["resampled"]["gaps_bridged"] == 1
    columns["time_s"][5] = columns["time_s"][4]
    with pytest.raises(DatasetError, match=r"time does not increase at row 5 \(trial 0\): cannot resample"):
        read_recording(_csv(tmp_path / "repeat.csv", columns), ["u"], ["y"], resample=0.03)


def test_unknown_columns_and_text_are_refused_naming_them(tmp_path):
    columns = _table()
    path = _csv(tmp_path / "record.csv", columns)
    with pytest.raises(DatasetError, match=r"record.csv: no column 'Fy' \(columns: trial, time_s, Fx_side, Fz_side, Fz\)"):
        read_recording(path, ["Fx_side"], ["Fy"])
    text = path.read_text().splitlines()
    cells = text[3].split(",")
    cells[4] = "high"
    path.write_text("\n".join([*text[:3], ",".join(cells), *text[4:]]) + "\n")
    with pytest.raises(DatasetError, match=r"record.csv: column 'Fz', line 4: 'high' is not a number"):
        read_recording(path, ["Fx_side"], ["Fz"])
    with pytest.raises(DatasetError, match="record.json: expected a .csv, .parquet, or whitespace-separated "
                                           ".dat or .txt file"):
        read_recording(path.rename(tmp_path / "record.json"), ["Fx_side"], ["Fz"])
    with pytest.raises(DatasetError, match="record.txt: its first line is separated by commas or semicolons, not "
                                           "whitespace: name the file .csv"):
        read_recording((tmp_path / "record.json").rename(tmp_path / "record.txt"), ["Fx_side"], ["Fz"])


def test_a_constant_input_is_refused_before_identification():
    u = np.column_stack([np.sin(np.arange(100)), np.full(100, 2.5)])
    recording = Recording.from_arrays(u, np.cos(np.arange(100)), TS, inputs=["Fx", "Fy"], outputs=["Fz"])
    with pytest.raises(DatasetError, match=r"input 'Fy' is constant \(2.5\) over the whole recording"):
        recording.require_excitation()


def test_detrending_removes_each_trials_mean_or_line():
    t = np.arange(60) * TS
    u = [np.column_stack([3 + 2 * t + np.sin(5 * t)]), np.column_stack([-1 + np.cos(3 * t)])]
    y = [np.column_stack([10 - t + np.cos(4 * t)]), np.column_stack([4 + 0.5 * t])]
    recording = Recording.from_arrays(u, y, TS)
    centred = recording.detrend("mean")
    for trial in centred.trials:
        np.testing.assert_allclose(trial.u.mean(axis=0), 0, atol=1e-12)
        np.testing.assert_allclose(trial.y.mean(axis=0), 0, atol=1e-12)
    straight = recording.detrend("linear")
    np.testing.assert_allclose(straight.trials[1].y, 0, atol=1e-12)  # a line less its line
    for trial in straight.trials:
        for values in (trial.u, trial.y):
            assert abs(np.polyfit(t, values[:, 0], 1)[0]) < 1e-12
    assert centred.detrended == "mean" and centred.detrend("linear").detrended == "linear"


def test_the_hash_covers_the_arrays_and_nothing_else():
    u, y = np.arange(20.0).reshape(10, 2), np.ones((10, 1))
    first = Recording.from_arrays(u, y, TS, source="a.csv")
    assert first.sha256 == Recording.from_arrays(u.copy(), y.copy(), TS, source="b.csv").sha256
    y[3] = 1.0000001
    assert Recording.from_arrays(u, y, TS).sha256 != first.sha256


def test_the_hash_covers_the_sample_time_it_documents():
    u, y = np.arange(20.0).reshape(10, 2), np.ones((10, 1))
    recording = Recording.from_arrays(u, y, TS)
    # the reference, by hand: the sample time as a float64, then per trial and role name NUL dtype NUL
    # shape NUL and the C-order bytes
    reference = hashlib.sha256(struct.pack("<d", TS))
    for name, array in (("000000/u", u), ("000000/y", y)):
        reference.update(f"{name}\0<f8\0{array.shape}\0".encode() + array.astype("<f8").tobytes())
    assert recording.sha256 == reference.hexdigest()
    assert Recording.from_arrays(u, y, 2 * TS).sha256 != recording.sha256


# ---------------------------------------------------------------------------------------------- splits


def _recording(trials=5, length=40) -> Recording:
    rng = np.random.default_rng(3)
    return Recording.from_arrays([rng.normal(size=(length, 2)) for _ in range(trials)],
                                 [rng.normal(size=(length, 1)) for _ in range(trials)], TS)


def test_split_by_trial_keeps_trials_whole():
    recording = _recording()
    estimation, validation = split_by_trial(recording, 0.8)
    assert [t.id for t in estimation.trials] == [0, 1, 2, 3] and [t.id for t in validation.trials] == [4]
    estimation, validation = split_by_trial(recording, 2, seed=1)
    ids = sorted(t.id for t in (*estimation.trials, *validation.trials))
    assert len(estimation.trials) == 2 and ids == [0, 1, 2, 3, 4]
    with pytest.raises(DatasetError, match="takes all 5 trials: none is left for validation"):
        split_by_trial(recording, 5)


def test_split_by_time_by_fraction_cuts_every_trial_in_two_contiguous_blocks():
    recording = _recording()
    estimation, validation = split_by_time(recording, 0.8)
    for whole, first, second in zip(recording.trials, estimation.trials, validation.trials, strict=True):
        assert len(first) == 32 and len(second) == 8 and second.start == 32
        np.testing.assert_array_equal(np.vstack([first.y, second.y]), whole.y)
    np.testing.assert_allclose(validation.time(0), np.arange(32, 40) * TS)


def test_split_by_time_in_seconds_runs_along_the_trials_laid_end_to_end():
    recording = _recording(trials=5, length=100)  # 50 s in all, 10 s per trial
    estimation, validation = split_by_time(recording, estimation_s=25.0, validation_s=10.0)
    assert [len(t) for t in estimation.trials] == [100, 100, 50]
    assert [(t.id, t.start, len(t)) for t in validation.trials] == [(2, 50, 50), (3, 0, 50)]
    with pytest.raises(DatasetError, match="250 \\+ 300 samples asked for, the recording has 500"):
        split_by_time(recording, estimation_s=25.0, validation_s=30.0)


def test_split_by_sample_warns_scores_only_held_out_samples_and_fills_them_for_estimation():
    recording = _recording(trials=3, length=100)
    with pytest.warns(LeakageWarning, match=r"split_by_sample: 3 of 3 trials have samples on both sides"):
        estimation, validation = split_by_sample(recording, 0.8, seed=0)
    held_out = np.concatenate([trial.scored for trial in validation.trials])
    assert held_out.sum() == 60 and len(estimation.trials) == len(validation.trials) == 3
    for whole, fitted, scored in zip(recording.trials, estimation.trials, validation.trials, strict=True):
        kept = ~scored.scored
        np.testing.assert_array_equal(fitted.y[kept], whole.y[kept])  # measured where kept
        inside = np.flatnonzero(scored.scored & (np.arange(100) > np.flatnonzero(kept)[0])
                                & (np.arange(100) < np.flatnonzero(kept)[-1]))
        k = inside[0]
        before, after = np.flatnonzero(kept[:k])[-1], k + np.flatnonzero(kept[k:])[0]
        expected = whole.y[before] + (whole.y[after] - whole.y[before]) * (k - before) / (after - before)
        np.testing.assert_allclose(fitted.y[k], expected)  # interpolated between its kept neighbours
        np.testing.assert_array_equal(fitted.u, whole.u)


def test_the_honest_splits_do_not_warn():
    recording = _recording()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        split_by_trial(recording, 0.8)
        split_by_time(recording, 0.8)


def test_a_loggers_missing_readings_are_dropped_and_a_headerless_csv_is_named(tmp_path):
    """A CSV without a header (named by ``names``) whose logger writes -1 for "no reading" in every other
    row: those rows are dropped, so the rest is resampled from the readings alone (np.interp on them the
    reference); without ``missing`` the -1 stay in as values."""
    t = 100.0 + np.cumsum(np.full(200, 0.05))
    force = np.sin(t)
    force[1::2] = -1.0
    path = tmp_path / "states.csv"
    path.write_text("".join(f"{a:.6f},{b:.6f},{c:.6f}\r\n" for a, b, c in zip(t, np.cos(t), force)))
    recording = read_recording(path, ["z"], ["grams"], names=["time", "z", "grams"], time_column="time",
                               missing=-1, resample=0.1)
    grid = t[0] + 0.1 * np.arange(recording.n_samples)
    np.testing.assert_allclose(recording.trials[0].y[:, 0], np.interp(grid, t[::2], np.round(np.sin(t[::2]), 6)),
                               atol=1e-12)
    assert recording.resampled.before == 100
    kept = read_recording(path, ["z"], ["grams"], names=["time", "z", "grams"], time_column="time", ts=0.05)
    assert kept.n_samples == 200 and np.sum(kept.trials[0].y == -1) == 100
    with pytest.raises(DatasetError, match="every row holds the missing value 0.5 in a signal"):
        path.write_text("1,0.5,0.5\n2,0.5,0.5\n")
        read_recording(path, ["z"], ["grams"], names=["time", "z", "grams"], time_column="time", missing=0.5)
