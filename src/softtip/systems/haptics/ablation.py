"""Ablations of the report's two measured shortfalls, each method rerun on the study's own tables with
one cause taken away at a time.

**Personalisation A as published trails softtip's 3-D variant.** The published search reads the DS's
raw wrench in the platform's own axes, the torques over a stated length. Under a frictionless contact
the DS's force lies along the platform's normal: its two tangential components and the torque about
the normal carry the sensor's noise and nothing else, yet count in the search's distances as much as
the three that carry the press (the normal force and the two tilting torques). The causes taken away:

- *the metric*: the published search on those three components alone (fz, τx / L, τy / L);
- *the platform's axes*: the published 6-D search with the DS's wrenches turned into the device's axes
  by the forward kinematics (the device model the published method does without), between it and the
  3-D variant only the torques;
- *the noise and quantisation*: both variants on the DS's exact readings (the same configurations read
  without noise or steps), the FS's own readings and the targets as the study has them;
- *the torque length*: swept in :mod:`.data_driven` (a quarter, once and four times the stated one);
- *the user table's sparseness*: both variants from a user table as dense as the FS table
  (``fs_levels``³ configurations instead of ``user_levels``³): each search averages its neighbours'
  motor inputs, and how far that is from the configuration wanted depends on how evenly the search's
  coordinates follow the motor inputs between the table's points.

**B+ (B with the user's stiffness from presses) trails B.** B+ reads each press's indentation from the
rigid kinematics, but the device's cables and springs give way under the press, so the indentation
it fits is too deep and the modulus too soft; it then places each entry by the same rigid
kinematics. The cause taken away: B+ with the cables' give (:func:`~.device.normal_give`) in both
steps (``cables = "compliant"``, :mod:`.personalisation`).

Every row renders the study's targets with the same noise (one stream of the seed per fingertip,
restarted for each row), so paired differences are the rows', not the noise's. Each row is tested
against its group's first (Wilcoxon signed-rank over every fingertip and target, Bonferroni over the
table's tests).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from softtip.report.tables import Table
from softtip.systems.haptics.collection import CollectionSettings, motor_grid, sensed_by_fingertip, sensed_contact
from softtip.systems.haptics.device import DeviceSpec
from softtip.systems.haptics.fingertips import FINGERTIP_SENSOR, Fingertip
from softtip.systems.haptics.personalisation import (
    fit_presses,
    in_device_axes,
    personalise_data_driven,
    personalise_force_model,
    personalise_geometric,
    readings_renderer,
)
from softtip.systems.haptics.rendering import NearestNeighbourRenderer, wrench_features
from softtip.systems.haptics.statistics import WilcoxonResult, rank_sum, wilcoxon
from softtip.systems.haptics.study import SharedTables, StudySettings, UserData

_ABLATION_STREAM = 4  # the renderings' noise: a stream of the seed no other stage draws from
# the DS's components a frictionless press carries: the normal force and the two tilting torques (platform axes)
PRESS_COMPONENTS = [2, 3, 4]

(A_PUBLISHED, A_PRESS_COMPONENTS, A_SIX_DEVICE_AXES, A_DEVICE_AXES, A_EXACT_PUBLISHED, A_EXACT_DEVICE_AXES,
 A_DENSE_PUBLISHED, A_DENSE_DEVICE_AXES) = range(8)
B, B_PLUS_RIGID, B_PLUS_COMPLIANT = range(8, 11)
ROWS = ("A as published: the DS's raw 6-D wrench", "A, published search on fz, τx, τy only",
        "A, published 6-D search in the device's axes", "A, softtip's 3-D variant (device axes)",
        "A as published, exact DS readings",
        "A, 3-D variant, exact DS readings", "A as published, user table as dense as the FS table",
        "A, 3-D variant, user table as dense as the FS table", "B (geometric)",
        "B+, presses and placement with rigid cables (the study's)", "B+, presses and placement with the cables' give")
GROUPS = ((A_PUBLISHED, A_PRESS_COMPONENTS, A_SIX_DEVICE_AXES, A_DEVICE_AXES, A_EXACT_PUBLISHED, A_EXACT_DEVICE_AXES,
           A_DENSE_PUBLISHED, A_DENSE_DEVICE_AXES), (B_PLUS_RIGID, B, B_PLUS_COMPLIANT))  # each against its first
_DENSE_USER = 5  # the dense user table's noise: a stage of the fingertip's ablation stream


@dataclass(frozen=True)
class Ablations:
    """Errors (rows in :data:`ROWS` order, fingertips, targets) in N and each row's test against its
    group's first (None for a group's first, or where both rendered every target alike)."""

    fingertips: tuple[str, ...]
    errors: np.ndarray
    tests: tuple[WilcoxonResult | None, ...]

    def pooled(self, row: int) -> tuple[float, float]:
        """A row's median and mean error (N) over every fingertip and target."""
        errors = self.errors[row].ravel()
        return float(np.median(errors)), float(errors.mean())

    def findings(self) -> tuple[str, str]:
        """What the ablations show, in a sentence each: A's gap and B+'s, with the cause they point to."""
        median = [self.pooled(row)[0] for row in range(len(ROWS))]
        gap = median[A_PUBLISHED] - median[A_DEVICE_AXES]
        closed = {"the noise-only components": median[A_PUBLISHED] - median[A_PRESS_COMPONENTS],
                  "the sensor's noise and steps": gap - (median[A_EXACT_PUBLISHED] - median[A_EXACT_DEVICE_AXES]),
                  "the user table's sparseness": gap - (median[A_DENSE_PUBLISHED] - median[A_DENSE_DEVICE_AXES])}
        frame = median[A_PUBLISHED] - median[A_SIX_DEVICE_AXES]
        a = (f"A as published trails the 3-D variant by {gap * 1e3:.1f} mN (pooled medians): turning the DS's 6-D "
             f"wrench into the device's axes (the forward kinematics, a device model the published method does "
             f"without) closes {frame * 1e3:.1f} mN of it and dropping the torques the other "
             f"{(gap - frame) * 1e3:.1f} mN, while taking away " + ", ".join(f"{name} closes {value * 1e3:+.1f} mN"
                                                                           for name, value in closed.items()))
        b_gap = median[B_PLUS_RIGID] - median[B]
        compliant = median[B_PLUS_COMPLIANT] - median[B]
        b = (f"B+ trails B by {b_gap * 1e3:.1f} mN with rigid cables; with the cables' give in its presses and "
             f"placement it is {abs(compliant) * 1e3:.1f} mN " + ("better than B: the rigid presses model is the "
                                                                  "cause" if compliant < 0 else "behind B"))
        return a, b

    def to_dict(self) -> dict:
        return {"rows": [{"ablation": name, "median_error_N": self.pooled(k)[0], "mean_error_N": self.pooled(k)[1],
                          "against": None if test is None else ROWS[next(g[0] for g in GROUPS if k in g)],
                          "signed_rank_sum": None if test is None else test.signed_rank_sum,
                          "p_bonferroni": None if test is None else test.p_bonferroni}
                         for k, (name, test) in enumerate(zip(ROWS, self.tests, strict=True))],
                "findings": list(self.findings())}

    def table(self) -> Table:
        columns = ["median error (N)", "mean error (N)", "against", "W+ − W−", "p (Bonferroni)"]
        cells = {}
        for k, (name, test) in enumerate(zip(ROWS, self.tests, strict=True)):
            median, mean = self.pooled(k)
            cells |= {(name, columns[0]): median, (name, columns[1]): mean}
            if test is not None:
                reference = next(group[0] for group in GROUPS if k in group)
                cells |= {(name, columns[2]): ROWS[reference].split(":")[0].split(",")[0],
                          (name, columns[3]): rank_sum(test.signed_rank_sum), (name, columns[4]): test.p_bonferroni}
        a, b = self.findings()
        return Table("Ablations: why A as published trails its 3-D variant, and B+ trails B", "method",
                     list(ROWS), columns, cells, digits=3,
                     notes={ROWS[A_PUBLISHED]: a + ".", ROWS[B_PLUS_RIGID]: b + "."}, caption=(
                         "Pooled over every fingertip and target, one cause taken away per row, every row on the "
                         "study's own tables and targets with the same noise. A: the published search on the three DS "
                         "components a frictionless press carries (the normal force, the two tilting torques), on the "
                         "DS's wrench turned into the device's axes by the kinematics, and "
                         "both searches on exact DS readings (no noise, no steps) and from a user table as dense "
                         "as the FS table. B+: the presses' depths and the "
                         "placement with the platform's give under the force (the cables' and springs' stiffness). "
                         "W+ − W− < 0: the row's errors are the smaller. softtip.systems.haptics.ablation."))


def _errors(device: DeviceSpec, fingertip: Fingertip, index: int, shared: SharedTables, motor: np.ndarray,
            settings: StudySettings, collection: CollectionSettings, seed: int) -> np.ndarray:
    """The ``index``-th fingertip's errors (targets,) rendering from the FS table with ``motor`` as its
    motor inputs, the sensor's noise on the fingertip's ablation stream, restarted for every row."""
    renderer = NearestNeighbourRenderer(settings.n_neighbours, settings.contact_threshold, settings.weighting_power)
    commanded = renderer.fit(shared.fs.finger_wrenches, motor).predict(shared.targets)
    produced, _ = sensed_by_fingertip(device, fingertip, commanded, collection,
                                      np.random.default_rng([seed, _ABLATION_STREAM, index]))
    return np.linalg.norm(shared.targets[:, :3] - produced[:, :3], axis=1)


def _fingertip_rows(device: DeviceSpec, fingertip: Fingertip, index: int, user_data: UserData, shared: SharedTables,
                    exact_fs_ds: np.ndarray, settings: StudySettings, collection: CollectionSettings,
                    seed: int) -> list:
    """Each row's personalised motor inputs (entries, 3) of the FS table for the ``index``-th ``fingertip``."""
    fs, user = shared.fs, user_data.user_table.unsaturated()
    options = (settings.n_neighbours, settings.contact_threshold, settings.weighting_power)
    dense = sensed_contact(device, fingertip, motor_grid(device, settings.fs_levels), collection,
                           np.random.default_rng([seed, _ABLATION_STREAM, index, _DENSE_USER])).unsaturated()

    def data_driven(fs_ds, user_ds, variant, table=user):
        return personalise_data_driven(device, fs.motor_inputs, fs_ds, table.motor_inputs, user_ds, *options, variant,
                                       settings.torque_length).motor_inputs

    def press_components(readings):
        return wrench_features(readings, settings.torque_length)[:, PRESS_COMPONENTS]

    exact_user_ds = sensed_contact(device, fingertip, user.motor_inputs, collection, None).platform_wrenches
    searched = readings_renderer(press_components(user.platform_wrenches), user.motor_inputs, *options)
    turned = readings_renderer(in_device_axes(device, user.motor_inputs, user.platform_wrenches), user.motor_inputs,
                               *options, settings.torque_length)
    geometric = personalise_geometric(device, fs.motor_inputs, FINGERTIP_SENSOR.radius, fingertip.radius)
    presses = user_data.presses

    def force_model(cables):
        pressed = fit_presses(device, presses.motor_inputs, presses.platform_wrenches, fingertip.radius,
                              settings.contact_threshold, saturated=presses.saturated, cables=cables)
        return personalise_force_model(device, fs.motor_inputs, fs.finger_wrenches, FINGERTIP_SENSOR.radius,
                                       fingertip.radius, pressed, settings.contact_threshold, geometric=geometric,
                                       cables=cables).motor_inputs

    return [data_driven(fs.platform_wrenches, user.platform_wrenches, "published"),
            searched.render(press_components(fs.platform_wrenches)).motor_inputs,
            turned.render(in_device_axes(device, fs.motor_inputs, fs.platform_wrenches)).motor_inputs,
            data_driven(fs.platform_wrenches, user.platform_wrenches, "device axes"),
            data_driven(exact_fs_ds, exact_user_ds, "published"),
            data_driven(exact_fs_ds, exact_user_ds, "device axes"),
            data_driven(fs.platform_wrenches, dense.platform_wrenches, "published", dense),
            data_driven(fs.platform_wrenches, dense.platform_wrenches, "device axes", dense),
            geometric.motor_inputs, force_model("rigid"), force_model("compliant")]


def ablate(device: DeviceSpec, fingertips: tuple[Fingertip, ...], shared: SharedTables,
           user_data: tuple[UserData, ...], settings: StudySettings, collection: CollectionSettings,
           seed: int) -> Ablations:
    """Every row of :data:`ROWS` on the study's own tables (``shared``, ``user_data``: what
    :func:`~.study.collect_study` returns) at its ``settings``."""
    if len(user_data) != len(fingertips):
        raise ValueError(f"user_data: expected one per fingertip, {len(fingertips)}, got {len(user_data)}")
    exact_fs_ds = sensed_contact(device, FINGERTIP_SENSOR, shared.fs.motor_inputs, collection, None).platform_wrenches
    errors = np.array([[_errors(device, fingertip, index, shared, motor, settings, collection, seed)
                        for motor in _fingertip_rows(device, fingertip, index, data, shared, exact_fs_ds, settings,
                                                     collection, seed)]
                       for index, (fingertip, data) in enumerate(zip(fingertips, user_data, strict=True))])
    errors = errors.transpose(1, 0, 2)  # (rows, fingertips, targets)
    tests = sum(len(group) - 1 for group in GROUPS)
    found: list[WilcoxonResult | None] = [None] * len(ROWS)
    for first, *others in GROUPS:
        for row in others:
            if not np.array_equal(errors[row], errors[first]):
                found[row] = wilcoxon(errors[row].ravel(), errors[first].ravel(), tests)
    return Ablations(tuple(f.name for f in fingertips), errors, tuple(found))
