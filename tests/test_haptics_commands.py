"""S3's commands: ``softtip haptics render`` (recorded to MCAP and read back) and ``softtip bench haptics``,
and their refusals of bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from softtip.cli.common import user_errors
from softtip.realtime.recording.reader import read_recording
from softtip.realtime.sinks.ros2 import ros2_available
from softtip.systems.haptics.commands import app as haptics_app
from softtip.systems.haptics.commands import bench_haptics
from softtip.systems.haptics.device import DEVICE_FILE, load_device, servo_angles
from softtip.systems.haptics.live import LOOP_RATE_HZ, TARGET_NAMES

# the CLI as softtip mounts them: the command group, and the bench command
cli = typer.Typer()
cli.add_typer(haptics_app, name="haptics")
cli.command("bench")(user_errors(bench_haptics))
runner = CliRunner()


def run(*args: str):
    return runner.invoke(cli, list(args))


def test_render_records_the_stream_and_reads_back(tmp_path):
    path = tmp_path / "render.mcap"
    result = run("haptics", "render", "--duration", "0.2", "--fs-levels", "7", "--record", str(path), "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["ticks"] == 200 and summary["loop_rate_hz"] == LOOP_RATE_HZ
    assert 0.2 <= summary["wall_s"] < 5  # paced on the wall clock: no faster than the ticks' time
    recording = read_recording(path)
    assert not recording.truncated
    estimates = recording.topics["/fingertip/estimates"]
    assert len(estimates.data) == 200
    values = np.array([m.data for m in estimates.decoded()])
    commands, servos = values[:, 0:3], values[:, 3:6]
    # the servos as the device model moves them: 50 Hz frames of the 1 kHz commands (recomputed here)
    assert np.allclose(servos, servo_angles(load_device(), np.zeros(3), commands, LOOP_RATE_HZ))
    wrench = recording.topics["/fingertip/wrench"].decoded()
    rendered = np.array([[w.wrench.force.x, w.wrench.force.y, w.wrench.force.z] for w in wrench])
    assert np.allclose(rendered, values[:, 6:9])
    wanted = recording.topics["/fingertip/chip0/wanted_force"].decoded()
    assert len(wanted) == 200 and all(np.isfinite(w.wrench.force.z) for w in wanted)
    assert json.loads(recording.metadata["softtip"]["target_names"]) == list(TARGET_NAMES)


def test_render_plays_a_recorded_sensation(tmp_path):
    sensation = tmp_path / "s.csv"
    sensation.write_text("time_s,fx_N,fy_N,fz_N\n0,0,0,0\n0.05,0,0,1.0\n0.1,0.1,0,1.5\n")
    result = run("haptics", "render", "--sensation", str(sensation), "--fs-levels", "7", "--json")
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["ticks"] == 100  # 0.1 s held at 1 kHz


@pytest.mark.parametrize(("args", "words"), [
    (("--duration", "nan"), "--duration = nan"),
    (("--duration", "-1"), "--duration = -1"),
    (("--duration", "inf"), "--duration = inf"),
    (("--duration", "1e9"), "expected at most 3600 s"),
    (("--fingertip", "thumb"), "--fingertip = 'thumb'"),
    (("--method", "magic"), "--method = 'magic'"),
    (("--fs-levels", "1"), "--fs-levels = 1"),
    (("--seed", "-2"), "--seed = -2"),
    (("--foxglove-port", "0"), "--foxglove-port = 0"),
    (("--device", "missing.toml"), "missing.toml"),
    (("--sensation", "missing.csv"), "missing.csv"),
    (("--sensation", "bad.txt"), "expected a .csv or .parquet"),
    (("--ros2",), "--ros2: ROS 2 is not available"),
])
def test_render_refuses_bad_input_in_one_line(args, words, tmp_path, monkeypatch):
    if args == ("--ros2",) and ros2_available():
        pytest.skip("ROS 2 is installed here")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.txt").write_text("x")
    result = run("haptics", "render", *args)
    assert result.exit_code == 2, result.output
    assert words in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_render_refuses_bad_sensation_files_and_outputs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for name, text, words in (("nan.csv", "time_s,fx_N,fy_N,fz_N\n0,0,0,nan\n", "finite"),
                              ("back.csv", "time_s,fx_N,fy_N,fz_N\n0,0,0,1\n0,0,0,1\n", "increase"),
                              ("cols.csv", "time_s,fx_N\n0,1\n", "missing column fy_N")):
        (tmp_path / name).write_text(text)
        result = run("haptics", "render", "--sensation", name)
        assert result.exit_code == 2 and words in result.stderr, result.output
    (tmp_path / "taken.mcap").write_text("")
    result = run("haptics", "render", "--record", "taken.mcap")
    assert result.exit_code == 2 and "--record" in result.stderr and "--force" in result.stderr
    broken = tmp_path / "device.toml"
    broken.write_text(DEVICE_FILE.read_text().replace("stiffness = 200.0",
                                                                                   "stiffness = -1.0"))
    result = run("haptics", "render", "--device", "device.toml")
    assert result.exit_code == 2 and "stiffness" in result.stderr


def test_bench_reports_each_figure_beside_its_baseline():
    result = run("bench", "--queries", "300", "--repeats", "1", "--no-reproduce", "--json")
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    rendering, table = report["rendering"], report["personalised_table_13^3"]
    assert rendering["queries"] == 300 and rendering["p99_us"] >= rendering["p50_us"] > 0
    assert rendering["baseline_cKDTree_query_p99_us"] > 0 and table["entries"] > 1000
    assert table["geometric_ms"] > 0 and table["data_driven_ms"] > 0
    for args, words in ((("--queries", "0"), "--queries = 0"), (("--repeats", "-1"), "--repeats = -1"),
                        (("--queries", "10000000"), "from 1 to 1000000"),
                        (("--seed", "-1"), "--seed = -1")):
        result = run("bench", *args)
        assert result.exit_code == 2 and words in result.stderr, result.output


def test_render_with_the_geometric_table_follows_a_large_finger():
    common = ("haptics", "render", "--duration", "0.5", "--fs-levels", "9", "--fingertip", "human 3 (10 mm)", "--json")
    standard = json.loads(run(*common).stdout)
    geometric = json.loads(run(*common, "--method", "geometric").stdout)
    # the standard table presses a 10 mm finger as if it were the 7.5 mm FS: far too hard
    assert geometric["median_error_N"] < standard["median_error_N"] / 3
    # a larger finger sits lower: the FS entries that lift the platform highest cannot be reproduced on it
    assert geometric["table_entries_out_of_reach"] > 0 and standard["table_entries_out_of_reach"] == 0


def test_a_sensation_beyond_the_table_is_flagged_every_tick(tmp_path):
    sensation = tmp_path / "hard.csv"
    sensation.write_text("time_s,fx_N,fy_N,fz_N\n0,0,0,500\n0.05,0,0,500\n")
    result = run("haptics", "render", "--sensation", str(sensation), "--fs-levels", "7", "--fast", "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["outside_table"] == summary["ticks"] == 50
