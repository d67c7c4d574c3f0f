"""The device's unknowns fitted to the publication's scale.

The publication gives no device dimensions. Three of its figures fix the experiment's scale
(``published.toml``, table ``haptics-scale``): the targets' mean force on the FS (1.72 N), and the
standard method's mean force rendered to the small spherical cast (0.41 N) and to the largest human
cast (5.99 N). :func:`fit_device` sets three of the device file's unknowns from them with scipy's
least squares (:data:`FITTED`): the released cable length (the release gap below the FS's pad), the
pulley radius (with the servos' range, the stroke past the pad) and the cables' series stiffness.

Each published figure is a mean over 100 targets, so it carries a sampling error: the residuals are
weighted by the standard error of a 100-target mean, the per-target spread the twin shows at the
starting device over :data:`FIT_SEEDS` (:func:`scale_figures`), and the parameters' standard errors
follow from the Jacobian at the solution. The figures are taken over :data:`FIT_TARGETS` targets per
seed, on fixed noise streams, so that the objective is the twin's expected figure, not one draw's.
Every other published finding stays a prediction of the fitted twin. The shipped device file
records the fit (``[fit]``); ``examples/haptics_device_fit.py`` reruns it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from softtip._core.config import checked, integer
from softtip._core.errors import NotConverged
from softtip._core.progress import SILENT, Progress
from softtip.published import published_table
from softtip.systems.haptics.collection import CollectionSettings, sensed_by_fingertip
from softtip.systems.haptics.device import DeviceSpec
from softtip.systems.haptics.fingertips import TEST_FINGERTIPS
from softtip.systems.haptics.rendering import NearestNeighbourRenderer
from softtip.systems.haptics.study import StudySettings, fs_table, record_targets

SCALE_TABLE = "haptics-scale"
SCALE_COLUMN = "mean |F|"
# the fingertips the standard method's two figures are rendered to: the small sphere, the largest human cast
SMALL_SPHERE, LARGEST_HUMAN = TEST_FINGERTIPS[0], TEST_FINGERTIPS[-1]
FITTED = ("device.released_length", "device.pulley_radius", "cables.stiffness")
FIT_SEEDS = (11, 12, 13)  # apart from the study's own seeds, so the fit never sees the report's draws
FIT_TARGETS = 300  # per seed: the expected figure, three times the published sample
PUBLISHED_TARGETS = 100  # each published figure is a mean over the publication's 100 targets
_RENDER_STREAM = 9  # the renderings' noise, apart from the study's streams of the same seed


def published_scale() -> np.ndarray:
    """The three published figures (N), in :func:`scale_figures`' order."""
    table = published_table(SCALE_TABLE)
    return np.array([table.value(row, SCALE_COLUMN).low for row in table.rows])


def fitted_values(device: DeviceSpec) -> np.ndarray:
    """The device's values of :data:`FITTED`."""
    return np.array([device.value(key) for key in FITTED])


def with_values(device: DeviceSpec, values) -> DeviceSpec:
    """``device`` with :data:`FITTED` set to ``values`` (validated as a device file is)."""
    return device.with_values(FITTED, values)


@dataclass(frozen=True)
class ScaleFigures:
    """Per seed, the three figures (seeds, 3) in N: the targets' mean |F| on the FS, the standard
    method's mean |F| rendered to the small sphere and to the largest human cast; and each figure's
    per-target standard deviation (seeds, 3)."""

    per_seed: np.ndarray
    spread: np.ndarray

    @property
    def mean(self) -> np.ndarray:
        return self.per_seed.mean(axis=0)

    def standard_error(self, targets: int = PUBLISHED_TARGETS) -> np.ndarray:
        """The standard error (N) of a mean over ``targets`` targets, from the twin's per-target spread."""
        return np.sqrt(np.mean(self.spread**2, axis=0) / targets)


def scale_figures(device: DeviceSpec, seeds=FIT_SEEDS, targets: int = FIT_TARGETS,
                  settings: StudySettings = StudySettings(),
                  collection: CollectionSettings = CollectionSettings()) -> ScaleFigures:
    """The three scale figures of ``device`` over ``seeds``: the study's FS table and ``targets``
    targets of each seed, every target rendered by the standard method to the two fingertips."""
    settings = replace(settings, targets=checked(integer(2), "targets", targets),
                       target_draws=max(settings.target_draws, 50 * targets))
    renderer = NearestNeighbourRenderer(settings.n_neighbours, settings.contact_threshold, settings.weighting_power)
    per_seed, spread = [], []
    for seed in seeds:
        fs = fs_table(device, settings.fs_levels, collection, seed)
        wanted = record_targets(device, settings, collection, seed)
        commands = renderer.fit(fs.finger_wrenches, fs.motor_inputs).render(wanted).motor_inputs
        rng = np.random.default_rng([seed, _RENDER_STREAM])
        magnitudes = [np.linalg.norm(wanted[:, :3], axis=1)]
        for fingertip in (SMALL_SPHERE, LARGEST_HUMAN):
            produced, _ = sensed_by_fingertip(device, fingertip, commands, collection, rng)
            magnitudes.append(np.linalg.norm(produced[:, :3], axis=1))
        per_seed.append([m.mean() for m in magnitudes])
        spread.append([m.std(ddof=1) for m in magnitudes])
    return ScaleFigures(np.array(per_seed), np.array(spread))


@dataclass(frozen=True)
class DeviceFit:
    """The fitted values of :data:`FITTED` with their covariance, the figures they give and the
    published ones (N), each figure's standard error, and the optimiser's count of evaluations."""

    values: np.ndarray
    covariance: np.ndarray
    figures: np.ndarray
    published: np.ndarray
    figure_errors: np.ndarray  # N: the standard error of a 100-target mean, each figure
    evaluations: int

    @property
    def standard_errors(self) -> np.ndarray:
        return np.sqrt(np.diag(self.covariance))

    @property
    def correlation(self) -> np.ndarray:
        return self.covariance / np.outer(self.standard_errors, self.standard_errors)

    @property
    def residuals(self) -> np.ndarray:
        """figure − published (N)."""
        return self.figures - self.published


def fit_device(device: DeviceSpec, seeds=FIT_SEEDS, targets: int = FIT_TARGETS,
               settings: StudySettings = StudySettings(), collection: CollectionSettings = CollectionSettings(),
               published: np.ndarray | None = None, progress: Progress = SILENT) -> DeviceFit:
    """:data:`FITTED` of ``device`` (its values the start) fitted to ``published`` (the publication's
    scale by default) by scipy's trust-region least squares; raises :class:`NotConverged` when the
    optimiser stops without meeting its tolerances or leaves a residual beyond two standard errors."""
    from scipy.optimize import least_squares

    published = published_scale() if published is None else np.asarray(published, dtype=float)
    start = fitted_values(device)
    figure_errors = scale_figures(device, seeds, targets, settings, collection).standard_error()
    with progress.task("device fit", total=None) as task:

        def residuals(scaled):
            task.advance()
            try:
                candidate = with_values(device, scaled * start)
            except ValueError:  # a released length the device file refuses: far from the fit
                return np.full(3, 1e3)
            return (scale_figures(candidate, seeds, targets, settings, collection).mean - published) / figure_errors

        # the parameters scaled by their start; steps of 1 % so that a target crossing the contact
        # threshold does not dominate the finite differences
        found = least_squares(residuals, np.ones(3), diff_step=1e-2, bounds=([0.5, 0.25, 0.01], [1.5, 4.0, 100.0]),
                              x_scale=1.0, xtol=1e-6, ftol=1e-8, max_nfev=200)
    if not found.success or np.max(np.abs(found.fun)) > 2.0:
        raise NotConverged(f"device fit: {found.message}; residuals {np.round(found.fun, 2).tolist()} standard errors "
                           f"after {found.nfev} evaluations")
    values = found.x * start
    # the parameters' covariance: the weighted residuals' Jacobian (in scaled units) at the solution
    covariance = np.linalg.inv(found.jac.T @ found.jac) * np.outer(start, start)
    figures = scale_figures(with_values(device, values), seeds, targets, settings, collection).mean
    return DeviceFit(values, covariance, figures, published, figure_errors, int(found.nfev))


def principal_moves(covariance, sigmas: float = 1.0) -> list[np.ndarray]:
    """Moves of the fitted values ``sigmas`` standard deviations down and up each principal axis of
    their correlation (so that the axes do not depend on the values' units), largest first: the
    devices the published figures cannot tell from the fitted one. Their second moment, summed, is
    twice the ``covariance`` times ``sigmas``²."""
    covariance = np.asarray(covariance, dtype=float)
    errors = np.sqrt(np.diag(covariance))
    variances, axes = np.linalg.eigh(covariance / np.outer(errors, errors))
    order = np.argsort(variances)[::-1]
    return [sign * sigmas * np.sqrt(max(variances[k], 0.0)) * errors * axes[:, k]
            for k in order for sign in (-1.0, 1.0)]
