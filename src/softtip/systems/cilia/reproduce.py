"""``softtip reproduce cilia``: the S4 force study of the lab's ``cilia`` dataset, beside the published figures.

The protocol's dataset holds the twin's measured curves (paper and balance modes, both sensors, repeated
loadings) and its brushings of four surfaces. The study fits the first paper-mode curve of the protocol's sensor (moment and tip diameter,
height and modulus held, as published), every repeat for the recovery of the twin's truth, and the first
balance-mode curve with the same paper-mode model (what the published fit would have made of the real
test); then the resolution, the measurement range and the layout's weight
(:func:`softtip.systems.cilia.study.analyse_curves`). Paper-mode is the fit the report leads with. The
roughness study (:func:`softtip.systems.cilia.roughness.analyse_roughness`) reads the dataset's brushings
from the written file; the design search (:mod:`softtip.systems.cilia.design`) runs on the twin's die.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from softtip._core.progress import Progress
from softtip._core.units import MM, MN, UM, UN
from softtip.data import Dataset
from softtip.lab import Protocol, run_protocol
from softtip.published import published_table
from softtip.report.document import Figure
from softtip.report.tables import Table, paper_table
from softtip.sensors.gmr import TESLA_PER_OERSTED
from softtip.studies.outcome import Headline, StudyOutcome
from softtip.systems.cilia.bench import SENSORS, curve_of, recordings_of
from softtip.systems.cilia.continuous import chain_against_stack, continuous_table
from softtip.systems.cilia.design import DESIGN_CAPTION, design_table, search_designs
from softtip.systems.cilia.fit import CurveFit
from softtip.systems.cilia.layout import MEMU
from softtip.systems.cilia.roughness import analyse_roughness, readout_levels
from softtip.systems.cilia.roughness_report import roughness_report
from softtip.systems.cilia.study import (
    CiliaStudy,
    analyse_curves,
    balance_contact,
    balance_descent,
    paper_forces,
    twin_model,
)

MOMENT, DIAMETER = "moment per pillar (memu)", "tip diameter (µm)"


def cilia(protocol: Protocol, seed: int, progress: Progress) -> StudyOutcome:
    made, timings = run_protocol(protocol, progress)
    with tempfile.TemporaryDirectory() as folder:  # the analysis reads the file, as it would a user's
        dataset = Dataset.read(made.write(Path(folder) / f"{protocol.name}.parquet"))
    settings = replace(protocol.parameters, die=str(protocol.design.path))
    model = twin_model(settings)
    repeats = sorted({int(r) for r in dataset.column("repeat")})
    measured = [curve_of(dataset, "paper", repeat, settings.sensor) for repeat in repeats]
    truth = model.curve(paper_forces(settings), settings.sensor)
    balance = model.balance_curve(balance_descent(model, settings), balance_contact(settings), settings.sensor)
    study = analyse_curves(settings, seed, model, truth, measured, balance,
                           curve_of(dataset, "balance", repeats[0], settings.sensor), progress)
    rest = {sensor: model.rest_volts(sensor) for sensor in SENSORS}
    with progress.task("roughness: the dataset's brushings, the classifier, the other readout"):
        rough = analyse_roughness(recordings_of(dataset), settings.brush_speed_mm_s * MM, settings.brush_rate_hz,
                                  seed)
        other = readout_levels(model, balance_contact(settings), settings.brush_engagement_um * UM,
                               settings.brush_length_mm * MM, settings.brush_speed_mm_s * MM, settings.brush_rate_hz,
                               settings.brush_strips, seed, not settings.brush_bridge)
        brushing = roughness_report(rough, other, settings.brush_bridge, settings.brush_speed_mm_s,
                                    settings.brush_rate_hz, settings.brush_engagement_um, settings.brush_strips,
                                    settings.brush_length_mm)
    with progress.task("the dipole chain against continuous cones"):
        continuous = chain_against_stack(model, np.array([1.0, 8.0, settings.force_max_mN]) * MN, "X")
    designs = search_designs(model.die, tuple(r * MN for r in settings.design_ranges_mN), settings.sensor,
                             settings.design_steps, settings.design_budget, settings.design_points,
                             settings.chain_count, seed, progress)
    tables = [_published_parameters(study), _range(study), _spin_valves(model), _readout(model, rest),
              _fit_table(study), _identifiability_table(study), _recovery_table(study), _resolution_table(study),
              _balance_table(study), _layout_table(study, model.die.depth), *brushing.tables, continuous_table(continuous),
              design_table(designs)]
    figures = [Figure.of("Voltage change against force", "The measured curve (the twin read through the meter and "
                         "the bench), its truth, the paper-mode fit, and the balance test's curve: the pillars "
                         "buckle before they bend, so the balance curve has its own shape.", study.figures.curve),
               Figure.of("The field over the die", "The in-plane field along the sensor's axis in the sensing "
                         "plane, at rest and at the largest force: far above the linear range near each base; "
                         "the meanders (boxes) see the edge of it.", study.figures.field_map),
               Figure.of("Deformed pillars", "The pillars' centre lines in paper mode (bending towards the "
                         "horizontal) and in balance mode (compressed, buckled, lying).", study.figures.pillars),
               Figure.of("Profile likelihoods", "n ln(RSS/RSS_min) of each parameter with the other at its best; "
                         "the 95 % interval is where it stays under 3.84.", study.figures.profiles),
               Figure.of("Roughness", "The AC rms of the voltage against the surfaces' rms roughness, against "
                         "the sampling rate and against the stage speed: a reading integrates over its interval, "
                         "so a slow rate or a fast stage averages the grains away.", brushing.figure),
               Figure.of("The dipole chain against continuous cones", "The X sensor's voltage change in paper mode "
                         "from the published dipole chain and from the pillars as stacks of uniformly magnetised "
                         "cylinders (dotted: the chain's gap).", continuous.figure()),
               Figure.of("Design search: the smallest force against the range", DESIGN_CAPTION, designs.figure)]
    headline = Headline.of(tables[0], MOMENT, "value", "fitted moment per pillar", unit="memu")
    results = _results(study, rest, timings) | {"roughness": rough.to_dict() | {"other_readout": other.to_dict()},
                                                "design_search": designs.to_dict(),
                                                "chain_against_continuous": continuous.to_dict()}
    return StudyOutcome(results, tables, figures, headline, _notes(study) + brushing.notes)


def _published_parameters(study: CiliaStudy) -> Table:
    fit = study.fit
    return paper_table(published_table("cilia-moment"), {(MOMENT, "value"): fit.moment / MEMU,
                                                         (DIAMETER, "value"): fit.diameter / UM},
                       caption="The twin's truth is the published moment and the nominal diameter: their recovery "
                               "tests the fit on a curve of known truth, not the sensor.")


def _range(study: CiliaStudy) -> Table:
    return paper_table(published_table("cilia-range"), {("X", "upper end"): study.resolution.range[1] / MN},
                       caption="softtip's range ends where the local slope has fallen to a tenth of its value at "
                               "zero force (the pillars have turned over).",
                       notes={"X": "The publication's 26 mN is where its balance test stopped, with no criterion; "
                                   "softtip's end is a slope criterion on the paper-mode curve."})


def _spin_valves(model) -> Table:
    cells = {}
    for sensor in SENSORS:
        valve = model.die.meander(sensor).readout.sensor
        cells[(sensor, "magnetoresistance (%)")] = 100 * valve.magnetoresistance
        cells[(sensor, "sensitivity (Ω/Oe)")] = valve.sensitivity * TESLA_PER_OERSTED
    return paper_table(published_table("cilia-gmr"), cells, caption="The figures the die file's spin valves are "
                       "built from, read back from the model.")


def _readout(model, rest: dict[str, float]) -> Table:
    current = model.die.meander("X").readout.current
    return paper_table(published_table("cilia-readout"),
                       {(sensor, "resistance"): rest[sensor] / current / 1e3 for sensor in SENSORS},
                       caption=f"At rest, self-heating included, at {current * 1e6:.0f} µA: X at "
                               f"{rest['X']:.2f} V, Y at {rest['Y']:.2f} V.")


def _interval(values: tuple[float | None, float | None], scale: float) -> tuple[float | None, float | None]:
    return tuple(None if v is None or not math.isfinite(v) else v / scale for v in values)


def _fit_table(study: CiliaStudy) -> Table:
    fit, pd, pm = study.fit, study.profile_diameter, study.profile_moment
    rows = [MOMENT, DIAMETER, "moment / diameter⁴ (memu/mm⁴)"]
    columns = ["fit", "95 % Wald low", "95 % Wald high", "95 % profile low", "95 % profile high", "truth"]
    ratio_scale = MEMU / 1e-12  # memu per mm⁴
    values = {MOMENT: (fit.moment / MEMU, *_interval(fit.interval_moment, MEMU), *_interval(pm.interval, MEMU),
                       study.recovery.truth_moment / MEMU),
              DIAMETER: (fit.diameter / UM, *_interval(fit.interval_diameter, UM), *_interval(pd.interval, UM),
                         study.recovery.truth_diameter / UM),
              rows[2]: (fit.ratio / ratio_scale, *_interval(fit.interval_ratio, ratio_scale), None, None,
                        study.recovery.truth_moment / study.recovery.truth_diameter**4 / ratio_scale)}
    cells = {(row, column): value for row in rows for column, value in zip(columns, values[row])}
    return Table("The paper-mode fit of the measured curve", "parameter", rows, columns, cells, digits=3,
                 caption=f"Least squares in log parameters, {fit.points} points, residual rms "
                         f"{fit.noise * 1e6:.1f} µV; correlation of the log parameters {fit.correlation:+.4f}. "
                         "A blank profile bound: the profile stays under the threshold to the grid's edge.")


def _identifiability_table(study: CiliaStudy) -> Table:
    part = study.identifiability
    rows = [f"linear part (≤ {part.linear_part_limit / MN:.1f} mN)", "whole curve"]
    columns = ["points", "moment (memu)", "diameter (µm)", "correlation", "moment 95 % width (×)",
               "diameter 95 % width (×)", "ratio 95 % width (×)"]
    cells = {}
    for row, fit in zip(rows, (part.linear, part.whole)):
        cells.update({(row, "points"): fit.points, (row, "moment (memu)"): fit.moment / MEMU,
                      (row, "diameter (µm)"): fit.diameter / UM, (row, "correlation"): fit.correlation,
                      (row, "moment 95 % width (×)"): _width(fit.interval_moment),
                      (row, "diameter 95 % width (×)"): _width(fit.interval_diameter),
                      (row, "ratio 95 % width (×)"): _width(fit.interval_ratio)})
    return Table("What the curve identifies: the linear part against the whole curve", "fitted on", rows, columns,
                 cells, digits=3, caption="Widths are high/low of the 95 % Wald interval (1 is a point). In the "
                 "linear part the voltage follows moment × compliance ∝ moment/diameter⁴: the ratio is held, "
                 "each parameter alone is not (correlation near +1); the saturating part separates them.")


def _width(interval: tuple[float, float]) -> float | None:
    low, high = interval
    return high / low if low > 0 and math.isfinite(high) else None


def _recovery_table(study: CiliaStudy) -> Table:
    recovery = study.recovery
    rows = ["moment", "tip diameter"]
    cells = {}
    for row, (bias, spread) in zip(rows, (recovery.moment_error, recovery.diameter_error)):
        cells.update({(row, "fits"): recovery.moments.size, (row, "bias (%)"): 100 * bias,
                      (row, "spread (%)"): 100 * spread if recovery.moments.size > 1 else None})
    return Table("Recovery of the twin's truth over the repeated loadings", "parameter", rows,
                 ["fits", "bias (%)", "spread (%)"], cells, digits=2,
                 caption="Each repeat of the protocol is a new reading of the same twin (meter noise, quantisation, "
                         "the bench's repeatability); every one is fitted from the same start.")


def _resolution_table(study: CiliaStudy) -> Table:
    rows = [study.resolution.sensor, study.other_sensor.sensor]
    columns = ["sensitivity at rest (mV/mN)", "noise σ (µV)", "meter count (µV)", "minimum force, 3σ (µN)",
               "smallest step (µN)", "range upper end (mN)"]
    cells = {}
    for resolved in (study.resolution, study.other_sensor):
        row = resolved.sensor
        beyond = resolved.minimum_force_at_rest > resolved.force[-1]  # insensitive: no force in reach resolves
        cells.update({(row, columns[0]): resolved.sensitivity, (row, columns[1]): resolved.noise.total * 1e6,
                      (row, columns[2]): resolved.noise.resolution * 1e6,
                      (row, columns[3]): "beyond the range" if beyond else resolved.minimum_force_at_rest / UN,
                      (row, columns[4]): "beyond the range" if beyond else resolved.smallest_step_at_rest / UN,
                      (row, columns[5]): resolved.range[1] / MN})
    return Table("The smallest force resolved and the measurement range", "sensor", rows, columns, cells, digits=3,
                 caption="At zero force. 3σ: three standard deviations of one reading over the local slope; the "
                         "smallest step: a difference of two readings above its own noise (3√2 σ) and at least "
                         "one meter count. The range ends where the slope has fallen to a tenth.",
                 notes={study.other_sensor.sensor: "Its strips sense across the bend: the pillars bent along x "
                        "barely change the field it sees."})


def _balance_table(study: CiliaStudy) -> Table:
    balance = study.balance
    rows = ["paper-mode curve", "balance-mode curve"]
    columns = ["moment (memu)", "diameter (µm)", "on a bound", "residual rms (µV)"]
    cells = {}
    for row, fit in zip(rows, (study.fit, balance.fit)):
        if fit is not None:
            cells.update({(row, columns[0]): fit.moment / MEMU, (row, columns[1]): fit.diameter / UM,
                          (row, columns[2]): "yes" if fit.at_bound else "no", (row, columns[3]): fit.noise * 1e6})
    notes = ({rows[1]: balance.refusal} if balance.fit is None
             else {rows[1]: "On a bound: the paper model (pillars bending from the first newton) cannot take the "
                            "shape of a curve whose pillars first compress and buckle; its figures mean little."}
             if balance.fit.at_bound else {})
    return Table("What balance mode does to the paper-mode fit", "fitted curve", rows, columns, cells, digits=3,
                 caption=f"Balance mode: the die pushed onto a plate (friction {study.settings.friction:g}, "
                         f"a {study.settings.imperfection_deg:g}° bow); the pillars buckle at "
                         f"{balance.buckling_force / MN:.2f} mN in all before they bend. The paper model "
                         "fitted to that curve is what the published fit would make of the real test.",
                 notes=notes)


def _layout_table(study: CiliaStudy, declared_depth: float) -> Table:
    layout, fit = study.layout, study.fit
    rows = [f"sensing plane {d / UM:g} µm deep" for d in layout.depths]
    rows += [f"meanders scaled × {s:g}" for s in layout.scales]
    moments = np.concatenate([layout.moments_by_depth, layout.moments_by_scale])
    diameters = np.concatenate([layout.diameters_by_depth, layout.diameters_by_scale])
    cells = {}
    for row, moment, diameter in zip(rows, moments, diameters):
        cells.update({(row, "moment (memu)"): moment / MEMU, (row, "moment / declared"): moment / fit.moment,
                      (row, "diameter (µm)"): diameter / UM})
    return Table("How the fitted moment depends on the declared layout", "die", rows,
                 ["moment (memu)", "moment / declared", "diameter (µm)"], cells, digits=3,
                 caption=f"The same measured curve fitted by dies of other layouts (declared: "
                         f"the sensing plane {declared_depth / UM:g} µm deep, "
                         "meanders as in die.toml). The averaged signal is an edge effect of the finite "
                         "meanders: the moment a curve implies moves with where they are.")


def _results(study: CiliaStudy, rest: dict[str, float], timings: dict) -> dict:
    def fit_of(fit: CurveFit | None) -> dict | None:
        if fit is None:
            return None
        return {"moment_memu": fit.moment / MEMU, "diameter_um": fit.diameter / UM,
                "interval_moment_memu": [v / MEMU for v in fit.interval_moment],
                "interval_diameter_um": [v / UM for v in fit.interval_diameter], "correlation": fit.correlation,
                "residual_rms_uV": fit.noise * 1e6, "at_bound": fit.at_bound}

    return {"fit": fit_of(study.fit),
            "profile_interval_moment_memu": list(_interval(study.profile_moment.interval, MEMU)),
            "profile_interval_diameter_um": list(_interval(study.profile_diameter.interval, UM)),
            "linear_part_limit_mN": study.identifiability.linear_part_limit / MN,
            "linear_part": fit_of(study.identifiability.linear), "whole_curve": fit_of(study.identifiability.whole),
            "recovery": {"moment_bias_spread": list(study.recovery.moment_error),
                         "diameter_bias_spread": list(study.recovery.diameter_error)},
            "minimum_force_3sigma_uN": {r.sensor: r.minimum_force_at_rest / UN
                                        for r in (study.resolution, study.other_sensor)},
            "smallest_step_uN": {r.sensor: r.smallest_step_at_rest / UN for r in (study.resolution, study.other_sensor)},
            "sensitivity_mV_per_mN": {r.sensor: r.sensitivity for r in (study.resolution, study.other_sensor)},
            "range_mN": [v / MN for v in study.resolution.range],
            "rest_V": rest,
            "balance": {"buckling_mN": study.balance.buckling_force / MN, "fit": fit_of(study.balance.fit),
                        "refusal": study.balance.refusal},
            "layout": {"depths_um": list(study.layout.depths / UM),
                       "moments_by_depth_memu": list(study.layout.moments_by_depth / MEMU),
                       "scales": list(study.layout.scales),
                       "moments_by_scale_memu": list(study.layout.moments_by_scale / MEMU)},
            "timings_s": timings}


def _notes(study: CiliaStudy) -> list[str]:
    notes = [
        "The measured curve is the twin's: the declared die with the published moment (2.8 memu per pillar) and "
        "the nominal tip diameter, read through the computed readout and the bench's repeatability. The fit's "
        "agreement with those figures tests the fit on a curve of known truth; it cannot confirm the sensor.",
        "The spec states no fitted diameter, no minimum force and no force sensitivity: softtip's figures for "
        "them stand alone. The published 26 mN is where the balance test stopped; softtip's range ends where "
        "the slope has fallen to a tenth.",
        "The die layout is declared (die.toml): the publication shows it only in figures. The layout table shows "
        "how much the fitted moment depends on it.",
        "The fit uses paper mode (a tip load perpendicular to each pillar), as published. The balance test "
        "pushes vertically: the pillars compress and buckle before they bend, so its curve differs in shape.",
    ]
    if study.balance.fit is None:
        notes.append(f"The paper-mode model could not fit the balance-mode curve: {study.balance.refusal}")
    elif study.balance.fit.at_bound:
        notes.append("The paper-mode fit of the balance-mode curve ends on a bound of its parameters: the paper "
                     "model cannot describe the balance test's curve, and its figures mean little.")
    if study.fit.at_bound:
        notes.append("The paper-mode fit ended on a bound: the curve does not hold that parameter.")
    return notes


