"""A lab's own logs brought in by ``softtip import`` and read by ``softtip cilia fit`` and ``cilia roughness``:
the curve read back against the numbers written (grams to newtons, the import's zero), its fit against the
twin's truth within the fit's intervals, the brushings' study against the same readings read from a CSV
table and an AC rms computed by hand; what is not a curve or a brushing is refused in one line naming the
fix."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from softtip.cli.main import app
from softtip.data import Dataset
from softtip.systems.cilia.bench import curve_from_dataset, recordings_of
from softtip.systems.cilia.layout import DieError, read_die
from softtip.systems.cilia.model import CiliaModel

G = 9.80665e-3  # N per gram on a balance
MAPPING = """[sensor]
time = "time_s"
chip = "other"
name = "gmr"
unit = "V"
chips = [["vx", "vy", "vy"]]  # a 2-axis die: the import takes three columns a chip, the third repeats Y

[labels]
columns = {labels}

[trials]
split = "file"
baseline = {{ samples = 1 }}
"""


def run(args: list[str]) -> dict:
    result = CliRunner().invoke(app, [*args, "--json"])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


@pytest.fixture(scope="module")
def balance_log(tmp_path_factory):
    """The twin's tip-load curve (2.8 memu, 200 µm), logged as a rig would: time, the balance in grams, the
    two sensors' whole voltages; imported with its first (unloaded) row as the zero."""
    folder = tmp_path_factory.mktemp("balance")
    model = CiliaModel(read_die())
    forces = np.linspace(0.0, 26e-3, 13)
    x, y = model.curves(forces, ("X", "Y"))
    volts_x = x.volts
    rows = [f"{k},{f / G:.12f},{vx:.12f},{vy:.12f}" for k, (f, vx, vy) in enumerate(zip(forces, volts_x, y.volts))]
    (folder / "run.csv").write_text("time_s,load_g,vx,vy\n" + "\n".join(rows) + "\n")
    (folder / "map.toml").write_text(MAPPING.format(labels='{ force_N = { column = "load_g", unit = "g" } }'))
    run(["import", str(folder / "run.csv"), "-m", str(folder / "map.toml"), "-o", str(folder / "run.parquet")])
    return folder / "run.parquet", forces, volts_x


def test_an_imported_curve_is_read_in_newtons_from_its_zero(balance_log):
    path, forces, volts = balance_log
    curve = curve_from_dataset(path, Dataset.read(path), "force_N", "gmr0_x_V", "X", tare=False, trial=None)
    np.testing.assert_allclose(curve.force, forces, rtol=0, atol=1e-14)  # grams written to 1e-12 g
    np.testing.assert_allclose(curve.change, volts - volts[0], rtol=0, atol=1e-11)
    with pytest.raises(DieError, match="no label 'fz_N' \\(--force-column\\); its labels: force_N"):
        curve_from_dataset(path, Dataset.read(path), "fz_N", "gmr0_x_V", "X", tare=False, trial=None)
    with pytest.raises(DieError, match="--trial = 1: expected one of its trials, 0 to 0"):
        curve_from_dataset(path, Dataset.read(path), "force_N", "gmr0_x_V", "X", tare=False, trial=1)


@pytest.mark.slow
def test_cilia_fit_takes_an_imported_curve_and_recovers_the_twins_truth(balance_log):
    """The noise-free curve through the import (grams, the zero, the channel's name) gives back the moment
    and diameter it was made with: a unit or a zero read wrongly would move them far more."""
    path, _, _ = balance_log
    report = run(["cilia", "fit", str(path), "--voltage-column", "gmr0_x_V"])
    assert report["points"] == 13
    own = report["fits"]["softtip's model: the die file's pillars"]
    assert own["moment_memu"] == pytest.approx(2.8, rel=1e-4) and own["diameter_um"] == pytest.approx(200.0, rel=1e-4)


def test_an_imported_file_of_several_curves_needs_its_trial_and_declares_its_units(balance_log, tmp_path):
    path, _, _ = balance_log
    folder = path.parent
    for name in ("a.csv", "b.csv"):
        (tmp_path / name).write_text((folder / "run.csv").read_text())
    two = tmp_path / "two.parquet"
    run(["import", str(tmp_path / "a.csv"), str(tmp_path / "b.csv"), "-m", str(folder / "map.toml"), "-o", str(two)])
    for options, message in (([], "2 trials (0 to 1): expected one curve; choose it with --trial"),
                             (["--force-unit", "g"], "--force-unit = 'g': a dataset declares its labels' units"),
                             (["--trial", "-1"], "--trial = -1: expected a trial number >= 0")):
        result = CliRunner().invoke(app, ["cilia", "fit", str(two), "--voltage-column", "gmr0_x_V", *options])
        assert result.exit_code == 2 and message in result.output and result.output.count("\n") == 1, result.output
    result = CliRunner().invoke(app, ["cilia", "fit", str(folder / "run.csv"), "--trial", "0"])
    assert result.exit_code == 2 and "--trial = 0: a CSV table is one curve" in result.output


@pytest.fixture(scope="module")
def brushing_logs(tmp_path_factory):
    """Brushings of four surfaces (two strips, two stage speeds, 50 readings/s) whose AC part grows with the
    roughness, on a slow drift: one log per surface with its roughness, speed, rate and strip on every
    reading, and the same readings as one CSV table of ``cilia roughness``'s own columns."""
    folder = tmp_path_factory.mktemp("brushing")
    rng = np.random.default_rng(5)
    table = ["surface,roughness_um,speed_mm_s,rate_hz,strip,reading_V"]
    for roughness in (0.0, 18.3, 46.2, 162.0):
        rows, time = [], 0.0
        for strip in (0, 1):
            for speed in (1.0, 2.0):
                readings = 18.7 + 2e-6 * np.arange(100) + rng.normal(0.0, 1e-6 + 4e-9 * roughness, 100)
                for value in readings:
                    rows.append(f"{time:.2f},{value:.10f},{roughness},{speed},50,{strip}")
                    table.append(f"{roughness:g} um,{roughness},{speed},50,{strip},{value:.10f}")
                    time += 0.02
        (folder / f"surface-{roughness:g}.csv").write_text("time_s,vx,roughness,speed,rate,strip\n" + "\n".join(rows))
    (folder / "brushings.csv").write_text("\n".join(table) + "\n")
    labels = ('{ roughness_um = { column = "roughness", unit = "um" }, speed_mm_s = { column = "speed", unit = '
              '"mm/s" }, rate_hz = { column = "rate", unit = "Hz" }, strip = { column = "strip", unit = "1" } }')
    (folder / "map.toml").write_text(MAPPING.format(labels=labels).replace('"vy", "vy"', '"vx", "vx"'))
    logs = sorted(str(path) for path in folder.glob("surface-*.csv"))
    run(["import", *logs, "-m", str(folder / "map.toml"), "-o", str(folder / "brushings.parquet")])
    return folder


def test_cilia_roughness_reads_an_imported_log_as_the_same_readings_in_a_table(brushing_logs):
    imported = run(["cilia", "roughness", str(brushing_logs / "brushings.parquet"), "--channel", "gmr0_x_V"])
    table = run(["cilia", "roughness", str(brushing_logs / "brushings.csv"), "--channel", "reading_V"])
    assert imported["recordings"] == table["recordings"] == 16
    # the import's zero is a constant: the AC rms (less the linear trend) does not see it
    np.testing.assert_allclose(imported["ac_rms_uV"], table["ac_rms_uV"], rtol=1e-6)
    assert imported["slope_as_published_uV_per_um"]["slope"] == pytest.approx(
        table["slope_as_published_uV_per_um"]["slope"], rel=1e-5)
    # by hand: P100's four recordings at the level's 1 mm/s (two strips), less their straight line
    readings = np.loadtxt(brushing_logs / "surface-162.csv", delimiter=",", skiprows=1, usecols=1)
    hand = []
    for start in (0, 200):  # strip 0 and strip 1 at 1 mm/s
        piece = readings[start:start + 100]
        trend = np.polyval(np.polyfit(np.arange(100), piece, 1), np.arange(100))
        hand.append(np.sqrt(np.mean((piece - trend) ** 2)))
    assert imported["ac_rms_uV"][-1] == pytest.approx(1e6 * np.mean(hand), rel=1e-6)


def test_an_imported_log_with_no_brushing_labels_is_refused_with_the_fix(balance_log):
    path, _, _ = balance_log
    with pytest.raises(DieError, match="or, for a log brought in by softtip import, the labels roughness_um, "
                                       "speed_mm_s, rate_hz on every reading \\(import them with --label"):
        recordings_of(Dataset.read(path), "gmr0_x_V")
    result = CliRunner().invoke(app, ["cilia", "roughness", str(path), "--channel", "gmr0_x_V"])
    assert result.exit_code == 2 and result.output.count("\n") == 1 and "--label roughness_um=COLUMN:um" in result.output

