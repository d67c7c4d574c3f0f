"""``softtip reproduce cilia``: the S4 force study of the lab's ``cilia`` dataset, beside the published figures.

The protocol's dataset holds the twin's measured curves (paper and balance modes, both sensors, repeated
loadings) and its brushings of four surfaces. The report leads with the publication's fit made again: its
model (a clamped uniform cylinder loaded at its tip, 1 mm and 1 MPa held) fitted to the twin's balance curve
as performed and to its tip-load curve, beside the published 0.9 memu and 280 µm, then the publication's
causes of its 3 × moment gap tried on the twin, the range by the publication's criterion and the balance
test's minimum force from its causes. softtip's own fit of its own tip-load curve follows as an
identifiability check (:func:`softtip.systems.cilia.study.analyse_curves`). The
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
from softtip.studies.outcome import Headline, StudyOutcome
from softtip.systems.cilia.bench import channel, curve_of, recordings_of
from softtip.systems.cilia.continuous import chain_against_stack, continuous_table
from softtip.systems.cilia.design import DESIGN_CAPTION, design_table, search_designs
from softtip.systems.cilia.fit import CurveFit
from softtip.systems.cilia.layout import MEMU, DieError, read_die
from softtip.systems.cilia.model import BalanceCurve
from softtip.systems.cilia.resolution import BUDGET_PARTS, ForceBudget, Resolution
from softtip.systems.cilia.roughness import RoughnessStudy, analyse_roughness, readout_levels
from softtip.systems.cilia.roughness_report import roughness_report
from softtip.systems.cilia.study import (
    CHAIN_CHECK,
    CiliaStudy,
    RigCase,
    analyse_curves,
    balance_contact,
    balance_descent,
    balance_plate,
    paper_forces,
    twin_model,
)

MOMENT, DIAMETER = "moment per pillar (memu)", "tip diameter (µm)"
PILLAR_DIAMETER = "pillar diameter (µm)"  # the publication's cylinder has one diameter


def cilia(protocol: Protocol, seed: int, progress: Progress) -> StudyOutcome:
    on_die = tuple(m.name for m in read_die(protocol.design.path).meanders)
    if protocol.parameters.sensor not in on_die:
        raise DieError(f"protocol {protocol.name}: parameters.sensor = {protocol.parameters.sensor!r}: the die file "
                       f"{protocol.design.path.name} has the sensor {' and '.join(on_die)} only; set "
                       f"sensor = \"{on_die[0]}\"")
    made, timings = run_protocol(protocol, progress)
    with tempfile.TemporaryDirectory() as folder:  # the analysis reads the file, as it would a user's
        dataset = Dataset.read(made.write(Path(folder) / f"{protocol.name}.parquet"))
    settings = replace(protocol.parameters, die=str(protocol.design.path))
    model = twin_model(settings)
    repeats = sorted({int(r) for r in dataset.column("repeat")})
    measured = [curve_of(dataset, "paper", repeat, settings.sensor) for repeat in repeats]
    truth = model.curve(paper_forces(settings), settings.sensor)
    balance = model.balance_curve(balance_descent(model, settings), balance_contact(settings), settings.sensor,
                                  balance_plate(settings))
    study = analyse_curves(settings, seed, model, truth, measured, balance,
                           curve_of(dataset, "balance", repeats[0], settings.sensor), progress,
                           protocol.realism.dwell_s)
    rest = {sensor: model.rest_volts(sensor) for sensor in on_die}
    with progress.task("roughness: the dataset's brushings, the classifier, the other readout"):
        rough = analyse_roughness(recordings_of(dataset, channel(settings.sensor)), settings.brush_speed_mm_s * MM,
                                  settings.brush_rate_hz, seed)
        other = readout_levels(model, balance_contact(settings), settings.brush_engagement_um * UM,
                               settings.brush_length_mm * MM, settings.brush_speed_mm_s * MM, settings.brush_rate_hz,
                               settings.brush_strips, seed, not settings.brush_bridge)
        brushing = roughness_report(rough, other, settings.brush_bridge, settings.brush_speed_mm_s,
                                    settings.brush_rate_hz, settings.brush_engagement_um, settings.brush_strips,
                                    settings.brush_length_mm)
    with progress.task("the dipole chain against continuous cones"):
        continuous = chain_against_stack(model, np.array([1.0, 8.0, settings.force_max_mN]) * MN, settings.sensor)
    designs = search_designs(model.die, tuple(r * MN for r in settings.design_ranges_mN), settings.sensor,
                             settings.design_steps, settings.design_budget, settings.design_points,
                             settings.chain_count, seed, progress)
    published_slope, *brushing_tables = brushing.tables
    tables = [_publication_fit_table(study), *_moment_gap_tables(study), _range(study),
              *_minimum_force_tables(study, model.die.depth), _balance_table(study), *([_rig_table(study)] if study.rig else []),
              published_slope, _sampling(rough),
              _readout(model, rest), _fit_table(study), _identifiability_table(study), _recovery_table(study),
              _resolution_table(study), _layout_table(study, model.die.depth), *brushing_tables,
              continuous_table(continuous),
              design_table(designs)]
    figures = [Figure.of("Voltage change against force", "The measured curve (the twin read through the meter and "
                         "the bench), its truth, the paper-mode fit, and the balance test's curve: the pillars "
                         "buckle before they bend, so the balance curve has its own shape.", study.figures.curve),
               Figure.of("The balance test as performed", "The twin's balance curve at its own scale, as read "
                         "through the meter and the bench: the pillars compress with hardly a signal, buckle, bend "
                         "and lie down while the balance reads on; the publication's tip-load model fitted to it, "
                         "and the meter's noise band.", study.figures.balance),
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
    headline = Headline.of(tables[0], MOMENT, TIP_LOAD, _headline_label(study), unit="memu")
    results = _results(study, rest, timings) | {"roughness": rough.to_dict() | {"other_readout": other.to_dict()},
                                                "design_search": designs.to_dict(),
                                                "chain_against_continuous": continuous.to_dict()}
    return StudyOutcome(results, tables, figures, headline, _notes(study) + brushing.notes)


BALANCE, TIP_LOAD = "balance test (as performed)", "tip load (the model's own load)"


def _fit_cells(fit: CurveFit | None) -> tuple[float | str, float | str]:
    """A publication fit's moment (memu) and diameter (µm), or why it says nothing."""
    if fit is None:
        return "no fit", "no fit"
    if fit.at_bound:
        return "on a bound", "on a bound"
    return fit.moment / MEMU, fit.diameter / UM


def _headline_label(study: CiliaStudy) -> str:
    balance = study.balance.publication.fit
    said = ("its balance curve, as performed, cannot be fitted by that model" if balance is None or balance.at_bound
            else f"its balance curve gives {balance.moment / MEMU:.2f} memu")
    return f"moment per pillar the publication's fit finds in the twin's tip-load curve ({said})"


def _publication_fit_table(study: CiliaStudy) -> Table:
    cells = {}
    for column, found in ((BALANCE, study.balance.publication), (TIP_LOAD, study.publication_tip_load)):
        moment, diameter = _fit_cells(found.fit)
        cells.update({(MOMENT, column): moment, (PILLAR_DIAMETER, column): diameter})
    balance = study.balance
    fit = balance.publication.fit
    why = (balance.publication.refusal if fit is None else
           f"the fit ends on a bound ({fit.moment / MEMU:.3g} memu, {fit.diameter / UM:.0f} µm, residual rms "
           f"{fit.noise * 1e6:.0f} µV): a tip-loaded cylinder's curve rises from the first newton, the balance "
           f"test's hardly moves until the pillars buckle at {balance.buckling_force / MN:.1f} mN"
           if fit.at_bound else "")
    return paper_table(published_table("cilia-publication-fit"), cells,
                       caption="The publication's model (each pillar a uniform cylinder 1 mm tall, E = 1 MPa, "
                               "clamped, loaded at its tip perpendicular to its axis; moment and diameter free) "
                               "fitted to the twin's balance curve up to 26 mN as read through the meter and the "
                               "bench, and to its tip-load curve (the same readout). The twin's pillars are a "
                               "200 → 320 µm cone of 2.8 memu (the magnetometer's figure) on a film of their own "
                               "material. softtip's own model fitted to its own curve is the identifiability "
                               "check further down, not agreement.",
                       notes={MOMENT: f"Balance test: {why}" if why else ""} if why else None)


def _moment_gap_tables(study: CiliaStudy) -> list[Table]:
    tip = study.publication_tip_load.fit
    truth = study.recovery.truth_moment
    ratio = paper_table(published_table("cilia-moment-gap"),
                        {("magnetometer moment / fitted moment", "ratio"): truth / tip.moment} if tip else {},
                        caption="The twin's moment (the magnetometer's 2.8 memu) over what the publication's fit "
                                "finds in the twin's tip-load curve: a prediction of the fit, whose inputs do not "
                                "include the published 0.9 memu.")
    rows = [f"{cause.cause}: {cause.change}" for cause in study.moment_gap]
    columns = ["fitted moment (memu)", "fitted diameter (µm)", "magnetometer / fitted"]
    cells = {}
    for row, cause in zip(rows, study.moment_gap):
        moment, diameter = _fit_cells(cause.fit)
        cells.update({(row, columns[0]): moment, (row, columns[1]): diameter, (row, columns[2]): cause.ratio})
    causes = Table("The publication's three causes of the 3 × gap, tried on the twin", "cause tried", rows, columns,
                   cells, digits=3,
                   caption="Each row: the twin changed as it says, its noise-free tip-load curve fitted by the "
                           "publication's model. The publication's gap is about 3. The cone and non-uniform "
                           "material move the fitted moment by up to the factors shown; the spin valves' "
                           "self-heating, even a hundred times the computed, hardly at all (their resistance and "
                           "magnetoresistance change with temperature in opposite senses). The layout rows are "
                           "softtip's own cause, measured the same way: the publication shows its meanders only in "
                           "figures, so a fit whose meanders sit off the die's reads another moment.")
    return [ratio, causes] if rows else [ratio]


def _range(study: CiliaStudy) -> Table:
    balance = study.balance
    lying = balance.all_lying_force
    modulus = study.truth.shapes.rod.youngs_modulus
    return paper_table(published_table("cilia-range"),
                       {("X", "upper end"): lying / MN if lying is not None else "not reached"},
                       caption="softtip's figure is the publication's criterion on the twin's balance test: the "
                               "balance's reading when every pillar lies on its side "
                               f"(the first lies at {(balance.first_lying_force or math.nan) / MN:.1f} mN). "
                               "Past it the plate folds the lying pillars further and the balance reads on "
                               f"(to {balance.curve.force.max() / MN:.1f} mN in this plan).",
                       notes={"X": "What stops it: the lying load is set by the pillars' stiffness and the friction at "
                                   "the plate, and at a given shape every push scales with Young's modulus, so the "
                                   "pillars would lie at 26 mN with E = "
                                   f"{modulus * 26 * MN / lying / 1e6:.2f} MPa instead of {modulus / 1e6:g} MPa. "
                                   "Nothing here is fitted to 26 mN."} if lying is not None else None)


def _minimum_force_tables(study: CiliaStudy, depth: float) -> list[Table]:
    balance, settings = study.balance, study.settings
    budget = balance.budget
    best = budget.best
    uniform = settings.magnetisation == "uniform"
    other = balance.chain_budget if uniform else balance.cone_budget
    chain = balance.chain_budget
    step = float(np.diff(chain.force)[max(0, chain.best - 1)])
    read = (f"each pillar a uniformly magnetised cone (the composite; magnetisation = uniform), at the "
            f"{balance.cone_budget.force.size} steps around the equal dipoles' best" if uniform
            else "the equal dipoles of the published chain (a non-uniform material; magnetisation = equal)")
    shares = budget.shares(best)
    published = paper_table(published_table("cilia-minimum-force"),
                            {("X", "minimum force"): budget.minimum_force[best] / UN},
                            caption=f"Three standard deviations of the force the balance test reads, where along "
                                    f"its curve (0–{settings.force_max_mN:g} mN) it is smallest: at "
                                    f"{budget.force[best] / MN:.1f} mN, read with {read}. Causes switched on: "
                                    f"{', '.join(budget.parts)}.",
                            notes={"X": f"{'With equal dipoles' if uniform else 'As uniformly magnetised cones'}: "
                                        f"{other.minimum_force[other.best] / UN:.0f} µN at "
                                        f"{other.force[other.best] / MN:.1f} mN. Either way the test resolves its "
                                        "smallest force just before the pillars lie, where the force barely rises "
                                        f"({step / MN:.2f} mN a step) while they swing; along the rest of the curve "
                                        f"the equal dipoles resolve {np.median(chain.minimum_force) / MN:.1f} mN "
                                        "(median). The root's reading: the causes' notes."})
    rows = list(BUDGET_PARTS)
    columns = ["σ (µN)", "share of the variance (%)", "3σ alone (µN)"]
    cells = {}
    for row in rows:
        sigma = float(budget.part(row)[best])
        cells.update({(row, columns[0]): sigma / UN, (row, columns[1]): 100 * shares[row] if row in shares else "off",
                      (row, columns[2]): 3 * sigma / UN})
    per_mrad = float(budget.plate_per_radian[best]) * 1e-3
    figure = published_table("cilia-minimum-force").value("X", "minimum force").low * UN
    alone = figure / 3 / per_mrad if per_mrad > 0 else math.inf
    causes = Table("The minimum force from its causes", "cause", rows, columns, cells, digits=3,
                   caption=f"At {budget.force[best] / MN:.1f} mN on the balance curve, where the voltage changes by "
                           f"{budget.slope[best] * 1e3 * MN:.3g} mV per mN. balance: readability "
                           f"{settings.balance_readability_mg:g} mg (an analytical balance's; chosen). plate: its "
                           f"seating turn scattering by {settings.plate_seating_mrad:g} mrad rms between steps "
                           f"(chosen, no source): {per_mrad / UN:.0f} µN per mrad here, so {alone:.2f} mrad "
                           f"alone would give the published {figure / UN:.0f} µN. meter: the readout's noise budget "
                           "on the range holding the sensor's voltage (the HP 34401A counts 1 ppm of its 100 V range, "
                           "100 µV, at "
                           "10 power-line cycles). drift: the spin valves' self-heating "
                           f"({budget.warming:.2f} K) still settling, {settings.warm_up_s:g} s after the current was "
                           f"switched on, over one step; the die's time constant is {budget.time_constant:.1f} s "
                           "(its heat capacity alone: a lower bound), so the drift of a step falls under the "
                           f"meter's σ after {_settled(budget, study.resolution.noise.total):.0f} s of warm-up.",
                   notes={"plate": "The plate's share follows the chosen scatter; the other three are computed.",
                          "meter": _chain_note(study, depth)})
    return [published, causes]


def _slope_ratio(study: CiliaStudy, other: BalanceCurve) -> float:
    """The slope of ``other`` (the balance test read with another chain) over the equal dipoles' slope, where
    their budget is smallest."""
    budget, curve = study.balance.chain_budget, study.balance.curve
    rows = np.searchsorted(curve.force, budget.force)
    return float(np.gradient(other.change[rows], budget.force)[budget.best] / budget.slope[budget.best])


def _chain_note(study: CiliaStudy, depth: float) -> str:
    """How the slope the budget divides by moves with the pillars' magnet, and how far the root turns, in
    numbers: why the chains are not the composite's magnet there, and what the cones leave out."""
    balance = study.balance
    chain, cone, curve = balance.chain_budget, balance.cone_budget, balance.curve
    count = study.settings.balance_chain_count
    rod = curve.shapes.rod
    row = int(np.searchsorted(curve.force, chain.force[chain.best]))
    turn = abs(float(curve.shapes.angles[row, 0]))  # the root's first section
    dip = rod.base_diameter / 2 * math.sin(turn)
    at = int(np.argmin(np.abs(cone.force - chain.force[chain.best])))
    return (f"The slope at {chain.force[chain.best] / MN:.1f} mN: with {CHAIN_CHECK * count} equal dipoles a pillar "
            f"{_slope_ratio(study, balance.finer_chain):.3f} times the {count}-dipole one (a line magnet, converged); "
            f"the same {count} dipoles carrying their slices' volume {_slope_ratio(study, balance.volume_chain):.3g} "
            f"times; the pillars as uniformly magnetised cones, their volume integrated in cells "
            f"{cone.slope[at] / chain.slope[chain.best]:.3g} times (cells of twice their height over the sensing "
            f"plane: a line of dipoles stands for a root {rod.base_diameter / UM:.0f} µm wide {depth / UM:g} µm over "
            f"the sensors only where the sensors are far). The root's base has turned {math.degrees(turn):.0f}° on "
            f"the half-space film the die declares, which would carry its rim {dip / UM:.0f} µm under the base; the "
            "cones' cells below the die's surface are left out (the magnet cannot go below its base).")


def _settled(budget: ForceBudget, sigma: float) -> float:
    """The warm-up (s) after which one step's self-heating drift falls under ``sigma`` (V)."""
    tau = budget.time_constant
    start = budget.drift_per_kelvin * budget.warming * -math.expm1(-budget.dwell / tau) if tau > 0 else 0.0
    return tau * math.log(start / sigma) if start > sigma else 0.0


def _rig_table(study: CiliaStudy) -> Table:
    """The balance test under other values of its unknowns (the die's tilt, the plate's turn)."""
    settings = study.settings
    balance = study.balance
    declared = RigCase(math.radians(settings.die_tilt_deg),
                       None if settings.plate_stiffness_uNm is None else settings.plate_stiffness_uNm * 1e-6,
                       balance.all_lying_force,
                       float(np.interp(5 * MN, balance.curve.force, balance.curve.change)),
                       float(np.abs(balance.curve.rotation).max()))
    columns = ["every pillar lies (mN)", "voltage change at 5 mN (µV)", "largest plate turn (mrad)"]
    rows, cells = [], {}
    for index, case in enumerate((declared, *study.rig)):
        plate = "fixed" if case.stiffness is None else f"{case.stiffness * 1e6:g} µN·m/rad"
        row = f"die {math.degrees(case.tilt):g}°, plate {plate}" + (" (declared)" if index == 0 else "")
        rows.append(row)
        cells.update({(row, columns[0]): case.all_lying_force / MN if case.all_lying_force else "not reached",
                      (row, columns[1]): case.change_at_5mN * 1e6 if case.change_at_5mN is not None else "not reached",
                      (row, columns[2]): case.largest_turn * 1e3})
    return Table("The balance test's unknowns: the die's tilt and the plate's turn", "rig", rows, columns, cells,
                 digits=3, caption="The twin's balance test with the die tilted and the plate turning (about the "
                 "axis across the bend under the die's centre, against the stated stiffness). A tilt makes the "
                 "pillars bend from the first newton; a plate that turns gives way under the pillars that touch "
                 "first and takes much of a tilt back. The plate's turn moves the pillars' gaps but is left out of "
                 "their own inclination, which is rough where the turn is as large as the tilt.")


def _sampling(rough: RoughnessStudy) -> Table:
    finest = rough.surfaces.index("P1000")
    row = rough.rms_by_rate[finest]
    order = np.argsort(rough.rates)
    rates, kept = rough.rates[order], row[order] / row[order][-1]
    above = np.flatnonzero(kept >= 0.5)
    if above.size == 0 or above[0] == 0:
        value: float | str = "not crossed"
    else:
        i = above[0]  # half its fastest-rate value is crossed between rates i − 1 and i, read in log rate
        t = (0.5 - kept[i - 1]) / (kept[i] - kept[i - 1])
        value = float(np.exp(np.log(rates[i - 1]) + t * (np.log(rates[i]) - np.log(rates[i - 1]))))
    return paper_table(published_table("cilia-sampling"), {("P1000", "rate below which it is missed"): value},
                       caption="The rate at which the finest paper's AC rms has fallen to half of its value at the "
                               f"fastest rate tried ({rates[-1]:g}/s), between the rates tried "
                               f"({', '.join(f'{r:g}' for r in rates)}/s).")


def _readout(model, rest: dict[str, float]) -> Table:
    current = model.die.meanders[0].readout.current
    cells = {(sensor, "resistance at rest (kΩ)"): rest[sensor] / current / 1e3 for sensor in rest}
    return Table("The readout at rest", "sensor", list(rest), ["resistance at rest (kΩ)"], cells, digits=1,
                 caption=f"At {current * 1e6:.0f} µA, self-heating included: "
                         + ", ".join(f"{sensor} at {volts:.2f} V" for sensor, volts in rest.items()) + ". The spin valves are built from the published magnetoresistance, "
                         "sensitivity and linear range (about 183 and 169 kΩ by the spec's arithmetic), so this "
                         "is a check of the readout, not of the publication.")


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
    return Table("Identifiability check: softtip's own model fitted to its own tip-load curve", "parameter", rows,
                 columns, cells, digits=3,
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


def _sensors(study: CiliaStudy) -> tuple[Resolution, ...]:
    """The study sensor's resolution, then the other sensor's if the die has it."""
    return (study.resolution,) + ((study.other_sensor,) if study.other_sensor is not None else ())


def _resolution_table(study: CiliaStudy) -> Table:
    rows = [resolved.sensor for resolved in _sensors(study)]
    columns = ["sensitivity at rest (mV/mN)", "noise σ (µV)", "meter count (µV)", "minimum force, 3σ (µN)",
               "smallest step (µN)", "range upper end (mN)"]
    cells = {}
    for resolved in _sensors(study):
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
                 notes={} if study.other_sensor is None else {
                     study.other_sensor.sensor: "Its strips sense across the bend: the pillars bent along x "
                                                "barely change the field it sees."})


def _balance_table(study: CiliaStudy) -> Table:
    balance, settings = study.balance, study.settings
    curve = balance.curve
    five = float(np.interp(5 * MN, curve.force, curve.change)) if curve.force.max() >= 5 * MN else None
    finer = balance.finer_chain
    buckled = int(np.searchsorted(curve.force, balance.buckling_force))
    count = study.settings.balance_chain_count
    rows = ["buckling (mN)", "first pillar lies (mN)", "every pillar lies (mN)", "largest reading (mN)",
            "voltage change at 5 mN (µV)", "meter noise σ (µV)", "largest plate turn (mrad)",
            f"voltage change at buckling, {count} dipoles a pillar (µV)",
            f"the same, {CHAIN_CHECK * count} dipoles a pillar (µV)",
            f"largest change, {count} dipoles (µV)", f"largest change, {CHAIN_CHECK * count} dipoles (µV)"]
    noise = study.resolution.noise.total
    values = [balance.buckling_force / MN,
              balance.first_lying_force / MN if balance.first_lying_force is not None else "not reached",
              balance.all_lying_force / MN if balance.all_lying_force is not None else "not reached",
              float(curve.force.max()) / MN, five * 1e6 if five is not None else "not reached", noise * 1e6,
              float(np.abs(curve.rotation).max()) * 1e3, curve.change[buckled] * 1e6, finer.change[buckled] * 1e6,
              float(np.abs(curve.change).max()) * 1e6, float(np.abs(finer.change).max()) * 1e6]
    stiffness = settings.plate_stiffness_uNm
    return Table("The balance test as performed", "figure", rows, ["twin"],
                 {(row, "twin"): value for row, value in zip(rows, values)}, digits=3,
                 caption=f"The die lowered onto the balance's plate in {settings.points} steps to 70 % of the "
                         f"pillars' height past first contact: friction {settings.friction:g} at the tips, a "
                         f"{settings.imperfection_deg:g}° bow, the die tilted {settings.die_tilt_deg:g}°, the plate "
                         + ("fixed" if stiffness is None else f"turning at {stiffness:g} µN·m/rad")
                         + ". The pillars compress, buckle, bend, lie on their side, and the plate folds them "
                           "further: the balance reads past the range, while the voltage hardly moves before the "
                           f"buckling. The balance test is read with {count} equal dipoles a pillar, not the "
                           f"published {settings.chain_count}: its voltage comes from the area elements under the "
                           "buckled and lying roots, where the published chain's points sit too far apart (10 "
                           "dipoles are 120 % of the largest change off 160, 40 within 4.3 %: "
                           "tests/test_cilia_model.py); the last rows read it again with four times as many. A "
                           "chain converges to a line magnet, not to the pillars' 320 µm roots: see the notes.")


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
            "minimum_force_3sigma_uN": {r.sensor: r.minimum_force_at_rest / UN for r in _sensors(study)},
            "smallest_step_uN": {r.sensor: r.smallest_step_at_rest / UN for r in _sensors(study)},
            "sensitivity_mV_per_mN": {r.sensor: r.sensitivity for r in _sensors(study)},
            "range_mN": [v / MN for v in study.resolution.range],
            "rest_V": rest,
            "balance": {"buckling_mN": study.balance.buckling_force / MN,
                        "first_lying_mN": _in(study.balance.first_lying_force, MN),
                        "all_lying_mN": _in(study.balance.all_lying_force, MN),
                        "largest_reading_mN": float(study.balance.curve.force.max()) / MN,
                        "largest_plate_turn_mrad": float(np.abs(study.balance.curve.rotation).max()) * 1e3},
            "publication_fit": {"balance": fit_of(study.balance.publication.fit),
                                "balance_refusal": study.balance.publication.refusal,
                                "tip_load": fit_of(study.publication_tip_load.fit),
                                "tip_load_refusal": study.publication_tip_load.refusal},
            "moment_gap": [{"cause": c.cause, "change": c.change, "fit": fit_of(c.fit), "ratio": c.ratio,
                            "refusal": c.refusal} for c in study.moment_gap],
            "minimum_force": _budget_of(study),
            "rig": [{"tilt_deg": math.degrees(c.tilt), "plate_uNm": None if c.stiffness is None else c.stiffness * 1e6,
                     "all_lying_mN": _in(c.all_lying_force, MN), "change_at_5mN_uV": _in(c.change_at_5mN, 1e-6),
                     "largest_turn_mrad": c.largest_turn * 1e3} for c in study.rig],
            "layout": {"depths_um": list(study.layout.depths / UM),
                       "moments_by_depth_memu": list(study.layout.moments_by_depth / MEMU),
                       "scales": list(study.layout.scales),
                       "moments_by_scale_memu": list(study.layout.moments_by_scale / MEMU)},
            "timings_s": timings}


def _in(value: float | None, unit: float) -> float | None:
    return None if value is None else value / unit


def _budget_of(study: CiliaStudy) -> dict:
    def summary(budget: ForceBudget) -> dict:
        best = budget.best
        return {"at_mN": budget.force[best] / MN, "minimum_force_uN": budget.minimum_force[best] / UN,
                "sigma_uN": {name: float(budget.part(name)[best]) / UN for name in BUDGET_PARTS},
                "shares": budget.shares(best), "parts": list(budget.parts),
                "plate_uN_per_mrad": float(budget.plate_per_radian[best]) * 1e-3 / UN,
                "slope_mV_per_mN": float(budget.slope[best]) * 1e3 * MN}

    balance = study.balance
    return {**summary(balance.budget), "magnetisation": study.settings.magnetisation,
            "uniform_cones": summary(balance.cone_budget), "equal_dipoles": summary(balance.chain_budget)}


def _notes(study: CiliaStudy) -> list[str]:
    notes = [
        "The twin's pillars are set from the published magnetometer moment (2.8 memu per pillar) and the nominal "
        "cone (200 µm at the tip, 320 µm at the base); every published figure is then a prediction. softtip's "
        "own model fitted to its own curve only checks that the fit recovers its inputs (identifiability).",
        "The publication fitted a tip-loaded cylinder to its balance test. On the twin, that model fits the "
        "tip-load curve (a cone read as a cylinder of about the published diameter) but not the balance curve "
        "as performed, whose pillars compress and buckle before they bend.",
        "The die layout is declared (die.toml): the publication shows it only in figures. The layout table shows "
        "how much the fitted moment depends on it.",
        f"The balance test's chain ({study.settings.balance_chain_count} equal dipoles a pillar) converges in its "
        "dipoles, but to a line magnet along the centre line, where the pillars' roots are 320 µm wide and 10 µm "
        "over the sensors. The minimum force reads the pillars as what the composite is "
        f"(magnetisation = {study.settings.magnetisation}; uniform: each a uniformly magnetised cone integrated over "
        "its volume in cells, the part of a turned root below the die's surface left out) at the steps around the "
        "chain's best; the balance curve, its range and the figures are read with the chain.",
    ]
    if study.fit.at_bound:
        notes.append("softtip's own fit ended on a bound: the curve does not hold that parameter.")
    return notes


