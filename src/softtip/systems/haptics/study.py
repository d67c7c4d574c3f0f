"""The published evaluation on the simulated device: six test fingertips, three methods (and two of
softtip's), 100 targets.

:func:`run_study` collects the FS table (13³ configurations, FS and DS; entries where a sensor
saturated are left out), records the target sensations (random configurations that touch the FS,
read by the FS), builds each test fingertip's tables (the standard FS table; personalisation A from
a 7³ user table read by the DS; personalisation B by geometry; and beyond the publication, B with
the user's stiffness from five presses, and A from an adaptive user table of 64 configurations),
renders every target with each and reads the force actually produced on the test fingertip by the
sensor under it. The error of a target is |F_target −
F_rendered| over the three force components (N). The statistics are those of the publication:
Friedman across the three published methods per fingertip, Wilcoxon post hoc between each pair of
them per fingertip and between the two personalisations pooled over every fingertip and target,
Bonferroni over all those Wilcoxon tests.

Departures from the published procedure, all of them stated in the result's ``notes``: the device,
fingertips and sensors are simulated (:mod:`.device`, :mod:`.fingertips`); the contact is
frictionless (only the force's magnitude and direction along the platform's normal are rendered);
the servos reach each commanded configuration to their dead band before the hold.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np
from matplotlib.figure import Figure

from softtip._core.config import NonNegativeNumber, PositiveNumber, checked, choice, integer, schema
from softtip._core.progress import SILENT, Progress
from softtip.mechanics.plate_contact import contact_radius
from softtip.systems.haptics.adaptive import AdaptiveTable, Drive, adaptive_user_table
from softtip.systems.haptics.collection import (
    Collection,
    CollectionSettings,
    motor_grid,
    sensed_by_fingertip,
    sensed_contact,
)
from softtip.systems.haptics.device import DeviceSpec, forward_kinematics, load_device
from softtip.systems.haptics.fingertips import CORE_RADIUS, FINGERTIP_SENSOR, TEST_FINGERTIPS, Fingertip, finger_wrench
from softtip.systems.haptics.limits import SHORT_NAMES  # the methods as the plots' ticks name them
from softtip.systems.haptics.personalisation import (
    DATA_DRIVEN_VARIANTS,
    DS_TORQUE_LENGTH,
    PressFit,
    fit_presses,
    personalise_data_driven,
    personalise_force_model,
    personalise_geometric,
    press_configurations,
)
from softtip.systems.haptics.rendering import CONTACT_THRESHOLD, NearestNeighbourRenderer, Rendering, WeightingPower
from softtip.systems.haptics.statistics import FriedmanResult, WilcoxonResult, friedman, wilcoxon

# the publication's three methods, then softtip's additions: B with the user's stiffness from five
# presses, and A from an adaptive user table of at most ``adaptive_budget`` configurations
METHODS = ("standard", "data-driven (A)", "geometric (B)", "geometric + presses (B+)", "data-driven, adaptive (A+)")
PUBLISHED_METHODS = 3  # the statistics compare these, as published
PAIRS = ((0, 1), (0, 2), (1, 2))


@schema(section="study")
class StudySettings:
    """The study's sizes: targets, FS and user table levels per servo (13 → 13³), neighbours and
    their weighting, the light-target bound (N) and the force below which a reading is no contact (N);
    personalisation A's variant and its torque length (m, :mod:`.personalisation`)."""

    targets: integer(2) = 100
    fs_levels: integer(2) = 13
    user_levels: integer(2) = 7
    adaptive_budget: integer(27) = 64
    n_neighbours: integer(1) = 8
    weighting_power: WeightingPower = 1.0  # 1/d^p: 1 the published distance weighting
    light_force: PositiveNumber = 1.0
    contact_threshold: PositiveNumber = CONTACT_THRESHOLD
    target_draws: integer(1) = 20_000  # random configurations tried to find targets that touch the FS
    min_target_force: NonNegativeNumber = CONTACT_THRESHOLD
    data_driven: choice(*DATA_DRIVEN_VARIANTS) = "published"
    torque_length: PositiveNumber = DS_TORQUE_LENGTH


@dataclass(frozen=True)
class FingertipOutcome:
    """One test fingertip: per method (rows in :data:`METHODS` order) and target, the error (N), the
    rendered force's magnitude (N), and whether the result is flagged (a target outside the table,
    a pose out of reach, the sensor under the fingertip saturated); Friedman and the post hoc tests
    over the published three."""

    fingertip: Fingertip
    errors: np.ndarray
    rendered: np.ndarray
    flagged: np.ndarray
    rendered_wrenches: np.ndarray  # (methods, targets, 6): the test fingertip's sensor, N and N·m
    motor_inputs: np.ndarray  # (methods, targets, 3): what each method commanded, rad
    user_table_flagged: int  # FS entries whose personalisation was flagged, method A
    geometric_flagged: int  # FS entries whose geometric personalisation was out of reach
    fitted_modulus: float  # Pa: the user's Hertz modulus from the presses (method B+)
    user_collection_s: float  # s: the user table's real collection time (method A)
    adaptive_collection_s: float  # s: the adaptive user table's real collection time (method A+)
    friedman: FriedmanResult
    post_hoc: tuple[WilcoxonResult, WilcoxonResult, WilcoxonResult]  # in PAIRS order


@dataclass(frozen=True)
class HapticsStudy:
    """What :func:`run_study` found, with what tables and figures need."""

    settings: StudySettings
    seed: int
    target_wrenches: np.ndarray
    fingertips: tuple[FingertipOutcome, ...]
    pooled: WilcoxonResult  # personalisation A against B over every fingertip and target
    fs_collection_s: float
    user_collection_s: float
    max_contact_to_layer: float  # the targets' largest Hertz contact radius on the FS over its elastomer thickness
    notes: tuple[str, ...] = field(default=())

    @property
    def target_magnitudes(self) -> np.ndarray:
        return np.linalg.norm(self.target_wrenches[:, :3], axis=1)

    def summary_rows(self) -> list[tuple[str, str, float, float, int]]:
        """(fingertip, method, median error N, mean error N, flagged targets) per fingertip and method."""
        return [(outcome.fingertip.name, method, float(np.median(outcome.errors[m])), float(np.mean(outcome.errors[m])),
                 int(outcome.flagged[m].sum()))
                for outcome in self.fingertips for m, method in enumerate(METHODS)]

    def figures(self) -> list[Figure]:
        return [error_box_plots([o.fingertip.name for o in self.fingertips],
                                np.array([o.errors for o in self.fingertips]))]


def error_box_plots(fingertips: list[str], errors: np.ndarray) -> Figure:
    """Box plots of the rendering error (N), ``errors`` (fingertips, methods in :data:`METHODS` order,
    targets), one panel per fingertip."""
    columns = min(3, len(fingertips))
    figure = Figure(figsize=(4 * columns, 3.25 * -(-len(fingertips) // columns)), layout="constrained")
    axes = np.atleast_1d(figure.subplots(-(-len(fingertips) // columns), columns, sharey=True, squeeze=False)).ravel()
    for axis, name, per_method in zip(axes, fingertips, errors, strict=False):
        axis.boxplot(list(per_method), tick_labels=list(SHORT_NAMES))
        axis.set_title(name)
        axis.grid(axis="y", alpha=0.3)
    for axis in axes[len(fingertips):]:
        axis.set_visible(False)
    for axis in axes[::columns]:
        axis.set_ylabel("rendering error |F_target − F_rendered| (N)")
    figure.suptitle(f"Rendering error over {errors.shape[-1]} targets (softtip, simulated device)")
    return figure


@dataclass(frozen=True)
class SharedTables:
    """What every test fingertip shares: the FS table (entries where a sensor saturated left out; its
    real collection time is the whole procedure's) and the target sensations (targets, 6)."""

    fs: Collection
    targets: np.ndarray


# each stage draws its noise from its own stream of the seed, so that a rerun which changes one
# stage (another FS table size, another finger) leaves every other stage's draws as they were
_FS_STREAM, _TARGET_STREAM, _FINGERTIP_STREAM = 0, 1, 2
_TARGET_BATCH = 512  # random configurations driven per batch while looking for targets


def _stream(seed: int, *keys: int) -> np.random.Generator:
    return np.random.default_rng([seed, *keys])


def fs_table(device: DeviceSpec, levels: int, collection: CollectionSettings, seed: int) -> Collection:
    """The FS table of ``levels``³ configurations, collected as the procedure does."""
    collected = sensed_contact(device, FINGERTIP_SENSOR, motor_grid(device, levels), collection,
                               _stream(seed, _FS_STREAM))
    return collected.unsaturated()


def record_targets(device: DeviceSpec, settings: StudySettings, collection: CollectionSettings,
                   seed: int) -> np.ndarray:
    """The target sensations: random configurations over the servos' range, driven in batches until
    ``settings.targets`` of them touch the FS (at most ``settings.target_draws`` tried), as read by the FS."""
    rng = _stream(seed, _TARGET_STREAM)
    least = max(settings.min_target_force, settings.contact_threshold)
    found, tried = [], 0
    while sum(map(len, found)) < settings.targets and tried < settings.target_draws:
        draws = rng.uniform(0.0, device.angle_max, (min(_TARGET_BATCH, settings.target_draws - tried), 3))
        tried += len(draws)
        read = sensed_contact(device, FINGERTIP_SENSOR, draws, collection, rng)
        touching = (np.linalg.norm(read.finger_wrenches[:, :3], axis=1) >= least) & ~read.saturated
        found.append(read.finger_wrenches[touching])
    found = np.vstack(found)
    if len(found) < settings.targets:
        raise ValueError(f"study.target_draws = {settings.target_draws}: only {len(found)} random configurations "
                         f"touch the FS, expected at least study.targets = {settings.targets}")
    return found[: settings.targets]


@dataclass(frozen=True)
class UserData:
    """What a test fingertip gives before any table is built: its fixed user table (``user_levels``³
    configurations, read by the DS) and its five presses (method B+), each collected on its own stream."""

    user_table: Collection
    presses: Collection


def _fingertip_stream(seed: int, index: int, stage: int) -> np.random.Generator:
    return _stream(seed, _FINGERTIP_STREAM, index, stage)


_USER, _PRESSES, _ADAPTIVE, _RENDERINGS = range(4)  # the stages of a fingertip, each on its own stream


def adaptive_stream(seed: int, index: int) -> np.random.Generator:
    """The stream the ``index``-th test fingertip's adaptive user table (A+) is drawn from."""
    return _fingertip_stream(seed, index, _ADAPTIVE)


def collect_user_data(device: DeviceSpec, fingertip: Fingertip, settings: StudySettings,
                      collection: CollectionSettings, seed: int, index: int) -> UserData:
    """The ``index``-th test fingertip's user table and presses."""
    return UserData(
        sensed_contact(device, fingertip, motor_grid(device, settings.user_levels), collection,
                       _fingertip_stream(seed, index, _USER)),
        sensed_contact(device, fingertip, press_configurations(device, fingertip.radius), collection,
                       _fingertip_stream(seed, index, _PRESSES)))


def study_fingertip(device: DeviceSpec, fingertip: Fingertip, shared: SharedTables, settings: StudySettings,
                    collection: CollectionSettings, seed: int, index: int, tests: int,
                    user_data: UserData | None = None) -> FingertipOutcome:
    """The ``index``-th test fingertip: its user data collected (unless given), the FS table
    personalised by each method, every target rendered by each and read by the sensor under the
    fingertip; the statistics count ``tests`` Wilcoxon tests in all. A fingertip the procedure
    cannot personalise is refused in one line."""
    fs, targets = shared.fs, shared.targets
    with _refusing(fingertip):
        if user_data is None:
            user_data = collect_user_data(device, fingertip, settings, collection, seed, index)
        personal = _personalise(device, fingertip, fs, user_data, settings, collection, adaptive_stream(seed, index))
    standard = NearestNeighbourRenderer(settings.n_neighbours, settings.contact_threshold,
                                        settings.weighting_power).get_params()
    rng = _fingertip_stream(seed, index, _RENDERINGS)
    wrenches, commanded, flagged = [], [], []
    for motor in (fs.motor_inputs, *personal.motor_inputs):
        rendering = NearestNeighbourRenderer(**standard).fit(fs.finger_wrenches, motor).render(targets)
        produced, saturated = sensed_by_fingertip(device, fingertip, rendering.motor_inputs, collection, rng)
        wrenches.append(produced)
        commanded.append(rendering.motor_inputs)
        flagged.append(rendering.outside | saturated)
    wrenches = np.array(wrenches)
    errors = np.linalg.norm(targets[:, :3] - wrenches[..., :3], axis=-1)
    return FingertipOutcome(
        fingertip, errors, np.linalg.norm(wrenches[..., :3], axis=-1), np.array(flagged), wrenches,
        np.array(commanded), personal.data_driven_flagged, personal.geometric_flagged, personal.fitted_modulus,
        user_data.user_table.duration_s, personal.adaptive_collection_s, friedman(errors[:PUBLISHED_METHODS]),
        tuple(wilcoxon(errors[a], errors[b], tests) for a, b in PAIRS))


def wilcoxon_tests(fingertips: int) -> int:
    """The Wilcoxon tests the study makes on ``fingertips`` test fingertips, which Bonferroni's
    correction counts: one per pair of published methods per fingertip, and the pooled A-vs-B test."""
    return len(PAIRS) * fingertips + 1


def pooled_test(errors, tests: int) -> WilcoxonResult:
    """Personalisation A against B over every fingertip and target; ``errors``: each fingertip's
    (methods, targets) errors."""
    return wilcoxon(np.concatenate([e[1] for e in errors]), np.concatenate([e[2] for e in errors]), tests)


@contextmanager
def _refusing(fingertip: Fingertip):
    """A fingertip the procedure cannot collect or personalise, refused in one line that names it."""
    try:
        yield
    except ValueError as problem:
        raise ValueError(f"fingertip {fingertip.name!r}: {problem}") from None


def collect_study(device: DeviceSpec, fingertips: tuple[Fingertip, ...], settings: StudySettings,
                  collection: CollectionSettings, seed: int, progress: Progress = SILENT,
                  fs: Collection | None = None) -> tuple[SharedTables, tuple[UserData, ...]]:
    """What the study collects before it renders: the FS table (``fs``: a recorded one instead) and
    targets, then each test fingertip's user table and presses, each on the stream the study draws it from."""
    with progress.task("FS table and targets", total=1) as task:
        shared = SharedTables(fs_table(device, settings.fs_levels, collection, seed) if fs is None else fs,
                              record_targets(device, settings, collection, seed))
        task.advance()
    user_data = []
    with progress.task("user tables and presses", total=len(fingertips)) as task:
        for index, fingertip in enumerate(fingertips):
            with _refusing(fingertip):
                user_data.append(collect_user_data(device, fingertip, settings, collection, seed, index))
            task.advance(note=fingertip.name)
    return shared, tuple(user_data)


def study_fingertips(device: DeviceSpec, fingertips: tuple[Fingertip, ...], shared: SharedTables,
                     user_data: tuple[UserData, ...], settings: StudySettings, collection: CollectionSettings,
                     seed: int, progress: Progress = SILENT) -> tuple[FingertipOutcome, ...]:
    """Every test fingertip's outcome (:func:`study_fingertip`) from its user data."""
    tests = wilcoxon_tests(len(fingertips))
    outcomes = []
    with progress.task("fingertips", total=len(fingertips)) as task:
        for index, (fingertip, data) in enumerate(zip(fingertips, user_data, strict=True)):
            outcomes.append(study_fingertip(device, fingertip, shared, settings, collection, seed, index, tests, data))
            task.advance(note=fingertip.name)
    return tuple(outcomes)


def run_study(settings: StudySettings = StudySettings(), seed: int = 0, progress: Progress = SILENT,
              device: DeviceSpec | None = None, fingertips: tuple[Fingertip, ...] = TEST_FINGERTIPS,
              collection: CollectionSettings = CollectionSettings(), fs: Collection | None = None) -> HapticsStudy:
    """The published study on the simulated device (see the module's notes); ``fs``: a recorded FS
    table instead of the simulated one."""
    seed = checked(integer(0), "seed", seed)
    device = load_device() if device is None else device
    shared, user_data = collect_study(device, fingertips, settings, collection, seed, progress, fs)
    outcomes = study_fingertips(device, fingertips, shared, user_data, settings, collection, seed, progress)
    return HapticsStudy(settings, seed, shared.targets, outcomes,
                        pooled_test([o.errors for o in outcomes], wilcoxon_tests(len(fingertips))),
                        shared.fs.duration_s, outcomes[-1].user_collection_s,
                        _contact_to_layer(device, shared.fs, shared.targets), NOTES)


@dataclass(frozen=True)
class _Personalised:
    """A fingertip's personalised FS tables: motor inputs per method after the standard (METHODS[1:])."""

    motor_inputs: tuple[np.ndarray, ...]
    data_driven_flagged: int
    geometric_flagged: int
    fitted_modulus: float
    adaptive_collection_s: float


def _personalise(device: DeviceSpec, fingertip: Fingertip, fs: Collection, user_data: UserData,
                 settings: StudySettings, collection: CollectionSettings, rng: np.random.Generator) -> _Personalised:
    data_driven = data_driven_table(device, fs.motor_inputs, fs.platform_wrenches, user_data.user_table, settings)
    geometric = personalise_geometric(device, fs.motor_inputs, FINGERTIP_SENSOR.radius, fingertip.radius)
    force_model, pressed = force_model_table(device, fingertip, fs.motor_inputs, fs.finger_wrenches,
                                             user_data.presses, settings, geometric)
    data_driven_adaptive, adaptive = adaptive_table(device, fingertip, fs.motor_inputs, fs.platform_wrenches,
                                                    settings, collection, rng)
    return _Personalised((data_driven.motor_inputs, geometric.motor_inputs, force_model.motor_inputs,
                          data_driven_adaptive.motor_inputs), int(data_driven.outside.sum()),
                         int(geometric.outside.sum()), pressed.youngs_modulus, adaptive.collection.duration_s)


def data_driven_table(device: DeviceSpec, fs_motor_inputs, fs_platform_wrenches, user_table: Collection,
                      settings: StudySettings) -> Rendering:
    """Method A: the FS table (its motor inputs and DS readings) personalised from the user's table
    (its unsaturated entries, at least ``n_neighbours`` of them) by the settings' variant."""
    usable = user_table.unsaturated()
    if len(usable.motor_inputs) < settings.n_neighbours:
        raise ValueError(f"user table: only {len(usable.motor_inputs)} of its {len(user_table.motor_inputs)} "
                         f"configurations read without saturating a sensor, expected at least n_neighbours = "
                         f"{settings.n_neighbours}")
    return personalise_data_driven(device, fs_motor_inputs, fs_platform_wrenches, usable.motor_inputs,
                                   usable.platform_wrenches, settings.n_neighbours, settings.contact_threshold,
                                   settings.weighting_power, settings.data_driven, settings.torque_length)


def force_model_table(device: DeviceSpec, fingertip: Fingertip, fs_motor_inputs, fs_finger_wrenches,
                      presses: Collection, settings: StudySettings,
                      geometric: Rendering | None = None) -> tuple[Rendering, PressFit]:
    """Method B+: the user's Hertz modulus fitted from the ``presses`` on ``fingertip``, and the FS
    table personalised with it (``geometric``: method B's personalisation of the same table, if made)."""
    pressed = fit_presses(device, presses.motor_inputs, presses.platform_wrenches, fingertip.radius,
                          settings.contact_threshold, saturated=presses.saturated)
    return personalise_force_model(device, fs_motor_inputs, fs_finger_wrenches, FINGERTIP_SENSOR.radius,
                                   fingertip.radius, pressed, settings.contact_threshold, geometric=geometric), pressed


def adaptive_table(device: DeviceSpec, fingertip: Fingertip, fs_motor_inputs, fs_platform_wrenches,
                   settings: StudySettings, collection: CollectionSettings,
                   rng: np.random.Generator | None, drive: Drive | None = None) -> tuple[Rendering, AdaptiveTable]:
    """Method A+: an adaptive user table of at most ``adaptive_budget`` configurations driven on
    ``fingertip`` (by ``drive``, else on the device model), and the FS table personalised from it."""
    adaptive = adaptive_user_table(device, fingertip, fs_motor_inputs, fs_platform_wrenches, collection, rng,
                                   settings.adaptive_budget, candidate_levels=settings.fs_levels,
                                   n_neighbours=settings.n_neighbours, contact_threshold=settings.contact_threshold,
                                   drive=drive)
    usable = adaptive.collection.unsaturated()
    # A+ picks its configurations by the DS's forces in the device's axes (.adaptive), and renders by them
    return personalise_data_driven(device, fs_motor_inputs, fs_platform_wrenches, usable.motor_inputs,
                                   usable.platform_wrenches, settings.n_neighbours, settings.contact_threshold,
                                   settings.weighting_power, "device axes"), adaptive


def _contact_to_layer(device: DeviceSpec, fs: Collection, targets: np.ndarray) -> float:
    """The largest contact radius over the FS table's entries as strong as the targets, over the FS's
    rubber thickness over its core: χ = √(Rδ)/t, where the bonded-layer law stays near its derivation (χ <~ 1)."""
    strongest = np.linalg.norm(targets[:, :3], axis=1).max()
    pose = forward_kinematics(device, fs.motor_inputs)
    _, depth = finger_wrench(FINGERTIP_SENSOR, device, pose)
    within = np.linalg.norm(fs.finger_wrenches[:, :3], axis=1) <= strongest
    radius = contact_radius(FINGERTIP_SENSOR.contact, depth[within], FINGERTIP_SENSOR.radius)
    return float(radius.max() / (FINGERTIP_SENSOR.radius - CORE_RADIUS))


NOTES = (
    "Device, fingertips and sensors are simulated: softtip's device dimensions (device.toml); VytaFlex 30 casts over "
    "one rigid core, their contact law calibrated by softtip's FE; Nano17-class sensors, one step of noise at 1 kHz.",
    "The contact is frictionless: a tilted platform renders force along its normal, no independent shear.",
    "W is given both as scipy's min(W+, W−) and as the signed-rank sum W+ − W− that the publication prints.",
    "Bonferroni's correction counts every Wilcoxon test made: three pairs per fingertip and the pooled A-vs-B test.",
)
