"""Personalisation A's two variants side by side on the same tables: the published one (the DS's raw
6-D wrenches, the torques over a stated length, no device model) and softtip's earlier one (the DS's
3-D forces turned into the device's axes by the forward kinematics), :mod:`.personalisation`.

:func:`compare_data_driven` takes what the study collected (the FS table, the targets and each test
fingertip's user table), personalises the FS table by each variant, renders every target with each
and reads the test fingertip's sensor. Both variants' renderings draw the same noise (one stream of
the seed per fingertip, restarted for each variant), so their paired differences are the variants',
not the noise's. Wilcoxon's signed-rank test compares them per fingertip and pooled, with
Bonferroni over all those tests.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure

from softtip.report.tables import Table
from softtip.systems.haptics.collection import Collection, CollectionSettings, sensed_by_fingertip
from softtip.systems.haptics.device import DeviceSpec
from softtip.systems.haptics.fingertips import Fingertip
from softtip.systems.haptics.personalisation import DATA_DRIVEN_VARIANTS, personalise_data_driven
from softtip.systems.haptics.rendering import NearestNeighbourRenderer
from softtip.systems.haptics.statistics import WilcoxonResult, wilcoxon
from softtip.systems.haptics.study import SharedTables, StudySettings, UserData

_VARIANT_STREAM = 3  # the renderings' noise: a stream of the seed the study's stages (0, 1, 2) do not draw from


@dataclass(frozen=True)
class VariantComparison:
    """Errors (fingertips, variants in :data:`DATA_DRIVEN_VARIANTS` order, targets) in N, the FS
    entries each variant flagged (fingertips, variants), and the published-vs-device-axes Wilcoxon
    tests, one per fingertip and then the pooled one (None where both erred alike on every target); the
    published variant's pooled median and mean error at other torque lengths."""

    fingertips: tuple[str, ...]
    errors: np.ndarray
    flagged_entries: np.ndarray
    tests: tuple[WilcoxonResult | None, ...]
    torque_length: float
    length_sweep: tuple[tuple[float, float, float], ...]  # the published variant: (torque length m, median, mean N)

    @property
    def pooled(self) -> WilcoxonResult | None:
        return self.tests[-1]

    def rows(self) -> list[tuple[str, float, float, float, float, float | None]]:
        """Per fingertip, then pooled: median and mean error of each variant (N) and the test's
        Bonferroni-corrected p (None: no test, the errors equal on every target)."""
        pooled = self.errors.transpose(1, 0, 2).reshape(len(DATA_DRIVEN_VARIANTS), -1)
        found = []
        for name, errors, test in zip((*self.fingertips, "all fingertips (pooled)"), (*self.errors, pooled),
                                      self.tests, strict=True):
            median, mean = np.median(errors, axis=1), errors.mean(axis=1)
            found.append((name, float(median[0]), float(median[1]), float(mean[0]), float(mean[1]),
                          None if test is None else test.p_bonferroni))
        return found

    def to_dict(self) -> dict:
        return {"torque_length_m": self.torque_length, "variants": list(DATA_DRIVEN_VARIANTS),
                "torque_length_sweep": [{"torque_length_m": length, "median_error_N": median, "mean_error_N": mean}
                                        for length, median, mean in self.length_sweep],
                "rows": [{"fingertip": name, "median_error_N": [median_p, median_d], "mean_error_N": [mean_p, mean_d],
                          "p_bonferroni": p, "signed_rank_sum": None if test is None else test.signed_rank_sum,
                          "w_scipy": None if test is None else test.w_scipy}
                         for (name, median_p, median_d, mean_p, mean_d, p), test in zip(self.rows(), self.tests,
                                                                                         strict=True)],
                "fs_entries_flagged": {name: flagged.tolist()
                                       for name, flagged in zip(self.fingertips, self.flagged_entries, strict=True)}}

    def table(self) -> Table:
        """The comparison as a report table."""
        columns = [f"{what}, A {variant}" for what in ("median error (N)", "mean error (N)")
                   for variant in DATA_DRIVEN_VARIANTS] + ["p (Bonferroni)"]
        rows = self.rows()
        cells = {(row[0], column): value for row in rows for column, value in zip(columns, row[1:], strict=True)}
        notes = {row[0]: "Both variants rendered every target alike: nothing to test."
                 for row in rows if row[5] is None}
        swept = []
        for length, median, mean in self.length_sweep:
            row = f"all fingertips (pooled), torques over {length * 1e3:g} mm"
            swept.append(row)
            cells |= {(row, columns[0]): median, (row, columns[2]): mean}
        return Table("Personalisation A as published (raw 6-D DS wrenches) against softtip's 3-D variant",
                     "fingertip", [row[0] for row in rows] + swept, columns, cells, digits=3, notes=notes, caption=(
                         "The same FS table, user tables and targets, each personalised by both variants and "
                         "rendered with the same noise. Published: the DS's raw wrenches, the torques divided by "
                         f"{self.torque_length * 1e3:g} mm, no device model; device axes: the DS's forces turned "
                         "into the static platform's axes by the forward kinematics. p: Wilcoxon signed-rank, "
                         "Bonferroni over every fingertip and the pooled test. The last rows: the published search "
                         "with the torque length a quarter, once and four times the stated one: how much the "
                         "choice matters."))

    def figure(self) -> Figure:
        """Median error per fingertip, the two variants side by side."""
        rows = self.rows()
        figure = Figure(figsize=(1.2 * len(rows) + 2.5, 3.6), layout="constrained")
        axis = figure.subplots()
        where = np.arange(len(rows))
        for k, (variant, offset) in enumerate(zip(DATA_DRIVEN_VARIANTS, (-0.2, 0.2), strict=True)):
            axis.bar(where + offset, [row[1 + k] for row in rows], 0.4, label=f"A, {variant}")
        axis.set_xticks(where, [row[0].replace(" (", "\n(") for row in rows], fontsize=8)
        # logarithmic: the fingertip the device presses at its floor (about 2 N) would flatten the others' 0.03-0.1 N
        axis.set_yscale("log")
        axis.set_ylabel("median |F_target − F_rendered| (N)")
        axis.set_title(f"Personalisation A: raw 6-D DS wrenches (torque / {self.torque_length * 1e3:g} mm) "
                       "against 3-D forces in the device's axes", fontsize=9)
        axis.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
        axis.grid(axis="y", alpha=0.3)
        return figure


# the torque length scaled by these factors in the comparison's sweep: how much the stated length matters
TORQUE_LENGTH_FACTORS = (0.25, 1.0, 4.0)


def _rendered_errors(device: DeviceSpec, fingertip: Fingertip, index: int, shared: SharedTables, user: Collection,
                     settings: StudySettings, collection: CollectionSettings, seed: int, variant: str,
                     torque_length: float) -> tuple[np.ndarray, int]:
    """The ``index``-th fingertip's errors (targets,) with A personalised by ``variant`` from its usable
    ``user`` table, and how many FS entries that flagged; the renderings' noise is the fingertip's own
    stream, the same for every variant."""
    fs, targets = shared.fs, shared.targets
    personal = personalise_data_driven(device, fs.motor_inputs, fs.platform_wrenches, user.motor_inputs,
                                       user.platform_wrenches, settings.n_neighbours, settings.contact_threshold,
                                       settings.weighting_power, variant, torque_length)
    renderer = NearestNeighbourRenderer(settings.n_neighbours, settings.contact_threshold, settings.weighting_power)
    motor = renderer.fit(fs.finger_wrenches, personal.motor_inputs).predict(targets)
    produced, _ = sensed_by_fingertip(device, fingertip, motor, collection,
                                      np.random.default_rng([seed, _VARIANT_STREAM, index]))
    return np.linalg.norm(targets[:, :3] - produced[:, :3], axis=1), int(personal.outside.sum())


def compare_data_driven(device: DeviceSpec, fingertips: tuple[Fingertip, ...], shared: SharedTables,
                        user_data: tuple[UserData, ...], settings: StudySettings, collection: CollectionSettings,
                        seed: int) -> VariantComparison:
    """Both variants of personalisation A on the study's own tables (``shared``, ``user_data``: what
    :func:`~.study.collect_study` returns) at its ``settings``, and the published one's pooled errors
    with the torque length scaled by :data:`TORQUE_LENGTH_FACTORS`."""
    if len(user_data) != len(fingertips):
        raise ValueError(f"user_data: expected one per fingertip, {len(fingertips)}, got {len(user_data)}")
    users = [data.user_table.unsaturated() for data in user_data]

    def rendered(variant: str, torque_length: float) -> tuple[np.ndarray, np.ndarray]:
        found = [_rendered_errors(device, fingertip, index, shared, user, settings, collection, seed, variant,
                                  torque_length)
                 for index, (fingertip, user) in enumerate(zip(fingertips, users, strict=True))]
        return np.array([errors for errors, _ in found]), np.array([flagged for _, flagged in found])

    both = [rendered(variant, settings.torque_length) for variant in DATA_DRIVEN_VARIANTS]
    errors = np.stack([errors for errors, _ in both], axis=1)  # (fingertips, variants, targets)
    flagged = np.stack([outside for _, outside in both], axis=1)
    sweep = []
    for factor in TORQUE_LENGTH_FACTORS:
        length = settings.torque_length * factor
        pooled = (errors[:, 0] if factor == 1.0 else rendered("published", length)[0]).ravel()
        sweep.append((length, float(np.median(pooled)), float(pooled.mean())))
    tests = len(fingertips) + 1
    paired = (*errors, errors.transpose(1, 0, 2).reshape(len(DATA_DRIVEN_VARIANTS), -1))
    return VariantComparison(tuple(f.name for f in fingertips), errors, flagged,
                             tuple(None if np.array_equal(*e) else wilcoxon(*e, tests) for e in paired),
                             settings.torque_length, tuple(sweep))
