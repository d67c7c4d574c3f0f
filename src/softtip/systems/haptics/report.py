"""The S3 study's report (``softtip reproduce haptics``): the haptics protocol's dataset read back into
errors per fingertip, method and target, the publication's statistics on them, and the tables beside
what the S3 spec says the published work found (``published.toml``).

The study's tables are computed from the dataset (:mod:`.bench`), so a dataset written by ``softtip
lab run haptics`` gives the same tables as the study run in one go. The sweeps beyond the
publication (error against n, weighting and table sizes; the methods' ranking as the human fingertips
vary) rerun the simulated study over the protocol's ``curve_*`` and ``variations`` parameters
(:mod:`.sensitivity`) from the dataset's errors: what they rerun draws the same noise as the dataset's
run, and their errors at the protocol's own settings are the dataset's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from softtip._core.progress import Progress
from softtip.data import Dataset
from softtip.lab import Protocol, run_protocol
from softtip.published import BETTER, WITHIN, published_table
from softtip.report.document import Figure
from softtip.report.tables import Table, paper_table
from softtip.sensors.wrench import shift_wrench
from softtip.studies.outcome import Headline, StudyOutcome
from softtip.systems.haptics.ablation import ablate
from softtip.systems.haptics.bench import CONDITIONS, RENDERED, study_fingertips
from softtip.systems.haptics.collection import collection_duration, motor_grid
from softtip.systems.haptics.data_driven import compare_data_driven
from softtip.systems.haptics.device import cable_tensions
from softtip.systems.haptics.fingertips import FINGERTIP_SENSOR, HUMAN_FINGERTIPS, loaded_contact
from softtip.systems.haptics.fit import FIT_SEEDS, FIT_TARGETS, LARGEST_HUMAN, SCALE_COLUMN, SMALL_SPHERE
from softtip.systems.haptics.sensitivity import (
    CURVE_LABELS,
    Baseline,
    CurvePoint,
    RobustnessRun,
    VariationOutcome,
    curves_figure,
    error_curves,
    robustness_study,
    sensitivity_figure,
    sensitivity_study,
)
from softtip.systems.haptics.statistics import friedman, rank_sum, wilcoxon
from softtip.systems.haptics.study import (
    NOTES,
    METHODS,
    PAIRS,
    PUBLISHED_METHODS,
    SHORT_NAMES,
    collect_study,
    error_box_plots,
    wilcoxon_tests,
)

STANDARD, A, B = range(PUBLISHED_METHODS)
BONFERRONI_THRESHOLD = 0.0028  # the publication's corrected significance threshold (0.05 over its 18 tests)
DIRECTIONS = {"standard − A": (STANDARD, A), "standard − B": (STANDARD, B), "B − A": (B, A)}
POOLED = "all fingertips (pooled)"


@dataclass(frozen=True)
class RenderedTargets:
    """The protocol's dataset as arrays: errors and rendered force magnitudes (fingertips, methods,
    targets) in N, flags (same shape), the targets' force magnitudes (targets,) in N."""

    fingertips: tuple[str, ...]
    errors: np.ndarray
    rendered: np.ndarray
    flagged: np.ndarray
    target_magnitudes: np.ndarray

    @classmethod
    def of(cls, dataset: Dataset) -> RenderedTargets:
        """Every trial (a target) holds the same renderings in the same order: fingertip, then method."""
        targets = len(dataset.trials)
        shape = (targets, -1, len(METHODS))
        fingertip = dataset.column("fingertip").reshape(shape)
        method = dataset.column("method").reshape(shape)
        if not (np.all(fingertip == fingertip[:1]) and np.all(method == np.array(METHODS))):
            raise ValueError("haptics dataset: expected every trial to render each fingertip by each method in order")

        def by_fingertip(values: np.ndarray) -> np.ndarray:
            return values.reshape(shape).transpose(1, 2, 0)

        rendered = np.linalg.norm([dataset.column(name) for name in RENDERED[:3]], axis=0)
        conditions = dataset.trial_conditions
        target = np.linalg.norm([conditions[name] for name in list(CONDITIONS)[:3]], axis=0)
        return cls(tuple(fingertip[0, :, 0]), by_fingertip(dataset.column("error_N")), by_fingertip(rendered),
                   by_fingertip(dataset.column("flagged").astype(bool)), target)


def haptics(protocol: Protocol, seed: int, progress: Progress) -> StudyOutcome:
    dataset, timings = run_protocol(protocol, progress)
    p, found = protocol.parameters, RenderedTargets.of(dataset)
    tests = wilcoxon_tests(len(found.fingertips))
    statistics = {name: (friedman(errors[:PUBLISHED_METHODS]),
                         [wilcoxon(errors[a], errors[b], tests) for a, b in PAIRS])
                  for name, errors in zip(found.fingertips, found.errors, strict=True)}
    pooled = wilcoxon(found.errors[:, A].ravel(), found.errors[:, B].ravel(), tests)
    device, fingertips = protocol.design.device, study_fingertips(p, protocol.design)
    minutes = {levels: collection_duration(device, motor_grid(device, levels), p.hold_s) / 60 for levels in (13, 7, 5)}
    floors = released_forces(device, fingertips)
    predictions = prediction_tables(found, p.contact_threshold_N, floors)
    tables = [_scale_table(found), *_fit_tables(device), *predictions, _floor_table(floors, release_gap(device)),
              _error_table(found),
              _statistics_table(statistics, pooled), _collection_table(minutes, p.hold_s),
              _light_table(found, p.light_force_N, p.contact_threshold_N),
              _departures_table(largest_tension(device, fingertips, p.fs_levels),
                                device.stall_tension)]
    figure = Figure.of("Rendering error per fingertip and method", (
        "Box plots over the targets of |F_target − F_rendered| (N), read by the sensor under each test fingertip. "
        "Look for the standard method's spread growing with the size mismatch, and for A against B on the "
        "largest fingertip."), error_box_plots(list(found.fingertips), found.errors))
    results = {
        "timings_s": timings, "methods": list(METHODS), "targets": int(found.errors.shape[-1]),
        "target_force_N": {"mean": float(found.target_magnitudes.mean()),
                           "median": float(np.median(found.target_magnitudes))},
        "collection_min": {f"{levels}^3": value for levels, value in minutes.items()},
        "collection": dataset.metadata.sensor_settings,
        "fingertips": {name: {
            "median_error_N": np.median(errors, axis=1).tolist(), "mean_error_N": errors.mean(axis=1).tolist(),
            "flagged": flagged.sum(axis=1).tolist(),
            "friedman": {"chi_square": statistics[name][0].chi_square, "p": statistics[name][0].p_value},
            "post_hoc": {f"{METHODS[a]} vs {METHODS[b]}": _test(t)
                         for (a, b), t in zip(PAIRS, statistics[name][1], strict=True)}}
            for name, errors, flagged in zip(found.fingertips, found.errors, found.flagged, strict=True)},
        "pooled_A_vs_B": _test(pooled)}
    sweeps = _sweeps(protocol, found, progress)
    results |= sweeps.results
    settings, collection = p.study_settings(), p.collection_settings()
    collected = collect_study(device, fingertips, settings, collection, protocol.seed, fs=protocol.design.fs)
    variants = compare_data_driven(device, fingertips, *collected, settings, collection, protocol.seed)
    tables.append(variants.table())
    if p.ablations:
        ablations = ablate(device, fingertips, *collected, settings, collection, protocol.seed)
        tables.append(ablations.table())
        results["ablations"] = ablations.to_dict()
    variants_figure = Figure.of("Personalisation A: as published against softtip's 3-D variant", (
        "Median error (N) per fingertip of A searching the DS's raw 6-D wrenches and of A searching its 3-D forces "
        "in the device's axes, on the same tables. Look for whether the published search loses anything by "
        "needing no device model."), variants.figure())
    results["data_driven_variants"] = variants.to_dict()
    held, made = held_predictions(predictions)
    results["predictions_held"] = {"held": held, "made": made}
    headline = Headline(f"published predictions the fitted twin reproduces (of {made})", float(held), "")
    return StudyOutcome(results, tables + sweeps.tables, [figure, variants_figure, *sweeps.figures], headline, [
        *NOTES,
        "Fitted, not predicted: the device's released length, pulley radius and cables' stiffness, set from the three "
        "figures of the scale table (the fit table names the fit); every other published figure is a prediction.",
        "Methods B+ (the geometric method with the user's stiffness from five presses) and A+ (the data-driven "
        "one from an adaptive user table) are softtip's, after the authors' future work; the statistics compare "
        "the published three only.", *sweeps.notes])


@dataclass(frozen=True)
class Sweeps:
    """The report's sweeps beyond the publication: tables, figures, JSON results and notes (none when
    the protocol asks for none)."""

    tables: list[Table]
    figures: list[Figure]
    results: dict
    notes: list[str]


def _sweeps(protocol: Protocol, found: RenderedTargets, progress: Progress) -> Sweeps:
    """The sweeps from the study's own errors."""
    p = protocol.parameters
    fingertips, curves, variations = study_fingertips(p, protocol.design), p.curves(), p.selected_variations()
    if protocol.design.fs is not None:  # a recorded FS table has one size: no sweep over it
        curves = tuple((setting, values) for setting, values in curves if setting != "fs_levels")
    robust = bool(p.robustness_seeds) or (p.robustness_sigmas > 0 and protocol.design.device.fit is not None)
    humans = [f.name for f in fingertips if f in HUMAN_FINGERTIPS]
    notes = []
    if variations and not humans:
        notes.append("No sensitivity study: it varies the human fingertips, and this run renders none of them.")
        variations = ()
    if not curves and not variations and not robust:
        return Sweeps([], [], {}, notes)
    baseline = Baseline.run(p.study_settings(), protocol.seed, protocol.design.device, fingertips,
                            p.collection_settings(), progress, errors=found.errors, fs=protocol.design.fs)
    tables, figures, results = [], [], {}
    if robust:
        runs = robustness_study(baseline, p.robustness_seeds, p.robustness_sigmas, progress)
        device = protocol.design.device
        fitted = tuple(device.value(key) for key in device.fit.parameters) if device.fit else ()
        study = RobustnessRun(f"fitted device, seed {protocol.seed} (the study)", protocol.seed, fitted, found.errors,
                              found.rendered)
        table, rows = _robustness_table((study, *runs), found, p.contact_threshold_N,
                                        device.fit.parameters if device.fit else (), p.robustness_sigmas)
        tables.append(table)
        results["robustness"] = rows
    if curves:
        points = error_curves(baseline, progress, curves)
        tables.append(_curves_table(points, p.study_settings()))
        figures.append(Figure.of("Rendering error against n, weighting and table size", (
            "Median |F_target − F_rendered| (N) over every fingertip and target, one setting changed at a time "
            "from the study's own. Look for the data-driven personalisation (A) gaining from a larger user table "
            "and losing from many neighbours, and for the FS table's size setting the floor of the geometric "
            "methods."), curves_figure(points)))
        results["error_curves"] = {setting: {
            "values": [point.value for point in points if point.setting == setting],
            "median_error_N": {method: [float(point.median_error[m]) for point in points if point.setting == setting]
                               for m, method in enumerate(METHODS)}} for setting, _ in curves}
    if variations:
        outcomes = sensitivity_study(baseline, progress, variations)
        tables.append(_sensitivity_table(outcomes, humans))
        if any(outcome.median_error is not None for outcome in outcomes):
            figures.append(Figure.of("The methods' errors as the human fingertips vary", (
                f"Median error (N, log scale) over the targets of {', '.join(humans)}, under each variation of "
                "those fingertips (the casts as published). Look for the geometric method (B) losing its lead "
                "once stiffness or shape departs from its spheres of the casts' rubber."),
                sensitivity_figure(outcomes)))
        results["sensitivity"] = [outcome.to_dict() for outcome in outcomes]
    return Sweeps(tables, figures, results, notes)


def _curves_table(points: tuple[CurvePoint, ...], settings) -> Table:
    rows, cells = [], {}
    for point in points:
        value = getattr(settings, point.setting)
        shown = f"{point.value:g}" + ("³" if point.setting.endswith("levels") else "")
        row = f"{CURVE_LABELS[point.setting].split(' (')[0]}: {shown}" + (" (the study's)" if point.value == value
                                                                            else "")
        rows.append(row)
        cells.update({(row, method): float(point.median_error[m]) for m, method in enumerate(METHODS)})
    return Table("Rendering error against n, weighting and table size (softtip, beyond the publication)", "setting",
                 rows, list(METHODS), cells, unit="N", digits=2, caption=(
                     "Median |F_target − F_rendered| (N) over every fingertip and target, each setting changed alone "
                     "from the study's own (marked); the same targets and noise streams at every point. The "
                     "weighting is 1/d^p over the n nearest entries (p = 0: uniform)."))


def _sensitivity_table(outcomes: tuple[VariationOutcome, ...], humans: list[str]) -> Table:
    columns = [*METHODS, "ranking (best first)", "A vs B pooled: W+ − W−", "A vs B pooled: p (Bonferroni)"]
    cells, notes = {}, {}
    for outcome in outcomes:
        row = outcome.variation.name
        if outcome.left_out:
            notes[row] = (f"Left out: {', '.join(outcome.left_out)} ({outcome.refused})" if outcome.median_error
                          is not None else f"Refused: {outcome.refused}")
        if outcome.median_error is None:
            continue
        cells.update({(row, method): float(outcome.median_error[m]) for m, method in enumerate(METHODS)})
        cells[(row, "ranking (best first)")] = " < ".join(SHORT_NAMES[METHODS.index(m)] for m in outcome.ranking)
        cells[(row, "A vs B pooled: W+ − W−")] = rank_sum(outcome.pooled.signed_rank_sum)
        cells[(row, "A vs B pooled: p (Bonferroni)")] = outcome.pooled.p_bonferroni
    return Table("How the methods' ranking depends on the finger (softtip, beyond the publication)", "variation",
                 [outcome.variation.name for outcome in outcomes], columns, cells, digits=3, notes=notes, caption=(
                     f"Median error (N) over the targets of {', '.join(humans)} under each variation of those "
                     "fingertips (stiffness, shape, core position, mounting; softtip.systems.haptics.sensitivity), "
                     "the casts as published. In softtip's contact model the core's position moves only the "
                     "torques about the sensor's origin, and every method renders from forces. W+ − W− < 0: A's "
                     "errors are the smaller over every fingertip and target studied."))


def _test(result) -> dict:
    return {"W_scipy_min": result.w_scipy, "W_signed_rank_sum": result.signed_rank_sum, "p": result.p_value,
            "p_bonferroni": result.p_bonferroni, "tests": result.tests}


def _directions_table(found: RenderedTargets, floors: dict[str, float] | None = None) -> Table:
    published = published_table("haptics-directions")
    medians = {name: np.median(errors, axis=1) for name, errors in zip(found.fingertips, found.errors, strict=True)}
    pooled = np.median(found.errors.transpose(1, 0, 2).reshape(len(METHODS), -1), axis=1)
    cells = {(name, column): float(median[a] - median[b])
             for name, median in (*medians.items(), (POOLED, pooled)) for column, (a, b) in DIRECTIONS.items()}
    notes = {}
    for name, floor in (floors or {}).items():
        if cells.get((name, "B − A"), 1.0) <= 0 and floor > 0:
            notes[name] = (f"B beats A here, against the publication. The device presses this fingertip with "
                           f"{floor:.2f} N with every servo released (the floor table), above "
                           f"{100 * np.mean(found.target_magnitudes < floor):.0f} % of the targets: every method "
                           "is held at that floor there, and what is left to tell A from B is small.")
    if "FS cast (7.5 mm)" in medians:
        notes["FS cast (7.5 mm)"] = ("The FS itself: no direction stated. B equals the standard table here (r_U = "
                                     "r_F); A is rebuilt from the sparse user table and loses precision.")
    return paper_table(published, {key: value for key, value in cells.items() if key[0] in published.rows},
                       rows={row: row for row in (*found.fingertips, POOLED)}, notes=notes, caption=(
                           "Differences of median error over the targets (N): > 0 means the second method renders "
                           "closer. The publication states directions, not medians: a verdict says only whether "
                           "softtip's twin shows the same direction. The robustness table shows which of them hold "
                           "on every device the fit allows and over seeds."))


def released_forces(device, fingertips) -> dict[str, float]:
    """The force (N) each fingertip feels with every servo at 0: the least a method can render on it."""
    return {f.name: float(np.linalg.norm(loaded_contact(f, device, np.zeros(3))[1][:3])) for f in fingertips}


def release_gap(device) -> float:
    """How far (m) the released platform sits below the FS's pad (negative: above it, pressing it)."""
    return device.device.released_length - (FINGERTIP_SENSOR.radius - device.centre[2])


def _floor_table(floors: dict[str, float], gap: float) -> Table:
    cells = {(name, "force with the servos released (N)"): value for name, value in floors.items()}
    return Table("The device's floor on each fingertip", "fingertip", list(floors),
                 ["force with the servos released (N)"], cells, digits=2, caption=(
                     f"The released platform sits {gap * 1e3:.2f} mm below the FS's pad, so a fingertip reaching lower "
                     "is pressed even with every servo released: no method renders a target lighter than this on "
                     "it. It bounds every method's error on the largest fingertips from below, A's and B's alike."))


def _scale_table(found: RenderedTargets) -> Table:
    """The three figures the device is fitted to, as this run gives them."""
    published = published_table("haptics-scale")
    targets, small, largest = published.rows
    cells = {(targets, SCALE_COLUMN): float(found.target_magnitudes.mean())}
    for row, fingertip in ((small, SMALL_SPHERE.name), (largest, LARGEST_HUMAN.name)):
        if fingertip in found.fingertips:
            cells[(row, SCALE_COLUMN)] = float(found.rendered[found.fingertips.index(fingertip), STANDARD].mean())
    return paper_table(published, cells, caption=(
        "Fitted: the device's unknowns (the fit table) were set from these three figures by least squares over "
        f"seeds {', '.join(map(str, FIT_SEEDS))} and {FIT_TARGETS} targets each (softtip.systems.haptics.fit); this "
        "run draws its own 100 targets, so its gap to each published figure is that draw's sampling error plus the "
        "fit's residual."))


def _fit_tables(device) -> list[Table]:
    """The device's fitted values with their standard errors and correlations, and the fit's residuals
    (none for a device file that records no fit)."""
    fit = device.fit
    if fit is None:
        return []
    rows = [_fitted_label(key) for key in fit.parameters]
    scale = [_shown_unit(key)[1] for key in fit.parameters]
    cells = {}
    for i, (row, key, factor, error) in enumerate(zip(rows, fit.parameters, scale, fit.standard_errors, strict=True)):
        cells[(row, "fitted value")] = device.value(key) * factor
        cells[(row, "standard error")] = error * factor
        cells.update({(row, f"correlation with {other}"): fit.correlation[i][j]
                      for j, other in enumerate(fit.parameters)})
    gap = release_gap(device)
    derived = {"release gap below the FS's pad (mm)": gap * 1e3,
               "stroke past the FS's pad (mm)": (device.device.released_length - gap - device.wound_length) * 1e3}
    for row, value in derived.items():
        cells[(row, "fitted value")] = value
    columns = ["fitted value", "standard error", *(f"correlation with {key}" for key in fit.parameters)]
    parameters = Table("The device's fitted unknowns", "parameter", [*rows, *derived], columns, cells, digits=3,
                       caption=(f"Fitted: {fit.method} Standard errors from the fit's Jacobian, each published "
                                "figure weighted by the standard error of a 100-target mean. The last two rows follow "
                                "from the fitted values."))
    residuals = {(figure, "fit − published (N)"): value for figure, value in zip(fit.figures, fit.residuals,
                                                                                strict=True)}
    return [parameters, Table("The fit's residuals", "figure", list(fit.figures), ["fit − published (N)"], residuals,
                              digits=3, caption="At the fitted values, over the fit's own seeds and targets.")]


def _fitted_label(key: str) -> str:
    unit, _ = _shown_unit(key)
    return f"{key} ({unit})" if unit else key


def _shown_unit(key: str) -> tuple[str, float]:
    """The unit a device file's value is shown in, and its factor from the file's (lengths in mm)."""
    if key.endswith(("length", "radius")):
        return "mm", 1e3
    return ("N/m", 1.0) if key.endswith("stiffness") else ("", 1.0)


def _shown(key: str, value: float) -> str:
    unit, factor = _shown_unit(key)
    return f"{value * factor:.4g} {unit}".strip()


def prediction_tables(found: RenderedTargets, contact: float, floors: dict[str, float] | None = None) -> list[Table]:
    """Every published figure the fitted twin predicts, beside softtip's: the directions, the standard
    method's largest error, the targets it leaves uncontacted on the small fingertips, the statistics;
    ``floors`` (each fingertip's force with the servos released, N) explain a direction that fails."""
    return [_directions_table(found, floors), _largest_error_table(found), _no_contact_table(found, contact),
            _significance_table(found, floors)]


def held_predictions(tables: list[Table]) -> tuple[int, int]:
    """How many of the tables' published predictions softtip's figures meet, of how many it has."""
    verdicts = [c.verdict for table in tables for c in table.comparisons()]
    return sum(v in (WITHIN, BETTER) for v in verdicts), len(verdicts)


def _largest_error_table(found: RenderedTargets) -> Table:
    published = published_table("haptics-largest-error")
    column = published.columns[0]
    cells = {(name, column): float(errors[STANDARD].max())
             for name, errors in zip(found.fingertips, found.errors, strict=True) if name in published.rows}
    return paper_table(published, cells)


def _no_contact_table(found: RenderedTargets, contact: float) -> Table:
    published = published_table("haptics-no-contact")
    column = published.columns[0]
    cells = {(name, column): 100.0 * float(np.mean(rendered[STANDARD] < contact))
             for name, rendered in zip(found.fingertips, found.rendered, strict=True) if name in published.rows}
    return paper_table(published, cells,
                       caption=f"No contact: the sensor under the fingertip reads below {contact:g} N.")


def _significance_table(found: RenderedTargets, floors: dict[str, float] | None = None) -> Table:
    published = published_table("haptics-significance")
    tests = wilcoxon_tests(len(found.fingertips))
    cells = {}
    for name, errors in zip(found.fingertips, found.errors, strict=True):
        if name not in published.rows:
            continue
        cells[(name, "Friedman p")] = friedman(errors[:PUBLISHED_METHODS]).p_value
        cells[(name, "standard vs A: p")] = wilcoxon(errors[STANDARD], errors[A], tests).p_value
        cells[(name, "standard vs B: p")] = wilcoxon(errors[STANDARD], errors[B], tests).p_value
    pooled = wilcoxon(found.errors[:, A].ravel(), found.errors[:, B].ravel(), tests)
    cells[(POOLED, "A vs B: W+ − W−")] = rank_sum(pooled.signed_rank_sum)
    cells[(POOLED, "A vs B: p")] = pooled.p_value
    notes = {}
    # the ablation of a failing pooled comparison: the same test without the fingertips the device presses
    # harder, released, than the targets' median force (every method held at that floor there)
    held_down = [name for name, floor in (floors or {}).items() if floor > np.median(found.target_magnitudes)]
    kept = [i for i, name in enumerate(found.fingertips) if name not in held_down]
    a_better = pooled.signed_rank_sum < 0 and pooled.p_value < BONFERRONI_THRESHOLD
    if not a_better and held_down and kept:
        without = wilcoxon(found.errors[kept, A].ravel(), found.errors[kept, B].ravel(), tests)
        notes[POOLED] = (f"A is not significantly better at 0.0028. Without {', '.join(held_down)} (pressed harder "
                         f"released than the targets' median, the floor table): W+ − W− = "
                         f"{rank_sum(without.signed_rank_sum)}, p = {without.p_value:.2g}. The robustness table "
                         "shows the comparison over the fit's devices and seeds.")
    return paper_table(published, cells, notes=notes, caption=(
        "p as computed, to be read against the publication's Bonferroni threshold 0.0028 (the statistics table "
        "gives the corrected p). W+ − W− < 0: A's errors are the smaller."))


def _robustness_table(runs, found: RenderedTargets, contact: float, keys, sigmas: float) -> tuple[Table, list[dict]]:
    """Each run's fitted values (``keys``), median errors of the published methods over every fingertip
    and target, pooled A-vs-B test and count of the published predictions it meets; a last row counts
    the runs. ``sigmas``: how far the devices were moved, in standard deviations."""
    columns = ["fitted values", "standard", "A", "B", "B − A pooled (N)", "A vs B pooled: W+ − W−",
               "A vs B pooled: p", "A better than B, pooled (p < 0.0028)", "predictions held"]
    tests = wilcoxon_tests(len(found.fingertips))
    cells, rows, results = {}, [], []
    for run in runs:
        same = RenderedTargets(found.fingertips, run.errors, run.rendered, found.flagged, found.target_magnitudes)
        held, made = held_predictions(prediction_tables(same, contact))
        medians = np.median(run.errors.transpose(1, 0, 2).reshape(run.errors.shape[1], -1), axis=1)
        pooled = wilcoxon(run.errors[:, A].ravel(), run.errors[:, B].ravel(), tests)
        better = bool(pooled.signed_rank_sum < 0 and pooled.p_value < BONFERRONI_THRESHOLD)
        rows.append(run.label)
        cells[(run.label, "fitted values")] = ", ".join(_shown(key, value)
                                                        for key, value in zip(keys, run.values, strict=True))
        cells.update({(run.label, "standard"): float(medians[STANDARD]), (run.label, "A"): float(medians[A]),
                      (run.label, "B"): float(medians[B]),
                      (run.label, "B − A pooled (N)"): float(medians[B] - medians[A]),
                      (run.label, "A vs B pooled: W+ − W−"): rank_sum(pooled.signed_rank_sum),
                      (run.label, "A vs B pooled: p"): pooled.p_value,
                      (run.label, "A better than B, pooled (p < 0.0028)"): "yes" if better else "no",
                      (run.label, "predictions held"): f"{held} of {made}"})
        results.append({"run": run.label, "seed": run.seed, "fitted_values": list(run.values),
                        "median_error_N": dict(zip(METHODS[:PUBLISHED_METHODS], medians[:PUBLISHED_METHODS].tolist(),
                                                   strict=True)),
                        "pooled_A_vs_B": _test(pooled), "A_better_than_B": better, "predictions_held": held,
                        "predictions_made": made})
    count = sum(r["A_better_than_B"] for r in results)
    summary = f"over all {len(runs)} runs"
    rows.append(summary)
    cells[(summary, "A better than B, pooled (p < 0.0028)")] = f"{count} of {len(runs)}"
    least = min(results, key=lambda r: r["predictions_held"])
    cells[(summary, "predictions held")] = f"at least {least['predictions_held']} of {least['predictions_made']}"
    return Table("Robustness: the conclusions over the devices the fit allows and over seeds", "run", rows, columns,
                 cells, digits=3, layout="rows", caption=(
                     "The study rerun on the devices the published scale cannot tell apart (the fitted values moved "
                     f"{sigmas:g}σ down and up each principal axis of their correlation, the fit table) "
                     "and on the fitted device over other seeds. Medians (N) over every fingertip and target. A "
                     "conclusion that holds on every row is the method's; one that flips is the device's or the "
                     "draw's.")), results


def _error_table(found: RenderedTargets) -> Table:
    rows, cells = [], {}
    for name, errors, rendered, flagged in zip(found.fingertips, found.errors, found.rendered, found.flagged,
                                               strict=True):
        for m, method in enumerate(METHODS):
            row = f"{name} · {method}"
            rows.append(row)
            cells.update({(row, "median error (N)"): float(np.median(errors[m])),
                          (row, "mean error (N)"): float(errors[m].mean()),
                          (row, "median rendered |F| (N)"): float(np.median(rendered[m])),
                          (row, "flagged targets"): int(flagged[m].sum())})
    return Table("Rendering error per fingertip and method", "fingertip · method", rows,
                 ["median error (N)", "mean error (N)", "median rendered |F| (N)", "flagged targets"], cells,
                 digits=2, caption=("The publication reports medians and means per fingertip with box plots. Flagged: "
                                    "the target lay outside the table's range or the sensor under the test fingertip "
                                    "saturated (rendered all the same, never silently)."))


def _statistics_table(statistics: dict, pooled) -> Table:
    columns = ["Friedman χ²", "Friedman p"] + [f"{METHODS[a]} vs {METHODS[b]}: {what}" for a, b in PAIRS
                                                for what in ("W (scipy)", "W+ − W−", "p (Bonferroni)")]
    cells = {}
    for name, (rank, post_hoc) in statistics.items():
        cells.update({(name, "Friedman χ²"): rank.chi_square, (name, "Friedman p"): rank.p_value})
        for (a, b), test in zip(PAIRS, post_hoc, strict=True):
            label = f"{METHODS[a]} vs {METHODS[b]}"
            cells.update({(name, f"{label}: W (scipy)"): rank_sum(test.w_scipy),
                          (name, f"{label}: W+ − W−"): rank_sum(test.signed_rank_sum),
                          (name, f"{label}: p (Bonferroni)"): test.p_bonferroni})
    label = f"{METHODS[A]} vs {METHODS[B]}"
    cells.update({(POOLED, f"{label}: W (scipy)"): rank_sum(pooled.w_scipy),
                  (POOLED, f"{label}: W+ − W−"): rank_sum(pooled.signed_rank_sum),
                  (POOLED, f"{label}: p (Bonferroni)"): pooled.p_bonferroni})
    return Table("Statistics as published: Friedman per fingertip, Wilcoxon post hoc with Bonferroni", "fingertip",
                 [*statistics, POOLED], columns, cells, digits=3, layout="rows", caption=(
                     "W (scipy) is min(W+, W−), what scipy.stats.wilcoxon returns; W+ − W− is the signed-rank sum the "
                     "publication prints (negative: the first method's errors are smaller). Bonferroni counts every "
                     "Wilcoxon test made: three per fingertip and the pooled one."))


def _collection_table(minutes: dict, hold_s: float) -> Table:
    published = published_table("haptics-collection")
    rows = dict(zip(published.rows, (13, 7, 5), strict=True))
    cells = {(row, "entries"): levels**3 for row, levels in rows.items()}
    cells.update({(row, "collection (min)"): minutes[levels] for row, levels in rows.items()})
    notes = {}
    for row, levels in rows.items():
        wanted = published.value(row, "collection (min)")
        if wanted is not None and minutes[levels] < wanted.low:
            holds = levels**3 * hold_s / 60
            notes[row] = (f"softtip's {minutes[levels]:.1f} min are {holds:.1f} min of holds and "
                          f"{minutes[levels] - holds:.1f} min of servo travel; the published {wanted.text} min leave "
                          f"{60 * (wanted.low - minutes[levels]) / levels**3:.2f} s per configuration that the "
                          "described procedure does not account for (settling, a person's pauses: not modelled).")
    return paper_table(published, cells, notes=notes,
        caption="Time a real collection takes on softtip's device: each configuration driven (slew, 50 Hz command "
                "frames) and held 1 s, in the order driven.")


def _light_table(found: RenderedTargets, light_force: float, contact: float) -> Table:
    light = found.target_magnitudes < light_force
    cells = {}
    for name, rendered in zip(found.fingertips, found.rendered, strict=True):
        cells[(name, "light targets")] = int(light.sum())
        cells[(name, "rendered as no contact (standard)")] = int(np.sum(light & (rendered[STANDARD] < contact)))
    return Table(f"Light targets (< {light_force:g} N) the standard method renders as no contact", "fingertip",
                 list(found.fingertips), ["light targets", "rendered as no contact (standard)"], cells, digits=0,
                 caption="On a smaller fingertip the FS table's light entries leave the platform short of the pad.")


def largest_tension(device, fingertips, levels: int) -> float:
    """The largest cable tension (N) over the FS table's configurations (``levels``³) pressed on each of
    ``fingertips``: what the servos must hold."""
    grid = motor_grid(device, levels)
    largest = 0.0
    for fingertip in fingertips:
        _, on_finger = loaded_contact(fingertip, device, grid)
        about_device = shift_wrench(on_finger, fingertip.centre(device) + np.array(fingertip.core_offset), np.zeros(3))
        largest = max(largest, float(cable_tensions(device, grid, about_device).max()))
    return largest


def _departures_table(tension: float, stall: float) -> Table:
    rows = {
        "device": ("a built device, dimensions not given",
                   "softtip's dimensions in a device file (device.toml); its released length, pulley radius and "
                   "cables' stiffness fitted to the published scale (the fit table)"),
        "cables": ("cables inside springs, wound by servos", "each cable a spring in series, its spring easing beside "
                   "it: the platform gives way along its normal under the contact, keeping its tilt; B+'s presses "
                   "take the cables rigid, as published methods' kinematics do (the ablations table measures what "
                   "that costs)"),
        "fingertips": ("VytaFlex 30 casts over a rigid core: three spheres and three casts of human fingertips",
                       "three spheres and three ellipsoidal casts (1.6 times longer along the finger), one rubber, "
                       "contact law calibrated by softtip's FE; the geometric method takes each human cast for its "
                       "sphere, as published"),
        "sensors": ("Nano17-class 6-axis sensors", "simulated Nano17: its ranges and steps, one step of noise at 1 kHz"),
        "contact": ("with friction (a tilted platform pushes sideways too)",
                    "frictionless: force along the platform's normal only"),
        "servos": ("position commands at about 50 Hz", "reach each configuration to their dead band before the hold; "
                   "a servo holds at most its stall torque over the pulley, beyond it the cable pays out and the "
                   f"platform stops short: the largest cable tension over the FS table on the test fingertips is "
                   f"{tension:.1f} N, the stall's {stall:.0f} N"
                   + (", so the study's servos never stall" if tension < stall else ": the hardest presses stall")),
        "targets": ("100 from random configurations that touch the FS",
                    "the same procedure, the servos' angles drawn uniformly over their range"),
        "statistics": ("Bonferroni over the publication's tests (threshold 0.0028)",
                       "Bonferroni over every Wilcoxon test softtip makes (three per fingertip and the pooled one)"),
        "people": ("a perception study rated realism", "not reproduced: only the forces"),
        "methods": ("standard, A, B", "also B+ (presses) and A+ (adaptive table), softtip's"),
        "method A's search": ("the DS's raw wrenches (force and torque)",
                              "the same, torques over the FS's radius; softtip's 3-D variant in the device's axes "
                              "compared beside it"),
    }
    cells = {(row, column): text for row, texts in rows.items()
             for column, text in zip(("published", "softtip"), texts, strict=True)}
    return Table("Where softtip's procedure departs from the published one", "item", list(rows),
                 ["published", "softtip"], cells)
