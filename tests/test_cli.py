"""The softtip command line: output contract, cross-checks, and one-line errors."""

from __future__ import annotations

import json

import magpylib
import numpy as np
import pytest
import scipy.stats
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from softtip.cli.main import app
from softtip.design.model import load_design, shipped_design_path
from softtip.sensors.mlx90393 import MLX90393Settings, lsb_uT, noise_rms_uT

runner = CliRunner()
FAST = ["--mesh-size", "2.0"]


def run(*args: str):
    return runner.invoke(app, list(args))


@pytest.fixture(scope="module")
def board_push():
    result = run("simulate", "--design", "cylindrical-D", "--indenter", "board", "--depth", "1.0", "--angle", "45",
                 "--json", *FAST)
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


def test_simulate_json_has_the_documented_fields(board_push):
    assert len(board_push["magnets"]) == 4 and len(board_push["sensors"]) == 1
    for magnet in board_push["magnets"]:
        for key, length in (("feature_displacement_mm", 3), ("position_mm", 3), ("rotvec", 3),
                            ("dimension_mm", 2), ("polarization_T", 3)):
            assert len(magnet[key]) == length
    assert len(board_push["sensors"][0]["dB_uT"]) == 3
    assert len(board_push["force_N"]) == 3 and board_push["force_N"][2] > 0
    assert "contact_solve_s" in board_push["timings_s"]
    # a board at 45 degrees presses all four magnets alike (they sit at 0, 90, 180 and 270 degrees)
    dz = [m["feature_displacement_mm"][2] for m in board_push["magnets"]]
    assert max(dz) < 0 and np.ptp(dz) < 0.03 * abs(np.mean(dz))


def test_printed_poses_reproduce_the_printed_field_in_magpylib(board_push):
    def field(poses):
        magnets = [magpylib.magnet.Cylinder(polarization=m["polarization_T"],
                                            dimension=np.array(m["dimension_mm"]) * 1e-3,
                                            position=np.array(p) * 1e-3, orientation=Rotation.from_rotvec(r))
                   for m, (p, r) in zip(board_push["magnets"], poses)]
        sensor = np.array(board_push["sensors"][0]["position_mm"]) * 1e-3
        return magpylib.getB(magnets, sensor, sumup=True)

    loaded = field([(m["position_mm"], m["rotvec"]) for m in board_push["magnets"]])

    rest = field([(np.array(m.center) * 1e3, [0, 0, 0]) for m in load_design("cylindrical-D").magnets])
    np.testing.assert_allclose(board_push["sensors"][0]["dB_exact_uT"], (loaded - rest) * 1e6, atol=0.01)


def test_noise_off_gives_the_exact_field_and_noise_on_has_the_noise_models_spread(tmp_path):
    # cylindrical-D with 16 chips on a 4 x 4 grid in its cavity: 48 noisy axes from one push
    grid = [[x, y, 0.8] for x in (-4.5, -1.5, 1.5, 4.5) for y in (-4.5, -1.5, 1.5, 4.5)]
    design = tmp_path / "sixteen-chips.toml"
    design.write_text(shipped_design_path("cylindrical-D").read_text().replace(
        "positions_mm = [[0.0, 0.0, 0.8]]", f"positions_mm = {grid}"))
    push = ("simulate", "--design", str(design), "--angle", "45", "--json", *FAST)
    off, on = (json.loads(run(*push, "--noise", switch).stdout)["sensors"] for switch in ("off", "on"))
    assert len(on) == 16 and all(chip["dB_uT"] == chip["dB_exact_uT"] for chip in off)
    # each axis is the difference of two noisy, quantised readings (baseline and loaded): a variance of
    # 2 (noise^2 + LSB^2 / 12) at the design's GAIN_SEL 7, RES 0, OSR 0, DIG_FILT 2; in those units the
    # 48 squared errors sum to a chi-square of 48 degrees of freedom, bounded from both sides by its
    # 0.1 % and 99.9 % quantiles, 23.3 and 84.0 (this push: 37.4; noise off gives 0, noise 1.5 x too small
    # 16.6, 1.5 x too large 84.2)
    settings = MLX90393Settings(gain_sel=7, res_xyz=(0, 0, 0), osr=0, dig_filt=2)
    sd = np.sqrt(2 * (noise_rms_uT(settings) ** 2 + lsb_uT(settings) ** 2 / 12))
    errors = np.array([np.subtract(chip["dB_uT"], chip["dB_exact_uT"]) for chip in on]) / sd
    assert scipy.stats.chi2.ppf(0.001, 48) < np.sum(errors**2) < scipy.stats.chi2.ppf(0.999, 48)


def test_deformed_mesh_is_saved_as_data_only_npz(tmp_path):
    path = tmp_path / "deformed.npz"
    result = run("simulate", "--design", "cylindrical-A", "--depth", "0.5", "--deformed-mesh", str(path), *FAST)
    assert result.exit_code == 0, result.output
    with np.load(path, allow_pickle=False) as data:
        points, displacements = data["points_m"], data["displacements_m"]
        assert points.shape == displacements.shape and data["tetrahedra"].shape[1] == 4
        top = np.isclose(points[:, 2], 9e-3) & (np.hypot(points[:, 0], points[:, 1]) < 0.8e-3)
        # the board's bottom face pushed the top surface under it 0.5 mm down
        np.testing.assert_allclose(displacements[top, 2], -0.5e-3, rtol=1e-3)


def test_sensor_model_facts_are_reported(board_push):
    chip = board_push["sensor_model"]
    assert chip["lsb_uT"] == pytest.approx([0.150, 0.150, 0.242])  # GAIN_SEL 7, RES 0 (datasheet table 17)
    # Datasheet Table 8 at OSR 0, DIG_FILT 2: T_STBY + T_ACTIVE + 3 (67 + 64 (2 + 2^2)) + T_CONV_END
    # = 264 + 432 + 3 x 451 + 120 = 2169 us, one reading after another: 461.0 Hz.
    assert chip["conversion_time_ms"] == pytest.approx(2.169, rel=1e-9)
    assert chip["max_rate_hz"] == pytest.approx(1e6 / 2169, rel=1e-9)


def test_ambient_field_cancels_in_the_change_but_shifts_the_raw_counts():
    base = json.loads(run("simulate", "--noise", "off", "--json", *FAST).stdout)["sensors"][0]
    ambient = json.loads(run("simulate", "--noise", "off", "--ambient", "0", "0", "50", "--json", *FAST).stdout)
    ambient = ambient["sensors"][0]
    np.testing.assert_allclose(ambient["dB_exact_uT"], base["dB_exact_uT"], atol=1e-3)
    shift = (np.array(ambient["counts"], dtype=np.int64) - np.array(base["counts"], dtype=np.int64)) % 65536
    assert shift[2] == pytest.approx(50 / 0.242, abs=1)  # 50 uT on z at 0.242 uT/LSB


def test_plot_writes_a_png(tmp_path):
    path = tmp_path / "section.png"
    result = run("simulate", "--design", "cylindrical-A", "--depth", "0.5", "--plot", str(path), *FAST)
    assert result.exit_code == 0, result.output
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["simulate", "--design", "cylindrical-Q"], "neither a file nor a shipped design"),
        (["simulate", "--depth", "-1"], "--depth = -1.0"),
        (["simulate", "--thickness", "0"], "--thickness = 0.0"),
        (["simulate", "--plot", "out.jpg"], "ending in .png"),
        (["simulate", "--indenter", "sphere", "--x", "40"], "does not reach the fingertip"),
    ],
)
def test_user_mistakes_give_one_line_and_exit_code_2(args, message):
    result = run(*args, *FAST)
    assert result.exit_code == 2
    assert message in result.output
    assert "Traceback" not in result.output
    assert len(result.output.strip().splitlines()) == 1


def test_a_bad_contact_layer_gives_one_line_before_any_work():
    result = run("bench", "rom", "--contact-layer-mm", "0.05")
    assert result.exit_code == 2
    assert "--contact-layer-mm = 0.05" in result.output and "Traceback" not in result.output
    assert len(result.output.strip().splitlines()) == 1


def test_a_bad_design_file_gives_one_line(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('kind = "cylindrical"\n[body]\ndiameter_mm = 25\nheight_mm = 9\n[cavity]\nradius_mm = 30\n'
                    'height_mm = 5\n[magnets]\ncircle_radius_mm = 5\ndiameter_mm = 2\nheight_mm = 1.5\ndepth_mm = 1\n')
    result = run("simulate", "--design", str(path), *FAST)
    assert result.exit_code == 2
    assert "cavity.radius_mm = 30" in result.output and "Traceback" not in result.output


def test_designs_lists_the_shipped_designs():
    rows = json.loads(run("designs", "--json").stdout)
    names = [r["name"] for r in rows]  # softtip's own among those of any system installed with it, by name
    assert names == sorted(names) and {"cylindrical-A", "cylindrical-B", "cylindrical-C", "cylindrical-D",
                                       "rectangular"} <= set(names)
    assert rows[names.index("cylindrical-A")] == {"name": "cylindrical-A", "kind": "cylindrical", "magnets": 4,
                                                  "sensors": 1, "description": load_design("cylindrical-A").spec[
                                                      "description"]}


@pytest.mark.parametrize("command", [[], ["simulate"], ["designs"], ["demo"], ["demo", "insertion"], ["bench"],
                                     ["bench", "twin"], ["bench", "rom"], ["bench", "live"], ["bench", "sysid"], ["lab", "run"],
                                     ["reproduce"], ["calibrate"], ["evaluate"], ["live"], ["convert"], ["sysid"],
                                     ["sysid", "fit"], ["sysid", "orders"], ["sysid", "predict"]])
def test_every_command_has_help(command):
    result = run(*command, "--help")
    assert result.exit_code == 0 and "Usage" in result.output


def _synthetic_dataset(path):
    """Trials of a sensor whose readings are an exact cubic map of a force (calibration and validation)."""
    from softtip.data import DatasetMetadata, TrialWriter, channel_columns

    rng = np.random.default_rng(0)
    writer = TrialWriter(1, labels={"fz_N": "N"}, conditions={"role": "1"}, metadata=DatasetMetadata(seed=0))
    for trial in range(12):
        force = np.linspace(0, rng.uniform(2, 4), 40)
        field = np.stack([np.column_stack([3 * force, -2 * force + 0.1 * force**2, 50 * force + force**3])], axis=1)
        writer.add({"time_s": np.arange(40) / 20, **channel_columns(field), "fz_N": force},
                   {"role": "calibration" if trial < 8 else "validation"})
    writer.write(path)
    return path


def test_calibrate_then_evaluate_a_saved_model(tmp_path):
    dataset = _synthetic_dataset(tmp_path / "push.parquet")
    model = tmp_path / "force.npz"
    fitted = json.loads(run("calibrate", str(dataset), "--target", "fz_N", "--model", "polynomial",
                            "--output", str(model), "--json").stdout)
    # the readings are a per-axis cubic of the force: the polynomial's inverse map is close to exact
    assert fitted["validation"]["fz_N"]["r2"] > 0.999 and model.is_file()
    scored = json.loads(run("evaluate", str(model), str(dataset), "--json").stdout)
    assert scored["fz_N"]["mean_abs_error"] < 0.02
    model.write_bytes(model.read_bytes()[:-200])
    refused = run("evaluate", str(model), str(dataset))
    assert refused.exit_code == 2 and len(refused.output.strip().splitlines()) == 1


def test_calibrate_names_a_missing_target(tmp_path):
    dataset = _synthetic_dataset(tmp_path / "push.parquet")
    result = run("calibrate", str(dataset), "--target", "angle_deg")
    assert result.exit_code == 2 and "angle_deg" in result.output


EVERY_COMMAND = {"designs", "simulate", "live", "convert", "optimize", "reproduce", "calibrate", "evaluate", "lab",
                 "demo", "bench", "sysid"}


def test_python_dash_m_softtip_lists_every_command_in_a_fresh_interpreter():
    import os
    import subprocess
    import sys

    # a fresh process: no test module has imported any command module first
    listed = subprocess.run([sys.executable, "-m", "softtip", "--help"], capture_output=True, text=True,
                            env={**os.environ, "COLUMNS": "200"}, check=True).stdout
    names = {line.split()[1] for line in listed.splitlines() if line.startswith("│ ") and len(line.split()) > 2}
    assert EVERY_COMMAND <= names, EVERY_COMMAND - names
    bench = subprocess.run([sys.executable, "-m", "softtip", "bench", "--help"], capture_output=True, text=True,
                           env={**os.environ, "COLUMNS": "200"}, check=True).stdout
    for name in ("twin", "rom", "live", "magnetics", "calibration", "sysid"):
        assert f"│ {name} " in bench
