"""Every check before the work: outputs never written over inputs or existing files without --force,
numbers that cannot be meant refused, sizes estimated and refused above the stated limit; one line each,
before any mesh, scenario or fit; help that reads as text."""

from __future__ import annotations

import hashlib
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from softtip.cli.main import app

DATA = Path(__file__).parent / "data"
runner = CliRunner()


def run(*args):
    return runner.invoke(app, [str(a) for a in args])


def refused(result, *words: str) -> str:
    lines = result.output.strip().splitlines()
    assert result.exit_code == 2 and len(lines) == 1 and "Traceback" not in result.output, result.output
    assert all(word in lines[0] for word in words), lines[0]
    return lines[0]


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def quick(*args, seconds: float = 3.0) -> str:
    """Refused within ``seconds``: before any mesh, scenario or fit (each takes far longer)."""
    started = time.perf_counter()
    result = run(*args)
    assert time.perf_counter() - started < seconds, result.output
    return result


@pytest.fixture
def dataset(tmp_path):
    from softtip.data import DatasetMetadata, TrialWriter, channel_columns

    writer = TrialWriter(1, labels={"fz_N": "N"}, conditions={"role": "1"}, metadata=DatasetMetadata(seed=0))
    for trial in range(6):
        force = np.linspace(0, 2 + trial / 3, 30)
        writer.add({"time_s": np.arange(30) / 20, **channel_columns(np.stack([np.column_stack(
            [3 * force, -2 * force, 50 * force])], axis=1)), "fz_N": force}, {"role": "calibration"})
    path = tmp_path / "d.parquet"
    writer.write(path)
    return path


@pytest.fixture
def recording_csv(tmp_path):
    rng = np.random.default_rng(0)
    u = rng.normal(size=300)
    y = np.convolve(u, [0.0, 0.5, 0.25])[:300]
    path = tmp_path / "r.csv"
    path.write_text("time_s,u,y\n" + "".join(f"{k * 0.01},{a},{b}\n" for k, (a, b) in enumerate(zip(u, y))))
    return path


def test_calibrate_never_writes_its_model_over_the_dataset(dataset):
    before = digest(dataset)
    refused(run("calibrate", dataset, "-t", "fz_N", "-o", dataset), "--output", "is the input")
    assert digest(dataset) == before


def test_calibrate_warns_when_the_dataset_has_no_validation_split(dataset, tmp_path):
    result = run("calibrate", dataset, "-t", "fz_N", "--model", "polynomial", "-o", tmp_path / "m.npz", "--json")
    assert result.exit_code == 0
    assert "warning:" in result.output and "no validation samples" in result.output


def test_calibrate_refuses_a_target_given_twice_and_an_existing_model_without_force(dataset, tmp_path):
    refused(run("calibrate", dataset, "-t", "fz_N", "-t", "fz_N"), "--target", "twice")
    model = tmp_path / "m.npz"
    model.write_bytes(b"another kind of model")
    refused(run("calibrate", dataset, "-t", "fz_N", "-o", model), "--output", "--force")
    assert model.read_bytes() == b"another kind of model"


def test_sysid_outputs_are_never_an_input(recording_csv, tmp_path):
    before = digest(recording_csv)
    common = ("-u", "u", "-y", "y", "--kind", "ss", "--order", "2")
    refused(run("sysid", "fit", "--data", recording_csv, *common, "-o", recording_csv), "--model", "is the input")
    validation = shutil.copy(recording_csv, tmp_path / "v.csv")
    refused(run("sysid", "fit", "--data", recording_csv, *common, "--validate", validation, "--bode", validation),
            "--bode")
    model = tmp_path / "m.npz"
    assert run("sysid", "fit", "--data", recording_csv, *common, "-o", model).exit_code == 0
    refused(run("sysid", "predict", model, "--data", recording_csv, "-o", recording_csv), "--out", "is the input")
    assert digest(recording_csv) == before


def test_sysid_orders_refuses_repeats_and_a_too_high_order_before_fitting(recording_csv, monkeypatch):
    refused(run("sysid", "orders", "--data", recording_csv, "-u", "u", "-y", "y", "--kind", "ss", "--orders", "2,2,2"),
            "--orders")
    refused(run("sysid", "fit", "--data", recording_csv, "-u", "u", "-u", "u", "-y", "y", "--kind", "ss",
                "--order", "2"), "--input", "twice")
    from softtip.sysid import models

    fitted = []
    original = models.StateSpaceModel._identify
    monkeypatch.setattr(models.StateSpaceModel, "_identify", lambda self, r: fitted.append(self) or original(self, r))
    refused(run("sysid", "orders", "--data", recording_csv, "-u", "u", "-y", "y", "--kind", "ss", "--orders", "1,2,300"),
            "too few samples for order 300")
    assert fitted == []  # refused before the orders below it were fitted


def test_convert_never_writes_over_its_recording(tmp_path):
    recording = shutil.copy(DATA / "recording-0.1.0.mcap", tmp_path / "r.mcap")
    before = digest(recording)
    refused(run("convert", recording, recording), "OUTPUT", "is the input")
    assert digest(recording) == before


@pytest.mark.parametrize("args, words", [
    (("live", "--emulate", "--duration", "nan"), ("--duration", "finite")),
    (("live", "--emulate", "--duration", "inf"), ("--duration", "finite")),
    (("live", "--emulate", "--duration", "-1"), ("--duration",)),
    (("live", "--emulate", "--duration", "0"), ("--duration",)),
    (("live", "--emulate", "--rate", "0"), ("--rate",)),
    (("live", "--emulate", "--rate", "-1"), ("--rate",)),
    (("live", "--emulate", "--chips", "0"), ("--chips",)),
    (("live", "--emulate", "--baseline-frames", "0"), ("--baseline-frames",)),
    (("live", "--emulate", "--foxglove", "70000"), ("--foxglove", "65535")),
    (("live", "--emulate", "--scenario", "nowhere"), ("--scenario",)),
    (("demo", "--duration", "nan"), ("--duration",)),
    (("demo", "--duration", "0"), ("--duration",)),
    (("demo", "wearable", "--duration", "inf"), ("--duration",)),
    (("demo", "wearable", "--duration", "-1"), ("--duration",)),
    (("simulate", "--depth", "20"), ("--depth", "deeper than", "9 mm")),
    (("simulate", "--mesh-size", "0.05"), ("--mesh-size", "tetrahedra", "--force")),
    (("simulate", "--x", "1e300"), ("--x",)),
    (("simulate", "--plot", "missing/a.png"), ("--plot", "does not exist")),
    (("bench", "live", "--rate", "0"), ("--rate",)),
    (("bench", "twin", "--poses", "1000000000000"), ("--poses",)),
    (("sysid", "predict", "m.npz", "--data", "d.csv", "--full-scale", "nan"), ("--full-scale", "nan")),
])
def test_bad_numbers_and_paths_are_refused_before_any_work(args, words, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    refused(quick(*args), *words)


def test_live_record_refuses_an_existing_file_before_the_scenario(tmp_path):
    record = tmp_path / "r.mcap"
    record.write_bytes(b"an afternoon's recording")
    refused(quick("live", "--emulate", "--record", record), "--record", "--force")
    refused(quick("demo", "--record", record), "--record", "--force")
    refused(quick("demo", "wearable", "--record", record), "--record", "--force")
    assert record.read_bytes() == b"an afternoon's recording"


@pytest.mark.parametrize("args, words", [
    (("--scenario", "push", "--chips", "3"), ("--chips = 3", "push scenario streams 1")),
    (("--scenario", "insertion", "--chips", "1"), ("--chips = 1", "insertion scenario streams 4")),
    (("--scenario", "wearable", "--rate", "50"), ("--rate = 50", "wearable scenario streams at 10 Hz")),
])
def test_options_a_scenario_contradicts_are_refused_before_it_is_computed(args, words, monkeypatch):
    import softtip.systems.hall_fingertip.live as fingertip_live
    import softtip.systems.wearable.live as wearable_live

    def computed(*args, **kwargs):
        raise AssertionError("the scenario was computed before its options were checked")

    monkeypatch.setattr(fingertip_live, "cached_scenario", computed)
    monkeypatch.setattr(wearable_live, "wearable_live_setup", computed)
    refused(run("live", "--emulate", *args), *words)


def test_study_outputs_given_as_a_file_are_refused_before_the_study(tmp_path):
    afile = tmp_path / "report.txt"
    afile.write_text("mine")
    refused(quick("reproduce", "pushing", "-o", afile), "--output", "is a file")
    config = Path(__file__).parents[1] / "examples" / "estimation-grid.toml"
    refused(quick("optimize", "--config", config, "--output", afile), "--output", "is a file")
    refused(quick("lab", "run", "pushing", "-o", afile), "--output", "--force")
    assert afile.read_text() == "mine"


def shipped_with(name: str, old: str, new: str, folder: Path) -> Path:
    """A copy of the shipped protocol ``name`` with one line changed."""
    from softtip.lab.protocols import shipped_protocol_path

    text = shipped_protocol_path(name).read_text()
    assert old in text
    path = folder / f"{name}-edited.toml"
    path.write_text(text.replace(old, new))
    return path


@pytest.mark.parametrize("name, old, new, words", [
    ("wearable", "participants = 3", "participants = 100000", ("4.2e+09 simulated samples", "participants x runs")),
    ("wearable", "trial_s = 15.0", "trial_s = 1e6", ("6.3e+09 simulated samples",)),
    ("pushing", "calibration_trials = 10", "calibration_trials = 1000000", ("4.9e+08 frames",)),
])
def test_protocols_asking_for_too_much_work_are_refused_before_the_bench(name, old, new, words, tmp_path):
    # hand-computed estimates: wearable 1e5 participants x 3 runs x 7 motions x 1 contact x (5 + 15 s) x 100 Hz;
    # 3 x 3 x 7 x (5 + 1e6 s) x 100 Hz; pushing 7 angles x (1e6 + 5 trials) x 3.5 s x 20 Hz
    protocol = shipped_with(name, old, new, tmp_path)
    line = refused(quick("lab", "run", protocol, "-o", tmp_path / "d.parquet"), f"protocol {name}", "--force", *words)
    assert "above the limit" in line and not (tmp_path / "d.parquet").exists()


def test_shipped_protocols_are_within_their_limits_and_estimated_as_their_datasets_are_counted():
    from softtip._core.systems import names
    from softtip.lab import load_protocol
    from softtip.lab.protocols import check_size

    for name in names("protocol"):
        check_size(load_protocol(name))
    pushing = load_protocol("pushing")
    size = pushing.bench.size("pushing", pushing.parameters)
    assert size.amount == pytest.approx(7 * 15 * (0.5 + 3.0 / 1.0) * 20)  # angles x trials x trial (s) x rate


def test_a_study_grid_too_fine_is_refused_without_making_it(tmp_path):
    config = Path(__file__).parents[1] / "examples" / "published-grid.toml"
    text = config.read_text().replace("step = 0.1", "step = 1e-300")
    study = tmp_path / "fine.toml"
    study.write_text(text.replace('design = "cylindrical-A"', 'design = "cylindrical-A"'))
    refused(quick("optimize", "--config", study), "1e+301 designs", "larger steps")


def test_a_usage_error_is_one_line_naming_the_option():
    refused(run("simulate", "--depth", "abc"), "--depth")
    refused(run("simulate", "--bogus"), "--bogus")


def test_help_reads_as_text():
    import os

    for words in (["live"], ["sysid", "fit"], ["simulate"], ["bench", "magnetics"], ["recording", "repair"],
                  ["reproduce"], ["convert"]):
        text = runner.invoke(app, [*words, "--help"], env={**os.environ, "COLUMNS": "200"}).output
        assert "<bool>" not in text and "list[" not in text and "<str>" not in text, text
    live = runner.invoke(app, ["live", "--help"], env={**os.environ, "COLUMNS": "200"}).output
    assert "push|insertion|wearable" in live  # the scenarios as choices
    # a docstring's line break, where the source wrapped, is not the reader's line break
    demo = runner.invoke(app, ["demo", "wearable", "--help"], env={**os.environ, "COLUMNS": "400"}).output
    assert "identified on them, and the emulated side chip" in demo


@pytest.mark.parametrize("unit", ["furlongs", "kN"])
def test_a_label_declared_in_another_unit_than_its_name_says_is_refused(tmp_path, unit):
    from softtip.data import DatasetMetadata, TrialWriter, channel_columns

    writer = TrialWriter(1, labels={"fz_N": unit}, conditions={"role": "1"}, metadata=DatasetMetadata(seed=0))
    force = np.linspace(0, 2, 30)
    for role in ("calibration", "validation"):
        writer.add({"time_s": np.arange(30) / 20, **channel_columns(np.stack([np.column_stack(
            [3 * force, -2 * force, 50 * force])], axis=1)), "fz_N": force}, {"role": role})
    path = tmp_path / "d.parquet"
    writer.write(path)
    refused(run("calibrate", path, "-t", "fz_N", "-o", tmp_path / "m.npz"), "fz_N", unit, "'N'")
    assert not (tmp_path / "m.npz").exists()


@pytest.mark.parametrize("tesla", [0.5, 3.3])
def test_readings_beyond_what_the_chip_can_output_are_refused(tmp_path, tesla):
    from softtip.data import DatasetMetadata, TrialWriter, channel_columns
    from softtip.sensors.mlx90393 import MLX90393Settings, full_scale_uT

    # the widest range of the chip, from its datasheet tables: the bound a reading of 0.5 T exceeds
    assert 2 * full_scale_uT(MLX90393Settings(gain_sel=0, res_xyz=(3, 3, 3))).max() < 0.5e6
    writer = TrialWriter(1, labels={"fz_N": "N"}, conditions={"role": "1"}, metadata=DatasetMetadata(seed=0))
    force = np.linspace(0, 2, 30)
    for role in ("calibration", "validation"):
        field = np.stack([np.column_stack([3 * force, -2 * force, tesla * 1e6 * force / 2])], axis=1)
        writer.add({"time_s": np.arange(30) / 20, **channel_columns(field), "fz_N": force}, {"role": role})
    path = tmp_path / "d.parquet"
    writer.write(path)
    refused(run("calibrate", path, "-t", "fz_N", "-o", tmp_path / "m.npz"), "s0_bz_uT", "MLX90393")
