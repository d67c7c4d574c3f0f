"""The whisker's study: the tip's force from the chip's field, and the chip's output as the data show it.

A linear map from the field's change (three axes) to the tip's force (two axes) is fitted by least squares
on the calibration pushes and judged on the validation pushes (their directions drawn at random). The
TLV493D's output step and rms noise are measured back from the readings: the step as the smallest gap
between distinct values of a channel, the noise from the readings at rest with the quantisation's share
(step² / 12, Sheppard) taken out.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure as PlotFigure

from softtip.plugin import MAGNETIC, Figure, Headline, StudyOutcome, Table, published_table, run_protocol
from softtip_whisker.bench import LABELS, deflection_profile


def fit_force_map(change_uT: np.ndarray, force_N: np.ndarray) -> np.ndarray:
    """The least-squares map (4, 2): [ΔB, 1] @ map = force."""
    design = np.column_stack([change_uT, np.ones(len(change_uT))])
    solution, *_ = np.linalg.lstsq(design, force_N, rcond=None)
    return solution


def apply_force_map(force_map: np.ndarray, change_uT: np.ndarray) -> np.ndarray:
    return np.column_stack([change_uT, np.ones(len(change_uT))]) @ force_map


def output_step(values: np.ndarray) -> float:
    """The smallest gap between distinct values: the output step of a quantised channel."""
    distinct = np.unique(values)
    return float(np.diff(distinct).min())


def rest_noise(rest_values: np.ndarray, step: float) -> float:
    """The rms noise of readings at rest (one column per channel and trial), the quantisation's share out."""
    variance = rest_values.var(axis=0, ddof=1).mean() - step ** 2 / 12.0
    return float(np.sqrt(max(variance, 0.0)))


def whisker(protocol, seed, progress) -> StudyOutcome:
    dataset, _ = run_protocol(protocol, progress)
    channels = MAGNETIC.channel_names(1)
    change = np.column_stack([dataset.column(name) for name in channels])
    force = np.column_stack([dataset.column(name) for name in LABELS])
    roles = np.asarray(dataset.column("role")).astype(str)
    calibration, validation = roles == "calibration", roles == "validation"
    force_map = fit_force_map(change[calibration], force[calibration])
    estimate = apply_force_map(force_map, change[validation])
    rmse_mN = 1e3 * np.sqrt(((estimate - force[validation]) ** 2).mean(axis=0))
    span_mN = 1e3 * np.abs(force[validation]).max(axis=0)

    step = min(output_step(change[:, axis]) for axis in range(3))
    rest = _rest_readings(dataset, protocol, change)
    noise = rest_noise(rest, step)
    chip = Table("TLV493D output step and noise, from the readings at rest", "figure", ["output step", "rms noise"],
                 ["at rest"], {("output step", "at rest"): step, ("rms noise", "at rest"): noise}, unit="µT", digits=0,
                 caption="The twin's chip is set from these data-sheet figures: measuring them back checks the "
                         "path from the chip through the protocol and the dataset.",
                 published=published_table("tlv493d-output"))
    board = Table("TLV493D rms noise at rest, beside a characterised board", "figure", ["rms noise"], ["at rest"],
                  {("rms noise", "at rest"): noise}, unit="µT", digits=0,
                  caption="The twin's chip has the data sheet's typical noise; one board measured on its own was "
                          "noisier.",
                  published=published_table("tlv493d-measured-noise"))
    forces = Table("The tip's force from the field, validation pushes", "axis", ["fx", "fy"],
                   ["RMSE", "largest"],
                   {(axis, column): float(value) for axis, k in (("fx", 0), ("fy", 1))
                    for column, value in (("RMSE", rmse_mN[k]), ("largest", span_mN[k]))},
                   unit="mN", digits=2,
                   caption="A linear map of the field's change fitted on the calibration pushes; the validation "
                           "pushes come from directions the calibration never saw.")
    figure = _force_figure(force[validation], estimate)
    results = {"force_rmse_mN": rmse_mN.tolist(), "largest_force_mN": span_mN.tolist(), "output_step_uT": step,
               "rms_noise_uT": noise, "tip_compliance_mm_per_N": protocol.design.whisker.tip_compliance * 1e3}
    return StudyOutcome(results, [forces, chip, board], [figure],
                        Headline.of(forces, "fx", "RMSE", "the tip's force fx from the field: RMSE"))


def _rest_readings(dataset, protocol, change: np.ndarray) -> np.ndarray:
    """Each trial's readings before its push, a column per channel and trial."""
    rest_samples = int((deflection_profile(protocol.parameters, protocol.design.sensor.rate_hz) == 0).argmin())
    trial = np.asarray(dataset.column("trial"))
    starts = np.flatnonzero(np.r_[True, trial[1:] != trial[:-1]])
    return np.column_stack([change[start:start + rest_samples, axis] for start in starts for axis in range(3)])


def _force_figure(measured: np.ndarray, estimated: np.ndarray) -> Figure:
    figure = PlotFigure(figsize=(8, 4))
    for k, (ax, axis) in enumerate(zip(figure.subplots(1, 2), ("x", "y"))):
        ax.plot(1e3 * measured[:, k], 1e3 * estimated[:, k], ".", ms=3, color="tab:blue")
        low, high = 1e3 * measured[:, k].min(), 1e3 * measured[:, k].max()
        ax.plot([low, high], [low, high], "k--", lw=0.8, label="equal")
        ax.set_xlabel(f"probe's force f{axis} (mN)")
        ax.set_ylabel(f"estimated f{axis} (mN)")
        ax.legend(fontsize=8)
    figure.tight_layout()
    return Figure.of("The tip's force estimated from the field against the probe's, validation pushes",
                     "Points on the dashed line are exact; their spread is the chip's noise and step.", figure)
