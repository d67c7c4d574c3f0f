"""A researcher's own material: recorded lookup tables read from CSV and Parquet (quantised values
merged by hand), tables exported for firmware (the C header compiled and rendered from by a C
program), fingertip files, and the commands that take them."""

from __future__ import annotations

import dataclasses
import json
import math
import shutil
import subprocess

import numpy as np
import pyarrow as pa
import pytest
from pyarrow import parquet
from typer.testing import CliRunner

from softtip.cli.main import app
from softtip.systems.haptics.collection import CollectionSettings
from softtip.systems.haptics.device import forward_kinematics, load_device
from softtip.systems.haptics.fingertip_file import FingertipFileError, load_fingertip
from softtip.systems.haptics.fingertips import TEST_FINGERTIPS, finger_wrench
from softtip.systems.haptics.live import fs_renderer
from softtip.systems.haptics.rendering import NearestNeighbourRenderer
from softtip.systems.haptics.table_files import TableFileError, c_header, read_table, write_table_csv

DEVICE = load_device()
runner = CliRunner()


def test_a_quantised_table_merges_the_entries_a_sensor_reads_alike(tmp_path):
    # whole degrees and Nano17 steps: rows 0 and 2 read the same force, rows 1 and 3 too
    path = tmp_path / "table.csv"
    path.write_text("motor1_deg,motor2_deg,motor3_deg,fx_N,fy_N,fz_N\n"
                    "10,20,30,0,0,0.5\n"
                    "40,50,60,0.003125,0,1.25\n"
                    "12,20,30,0,0,0.5\n"
                    "40,51,60,0.003125,0,1.25\n"
                    "90,90,90,0,0.00625,2\n")
    table = read_table(path)
    assert table.merged == 2 and table.platform_wrenches is None
    # by hand: the mean motor inputs of each pair, in the order each force first appears
    assert np.allclose(table.wrenches, [[0, 0, 0.5], [0.003125, 0, 1.25], [0, 0.00625, 2]], rtol=0, atol=0)
    assert np.allclose(np.degrees(table.motor_inputs), [[11, 20, 30], [40, 50.5, 60], [90, 90, 90]], rtol=1e-12)


def test_a_parquet_table_with_torques_and_the_ds_reads_back_as_written(tmp_path):
    rng = np.random.default_rng(5)
    wrench, ds, motor = rng.normal(size=(20, 6)), rng.normal(size=(20, 6)), rng.uniform(0, 3, (20, 3))
    names = ["fx_N", "fy_N", "fz_N", "tx_Nm", "ty_Nm", "tz_Nm"]
    columns = {**dict(zip(names, wrench.T)), **{f"ds_{n}": c for n, c in zip(names, ds.T)},
               **{f"motor{k + 1}_rad": c for k, c in enumerate(motor.T)}}
    parquet.write_table(pa.table(columns), tmp_path / "table.parquet")
    table = read_table(tmp_path / "table.parquet", DEVICE)
    assert table.merged == 0
    assert np.array_equal(table.wrenches, wrench) and np.array_equal(table.platform_wrenches, ds)
    assert np.array_equal(table.motor_inputs, motor)


@pytest.mark.parametrize(("text", "words"), [
    ("fx_N,fy_N,motor1_rad,motor2_rad,motor3_rad\n0,0,0,0,0\n1,1,1,1,1\n", "missing column fz_N"),
    ("fx_N,fy_N,fz_N\n0,0,0\n1,1,1\n", "motor inputs as motor1_rad"),
    ("fx_N,fy_N,fz_N,motor1_rad,motor2_rad,motor3_rad,motor1_deg,motor2_deg,motor3_deg\n0,0,0,0,0,0,0,0,0\n"
     "1,1,1,1,1,1,1,1,1\n", "(not both)"),
    ("fx_N,fy_N,fz_N,tz_Nm,motor1_rad,motor2_rad,motor3_rad\n0,0,0,0,0,0,0\n1,1,1,1,1,1,1\n", "missing column tx_Nm"),
    ("fx_N,fy_N,fz_N,ds_fx_N,motor1_rad,motor2_rad,motor3_rad\n0,0,0,0,0,0,0\n1,1,1,1,1,1,1\n",
     "missing column ds_fy_N"),
    ("fx_N,fy_N,fz_N,motor1_rad,motor2_rad,motor3_rad\n0,0,0,0,0,0\n", "1 rows, expected 2 to 29791 entries"),
    ("fx_N,fy_N,fz_N,motor1_rad,motor2_rad,motor3_rad\n0,0,0,0,0,0\n1,inf,1,1,1,1\n", "column fy_N, row 1"),
    ("fx_N,fy_N,fz_N,motor1_rad,motor2_rad,motor3_rad\n0,0,0,0,0,0\n1,1,1,1,x,1\n", "column motor2_rad: expected"),
    ("fx_N,fy_N,fz_N,motor1_deg,motor2_deg,motor3_deg\n0,0,0,0,0,0\n1,1,1,1,1,181\n",
     "column motor3_deg, row 1: 181 is beyond"),
    ("fx_N,fy_N,fz_N,motor1_rad,motor2_rad,motor3_rad\n0,0,0,0,0,0\n1,1,1,-0.1,1,1\n", "column motor1_rad, row 1"),
    ("fx_N,fy_N,fz_N,motor1_rad,motor2_rad,motor3_rad\n0,0,0,0,0,0\n1,1,1,1,1,1\n0,0,1,1,1,1\n",
     "n_neighbours = 8: the table has only 3 distinct entries"),
])
def test_bad_table_files_are_refused_in_one_line(tmp_path, text, words):
    path = tmp_path / "table.csv"
    path.write_text(text)
    with pytest.raises(TableFileError, match=f"table file {path}: .*" + words.replace("(", r"\(").replace(")", r"\)")) \
            as refused:
        read_table(path, DEVICE).renderer()
    assert "\n" not in str(refused.value)


def test_a_table_larger_than_the_largest_fs_table_is_refused_before_it_is_read_further(tmp_path):
    # 31³ rows is the largest FS table --fs-levels collects: one more is refused as --fs-levels 32 is
    rows = np.arange(31**3 + 1)
    path = tmp_path / "huge.csv"
    path.write_text("fx_N,fy_N,fz_N,motor1_rad,motor2_rad,motor3_rad\n" + "".join(f"0,0,{k},0,0,1\n" for k in rows))
    with pytest.raises(TableFileError, match=r"29792 rows, expected 2 to 29791 entries \(the largest FS table, "
                                             r"--fs-levels 31\)"):
        read_table(path, DEVICE)
    path.write_text("fx_N,fy_N,fz_N,motor1_rad,motor2_rad,motor3_rad\n" + "".join(f"0,0,{k},0,0,1\n" for k in rows[1:]))
    assert len(read_table(path, DEVICE).motor_inputs) == 31**3


def test_the_exported_csv_reads_back_into_the_same_renderer(tmp_path):
    renderer = fs_renderer(DEVICE, 7, np.random.default_rng(2))
    write_table_csv(tmp_path / "t.csv", renderer)
    table = read_table(tmp_path / "t.csv", DEVICE)
    again = NearestNeighbourRenderer().fit(table.wrenches, table.motor_inputs)
    wanted = np.random.default_rng(3).normal([0, 0, 2], [1, 1, 2], size=(200, 3))
    assert np.array_equal(again.predict(wanted), renderer.predict(wanted))
    assert np.array_equal(again.render(wanted).outside, renderer.render(wanted).outside)


C_RENDERER = r"""
#include <math.h>
#include <stdio.h>
#include "table.h"
/* brute force: the SOFTTIP_TABLE_NEIGHBOURS nearest entries by insertion, weights 1/d^p */
int main(void) {
    float f[3];
    while (scanf("%f %f %f", &f[0], &f[1], &f[2]) == 3) {
        int nearest[SOFTTIP_TABLE_NEIGHBOURS];
        float distance[SOFTTIP_TABLE_NEIGHBOURS];
        int found = 0;
        for (int i = 0; i < SOFTTIP_TABLE_ENTRIES; ++i) {
            float dx = f[0] - softtip_table_force_N[i][0], dy = f[1] - softtip_table_force_N[i][1],
                  dz = f[2] - softtip_table_force_N[i][2];
            float d = sqrtf(dx * dx + dy * dy + dz * dz);
            int at = found < SOFTTIP_TABLE_NEIGHBOURS ? found++ : SOFTTIP_TABLE_NEIGHBOURS;
            while (at > 0 && distance[at - 1] > d) {
                if (at < SOFTTIP_TABLE_NEIGHBOURS) { distance[at] = distance[at - 1]; nearest[at] = nearest[at - 1]; }
                --at;
            }
            if (at < SOFTTIP_TABLE_NEIGHBOURS) { distance[at] = d; nearest[at] = i; }
        }
        double total = 0, motor[3] = {0, 0, 0};
        for (int k = 0; k < SOFTTIP_TABLE_NEIGHBOURS; ++k) {
            double w = distance[0] == 0 ? (distance[k] == 0) : pow(distance[k], -SOFTTIP_TABLE_WEIGHTING_POWER);
            total += w;
            for (int j = 0; j < 3; ++j) motor[j] += w * softtip_table_motor_deg[nearest[k]][j];
        }
        printf("%.9g %.9g %.9g\n", motor[0] / total, motor[1] / total, motor[2] / total);
    }
    return 0;
}
"""


@pytest.mark.skipif(shutil.which("cc") is None, reason="needs a C compiler")
def test_a_c_program_renders_from_the_exported_header_as_softtip_does(tmp_path):
    renderer = fs_renderer(DEVICE, 9, np.random.default_rng(4))
    (tmp_path / "table.h").write_text(c_header(renderer, "TABLE_H", "a test table"))
    (tmp_path / "render.c").write_text(C_RENDERER)
    subprocess.run(["cc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O1", "-o", str(tmp_path / "render"),
                    str(tmp_path / "render.c"), "-lm"], check=True, capture_output=True)
    # wanted forces away from ties: the table's entries moved by a little
    wanted = renderer.features_[1:60] + np.random.default_rng(6).normal(0, 0.05, (59, 3))
    typed = "\n".join(" ".join(f"{v:.9g}" for v in row) for row in wanted.astype(np.float32))
    printed = subprocess.run([str(tmp_path / "render")], input=typed, text=True, capture_output=True, check=True)
    from_c = np.radians(np.loadtxt(printed.stdout.splitlines()))
    expected = renderer.predict(wanted.astype(np.float32).astype(float))
    # float32 forces and angles: 6e-8 relative, times the weights' sensitivity to distances near 0.05 N
    assert np.allclose(from_c, expected, rtol=0, atol=2e-5)
    header = (tmp_path / "table.h").read_text()
    assert f"#define SOFTTIP_TABLE_ENTRIES {len(renderer.features_)}" in header
    assert "#define SOFTTIP_TABLE_NEIGHBOURS 8" in header


def test_a_fingertip_file_gives_the_fingertip_it_describes(tmp_path):
    path = tmp_path / "finger.toml"
    path.write_text('[fingertip]\nname = "human 3 again"\nradius_mm = 10.0\nshape = "ellipsoid"\n')
    # an ellipsoidal cast of 10 mm: the shipped human cast of that size, shape, contact law and all
    assert load_fingertip(path) == dataclasses.replace(TEST_FINGERTIPS[-1], name="human 3 again")
    path.write_text('[fingertip]\nname = "pulp"\nradius_mm = 8.0\nlaw = "exponential"\n'
                    'stiffness_N_per_m = 400\nstiffening_per_m = 1500\ncore_offset_mm = [0, 0, 1.5]\n'
                    'mounting = "nail"\n')
    finger = load_fingertip(path)
    assert finger.mounting == "nail" and finger.core_offset == pytest.approx((0, 0, 1.5e-3))
    # resting on the nail, its top where the FS's is: its centre 0.5 mm lower than the device's
    assert finger.centre(DEVICE)[2] == pytest.approx(DEVICE.centre[2] - 0.5e-3, abs=1e-15)
    # a level platform 0.5 mm into the pad's lowest point: Pawluk and Howe's law by hand, F = (b/m)(e^{mδ} − 1)
    lowest = finger.centre(DEVICE)[2] - finger.semi_axes[2]
    pose = forward_kinematics(DEVICE, np.zeros((1, 3)))
    pose = type(pose)(np.array([[0.0, 0.0, lowest + 0.5e-3]]), pose.normal)
    wrench, depth = finger_wrench(finger, DEVICE, pose)
    assert depth[0] == pytest.approx(0.5e-3, rel=1e-9)
    assert np.linalg.norm(wrench[0, :3]) == pytest.approx(400 / 1500 * math.expm1(1500 * 0.5e-3), rel=1e-9)
    path.write_text('[fingertip]\nname = "flat"\nradius_mm = 8.0\nshape = "pad"\n')
    assert load_fingertip(path).semi_axes == pytest.approx([10.4e-3, 10.4e-3, 8e-3])


@pytest.mark.parametrize(("text", "words"), [
    ('[fingertip]\nname = "x"\nradius_mm = 5.0\n', "fingertip.radius_mm = 5.0: expected 6.5 to 11 mm for a cast"),
    ('[fingertip]\nname = "x"\nradius_mm = 9.0\nlaw = "jelly"\n', "fingertip.law = 'jelly'"),
    ('[fingertip]\nname = "x"\nradius_mm = 9.0\nyoungs_modulus_MPa = -1\n', "fingertip.youngs_modulus_MPa = -1"),
    ('[fingertip]\nname = "x"\nradius_mm = 9.0\nmounting = "glove"\n', "fingertip.mounting = 'glove'"),
    ('[fingertip]\nradius_mm = 9.0\n', "fingertip.name is missing"),
    ('[fingertip]\nname = "x"\nradius_mm = 9.0\n[device]\n', "unknown table or key 'device'"),
    ('name = "x"\n', "unknown table or key 'name'"),
    ("[fingertip\n", "not valid TOML"),
])
def test_bad_fingertip_files_are_refused_in_one_line(tmp_path, text, words):
    path = tmp_path / "finger.toml"
    path.write_text(text)
    with pytest.raises(FingertipFileError, match=words.replace("(", r"\(").replace(".", r"\.")) as refused:
        load_fingertip(path)
    assert "\n" not in str(refused.value) and "finger.toml" in str(refused.value)


def test_render_takes_a_fingertip_file_and_a_recorded_table(tmp_path):
    finger = tmp_path / "finger.toml"
    finger.write_text('[fingertip]\nname = "my 10 mm finger"\nradius_mm = 10.0\nshape = "ellipsoid"\n')
    table = tmp_path / "fs.csv"
    exported = runner.invoke(app, ["haptics", "table", "export", str(tmp_path / "fs.h"), "--csv", str(table),
                                   "--fs-levels", "9", "--json"])
    assert exported.exit_code == 0, exported.output
    summary = json.loads(exported.stdout)
    assert summary["entries"] == len(read_table(table).wrenches)
    result = runner.invoke(app, ["haptics", "render", "--duration", "0.3", "--fast", "--fingertip", str(finger),
                                 "--method", "geometric", "--table", str(table), "--json"])
    assert result.exit_code == 0, result.output
    rendered = json.loads(result.stdout)
    assert rendered["fingertip"] == "my 10 mm finger" and rendered["table"] == str(table)
    # the same as the shipped 10 mm cast (the file describes it) on the same recorded table
    shipped = runner.invoke(app, ["haptics", "render", "--duration", "0.3", "--fast", "--fingertip", "human 3 (10 mm)",
                                  "--method", "geometric", "--table", str(table), "--json"])
    again = json.loads(shipped.stdout)
    assert rendered["median_error_N"] == again["median_error_N"] and rendered["p90_error_N"] == again["p90_error_N"]
    # the device model presses the file's shape: a 10 mm sphere, which B takes alike, feels another force
    finger.write_text('[fingertip]\nname = "my 10 mm sphere"\nradius_mm = 10.0\n')
    sphere = runner.invoke(app, ["haptics", "render", "--duration", "0.3", "--fast", "--fingertip", str(finger),
                                 "--method", "geometric", "--table", str(table), "--json"])
    assert json.loads(sphere.stdout)["median_error_N"] != again["median_error_N"]


def test_exported_table_is_the_personalised_one_for_the_geometric_method(tmp_path):
    result = runner.invoke(app, ["haptics", "table", "export", str(tmp_path / "b.h"), "--csv", str(tmp_path / "b.csv"),
                                 "--fs-levels", "7", "--method", "geometric", "--fingertip", "human 3 (10 mm)"])
    assert result.exit_code == 0, result.output
    standard = fs_renderer(DEVICE, 7, np.random.default_rng(1))
    table = read_table(tmp_path / "b.csv")
    # the same forces, the motor inputs moved by the geometric method: the 10 mm finger's pad sits lower
    assert np.allclose(table.wrenches, standard.features_, rtol=0, atol=0)
    assert np.all(table.motor_inputs.sum(axis=1)[1:] <= standard.motor_inputs_.sum(axis=1)[1:] + 1e-12)
    assert not np.allclose(table.motor_inputs, standard.motor_inputs_)


def _protocol(tmp_path, **top):
    from softtip.lab.protocols import protocol_from_dict

    parameters = {"trials": 12, "fs_levels": 7, "user_levels": 6, "fingertips": ["human 3 (10 mm)"],
                  "curve_n_neighbours": [], "curve_weighting_powers": [], "curve_fs_levels": [], "curve_user_levels": [],
                  "variations": []}
    return protocol_from_dict({"protocol": "haptics", "seed": 3, "parameters": parameters, **top}, "test.toml", tmp_path)


def test_a_protocol_takes_fingertip_files_and_a_recorded_fs_table(tmp_path):
    from softtip.lab import run_protocol
    from softtip.systems.haptics.study import fs_table

    (tmp_path / "mine.toml").write_text('[fingertip]\nname = "mine"\nradius_mm = 10.0\n')
    simulated = _protocol(tmp_path)
    # the FS table the simulated study collects, written as a researcher's recording (with the DS's readings)
    fs = fs_table(DEVICE, 7, simulated.parameters.collection_settings(), 3)
    names = ["fx_N", "fy_N", "fz_N", "tx_Nm", "ty_Nm", "tz_Nm"]
    columns = {**dict(zip(names, fs.finger_wrenches.T)), **{f"ds_{n}": c for n, c in zip(names, fs.platform_wrenches.T)},
               **{f"motor{k + 1}_rad": c for k, c in enumerate(fs.motor_inputs.T)}}
    parquet.write_table(pa.table(columns), tmp_path / "fs.parquet")
    recorded = _protocol(tmp_path, fingertip_files=["mine.toml"], fs_table="fs.parquet")
    assert [f.name for f in recorded.design.fingertips] == ["mine"]
    expected, _ = run_protocol(simulated)
    found, _ = run_protocol(recorded)
    rows = found.column("fingertip") == "human 3 (10 mm)"
    # the recording is the simulation's own table: the study renders exactly as the simulated one did
    assert np.array_equal(found.column("error_N")[rows], expected.column("error_N"))
    assert found.metadata.sensor_settings["fs_table"] == str(tmp_path / "fs.parquet")
    # the file's fingertip is the 10 mm cast: the same commanded motor inputs for the noise-free methods
    methods = found.column("method")
    for method in ("standard", "geometric (B)"):
        mine, cast = (found.column("fingertip") == "mine") & (methods == method), rows & (methods == method)
        for motor in ("motor1_rad", "motor2_rad", "motor3_rad"):
            assert np.array_equal(found.column(motor)[mine], found.column(motor)[cast])


def test_an_exported_fs_table_feeds_a_protocol_that_renders_as_the_simulated_one(tmp_path):
    from softtip.lab import run_protocol

    exported = runner.invoke(app, ["haptics", "table", "export", str(tmp_path / "fs.h"), "--fs-table",
                                   str(tmp_path / "fs.csv"), "--fs-levels", "7", "--seed", "3", "--json"])
    assert exported.exit_code == 0, exported.output
    table = read_table(tmp_path / "fs.csv", DEVICE)
    assert table.merged == 0 and table.platform_wrenches is not None and table.wrenches.shape[1] == 6
    # the header is the renderer on that same table
    assert json.loads(exported.stdout)["entries"] == len(NearestNeighbourRenderer().fit(table.wrenches,
                                                                                         table.motor_inputs).features_)
    expected, _ = run_protocol(_protocol(tmp_path))
    found, _ = run_protocol(_protocol(tmp_path, fs_table="fs.csv"))
    # the researcher's round trip: the study on the exported table renders exactly as on its own collection
    assert np.array_equal(found.column("error_N"), expected.column("error_N"))
    assert np.array_equal(found.column("motor1_rad"), expected.column("motor1_rad"))
    refused = runner.invoke(app, ["haptics", "table", "export", str(tmp_path / "b.h"), "--fs-table",
                                  str(tmp_path / "b.csv"), "--method", "geometric"])
    assert refused.exit_code == 2 and "--fs-table with --method = 'geometric'" in refused.stderr
    plain = runner.invoke(app, ["haptics", "table", "export", str(tmp_path / "c.h"), "--csv", str(tmp_path / "c.csv")])
    assert plain.exit_code == 0
    refused = runner.invoke(app, ["haptics", "table", "export", str(tmp_path / "d.h"), "--table",
                                  str(tmp_path / "c.csv"), "--fs-table", str(tmp_path / "d.csv")])
    assert refused.exit_code == 2 and "has no DS readings" in refused.stderr and not (tmp_path / "d.h").exists()


_WRENCH = ("fx_N", "fy_N", "fz_N", "tx_Nm", "ty_Nm", "tz_Nm")


def _imported_fs_table(tmp_path, labels: bool = True):
    """The study's 7³ FS table at seed 3 logged as a rig would (two log files, one per trial) and brought in
    by ``softtip import``: the FS's forces as an "other" chip, and with ``labels`` every table column as a label."""
    from softtip.systems.haptics.study import fs_table

    fs = fs_table(DEVICE, 7, CollectionSettings(), 3)
    names = [*_WRENCH, *(f"ds_{n}" for n in _WRENCH), "motor1_rad", "motor2_rad", "motor3_rad"]
    values = np.hstack([fs.finger_wrenches, fs.platform_wrenches, fs.motor_inputs])
    half = len(values) // 2
    for name, rows, start in (("a.csv", values[:half], 0), ("b.csv", values[half:], half)):
        (tmp_path / name).write_text("t," + ",".join(names) + "\n" + "".join(
            f"{(start + k) * 0.01!r}," + ",".join(map(repr, map(float, row))) + "\n" for k, row in enumerate(rows)))
    units = {"N": "N", "Nm": "Nm", "rad": "rad"}
    columns = ", ".join(f'{n} = {{ column = "{n}", unit = "{units[n.rsplit("_", 1)[1]]}" }}' for n in names)
    (tmp_path / "map.toml").write_text(
        '[sensor]\ntime = "t"\nchip = "other"\nname = "fs"\nunit = "N"\nchips = [["fx_N", "fy_N", "fz_N"]]\n'
        + (f"[labels]\ncolumns = {{ {columns} }}\n" if labels else "")
        + '[trials]\nsplit = "file"\nvalidation = { last = 1 }\nbaseline = { samples = 1 }\n')
    made = runner.invoke(app, ["import", str(tmp_path / "a.csv"), str(tmp_path / "b.csv"), "-m",
                               str(tmp_path / "map.toml"), "-o", str(tmp_path / "imported.parquet"), "--force"])
    assert made.exit_code == 0, made.output
    return fs, tmp_path / "imported.parquet"


def test_a_table_brought_in_by_softtip_import_is_a_table_file(tmp_path):
    fs, imported = _imported_fs_table(tmp_path)
    # as a protocol's fs_table: exactly the collection it was logged from, so the study renders as on it
    recorded = _protocol(tmp_path, fs_table="imported.parquet").design.fs
    for name in ("finger_wrenches", "platform_wrenches", "motor_inputs"):
        assert np.array_equal(getattr(recorded, name), getattr(fs, name)), name
    # and for --table: the renderer on the dataset is the renderer on the collection
    result = runner.invoke(app, ["haptics", "table", "export", str(tmp_path / "t.h"), "--table", str(imported),
                                 "--csv", str(tmp_path / "t.csv"), "--json"])
    assert result.exit_code == 0, result.output
    direct = NearestNeighbourRenderer().fit(fs.finger_wrenches, fs.motor_inputs)
    assert np.array_equal(read_table(tmp_path / "t.csv").wrenches, direct.features_)
    # a dataset is verified as every dataset is: one flipped byte is refused in one line naming the file
    damaged = tmp_path / "damaged.parquet"
    content = bytearray(imported.read_bytes())
    content[len(content) // 3] ^= 0x01
    damaged.write_bytes(bytes(content))
    with pytest.raises(TableFileError, match=f"table file {damaged}: ") as refused:
        read_table(damaged, DEVICE)
    assert "\n" not in str(refused.value)


def test_a_dataset_without_the_table_s_labels_is_refused_naming_the_fix(tmp_path):
    from softtip.data import DatasetMetadata, TrialWriter

    _, imported = _imported_fs_table(tmp_path, labels=False)
    with pytest.raises(TableFileError, match=r"missing column fx_N .*; a softtip dataset holds them as labels of "
                                             r"these names: softtip import \.\.\. --label fx_N=COLUMN:N"):
        read_table(imported, DEVICE)
    # a label whose unit is not its name's is refused: the name is what the reader trusts
    writer = TrialWriter({"fs0_x_N": "N"}, labels={"fx_N": "g", "fy_N": "N", "fz_N": "N", "motor1_rad": "rad",
                                                   "motor2_rad": "rad", "motor3_rad": "rad"},
                         metadata=DatasetMetadata(seed=0))
    ramp = np.linspace(0, 1, 10)
    writer.add({"time_s": ramp, "fs0_x_N": ramp, "fx_N": ramp, "fy_N": ramp, "fz_N": ramp, "motor1_rad": ramp,
                "motor2_rad": ramp, "motor3_rad": ramp})
    writer.write(tmp_path / "grams.parquet")
    with pytest.raises(TableFileError, match="grams.parquet: label fx_N is declared in g, expected N as its name says"):
        read_table(tmp_path / "grams.parquet", DEVICE)


@pytest.mark.parametrize(("top", "words"), [
    ({"fingertip_files": ["missing.toml"]}, "missing.toml"),
    ({"fingertip_files": ["same.toml"]}, "fingertip_files = .*'human 3 \\(10 mm\\)' is used twice"),
    ({"fs_table": "plain.csv"}, "plain.csv: the study's personalisation A needs the DS's readings"),
    ({"fs_table": "missing.csv"}, "missing.csv does not exist"),
    ({"fs_table": "small.csv"}, "small.csv: n_neighbours = 8: the table has only 2 distinct entries"),
])
def test_bad_researcher_files_in_a_protocol_are_refused_in_one_line(tmp_path, top, words):
    (tmp_path / "same.toml").write_text('[fingertip]\nname = "human 3 (10 mm)"\nradius_mm = 10.0\n')
    (tmp_path / "plain.csv").write_text("fx_N,fy_N,fz_N,motor1_rad,motor2_rad,motor3_rad\n0,0,0,0,0,0\n0,0,1,1,1,1\n")
    ds = ",".join(f"ds_{n}" for n in ("fx_N", "fy_N", "fz_N", "tx_Nm", "ty_Nm", "tz_Nm"))
    (tmp_path / "small.csv").write_text(f"fx_N,fy_N,fz_N,motor1_rad,motor2_rad,motor3_rad,{ds}\n"
                                        "0,0,0,0,0,0,0,0,0,0,0,0\n0,0,1,1,1,1,0,0,-1,0,0,0\n")
    with pytest.raises(ValueError, match=words) as refused:
        _protocol(tmp_path, **top)
    assert "\n" not in str(refused.value)
