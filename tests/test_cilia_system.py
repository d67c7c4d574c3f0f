"""S4 registered: its record, the lab's ``cilia`` protocol and dataset, ``softtip reproduce cilia`` and
``softtip bench cilia``, and the bad input each refuses in one line before any work."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from softtip._core.systems import register, systems, unregister
from softtip.cli.common import user_errors
from softtip.lab import load_protocol, run_protocol
from softtip.systems.cilia import SYSTEM
from softtip.systems.cilia.layout import SHIPPED_DIE, read_die

SOURCE = Path(__file__).parents[1] / "src"
COARSE = """
    protocol = "cilia"
    seed = 3

    [parameters]
    points = {points}
    trials = 2
    depths_um = [10.0, 20.0]
    meander_scales = [0.9]
    brush_length_mm = 6.0
    brush_strips = 2
    brush_bridge = true
    brush_speeds_mm_s = [0.5, 2.0]
    brush_rates_hz = [2.0, 50.0]
    design_steps = 3
    design_budget = 4
    design_points = 9
"""


@pytest.fixture(autouse=True, scope="module")
def registered():
    """The record registered for this module (the installed entry points may predate it)."""
    added = "cilia" not in systems()
    if added:
        register(SYSTEM)
    yield
    if added:
        unregister("cilia")


@pytest.fixture(scope="module")
def environment(tmp_path_factory) -> dict:
    """A dist-info declaring the entry point, for the command line in a subprocess."""
    root = tmp_path_factory.mktemp("entry")
    info = root / "softtip_cilia-0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: softtip-cilia\nVersion: 0\n")
    (info / "entry_points.txt").write_text("[softtip.systems]\ncilia = softtip.systems.cilia:SYSTEM\n")
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(SOURCE), str(root)])}


def coarse(tmp_path: Path, points: int = 12, **extra: str) -> Path:
    path = tmp_path / "coarse.toml"
    text = textwrap.dedent(COARSE.format(points=points)) + "".join(f"{k} = {v}\n" for k, v in extra.items())
    path.write_text(text)
    return path


def broken_die(tmp_path: Path) -> Path:
    path = tmp_path / "overlap.toml"
    path.write_text(SHIPPED_DIE.read_text().replace("[0.0, 0.0]]", "[0.9, 0.9]]"))
    return path


def y_only_die(tmp_path: Path) -> Path:
    """The shipped die with its X meander taken out: one sensor direction."""
    text = SHIPPED_DIE.read_text()
    start, end = text.index("[sensors.X]"), text.index("[sensors.Y]")
    path = tmp_path / "y-only.toml"
    path.write_text(text[:start] + text[end:])
    return path


def test_a_die_with_one_sensor_direction_runs_the_protocol_and_the_bench(tmp_path):
    die = y_only_die(tmp_path)
    assert [m.name for m in read_die(die).meanders] == ["Y"]
    dataset, _ = run_protocol(load_protocol(coarse(tmp_path, points=5, die=f'"{die}"')))
    assert list(dataset.channels) == ["gmr_y_V"] and "tare_y_V" in dataset.conditions and "tare_x_V" not in dataset.conditions
    brushing = dataset.select(rows=dataset.column("mode") == "brushing")
    assert len(brushing.trials) == 28 and np.all(np.isfinite(brushing.column("gmr_y_V")))
    ran = CliRunner().invoke(bench_app(), ["--die", str(die), "--loads", "5", "--repeats", "1", "--json"])
    assert ran.exit_code == 0, ran.output
    assert json.loads(ran.stdout)["sensor"] == "Y"


def test_reproduce_on_a_die_of_the_other_sensor_alone_asks_for_it_before_any_work(tmp_path):
    from softtip.studies.reproduce import reproduce_study
    from softtip.systems.cilia.layout import DieError

    with pytest.raises(DieError, match=r"parameters.sensor = 'X': the die file y-only.toml has the sensor Y only; "
                                       r'set sensor = "Y"'):
        reproduce_study("cilia", seed=1, protocol_path=coarse(tmp_path, points=5, die=f'"{y_only_die(tmp_path)}"'))


@pytest.mark.slow
def test_reproduce_reads_a_die_with_one_sensor_direction(tmp_path):
    from softtip.studies.reproduce import reproduce_study

    die = y_only_die(tmp_path)
    report = reproduce_study("cilia", seed=1, protocol_path=coarse(tmp_path, points=8, die=f'"{die}"', sensor='"Y"',
                                                                   gap_causes="false"))
    results = report.outcome.results
    assert list(results["rest_V"]) == list(results["minimum_force_3sigma_uN"]) == ["Y"]
    # the Y strips sense across the bend: the pillars bent along x barely move its voltage, so no force in
    # reach is resolved (the shipped die's Y: 0.006 V/N at rest)
    assert results["minimum_force_3sigma_uN"]["Y"] > 26e3
    assert results["roughness"]["recordings"] == 4 * (2 * 3 + 1)  # 2 strips x 3 speeds, and a rate of 2/s on one
    assert results["chain_against_continuous"]["sensor"] == "Y"
    assert all(figure.png.startswith(b"\x89PNG") for figure in report.outcome.figures)


def test_the_record_is_light_and_names_every_part():
    loaded = subprocess.run([sys.executable, "-c", "import sys, softtip.systems.cilia as c; "
                             "print(sorted(m for m in sys.modules if m.startswith(('matplotlib', 'scipy', "
                             "'softtip.systems.cilia.'))))"],
                            env={**os.environ, "PYTHONPATH": str(SOURCE)}, capture_output=True, text=True, timeout=60)
    assert loaded.returncode == 0, loaded.stderr
    assert loaded.stdout.strip() == "[]"
    assert (SYSTEM.name, SYSTEM.label) == ("cilia", "S4")
    assert SYSTEM.protocol_file("cilia").is_file() and SYSTEM.published() is not None
    assert [study.name for study in SYSTEM.studies] == ["cilia"] and "cilia" in SYSTEM.bench_commands


def test_the_protocol_writes_the_twins_curves_within_their_stated_noise(tmp_path):
    protocol = load_protocol(coarse(tmp_path, points=8))
    dataset, _ = run_protocol(protocol)
    mode, repeat = dataset.column("mode"), dataset.column("repeat")
    loadings = mode != "brushing"
    assert sorted(set(zip(mode[loadings], repeat[loadings]))) == [("balance", 0), ("balance", 1), ("paper", 0),
                                                                  ("paper", 1)]
    paper = dataset.select(rows=(mode == "paper") & (repeat == 1))
    force = paper.column("force_N")
    assert np.allclose(force, np.linspace(26e-3 / 8, 26e-3, 8))  # the plan: 8 equal steps to 26 mN
    # the readings scatter about the noise-free twin by the bench's 1 % of full scale and the meter's noise
    from softtip.systems.cilia.model import CiliaModel

    truth = CiliaModel(read_die()).curve(force, "X")
    readout = read_die().meander("X").readout
    sigma = math.hypot(0.01 * np.abs(truth.change).max(), math.sqrt(2) * readout.noise(truth.volts[0]).total)
    residual = paper.column("gmr_x_V") - truth.change
    assert np.all(np.abs(residual) < 5 * sigma) and np.std(residual) > 0.2 * sigma
    # the tare is the sensor at rest: 100 µA through the spec's ≈ 183 kΩ, within 3 %
    assert paper.column("tare_x_V")[0] == pytest.approx(100e-6 * 183e3, rel=0.03)
    balance = dataset.select(rows=(mode == "balance") & (repeat == 0)).column("force_N")
    assert balance[0] == 0 and balance.max() > 0  # the balance reads nothing until the plate touches


def test_the_protocol_records_the_brushings_and_the_study_reads_them_back_from_the_file(tmp_path):
    from softtip.data import Dataset
    from softtip.systems.cilia.bench import recordings_of
    from softtip.systems.cilia.roughness import analyse_roughness

    dataset, _ = run_protocol(load_protocol(coarse(tmp_path, points=5)))
    brushing = dataset.select(rows=dataset.column("mode") == "brushing")
    conditions = brushing.trial_conditions
    # 4 surfaces x (2 strips x 3 speeds at 50/s + the first strip at 1 mm/s at 2/s): 7 recordings each
    assert len(brushing.trials) == 28
    assert sorted(set(conditions["surface"])) == ["P100", "P1000", "P320", "silicon"]
    assert set(zip(conditions["speed_mm_s"], conditions["rate_hz"])) == {(0.5, 50.0), (2.0, 50.0), (1.0, 2.0),
                                                                         (1.0, 50.0)}
    # at 2 mm/s and 50/s over 6 mm less the pillars' 2 mm spread: 2 s, 100 whole readings, 1/50 s apart
    fast = brushing.select(trials=[conditions["trial"][np.flatnonzero(conditions["speed_mm_s"] == 2.0)[0]]])
    assert len(fast) in (99, 100) and np.allclose(np.diff(fast.column("time_s")), 0.02)
    read = Dataset.read(dataset.write(tmp_path / "cilia.parquet"))
    recordings = recordings_of(read)
    assert len(recordings) == 28
    assert np.allclose(sorted({r.roughness for r in recordings}), [0.0, 18.3e-6, 46.2e-6, 162e-6], rtol=1e-12)
    study = analyse_roughness(recordings, 1e-3, 50.0, seed=0)
    assert np.all(np.diff(study.total_rms) > 0) and study.classification.windows > 0
    with pytest.raises(ValueError, match="dataset: expected the channel s0_bx_uT; its channels: gmr_x_V, gmr_y_V"):
        recordings_of(read, channel="s0_bx_uT")
    with pytest.raises(ValueError, match="dataset: no brushing trials"):
        recordings_of(read.select(rows=read.column("mode") == "paper"))
    # the command reads the same file the same way
    from softtip.systems.cilia.commands import roughness_cilia

    app = typer.Typer()
    app.command()(user_errors(roughness_cilia))
    ran = CliRunner().invoke(app, [str(tmp_path / "cilia.parquet"), "--speed-mm-s", "1", "--seed", "0", "--json"])
    assert ran.exit_code == 0, ran.output
    report = json.loads(ran.stdout)
    assert report["recordings"] == 28 and np.allclose(report["ac_rms_uV"], study.total_rms * 1e6, rtol=1e-12)
    assert report["classification"]["accuracy_by_strip"] == study.classification.by_strip
    refused = CliRunner().invoke(app, [str(tmp_path / "cilia.parquet"), "--speed-mm-s", "3"])
    assert refused.exit_code == 2 and "cilia.parquet: recordings: no brushing of silicon at 3 mm/s" in refused.output


@pytest.mark.parametrize("setting, message", [
    ("points = 2", r"points = 2: expected an integer 5..400"),
    ("force_max_mN = nan", r"force_max_mN"),
    ("force_max_mN = -1.0", r"force_max_mN = -1.0"),
    ("trials = 0", r"trials = 0"),
    ("repeatability = 2.0", r"repeatability = 2.0"),
    ("height_mm = 0.0", r"height_mm = 0.0"),
    ("brush_rates_hz = [2.0, 1000.0]", r"brush_rates_hz = \[2.0, 1000.0\]: expected rates at most 250 /s at 0.5 mm/s"),
    ("brush_length_mm = 1.5", r"brush_length_mm = 1.5: expected a stroke of at least one second at 2 mm/s"),
    ("brush_engagement_um = 800.0", r"brush_engagement_um = 800: expected less than 70 % of the pillars' height"),
    ("die_tilt_deg = 20.0", r"die_tilt_deg = 20.0: expected an angle in degrees from -10 to 10"),
    ("plate_stiffness_uNm = 0.0", r"plate_stiffness_uNm = 0.0"),
    ('budget_parts = ["heat"]', r"budget_parts"),
    ("plate_seating_mrad = -1.0", r"plate_seating_mrad = -1.0"),
    ("rig_tilts_deg = [20.0]", r"rig_tilts_deg"),
    ("gap_causes = 1", r"gap_causes = 1: expected true or false"),
    ("balance_chain_count = 0", r"balance_chain_count = 0"),
    ('magnetisation = "dipoles"', r"magnetisation = 'dipoles': expected one of uniform, equal"),
    ("brush_length_mm = 2.001", r"brush_length_mm = 2.001: expected a stroke longer than the pillars' spread"),
    ("truth_diameter_um = 700.0", r"parameters.truth_diameter_um = 700: pillars wider than they are high \(1000 um\)"),
    ("truth_moment_memu = 70.0", r"parameters.truth_moment_memu = 70: more than a pillar of solid NdFeB holds"),
    ("youngs_modulus_MPa = 1e300", r"youngs_modulus_MPa = 1e\+300: expected 0.001 <= E <= 100 MPa"),
])
def test_bad_protocol_settings_are_refused_when_read(tmp_path, setting, message):
    path = coarse(tmp_path)
    key = setting.split(" =")[0]
    lines = [line for line in path.read_text().splitlines() if not line.strip().startswith(key + " ")]
    path.write_text("\n".join(lines + [setting, ""]))
    with pytest.raises(ValueError, match=message) as refused:
        load_protocol(path)
    assert "\n" not in str(refused.value)


def test_a_die_file_that_breaks_the_layout_is_refused_when_the_protocol_is_read(tmp_path):
    die = broken_die(tmp_path)
    path = coarse(tmp_path)
    path.write_text(path.read_text() + f'die = "{die.name}"\n')  # relative to the protocol file
    with pytest.raises(ValueError, match=r"overlap.toml: pillars.positions_mm\[3\] and \[4\]: the pillars' bases "
                                         "overlap"):
        load_protocol(path)


@pytest.mark.slow
def test_reproduce_fits_the_dataset_and_sets_it_beside_the_published_figures(tmp_path):
    from softtip.studies.reproduce import reproduce_study

    report = reproduce_study("cilia", seed=2, protocol_path=coarse(tmp_path))
    outcome = report.outcome
    fit = outcome.results["fit"]
    # the twin's truth (2.8 memu, 200 µm) within the fit's 95 % intervals and the profiles'
    assert fit["interval_moment_memu"][0] <= 2.8 <= fit["interval_moment_memu"][1]
    assert fit["interval_diameter_um"][0] <= 200 <= fit["interval_diameter_um"][1]
    low, high = outcome.results["profile_interval_moment_memu"]
    assert low < fit["moment_memu"] < high
    # the linear part holds the parameters far more loosely than the whole curve
    assert outcome.results["linear_part"]["correlation"] > fit["correlation"]
    comparisons = report.comparisons()
    # every figure the publication reports is a row beside softtip's, and none is softtip's own input
    published = ("cilia-publication-fit", "cilia-moment-gap", "cilia-range", "cilia-minimum-force",
                 "cilia-roughness", "cilia-sampling")
    assert {c["table"] for c in comparisons} == set(published)
    assert all(c["verdict"] in ("within", "better", "outside") for c in comparisons)
    tip_load = outcome.results["publication_fit"]["tip_load"]
    assert outcome.headline.value == pytest.approx(tip_load["moment_memu"])
    # the publication's cylinder fitted to the twin's cone (200 → 320 µm) reads a diameter between the two
    assert 200 < tip_load["diameter_um"] < 320
    assert len(outcome.figures) == 8 and all(figure.png.startswith(b"\x89PNG") for figure in outcome.figures)
    assert any("balance" in note for note in outcome.notes)
    budget = outcome.results["minimum_force"]
    assert budget["minimum_force_uN"] == pytest.approx(3 * math.sqrt(sum(v**2 for v in budget["sigma_uN"].values())),
                                                       rel=1e-9)
    # a minimum force of the X sensor of tens of µN (3σ of a 100 µV count over ≈ 5.7 V/N), Y beyond reach
    assert 5 < outcome.results["minimum_force_3sigma_uN"]["X"] < 50
    assert outcome.results["minimum_force_3sigma_uN"]["Y"] > 26e3
    rough = outcome.results["roughness"]
    assert np.all(np.diff(rough["ac_rms_uV"]) > 0) and rough["slope_through_origin_uV_per_um"]["slope"] > 0
    assert rough["classification"]["accuracy_by_strip"] > 0.5  # chance 0.25
    # the published slope beside both fits of both readouts (this protocol reads through a bridge)
    slopes = [c["row"] for c in comparisons if c["table"] == "cilia-roughness"]
    assert len(slopes) == 4 and rough["other_readout"]["floor_uV"] > 10 * rough["floor_uV"]
    assert any(table.title.startswith("Roughness missed") for table in outcome.tables)
    continuous = outcome.results["chain_against_continuous"]
    assert continuous["force_mN"] == [1.0, 8.0, 26.0] and all(gap > 0 for gap in continuous["gap"])
    design = outcome.results["design_search"]
    assert [r["range_mN"] for r in design["ranges"]] == [13.0, 26.0, 39.0]
    assert all(r["evaluations"] == 4 and r["published"]["pillars"] == 5 for r in design["ranges"])
    assert any(table.title.startswith("Design search") for table in outcome.tables)


@pytest.mark.slow
def test_quick_runs_a_coarse_protocol():
    from softtip.studies.reproduce import reproduce_study

    start = time.process_time()  # in this process: a shared machine's load stretches the wall time, not this
    report = reproduce_study("cilia", seed=1, quick=True)
    cpu = time.process_time() - start
    rows = {row: report.protocol_table.cells[(row, "where from")] for row in report.protocol_table.rows}
    for key in ("points", "trials", "brush_length_mm", "brush_strips", "design_steps", "design_budget", "gap_causes",
                "rig_tilts_deg"):
        assert rows[f"parameters.{key}"] == "--quick (a smoke run)"
    results = report.outcome.results
    assert results["design_search"]["steps"] == 3 and results["roughness"]["recordings"] == 4 * (2 * 3 + 2)
    assert report.provenance["quick (smoke run)"] == "yes: fewer trials than the study, a coarse protocol"
    # measured 55 s of CPU (softtip reproduce cilia --quick; 13.5 min wall at a load average of 22 on two cores):
    # the meanders' 25 µm area elements over four squares each, the balance test's 40 dipoles read three ways
    # and its minimum force's steps as cones, the continuous cones' check
    assert cpu < 60


def bench_app() -> typer.Typer:
    from softtip.systems.cilia.commands import bench_cilia

    app = typer.Typer()
    app.command()(user_errors(bench_cilia))
    return app


@pytest.mark.parametrize("options, message", [
    (["--loads", "0"], "--loads = 0: expected 5 to 2000"),
    (["--force-max-mn", "nan"], "--force-max-mn = nan: expected a force above 0"),
    (["--force-max-mn", "inf"], "--force-max-mn = inf"),
    (["--force-max-mn", "-1"], "--force-max-mn = -1.0"),
    (["--repeats", "0"], "--repeats = 0"),
    (["--fe-loads", "1"], "--fe-loads = 1"),
])
def test_bench_refuses_bad_options_in_one_line(options, message):
    result = CliRunner().invoke(bench_app(), options)
    assert result.exit_code == 2 and message in result.output and result.output.count("\n") == 1


def test_bench_refuses_a_broken_die_and_an_output_it_may_not_write(tmp_path):
    runner = CliRunner()
    result = runner.invoke(bench_app(), ["--die", str(broken_die(tmp_path))])
    assert result.exit_code == 2 and "the pillars' bases overlap" in result.output
    existing = tmp_path / "report.json"
    existing.write_text("{}")
    result = runner.invoke(bench_app(), ["--save", str(existing)])
    assert result.exit_code == 2 and "the file exists (pass --force" in result.output
    result = runner.invoke(bench_app(), ["--save", str(tmp_path / "missing" / "report.json")])
    assert result.exit_code == 2 and "does not exist" in result.output
    assert existing.read_text() == "{}"


def test_the_bench_says_what_each_figure_is_and_gives_a_verdict():
    ran = CliRunner().invoke(bench_app(), ["--loads", "5", "--repeats", "1"])
    assert ran.exit_code == 0, ran.output
    lines = ran.output.splitlines()
    timed = [line for line in lines if line.startswith(("force-voltage curve, 5 loads: ", "fit of moment"))]
    assert len(timed) == 2 and all(" s of CPU, " in line and " s wall (target " in line for line in timed)
    assert "(target 0.3 s of CPU, idle: " in timed[0] and "(target 5 s of CPU, idle: " in timed[1]
    assert sum(line.startswith("load average before the timings (1, 5, 15 min): ") for line in lines) == 1
    assert sum("times the baseline's CPU time" in line for line in lines) == 2 and "ratio" not in ran.output
    met = ["MISSED" not in line for line in timed]
    assert lines[-1] == ("verdict: every target met" if all(met) else
                         f"verdict: {met.count(False)} of 2 targets missed: " + "; ".join(
                             line.split(":")[0] for line, ok in zip(timed, met) if not ok))


def test_the_command_line_finds_the_system_and_times_it(environment, tmp_path):
    ran = subprocess.run([sys.executable, "-m", "softtip", "bench", "cilia", "--loads", "10", "--repeats", "1",
                          "--save", "bench.json", "--json"], env=environment, cwd=tmp_path, capture_output=True,
                         text=True, timeout=120)
    assert ran.returncode == 0, ran.stderr
    report = json.loads(ran.stdout)
    assert json.loads((tmp_path / "bench.json").read_text()) == report
    curve, fit = report["timings"]["force-voltage curve, 10 loads"], report["timings"]["fit of moment and diameter, 10 points"]
    assert curve["seconds"] > 0 and curve["baseline_seconds"] > 0 and fit["baseline_seconds"] > 0
    # the fit's own result on the shipped die's curve: 2.8 memu and 200 µm, from a 1 % noisy curve
    assert "moment 2.8" in report["notes"][0] or "moment 2.7" in report["notes"][0]
    listed = subprocess.run([sys.executable, "-m", "softtip", "lab", "run", "--help"], env=environment, cwd=tmp_path,
                            capture_output=True, text=True, timeout=120)
    assert "cilia" in listed.stdout


@pytest.mark.slow
def test_the_fe_reference_curve_of_two_loads_converges_in_steps_no_larger_than_the_default_runs():
    # two loads to 26 mN are 2.6 mN a pillar each: Newton from the straight pillar in two steps of 1.3 mN did
    # not converge in 30 iterations (before this bench sized its steps; on the earlier releases too)
    from softtip.systems.cilia.benchmark import FE_STEP_N, _fe_curve
    from softtip.systems.cilia.model import CiliaModel

    model = CiliaModel(read_die(SHIPPED_DIE))
    _, _, gap, unknowns, iterations = _fe_curve(model, 26e-3, 2, 1)
    assert 26e-3 / 6 / model.pillar_count / 2 <= FE_STEP_N  # the default run (6 loads, 2 steps each) unchanged
    # measured: 97 Newton iterations over 12 steps, the voltage changes within 6.4 % of the bonded-root rod's
    # (6.6 % over six loads): the solid and the rod agree as they do on the default run's loads
    assert unknowns > 8000 and iterations <= 12 * 10
    assert gap < 0.07
