"""How the methods' errors depend on what makes real fingers differ, and on the renderer's choices.

The publication casts every test fingertip in one rubber, mounted like the FS. Real fingers differ
in stiffness, shape and how the device sits on them; each :class:`FingerVariation` changes one of
those on the three human fingertips (the casts stay as published) and :func:`sensitivity_study`
reruns the study under each, reporting every method's pooled median error and their order.

:func:`error_curves` reruns the study over the number of neighbours n, the weighting's power and
the FS and user tables' sizes (the effects the authors named as future work), one at a time from
the published settings, and :func:`curves_figure` draws them.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from matplotlib.figure import Figure

from softtip._core.config import PositiveNumber, Text, choice, schema
from softtip._core.progress import SILENT, Progress
from softtip.mechanics.plate_contact import PlateContactLaw
from softtip.systems.haptics.fingertips import CASTS, HUMAN_FINGERTIPS, SHAPE_AXES, Fingertip
from softtip.systems.haptics.statistics import WilcoxonResult
from softtip.systems.haptics.study import METHODS, StudySettings, run_study


@schema(section="variation")
class FingerVariation:
    """A change to the human fingertips: their rubber's modulus scaled, another shape, another mounting
    (None keeps the published setting)."""

    name: Text
    stiffness_scale: PositiveNumber = 1.0
    shape: choice(*SHAPE_AXES) | None = None
    mounting: choice("centre", "nail") | None = None

    def apply(self, fingertip: Fingertip) -> Fingertip:
        law: PlateContactLaw = fingertip.contact
        changes = {"contact": replace(law, youngs_modulus=law.youngs_modulus * self.stiffness_scale)}
        if self.shape is not None:
            changes["shape"] = self.shape
        if self.mounting is not None:
            changes["mounting"] = self.mounting
        return replace(fingertip, **changes)


# stiffness: in-vivo finger pads span about a factor of two either way of a soft cast at these loads
DEFAULT_VARIATIONS = (
    FingerVariation(name="as published"),
    FingerVariation(name="human pads half as stiff", stiffness_scale=0.5),
    FingerVariation(name="human pads twice as stiff", stiffness_scale=2.0),
    FingerVariation(name="human pads ellipsoidal", shape="ellipsoid"),
    FingerVariation(name="human pads flattened", shape="pad"),
    FingerVariation(name="device resting on the nail", mounting="nail"),
)


@dataclass(frozen=True)
class VariationOutcome:
    """One variation: each method's median error (N) over the human fingertips' targets, the
    methods from best to worst, and the pooled A-vs-B test over every fingertip; or, when the study
    cannot run under it (a fingertip out of the device's reach), why (and no figures)."""

    variation: FingerVariation
    median_error: np.ndarray | None
    ranking: tuple[str, ...]
    pooled: WilcoxonResult | None
    refused: str | None = None


def sensitivity_study(settings: StudySettings = StudySettings(), seed: int = 0, progress: Progress = SILENT,
                      variations: tuple[FingerVariation, ...] = DEFAULT_VARIATIONS) -> tuple[VariationOutcome, ...]:
    """The study rerun under each variation of the human fingertips (same seed: same tables' noise draws)."""
    if not variations:
        raise ValueError("variations: expected at least one")
    outcomes = []
    with progress.task("finger variations", total=len(variations)) as task:
        for variation in variations:
            fingertips = CASTS + tuple(variation.apply(finger) for finger in HUMAN_FINGERTIPS)
            try:
                study = run_study(settings, seed, device=None, fingertips=fingertips)
            except ValueError as problem:
                outcomes.append(VariationOutcome(variation, None, (), None, str(problem)))
                task.advance(note=f"{variation.name}: refused")
                continue
            human = np.hstack([outcome.errors for outcome in study.fingertips[len(CASTS):]])
            median = np.median(human, axis=1)
            outcomes.append(VariationOutcome(variation, median, tuple(METHODS[i] for i in np.argsort(median)),
                                             study.pooled))
            task.advance(note=variation.name)
    return tuple(outcomes)


@dataclass(frozen=True)
class CurvePoint:
    """The study at one value of one setting: each method's median error (N) over every fingertip and target."""

    setting: str  # a field of StudySettings
    value: float
    median_error: np.ndarray


CURVES = (("n_neighbours", (1, 2, 4, 8, 16)), ("weighting_power", (0.0, 1.0, 2.0)),
          ("fs_levels", (7, 9, 11, 13)), ("user_levels", (4, 5, 7)))


def error_curves(settings: StudySettings = StudySettings(), seed: int = 0, progress: Progress = SILENT,
                 curves: tuple[tuple[str, tuple], ...] = CURVES) -> tuple[CurvePoint, ...]:
    """The study rerun with each setting of ``curves`` varied alone (the others as ``settings``)."""
    runs = [(name, value) for name, values in curves for value in values]
    if not runs:
        raise ValueError("curves: expected at least one setting with values")
    points = []
    with progress.task("error curves", total=len(runs)) as task:
        for name, value in runs:
            if name not in StudySettings.__dataclass_fields__:
                raise ValueError(f"curves: {name!r} is not a study setting")
            study = run_study(replace(settings, **{name: value}), seed)
            errors = np.hstack([outcome.errors for outcome in study.fingertips])
            points.append(CurvePoint(name, float(value), np.median(errors, axis=1)))
            task.advance(note=f"{name} = {value}")
    return tuple(points)


def curves_figure(points: tuple[CurvePoint, ...]) -> Figure:
    """Median error (N) against each varied setting, one line per method."""
    settings = list(dict.fromkeys(point.setting for point in points))
    figure = Figure(figsize=(4 * len(settings), 3.6), layout="constrained")
    axes = np.atleast_1d(figure.subplots(1, len(settings), sharey=True))
    for axis, setting in zip(axes, settings, strict=True):
        mine = [point for point in points if point.setting == setting]
        values = [point.value for point in mine]
        for m, method in enumerate(METHODS):
            axis.plot(values, [point.median_error[m] for point in mine], marker="o", label=method)
        axis.set_xlabel(setting)
        axis.grid(alpha=0.3)
    axes[0].set_ylabel("median rendering error (N)")
    axes[0].legend(fontsize="small")
    return figure
