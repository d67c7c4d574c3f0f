"""How the methods' errors depend on what makes real fingers differ, and on the renderer's choices.

The publication casts every test fingertip in one rubber, mounted like the FS. Real fingers differ
in stiffness, shape and how the device sits on them; each :class:`FingerVariation` changes one of
those on the human fingertips (the casts stay as published) and :func:`sensitivity_study` reruns
their part of the study under each, reporting every method's median error over the human
fingertips' targets, the methods' order and the pooled A-vs-B test.

:func:`error_curves` reruns the study over the number of neighbours n, the weighting's power and
the FS and user tables' sizes (the effects the authors named as future work), one at a time from
the study's settings, and :func:`curves_figure` draws them.

:func:`robustness_study` reruns the whole study on the devices the fit of the device's unknowns
cannot tell apart (:mod:`.fit`) and over seeds: whether a conclusion is the method's or one device's.

All start from one :class:`Baseline`: the study at its own settings, with its FS table and targets.
A rerun collects again only what its change touches (a new FS table for another FS size, the
fingertips' user data and renderings otherwise), and every collection draws the noise stream it
draws in the study (each stage of each fingertip its own stream of the seed), so the differences
between points are the change's, not the noise's; the baseline's errors are the study's own. A
fingertip's fixed user table and presses are collected once and reused by every rerun that keeps
the finger and the user table's size.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from matplotlib.figure import Figure

from softtip._core.config import PositiveNumber, Text, checked, choice, integer, schema
from softtip._core.progress import SILENT, Progress
from softtip.mechanics.plate_contact import PlateContactLaw
from softtip.systems.haptics.collection import CollectionSettings
from softtip.systems.haptics.device import DeviceSpec, load_device
from softtip.systems.haptics.fingertips import HUMAN_FINGERTIPS, SHAPE_AXES, TEST_FINGERTIPS, Fingertip, Offset3
from softtip.systems.haptics.fit import principal_moves
from softtip.systems.haptics.statistics import WilcoxonResult
from softtip.systems.haptics.study import (
    METHODS,
    FingertipOutcome,
    SharedTables,
    StudySettings,
    UserData,
    collect_study,
    fs_table,
    pooled_test,
    study_fingertip,
    study_fingertips,
    wilcoxon_tests,
)


@schema(section="variation")
class FingerVariation:
    """A change to the human fingertips: their rubber's modulus scaled, another shape, the core's
    sensor origin moved (m, from the cap's centre; +z towards the nail), another mounting (None keeps
    the published setting)."""

    name: Text
    stiffness_scale: PositiveNumber = 1.0
    shape: choice(*SHAPE_AXES) | None = None
    core_offset: Offset3 | None = None
    mounting: choice("centre", "nail") | None = None

    def apply(self, fingertip: Fingertip) -> Fingertip:
        law: PlateContactLaw = fingertip.contact
        changes = {"contact": replace(law, youngs_modulus=law.youngs_modulus * self.stiffness_scale)}
        for name in ("shape", "core_offset", "mounting"):
            if getattr(self, name) is not None:
                changes[name] = getattr(self, name)
        return replace(fingertip, **changes)


# stiffness: in-vivo finger pads span about a factor of two either way of a soft cast at these loads;
# the core: a finger's distal phalanx sits off the pulp's centre, here 1.5 mm towards the nail
DEFAULT_VARIATIONS = (
    FingerVariation(name="as published"),
    FingerVariation(name="human pads half as stiff", stiffness_scale=0.5),
    FingerVariation(name="human pads twice as stiff", stiffness_scale=2.0),
    FingerVariation(name="human pads spherical", shape="sphere"),
    FingerVariation(name="human pads flattened", shape="pad"),
    FingerVariation(name="core 1.5 mm towards the nail", core_offset=(0.0, 0.0, 1.5e-3)),
    FingerVariation(name="device resting on the nail", mounting="nail"),
)

VARIATION_NAMES = tuple(variation.name for variation in DEFAULT_VARIATIONS)


@dataclass(frozen=True)
class Baseline:
    """The study at ``settings`` on ``fingertips``: its FS table and targets, each fingertip's user
    data and errors (methods, targets) in N; each fingertip's outcome when the baseline computed its
    errors itself (none when they were given)."""

    device: DeviceSpec
    fingertips: tuple[Fingertip, ...]
    settings: StudySettings
    collection: CollectionSettings
    seed: int
    shared: SharedTables
    user_data: tuple[UserData, ...]
    errors: tuple[np.ndarray, ...]
    outcomes: tuple[FingertipOutcome, ...] = ()

    @classmethod
    def run(cls, settings: StudySettings = StudySettings(), seed: int = 0, device: DeviceSpec | None = None,
            fingertips: tuple[Fingertip, ...] = TEST_FINGERTIPS,
            collection: CollectionSettings = CollectionSettings(), progress: Progress = SILENT,
            errors=None, fs=None) -> Baseline:
        """The study's tables and user data; its errors ``errors`` (fingertips, methods, targets) when
        the study was already run on the same seed and settings, else computed here; ``fs``: the
        study's recorded FS table, if it had one."""
        seed = checked(integer(0), "seed", seed)
        if errors is not None and len(errors) != len(fingertips):
            raise ValueError(f"errors: expected one (methods, targets) array per fingertip, {len(fingertips)}, "
                             f"got {len(errors)}")
        device = load_device() if device is None else device
        shared, user_data = collect_study(device, fingertips, settings, collection, seed, progress, fs)
        outcomes = ()
        if errors is None:
            outcomes = study_fingertips(device, fingertips, shared, user_data, settings, collection, seed, progress)
            errors = [outcome.errors for outcome in outcomes]
        return cls(device, tuple(fingertips), settings, collection, seed, shared, user_data,
                   tuple(np.asarray(e) for e in errors), outcomes)

    @property
    def tests(self) -> int:
        return wilcoxon_tests(len(self.fingertips))

    def rerun(self, settings: StudySettings, shared: SharedTables, indices,
              fingertips: tuple[Fingertip, ...] | None = None) -> tuple[np.ndarray, ...]:
        """The errors of the fingertips at ``indices`` (of ``fingertips``, by default the baseline's)
        under ``settings`` with ``shared`` tables: the baseline's own where nothing changed, its user
        data where it still holds."""
        fingertips = self.fingertips if fingertips is None else fingertips
        errors = []
        for i in indices:
            same_finger = fingertips[i] == self.fingertips[i]
            if same_finger and settings == self.settings and shared is self.shared:
                errors.append(self.errors[i])
                continue
            same = same_finger and settings.user_levels == self.settings.user_levels
            errors.append(study_fingertip(self.device, fingertips[i], shared, settings, self.collection, self.seed,
                                          i, self.tests, self.user_data[i] if same else None).errors)
        return tuple(errors)


@dataclass(frozen=True)
class VariationOutcome:
    """One variation: each method's median error (N) over the targets of the human fingertips it
    could be studied on, the methods from best to worst, and the pooled A-vs-B test over every
    fingertip studied; the human fingertips left out (the procedure cannot run on them, e.g. out of
    the device's reach) and why. With every human fingertip left out, no figures."""

    variation: FingerVariation
    median_error: np.ndarray | None
    ranking: tuple[str, ...]
    pooled: WilcoxonResult | None
    left_out: tuple[str, ...] = ()
    refused: str | None = None  # why each fingertip left out was, one after the other

    def to_dict(self) -> dict:
        """JSON-ready: medians in N by method, the ranking, the pooled test, what was left out and why."""
        found = {"variation": self.variation.name, "left_out": list(self.left_out), "refused": self.refused}
        if self.median_error is None:
            return found
        return found | {
            "median_error_N": dict(zip(METHODS, self.median_error.tolist(), strict=True)),
            "ranking": list(self.ranking),
            "pooled_A_vs_B": {"W_signed_rank_sum": self.pooled.signed_rank_sum, "W_scipy_min": self.pooled.w_scipy,
                              "p_bonferroni": self.pooled.p_bonferroni}}


def sensitivity_study(baseline: Baseline, progress: Progress = SILENT,
                      variations: tuple[FingerVariation, ...] = DEFAULT_VARIATIONS) -> tuple[VariationOutcome, ...]:
    """The human fingertips of ``baseline`` rerun under each variation (the casts as they are). A
    human fingertip the procedure refuses under a variation is left out of its figures, and said so."""
    if not variations:
        raise ValueError("variations: expected at least one")
    human = [i for i, finger in enumerate(baseline.fingertips) if finger in HUMAN_FINGERTIPS]
    if not human:
        raise ValueError("fingertips: the sensitivity study varies the human fingertips, expected at least one of "
                         + ", ".join(finger.name for finger in HUMAN_FINGERTIPS))
    outcomes = []
    with progress.task("finger variations", total=len(variations)) as task:
        for variation in variations:
            fingertips = tuple(variation.apply(f) if i in human else f for i, f in enumerate(baseline.fingertips))
            varied, refusals = {}, {}
            for i in human:
                try:
                    varied[i] = baseline.rerun(baseline.settings, baseline.shared, [i], fingertips)[0]
                except ValueError as problem:
                    refusals[baseline.fingertips[i].name] = str(problem)
            left_out = tuple(refusals)
            why = "; ".join(refusals.values()) or None
            if not varied:
                outcomes.append(VariationOutcome(variation, None, (), None, left_out, why))
                task.advance(note=f"{variation.name}: refused")
                continue
            every = [varied.get(i, errors) for i, errors in enumerate(baseline.errors) if i in varied or i not in human]
            median = np.median(np.hstack(list(varied.values())), axis=1)
            outcomes.append(VariationOutcome(variation, median, tuple(METHODS[i] for i in np.argsort(median)),
                                             pooled_test(every, baseline.tests), left_out, why))
            task.advance(note=variation.name)
    return tuple(outcomes)


def sensitivity_figure(outcomes: tuple[VariationOutcome, ...]) -> Figure:
    """Each method's median error (N) over the human fingertips under each variation (refused ones left out)."""
    shown = [outcome for outcome in outcomes if outcome.median_error is not None]
    if not shown:
        raise ValueError("sensitivity: every variation was refused, nothing to draw")
    figure = Figure(figsize=(1.6 * len(shown) + 5, 3.8), layout="constrained")
    axis = figure.subplots()
    width = 0.8 / len(METHODS)
    places = np.arange(len(shown))
    for m, method in enumerate(METHODS):
        axis.bar(places + (m - (len(METHODS) - 1) / 2) * width, [o.median_error[m] for o in shown], width,
                 label=method)
    axis.set_xticks(places, [o.variation.name for o in shown], rotation=20, ha="right")
    axis.set_ylabel("median rendering error, human fingertips (N)")
    axis.set_yscale("log")
    axis.grid(axis="y", alpha=0.3)
    axis.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.01, 1.0))  # beside the bars, never on them
    return figure


@dataclass(frozen=True)
class CurvePoint:
    """The study at one value of one setting: each method's median error (N) over every fingertip and target."""

    setting: str  # a field of StudySettings
    value: float
    median_error: np.ndarray


CURVES = (("n_neighbours", (1, 2, 4, 8, 16)), ("weighting_power", (0.0, 1.0, 2.0)),
          ("fs_levels", (7, 9, 11, 13)), ("user_levels", (4, 5, 7)))
CURVE_LABELS = {"n_neighbours": "neighbours n", "weighting_power": "weighting power p (weights 1/d^p)",
                "fs_levels": "FS table levels per servo (levels³ entries)",
                "user_levels": "user table levels per servo (levels³ entries)"}


def error_curves(baseline: Baseline, progress: Progress = SILENT,
                 curves: tuple[tuple[str, tuple], ...] = CURVES) -> tuple[CurvePoint, ...]:
    """The study rerun with each setting of ``curves`` varied alone (the others as the baseline's)."""
    runs = [(name, value) for name, values in curves for value in values]
    if not runs:
        raise ValueError("curves: expected at least one setting with values")
    unknown = [name for name, _ in runs if name not in CURVE_LABELS]
    if unknown:
        raise ValueError(f"curves: {unknown[0]!r} is not a setting the curves vary, expected one of "
                         + ", ".join(CURVE_LABELS))
    every = range(len(baseline.fingertips))
    points = []
    with progress.task("error curves", total=len(runs)) as task:
        for name, value in runs:
            settings = replace(baseline.settings, **{name: value})
            shared = baseline.shared if settings.fs_levels == baseline.settings.fs_levels else replace(
                baseline.shared, fs=fs_table(baseline.device, value, baseline.collection, baseline.seed))
            errors = np.hstack(baseline.rerun(settings, shared, every))
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
        axis.set_xticks(values, [f"{value:g}" for value in values])
        axis.set_xlabel(CURVE_LABELS[setting])
        axis.set_yscale("log")
        axis.grid(alpha=0.3)
    axes[0].set_ylabel("median rendering error (N)")
    figure.legend(*axes[0].get_legend_handles_labels(), loc="outside right upper", fontsize="small")  # off the lines
    return figure


@dataclass(frozen=True)
class RobustnessRun:
    """The study on one device and seed: its label, the fitted parameters' values on its device, and
    each fingertip's errors (fingertips, methods, targets) and rendered force magnitudes (same shape), in N."""

    label: str
    seed: int
    values: tuple[float, ...]
    errors: np.ndarray
    rendered: np.ndarray


def robustness_study(baseline: Baseline, seeds=(), sigmas: float = 1.0,
                     progress: Progress = SILENT) -> tuple[RobustnessRun, ...]:
    """The study rerun on the devices the published figures cannot tell from the fitted one (the
    fitted values moved ``sigmas`` standard deviations down and up each principal axis of their
    correlation, the device file's ``[fit]``; none without one or with ``sigmas`` 0) at the
    baseline's seed, and on the fitted device over the other ``seeds``."""
    device, fit = baseline.device, baseline.device.fit
    keys = tuple(fit.parameters) if fit else ()
    values = np.array([device.value(key) for key in keys])
    runs = []
    if fit and sigmas > 0:
        for k, move in enumerate(principal_moves(fit.covariance, sigmas)):
            sign = "−" if k % 2 == 0 else "+"
            runs.append((f"principal axis {k // 2 + 1} {sign}{sigmas:g}σ, seed {baseline.seed}",
                         device.with_values(keys, values + move), baseline.seed, values + move))
    runs += [(f"fitted device, seed {seed}", device, seed, values) for seed in seeds if seed != baseline.seed]
    found = []
    with progress.task("robustness", total=len(runs)) as task:
        for label, variant, seed, moved in runs:
            outcomes = Baseline.run(baseline.settings, seed, variant, baseline.fingertips, baseline.collection).outcomes
            found.append(RobustnessRun(label, seed, tuple(float(v) for v in moved),
                                       np.array([o.errors for o in outcomes]),
                                       np.array([o.rendered for o in outcomes])))
            task.advance(note=label)
    return tuple(found)
