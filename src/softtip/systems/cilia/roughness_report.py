"""The roughness study's part of ``softtip reproduce cilia``: its tables, its figure and its notes.

:func:`roughness_report` takes the study of the dataset's brushings (read with the protocol's readout) and
the same surfaces read the other way (:func:`softtip.systems.cilia.roughness.readout_levels`: with a bridge
when the protocol reads as published, as published when it reads through one), and sets the published slope
beside both of softtip's fits and both readouts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure

from softtip._core.units import MM, UM
from softtip.published import published_table
from softtip.report.tables import Table, paper_table
from softtip.systems.cilia.roughness import RoughnessStudy

SLOPE = "slope (µV/µm)"
READOUTS = {False: "the meter across the sensor (as published)", True: "through a bridge (softtip's addition)"}

NOTES = [
    "Roughness: the published 18.3, 46.2 and 162 µm equal the grits' (P1000, P320, P100) average grain sizes; "
    "softtip makes each sandpaper a Gaussian random profile with that rms and that correlation length (a grain "
    "wide). The brushings are the lab's dataset (mode brushing: a trial per recording, its surface, strip, speed "
    "and rate as conditions), read back from its file: the same analysis reads a measured dataset or a CSV "
    "(softtip cilia roughness).",
    "Roughness: the readout is the publication's, 100 µA and the HP 34401A across the ~18.7 V sensor, on its "
    "100 V range at the integration the sampling rate allows (1 power-line cycle at 50 readings/s: 300 µV "
    "steps, and the datasheet's additional noise error of 0.001 % of range plus 20 µV, read as one standard "
    "deviation). A bridge that takes the rest voltage off before the meter, so it reads on its 0.1 V range, is "
    "softtip's addition, shown beside it.",
    "Roughness: the published work trains no classifier: softtip adds one, validated only where the recordings "
    "allow it (two strips of each surface; two speeds for the held-out speed).",
]


@dataclass(frozen=True)
class RoughnessReport:
    """The tables, the figure and the notes :func:`roughness_report` gives the study's report."""

    tables: list[Table]
    figure: Figure
    notes: list[str]


def _slope_cells(study: RoughnessStudy, label: str) -> tuple[dict, dict]:
    rows, notes = {}, {}
    for name, fit, how in (("line with intercept, as published", study.published_fit,
                            "least squares through the four surfaces' AC rms"),
                           ("through the origin, above the floor", study.origin_fit,
                            "the rough surfaces' rms above silicon's, in quadrature")):
        if fit is None:
            continue
        row = f"{label}: {name}"
        low, high = (v * UM / 1e-6 for v in fit.slope_interval)
        rows[row] = fit.slope * UM / 1e-6
        notes[row] = (f"{how}; 95 % interval {low:.3g} to {high:.3g} µV/µm (Student's t, {fit.dof} degrees of "
                      f"freedom); this readout's floor (silicon): {study.floor * 1e6:.3g} µV")
    return rows, notes


def roughness_report(study: RoughnessStudy, other: RoughnessStudy, bridge: bool, speed_mm_s: float,
                     rate_hz: float, engagement_um: float, strips: int, length_mm: float) -> RoughnessReport:
    """The report's roughness part: ``study`` read as the protocol reads (``bridge``), ``other`` the same
    surfaces read the other way; the brushing's settings for the captions."""
    readouts = {bridge: study, not bridge: other}
    slopes, notes = {}, {}
    for with_bridge, levels in readouts.items():
        cells, why = _slope_cells(levels, READOUTS[with_bridge])
        slopes.update(cells)
        notes.update(why)
    slope = paper_table(published_table("cilia-roughness"), {(row, "value"): value for row, value in slopes.items()},
                        rows=dict.fromkeys(slopes, SLOPE), notes=notes,
                        caption=f"The rms of the AC voltage of sensor X against the surfaces' rms roughness, brushed "
                                f"at {speed_mm_s:g} mm/s, {rate_hz:g} readings/s, {engagement_um:g} µm past first "
                                f"contact, mean over {strips} strips of {length_mm:g} mm. The publication fits a "
                                "straight line with intercept through its four surfaces; softtip's own fit goes "
                                "through the origin once the flat surface's floor is removed.")
    rows = list(study.surfaces)
    columns = [f"AC rms, {READOUTS[False]} (µV)", f"AC rms, {READOUTS[True]} (µV)"]
    cells = {(row, "rms roughness (µm)"): roughness / UM for row, roughness in zip(rows, study.roughness)}
    for column, with_bridge in zip(columns, (False, True)):
        cells.update({(row, column): value * 1e6 for row, value in zip(rows, readouts[with_bridge].total_rms)})
    level = Table("Roughness: the AC voltage's rms against the surface's, by readout", "surface", rows,
                  ["rms roughness (µm)", *columns], cells, digits=2,
                  caption=f"The flat silicon gives each readout's floor: {study.floor * 1e6:.3g} µV "
                          f"({READOUTS[bridge]}), {other.floor * 1e6:.3g} µV the other way. The same profiles both "
                          "ways (one seed).")

    def missed(against: str, columns: list[str], rms: np.ndarray, caption: str) -> Table:
        return Table(f"Roughness missed: the AC rms (µV) against the {against}", "surface", rows, columns,
                     {(row, column): rms[i, j] * 1e6 for i, row in enumerate(rows) for j, column in enumerate(columns)},
                     digits=2, caption=caption)

    tables = [slope, level,
              missed("sampling rate", [f"{r:g}/s" for r in study.rates], study.rms_by_rate,
                     f"At {speed_mm_s:g} mm/s, one strip each ({READOUTS[bridge]}); the meter integrates each reading "
                     "over the longest integration time the rate allows, averaging the grains it crosses meanwhile."),
              missed("stage speed", [f"{v / MM:g} mm/s" for v in study.speeds], study.rms_by_speed,
                     f"At {rate_hz:g} readings/s, mean over the strips; the faster the stage, the more grains one "
                     "reading crosses and averages.")]
    tables += _classifier_tables(study)
    return RoughnessReport(tables, roughness_figure(study, other, bridge), list(NOTES))


def _classifier_tables(study: RoughnessStudy) -> list[Table]:
    c = study.classification
    if c is None:
        return [Table("A classifier of the surfaces (softtip's addition)", "validation", ["not trained"], ["why"],
                      {("not trained", "why"): study.unclassified})]
    rows, cells = [], {}
    for row, accuracy, matrix in (("by strip (grouped folds)", c.by_strip, c.confusion_by_strip),
                                  (f"trained without {(c.held_speed or 0) / MM:g} mm/s, tested on it", c.at_held_speed,
                                   c.confusion_at_held_speed)):
        if accuracy is not None:
            rows.append(row)
            cells.update({(row, "accuracy"): accuracy, (row, "windows"): int(matrix.sum())})
    accuracy = Table("A classifier of the surfaces (softtip's addition)", "validation", rows, ["accuracy", "windows"],
                     cells, digits=3,
                     caption="A random forest (scikit-learn) on one-second windows: log AC rms, log rms of the "
                             "reading-to-reading step, and three spectral band shares. No strip gives windows to "
                             f"both training and validation. Chance: {1 / len(c.surfaces):.2f}."
                             + (" Not validated: " + "; ".join(c.missing) if c.missing else ""))
    confusions = [Table(title, "true", list(c.surfaces), list(c.surfaces),
                        {(t, p): int(matrix[i, j]) for i, t in enumerate(c.surfaces) for j, p in enumerate(c.surfaces)},
                        digits=0)
                  for title, matrix in (("Confusion by strip (rows: true surface, columns: predicted)",
                                         c.confusion_by_strip),
                                        (f"Confusion at the held-out {(c.held_speed or 0) / MM:g} mm/s (rows: true "
                                         "surface, columns: predicted)", c.confusion_at_held_speed))
                  if matrix is not None]
    return [accuracy, *confusions]


def _lines(axes, levels: RoughnessStudy, x: np.ndarray, name: str, color: str) -> None:
    """Both fits over ``x`` (m) in the plot's AC-rms space: the line with intercept as it is, the fit through
    the origin above the floor added back to the floor in quadrature."""
    for fit, style, label in ((levels.published_fit, "-", "line"), (levels.origin_fit, ":", "origin")):
        if fit is None:
            continue
        values = fit.slope * x + fit.intercept if label == "line" else np.hypot(levels.floor, fit.slope * x)
        axes.plot(x / UM, values * 1e6, style, color=color, lw=1,
                  label=f"{name}, {label}: {fit.slope * UM / 1e-6:.3g} µV/µm")


def roughness_figure(study: RoughnessStudy, other: RoughnessStudy, bridge: bool) -> Figure:
    """The AC rms against the roughness (both readouts, both fits, the published slope), against the
    sampling rate and against the stage speed."""
    figure = Figure(figsize=(12.0, 3.8), layout="constrained")
    left, right, fast = (figure.add_subplot(1, 3, k) for k in (1, 2, 3))
    x = np.linspace(0.0, study.roughness.max(), 50)
    for index, (with_bridge, levels) in enumerate(((bridge, study), (not bridge, other))):
        color = f"C{index}"
        name = "bridge" if with_bridge else "as published"
        left.plot(levels.roughness / UM, levels.total_rms * 1e6, "o", color=color, label=f"AC rms, {name}")
        _lines(left, levels, x, name, color)
    published = published_table("cilia-roughness").value(SLOPE, "value").centre
    left.plot(x / UM, study.floor * 1e6 + published * x / UM, "k--", lw=1,
              label=f"published slope {published:g} µV/µm, from the floor")
    left.set_xlabel("rms roughness (µm)")
    left.set_ylabel("AC rms of sensor X (µV)")
    left.legend(fontsize=6)
    # linear in the AC rms: a quantised reading that never changes has an AC rms of 0
    for axes, values, rows, label in ((right, study.rates, study.rms_by_rate, "readings per second"),
                                      (fast, study.speeds / MM, study.rms_by_speed, "stage speed (mm/s)")):
        for name, row in zip(study.surfaces, rows):
            axes.semilogx(values, row * 1e6, "o-", label=name)
        axes.set_xticks(values, [f"{v:g}" for v in values], minor=False)
        axes.minorticks_off()
        axes.set_xlabel(label)
        axes.set_ylabel(f"AC rms (µV), {READOUTS[bridge].split(' (')[0]}")
    right.axvline(20, color="k", ls=":", lw=0.8, label="20 readings/s")
    right.legend(fontsize=7)
    fast.legend(fontsize=7)
    return figure
