"""S3 as a registered system: its record, its protocol (the study as a dataset) and its report beside
the published figures."""

from __future__ import annotations

import numpy as np
import pytest

from softtip._core.config import ConfigError
from softtip._core.progress import SILENT
from softtip._core.systems import owner, register, systems
from softtip.data import Dataset
from softtip.lab import load_protocol, run_protocol
from softtip.lab.protocols import protocol_from_dict
from softtip.published import tables_of
from softtip.systems.haptics import SYSTEM
from softtip.systems.haptics.bench import RENDERED, TARGET
from softtip.systems.haptics.report import RenderedTargets, haptics
from softtip.systems.haptics.statistics import wilcoxon
from softtip.systems.haptics.study import METHODS, run_study

COARSE = {"trials": 6, "fs_levels": 7, "user_levels": 7, "fingertips": ["FS cast (7.5 mm)", "human 3 (10 mm)"],
          "curve_n_neighbours": [1, 8], "curve_weighting_powers": [], "curve_fs_levels": [5, 7],
          "curve_user_levels": [],
          "variations": ["as published", "human pads half as stiff"], "robustness_seeds": [4], "robustness_sigmas": 0.0}


@pytest.fixture(scope="module", autouse=True)
def registered():
    if "haptics" not in systems():  # the entry point is installed with the package
        register(SYSTEM)


@pytest.fixture(scope="module")
def coarse_protocol():
    return load_protocol("haptics").changed(seed=3, **COARSE)


@pytest.fixture(scope="module")
def coarse_dataset(coarse_protocol):
    return run_protocol(coarse_protocol)[0]


def test_the_record_names_what_it_registers():
    assert owner("protocol", "haptics") is SYSTEM and owner("study", "haptics") is SYSTEM
    assert owner("bench", "haptics") is SYSTEM and owner("command", "haptics") is SYSTEM
    assert SYSTEM.label == "S3" and SYSTEM.published() is not None
    assert {table.key for table in tables_of("haptics")} == {
        "haptics-scale", "haptics-collection", "haptics-directions", "haptics-largest-error", "haptics-no-contact",
        "haptics-significance"}
    assert [table.fitted for table in tables_of("haptics")].count(True) == 1  # only the scale is fitted


def test_the_shipped_protocol_is_the_published_procedure():
    p = load_protocol("haptics").parameters
    assert (p.trials, p.fs_levels, p.user_levels, p.n_neighbours, p.hold_s, p.window_s) == (100, 13, 7, 8, 1.0, 0.2)
    assert len(p.fingertips) == 6


def test_the_dataset_holds_every_rendering_and_its_error(coarse_dataset):
    dataset = coarse_dataset
    assert isinstance(dataset, Dataset) and len(dataset.trials) == 6
    assert len(dataset.groups) == 6 * 2 * len(METHODS)
    found = RenderedTargets.of(dataset)
    assert found.errors.shape == (2, len(METHODS), 6)
    # the error is recomputed by hand from the rendered wrench and the target (a condition of the trial)
    rendered = np.column_stack([dataset.column(name) for name in RENDERED[:3]])
    target = np.column_stack([dataset.column(name) for name in TARGET[:3]])
    assert np.allclose(dataset.column("error_N"), np.linalg.norm(target - rendered, axis=1))
    # on the FS cast, the geometric table is the FS table itself: the same motor commands as the standard
    fs = dataset.column("fingertip") == "FS cast (7.5 mm)"
    method = dataset.column("method")
    standard, geometric = (np.column_stack([dataset.column(f"motor{k}_rad")[fs & (method == m)] for k in (1, 2, 3)])
                           for m in (METHODS[0], METHODS[2]))
    assert np.allclose(standard, geometric, atol=1e-12)


def test_the_report_compares_with_the_published_directions(coarse_protocol, coarse_dataset):
    outcome = haptics(coarse_protocol, 3, SILENT)
    tables = {table.title: table for table in outcome.tables}
    directions = next(table for table in outcome.tables
                      if table.published and table.published.key == "haptics-directions")
    largest = outcome.results["fingertips"]["human 3 (10 mm)"]
    medians = largest["median_error_N"]
    assert directions.cells[("human 3 (10 mm)", "standard − A")] == pytest.approx(medians[0] - medians[1])
    assert directions.cells[("human 3 (10 mm)", "B − A")] == pytest.approx(medians[2] - medians[1])
    # a direction the publication states and softtip's twin does not show carries its measured cause: the
    # force the device presses that fingertip with, released, which is the floor table's
    floors = tables["The device's floor on each fingertip"]
    floor = floors.cells[("human 3 (10 mm)", "force with the servos released (N)")]
    assert floor > 1.0
    assert ("human 3 (10 mm)" in directions.notes) == (directions.cells[("human 3 (10 mm)", "B − A")] <= 0)
    if "human 3 (10 mm)" in directions.notes:
        assert f"{floor:.2f} N" in directions.notes["human 3 (10 mm)"]
    # the fit's tables: the device's own values and record; the scale figures this run's, each "fitted"
    device = coarse_protocol.design.device
    fitted = tables["The device's fitted unknowns"]
    assert fitted.cells[("cables.stiffness (N/m)", "fitted value")] == device.cables.stiffness
    assert fitted.cells[("device.pulley_radius (mm)", "standard error")] == pytest.approx(
        1e3 * device.fit.standard_errors[1])
    # the wound platform's height above the FS's pad (at the centre's height less the FS's 7.5 mm)
    stroke = device.device.pulley_radius * np.pi - device.device.released_length - (device.centre[2] - 7.5e-3)
    assert fitted.cells[("stroke past the FS's pad (mm)", "fitted value")] == pytest.approx(1e3 * stroke)
    scale = [c for c in tables["The experiment's scale: the figures the device's unknowns are fitted to"].comparisons()]
    assert {c.verdict for c in scale} <= {"fitted", "outside"} and len(scale) == 2  # no small sphere in this run
    assert scale[0].value == pytest.approx(outcome.results["target_force_N"]["mean"])
    # the servos' stall (modelled: device tests) is shown to be far from what the cables carry in the study
    servos = tables["Where softtip's procedure departs from the published one"].cells[("servos", "softtip")]
    stall = device.servo.stall_torque / device.device.pulley_radius
    tension = float(servos.split("test fingertips is ")[1].split(" N")[0])
    assert f"the stall's {stall:.0f} N" in servos and 1.0 < tension < stall / 4
    # the headline counts the published predictions the twin meets, over every prediction table
    predictions = [c for table in outcome.tables if table.published and not table.published.fitted
                   and table.published.key != "haptics-collection" for c in table.comparisons()]
    held = sum(c.verdict == "within" for c in predictions)
    assert outcome.headline.value == held and outcome.headline.label.endswith(f"(of {len(predictions)})")
    # the pooled A-vs-B test is scipy's on the pooled errors, Bonferroni over 3 x 2 + 1 tests
    found = RenderedTargets.of(coarse_dataset)
    reference = wilcoxon(found.errors[:, 1].ravel(), found.errors[:, 2].ravel(), 7)
    assert outcome.results["pooled_A_vs_B"]["p_bonferroni"] == pytest.approx(reference.p_bonferroni)
    assert any(c.verdict for c in directions.comparisons())
    assert len(outcome.figures) == 4 and all(figure.png.startswith(b"\x89PNG") for figure in outcome.figures)
    # A's two variants on the dataset's own tables, per fingertip and pooled
    variants = outcome.results["data_driven_variants"]
    assert [row["fingertip"] for row in variants["rows"]] == [*found.fingertips, "all fingertips (pooled)"]
    assert variants["variants"] == ["published", "device axes"]
    collection = {c.row: c for table in outcome.tables for c in table.comparisons() if c.column == "entries"}
    assert collection["FS table (13³)"].value == 2197 and collection["user table (7³)"].value == 343
    # a collection time short of the published one is broken down: 7³ holds of 1 s are 5.7 min
    collection_table = tables["Table collection: entries and the time a real collection takes"]
    assert collection_table.notes["user table (7³)"].split(" min are ")[1].startswith("5.7 min of holds")
    # counts print as counts, beside the published ones
    assert "<td class='num within' title='published 2197; difference +0'>2197 " in tables[
        "Table collection: entries and the time a real collection takes"].html()
    errors_html = tables["Rendering error per fingertip and method"].html()
    flagged = [int(outcome.results["fingertips"][name]["flagged"][m]) for name in found.fingertips
               for m in range(len(METHODS))]
    assert all(f"<td class='num'>{count}</td></tr>" in errors_html for count in flagged)


def test_the_sweeps_rerun_the_datasets_study(coarse_protocol, coarse_dataset):
    outcome = haptics(coarse_protocol, 3, SILENT)
    found = RenderedTargets.of(coarse_dataset)
    pooled = np.median(found.errors.transpose(1, 0, 2).reshape(len(METHODS), -1), axis=1)
    curves = outcome.results["error_curves"]
    assert list(curves) == ["n_neighbours", "fs_levels"] and curves["n_neighbours"]["values"] == [1, 8]
    # at the protocol's own settings (n = 8, 7³ FS table) the curves are the dataset's errors: same noise draws
    for setting, own in (("n_neighbours", 1), ("fs_levels", 1)):
        assert [curves[setting]["median_error_N"][m][own] for m in METHODS] == pytest.approx(pooled)
    as_published, softer = outcome.results["sensitivity"]
    human_3 = np.median(found.errors[found.fingertips.index("human 3 (10 mm)")], axis=1)
    assert [as_published["median_error_N"][m] for m in METHODS] == pytest.approx(human_3)
    # a softer pad is pressed less by the device released: the floor on the largest finger drops, and every
    # method's median error there with it (measured: 1.70 -> 1.35 N for the geometric method)
    assert all(softer["median_error_N"][m] < as_published["median_error_N"][m] for m in METHODS)
    # robustness: the study's own row is the dataset's, the other seed's is the whole study run anew on it
    study, other = outcome.results["robustness"]
    assert [study["median_error_N"][m] for m in METHODS[:3]] == pytest.approx(pooled[:3])
    rerun = run_study(coarse_protocol.parameters.study_settings(), seed=4,
                      fingertips=coarse_protocol.parameters.selected_fingertips())
    medians = np.median(np.hstack([o.errors for o in rerun.fingertips]), axis=1)
    assert other["seed"] == 4 and [other["median_error_N"][m] for m in METHODS[:3]] == pytest.approx(medians[:3])
    better = [run["A_better_than_B"] for run in (study, other)]
    for run in (study, other):
        test = run["pooled_A_vs_B"]
        assert run["A_better_than_B"] == (test["W_signed_rank_sum"] < 0 and test["p"] < 0.0028)
    robustness = next(table for table in outcome.tables if table.title.startswith("Robustness"))
    assert robustness.cells[("over all 2 runs", "A better than B, pooled (p < 0.0028)")] == f"{sum(better)} of 2"
    titles = [table.title for table in outcome.tables]
    assert any(title.startswith("Rendering error against n") for title in titles)
    assert any(title.startswith("How the methods' ranking depends on the finger") for title in titles)
    assert any(title.startswith("Ablations") for title in titles) and "ablations" in outcome.results


def test_no_sweep_without_its_settings(coarse_protocol):
    bare = coarse_protocol.changed(curve_n_neighbours=[], curve_fs_levels=[], fingertips=["FS cast (7.5 mm)"],
                                   ablations=False)
    outcome = haptics(bare, 3, SILENT)
    assert "error_curves" not in outcome.results and "sensitivity" not in outcome.results
    assert "ablations" not in outcome.results and not any(t.title.startswith("Ablations") for t in outcome.tables)
    assert len(outcome.figures) == 2  # the box plots and A's two variants
    assert any(note.startswith("No sensitivity study") for note in outcome.notes)


def test_bad_protocols_are_refused_in_one_line(tmp_path):
    base = {"protocol": "haptics"}
    cases = [({"parameters": {"trials": 1}}, "trials"),
             ({"parameters": {"fingertips": ["thumb"]}}, "fingertips"),
             ({"parameters": {"fingertips": ["FS cast (7.5 mm)"] * 2}}, "each fingertip once"),
             ({"parameters": {"window_s": 2.0}}, "window_s"),
             ({"parameters": {"hold_s": float("nan")}}, "hold_s"),
             ({"parameters": {"weighting_power": -1.0}}, "weighting_power"),
             ({"parameters": {"target_draws": 5}}, "target_draws"),
             ({"parameters": {"curve_n_neighbours": [0, 8]}}, "curve_n_neighbours"),
             ({"parameters": {"curve_fs_levels": [7, 7]}}, "curve_fs_levels = .*each value once"),
             ({"parameters": {"curve_weighting_powers": [5.0]}}, "curve_weighting_powers"),
             ({"parameters": {"variations": ["thumb"]}}, "variations"),
             ({"parameters": {"data_driven": "raw"}}, "data_driven = 'raw'"),
             ({"parameters": {"ds_torque_length_m": 0.0}}, "ds_torque_length_m = 0"),
             ({"parameters": {"robustness_seeds": [2, 2]}}, "robustness_seeds = .*each value once"),
             ({"parameters": {"robustness_sigmas": 4.0}}, "robustness_sigmas"),
             ({"parameters": {"fs_levels": 1000}}, r"fs_levels = 1000: expected an integer from 2 to 31 \(a table"),
             ({"parameters": {"ablations": "yes"}}, "ablations = 'yes': expected true or false"),
             ({"device": "missing.toml"}, "missing.toml"),
             ({"fingertip_files": ["f.toml"] * 13}, "fingertip_files = 13: expected at most 12 fingertip files")]
    for extra, word in cases:
        with pytest.raises(ValueError, match=word) as raised:
            protocol_from_dict(base | extra, "test", tmp_path)
        assert "\n" not in str(raised.value)
    broken = tmp_path / "device.toml"
    broken.write_text((SYSTEM.files() / "device.toml").read_text().replace("pulley_radius = 0.00092997",
                                                                           "pulley_radius = 0.05"))
    with pytest.raises(ConfigError, match="released_length"):
        protocol_from_dict(base | {"device": "device.toml"}, "test", tmp_path)


def test_reproduce_quick_renders_fewer_targets_and_writes_the_report(tmp_path):
    from softtip.studies.reproduce import reproduce_study

    shipped = (SYSTEM.files() / "protocols" / "haptics.toml").read_text()
    coarse = shipped.replace("fs_levels = 13", "fs_levels = 7").replace(
        'fingertips = ["small cast (6.5 mm)", "FS cast (7.5 mm)", "large cast (8.5 mm)", "human 1 (6.5 mm)",\n'
        '              "human 2 (8 mm)", "human 3 (10 mm)"]', 'fingertips = ["FS cast (7.5 mm)", "human 2 (8 mm)"]')
    assert coarse.count("fs_levels = 7") == 1 and "human 3" not in coarse
    path = tmp_path / "coarse.toml"
    path.write_text(coarse)
    report = reproduce_study("haptics", seed=3, quick=True, protocol_path=path)
    assert report.outcome.results["targets"] == 2  # --quick cuts the targets (the protocol's trials) to two
    where = report.protocol_table.cells[("parameters.trials", "where from")]
    assert where.startswith("--quick")
    # and coarse sweeps: the study's quick settings
    assert report.protocol_table.cells[("parameters.curve_fs_levels", "where from")].startswith("--quick")
    assert report.outcome.results["error_curves"]["fs_levels"]["values"] == SYSTEM.studies[0].quick["curve_fs_levels"]
    assert [v["variation"] for v in report.outcome.results["sensitivity"]] == SYSTEM.studies[0].quick["variations"]
    written = report.write(tmp_path)
    assert written.is_file() and (tmp_path / "haptics.json").is_file()
    # the headline: the published predictions this run can make, and how many hold
    assert report.outcome.headline.label.startswith("published predictions the fitted twin reproduces")
    assert [run["seed"] for run in report.outcome.results["robustness"]] == [3, 2]  # the study, then quick's seed 2


def test_a_failing_pooled_comparison_is_shown_without_the_fingertips_held_at_the_floor():
    from scipy import stats

    from softtip.systems.haptics.report import prediction_tables

    rng = np.random.default_rng(0)
    names = ("small cast (6.5 mm)", "human 3 (10 mm)")
    errors = rng.uniform(0.05, 0.3, (2, len(METHODS), 60))
    errors[0, 1] *= 0.5  # A clearly better on the small cast
    errors[1, 1] += 1.0  # and worse on the floored fingertip, enough to drown the pooled test
    found = RenderedTargets(names, errors, np.ones_like(errors), np.zeros(errors.shape, bool), np.full(60, 1.7))
    significance = prediction_tables(found, 0.015625, {names[0]: 0.0, names[1]: 3.4})[-1]
    note = significance.notes["all fingertips (pooled)"]
    reference = stats.wilcoxon(errors[0, 1], errors[0, 2])
    assert "Without human 3 (10 mm)" in note and f"p = {reference.pvalue:.2g}" in note
    # with no fingertip above the targets' median force, nothing to leave out: no note
    calm = prediction_tables(found, 0.015625, {names[0]: 0.0, names[1]: 1.0})[-1]
    assert "all fingertips (pooled)" not in calm.notes
