"""Brushing the die across a rough surface: the surfaces, the voltage trace, its AC rms, and a classifier.

The surfaces (as the S4 spec states them): atomically flat silicon (0 µm) and sandpapers P1000, P320 and
P100, published as 18.3, 46.2 and 162 µm rms roughness. Those three figures equal the grits' standard
average grain sizes, so softtip reads each as both: a Gaussian random height profile along the brushing
direction whose rms is the published figure and whose correlation length (Gaussian autocorrelation) is the
same figure, the grain size — bumps one grain wide. Silicon is flat: its trace is the noise floor.

The brush: the die is held ``engagement`` past first contact (balance mode: the plate is the surface) and
moved at ``speed``; each pillar's tip rides the surface under it, so its engagement is the nominal one
plus the local height (a tip over a valley deeper than the engagement leaves the surface). The voltage is
the balance-mode curve's at each pillar's engagement, the pillars' changes added up (each pillar's field
adds to the others'; the bend of one does not move another).

The readout is the publication's: 100 µA through the meander and the HP 34401A across it
(:class:`softtip.sensors.gmr.Voltmeter`) on the range the ~18.7 V needs (100 V), set to the longest
integration that gives the sampling rate (1 power-line cycle at 50 readings/s), with that setting's
resolution and noise. A reading integrates the die's travel over its integration time: a fast stage or a
slow rate averages grains away. A bridge (the rest voltage taken off before the meter, so it reads on its
0.1 V range) is softtip's addition, off unless asked, and compared in the report.

The slope is fitted two ways, each with 95 % intervals (Student's t with the residual degrees of freedom):
as the publication fits it, a straight line with intercept through the four surfaces' AC rms against their
roughness, and softtip's way, through the origin of the rough surfaces' rms above the flat one's floor
(removed in quadrature: noise and signal add as powers). The AC rms is the readings' rms about their
linear trend: a measured trace drifts (the spin valves warm, the stage is not level), and that drift is no
roughness.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from softtip._core.units import MM, UM
from softtip.mechanics.rod import PlateContact
from softtip.sensors.gmr import ConstantCurrentReadout
from softtip.systems.cilia.layout import DieError
from softtip.systems.cilia.model import CiliaModel

BRUSH_SPACING_MM = 2e-3  # the profiles' sampling (mm), a ninth of the finest grain
SPACING = BRUSH_SPACING_MM * MM  # m
SURFACES = {"silicon": 0.0, "P1000": 18.3 * UM, "P320": 46.2 * UM, "P100": 162.0 * UM}  # rms = grain size, m


def surface_profile(rms: float, correlation: float, length: float, spacing: float,
                    rng: np.random.Generator) -> NDArray[np.float64]:
    """Heights (m) every ``spacing`` over ``length`` of a Gaussian random profile with a Gaussian
    autocorrelation of length ``correlation`` (its spectrum ∝ exp(−(k ℓ)²/4)), scaled to ``rms`` exactly;
    all zero when ``rms`` is 0."""
    for name, value in (("length", length), ("spacing", spacing)):
        if not (math.isfinite(value) and value > 0):
            raise DieError(f"{name} = {value!r}: expected a positive length in m")
    if not (math.isfinite(rms) and rms >= 0):
        raise DieError(f"rms = {rms!r}: expected a roughness >= 0 m")
    count = int(math.ceil(length / spacing)) + 1
    if rms == 0:
        return np.zeros(count)
    if not (math.isfinite(correlation) and correlation >= 2 * spacing):
        raise DieError(f"correlation = {correlation!r}: expected at least two samples ({2 * spacing:g} m) per grain")
    k = 2 * np.pi * np.fft.rfftfreq(count, spacing)
    amplitude = np.exp(-(k * correlation) ** 2 / 8)  # the square root of the spectrum
    heights = np.fft.irfft(np.fft.rfft(rng.standard_normal(count)) * amplitude, count)
    heights -= heights.mean()
    return heights * (rms / heights.std())


@dataclass(frozen=True)
class Brush:
    """The die's response to its engagement: the balance-mode voltage change of one sensor and the vertical
    force on the plate against the descent past first contact (``descent`` m ascending from 0, ``change`` V
    and ``force`` N of all pillars together); ``rest`` the sensor's voltage at zero force (V)."""

    model: CiliaModel
    sensor: str
    descent: NDArray[np.float64]
    change: NDArray[np.float64]
    force: NDArray[np.float64]
    rest: float

    @classmethod
    def of(cls, model: CiliaModel, sensor: str = "X", contact: PlateContact = PlateContact(),
           points: int = 60) -> Brush:
        return cls.each(model, (sensor,), contact, points)[0]

    @classmethod
    def each(cls, model: CiliaModel, sensors: tuple[str, ...], contact: PlateContact = PlateContact(),
             points: int = 60) -> tuple[Brush, ...]:
        """:meth:`of` each of ``sensors``: the plate lowered once for all."""
        rod = model.die.pillars.rod
        descent = np.linspace(0.0, 0.7 * rod.length, points)
        curves = model.balance_curves(descent, contact, sensors)
        return tuple(cls(model, curve.sensor, descent, curve.change, curve.force, model.rest_volts(curve.sensor))
                     for curve in curves)

    def trace(self, heights: NDArray, spacing: float, engagement: float) -> NDArray[np.float64]:
        """The noise-free voltage change (V) at each position of the die along a profile of ``heights``
        every ``spacing`` (m), each pillar over its own point of the surface."""
        return self._shares(self.change, heights, spacing, engagement)

    def load(self, heights: NDArray, spacing: float, engagement: float) -> NDArray[np.float64]:
        """The vertical force (N) on the surface at each position, as :meth:`trace`."""
        return self._shares(self.force, heights, spacing, engagement)

    def _shares(self, values: NDArray, heights: NDArray, spacing: float, engagement: float) -> NDArray[np.float64]:
        if not 0 < engagement < self.descent[-1]:
            raise DieError(f"engagement = {engagement!r}: expected a descent past first contact within "
                           f"(0, {self.descent[-1]:.4g}) m")
        offsets = np.rint(self.model.die.pillars.positions[:, 0] / spacing).astype(int)
        offsets -= offsets.min()
        span = heights.size - offsets.max()
        if span < 2:
            raise DieError("heights: the profile is shorter than the pillars' spread along it")
        under = np.stack([heights[o:o + span] for o in offsets])  # (P, positions)
        local = np.clip(engagement + under, 0.0, self.descent[-1])  # off the surface: at rest
        # one pillar's share of the die's value at its own engagement; the shares add
        return (np.interp(local, self.descent, values) / len(offsets)).sum(axis=0)


def _check_motion(speed: float, rate: float) -> None:
    for name, value in (("speed", speed), ("rate", rate)):
        if not (math.isfinite(value) and value > 0):
            raise DieError(f"{name} = {value!r}: expected a positive number")


def _per_reading(trace: NDArray, spacing: float, speed: float, rate: float,
                 aperture: float | None = None) -> NDArray[np.float64]:
    """``trace`` (one value every ``spacing`` of travel) averaged over each reading: a reading every
    1/``rate`` at ``speed``, integrating over ``aperture`` s from its start (default: the whole interval);
    whole readings only."""
    _check_motion(speed, rate)
    per_reading = speed / rate / spacing  # profile samples the die crosses per reading
    if per_reading < 1:
        raise DieError(f"spacing = {spacing!r}: expected a profile finer than one reading's travel "
                       f"({speed / rate:.3g} m)")
    edges = np.arange(0.0, trace.size, per_reading).astype(int)
    if edges.size < 3:
        raise DieError("the profile holds fewer than 3 readings at this speed and rate")
    starts = edges[:-1]
    span = 1.0 if aperture is None else min(1.0, aperture * rate)  # the share of an interval integrated
    ends = np.maximum(starts + 1, starts + np.rint(span * np.diff(edges)).astype(int))
    total = np.concatenate([[0.0], np.cumsum(trace)])
    return (total[ends] - total[starts]) / (ends - starts)


def brushing_readout(brush: Brush, rate: float, bridge: bool = False) -> ConstantCurrentReadout:
    """The sensor's readout with its meter set for ``rate`` readings/s (the longest integration that gives
    it) and, with ``bridge``, the rest voltage taken off before the meter."""
    readout = brush.model.die.meander(brush.sensor).readout
    return replace(readout, offset=brush.rest if bridge else 0.0, voltmeter=readout.voltmeter.at_rate(rate))


def read_brushing(brush: Brush, heights: NDArray, spacing: float, engagement: float, speed: float, rate: float,
                  rng: np.random.Generator, bridge: bool = False) -> NDArray[np.float64]:
    """Readings (V, the change from the rest voltage) of a brushing at ``speed`` (m/s) sampled at ``rate``
    (Hz): each the meter's average over its integration time (:func:`brushing_readout`), with the readout's
    noise at that setting, quantised on the range the voltage needs (with ``bridge``: the change's)."""
    _check_motion(speed, rate)
    readout = brushing_readout(brush, rate, bridge)
    averaged = _per_reading(brush.trace(heights, spacing, engagement), spacing, speed, rate,
                            readout.voltmeter.integration_time)
    return readout.read(brush.rest + averaged, rng) + readout.offset - brush.rest


def ac_rms(readings: NDArray) -> float:
    """rms of the AC part: the readings less their linear trend (a drift is no roughness)."""
    return float(np.std(signal.detrend(readings)))


@dataclass(frozen=True)
class LineFit:
    """A least-squares straight line y = slope·x + intercept (through the origin: intercept 0, no interval)
    with 95 % intervals (Student's t with ``dof`` = n − parameters residual degrees of freedom)."""

    slope: float
    slope_interval: tuple[float, float]
    intercept: float
    intercept_interval: tuple[float, float] | None
    dof: int

    def to_dict(self, x_unit: float, y_unit: float) -> dict:
        """In the units ``x_unit`` and ``y_unit`` (SI values per unit): slope in y per x."""
        scale = x_unit / y_unit
        return {"slope": self.slope * scale, "slope_interval": [v * scale for v in self.slope_interval],
                "intercept": self.intercept / y_unit,
                "intercept_interval": None if self.intercept_interval is None
                else [v / y_unit for v in self.intercept_interval], "degrees_of_freedom": self.dof}


def fit_line(x: NDArray, y: NDArray, through_origin: bool = False) -> LineFit:
    """The least-squares line through the points (``x``, ``y``), with or without an intercept; it needs one
    more point than it has parameters (for the intervals)."""
    from scipy import stats

    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    design = x[:, None] if through_origin else np.column_stack([x, np.ones_like(x)])
    dof = x.size - design.shape[1]
    if x.shape != y.shape or x.ndim != 1 or dof < 1 or np.ptp(x) == 0:
        raise DieError(f"a line fit: expected at least {design.shape[1] + 1} points at two or more roughnesses, "
                       f"got {x.size}")
    coefficients, *_ = np.linalg.lstsq(design, y, rcond=None)
    residual = y - design @ coefficients
    covariance = residual @ residual / dof * np.linalg.inv(design.T @ design)
    half = float(stats.t.ppf(0.975, dof)) * np.sqrt(np.diag(covariance))
    bounds = [(float(c - h), float(c + h)) for c, h in zip(coefficients, half)]
    return LineFit(float(coefficients[0]), bounds[0], 0.0 if through_origin else float(coefficients[1]),
                   None if through_origin else bounds[1], int(dof))


def window_features(readings: NDArray, window: int, rate: float) -> NDArray[np.float64]:
    """(W, 5) features of consecutive windows of ``window`` readings: log AC rms, log rms of the
    reading-to-reading difference, and the log shares of power in three bands (below 5 %, 5–20 %, above
    20 % of the rate) of each window's periodogram."""
    if window < 8 or readings.size < window:
        raise DieError(f"window = {window!r}: expected at least 8 readings and no more than the {readings.size} held")
    rows = readings[: readings.size // window * window].reshape(-1, window)
    ac = signal.detrend(rows, axis=1)
    frequency, power = signal.periodogram(ac, fs=rate, axis=1)
    total = power.sum(axis=1) + 1e-300
    bands = [(frequency < 0.05 * rate), (frequency >= 0.05 * rate) & (frequency < 0.2 * rate),
             (frequency >= 0.2 * rate)]
    shares = np.stack([power[:, band].sum(axis=1) / total for band in bands], axis=1)
    tiny = 1e-12
    return np.column_stack([np.log(ac.std(axis=1) + tiny), np.log(np.diff(rows, axis=1).std(axis=1) + tiny),
                            np.log(shares + 1e-6)])


@dataclass(frozen=True)
class Recording:
    """One brushing: its surface and that surface's rms roughness (m), which strip of it (the same strip is
    brushed at every speed and rate), the stage speed (m/s), the sampling rate (Hz) and the readings (V)."""

    surface: str
    roughness: float
    strip: int
    speed: float
    rate: float
    readings: NDArray[np.float64]


@dataclass(frozen=True)
class Classification:
    """Accuracy of telling the surfaces apart from windows, where the recordings allow it: split by strip
    (every recording of a strip held out together; needs two strips of every surface), and trained on every
    speed but ``held_speed`` and tested on it (needs two speeds of every surface); the confusion matrices
    (rows: true, columns: predicted, in ``surfaces`` order). A validation the data do not allow is None, and
    ``missing`` says why."""

    surfaces: tuple[str, ...]
    windows: int
    by_strip: float | None
    confusion_by_strip: NDArray[np.int64] | None
    held_speed: float | None
    at_held_speed: float | None
    confusion_at_held_speed: NDArray[np.int64] | None
    missing: tuple[str, ...]

    def to_dict(self) -> dict:
        def matrix(values: NDArray | None) -> list | None:
            return None if values is None else values.tolist()

        return {"windows": self.windows, "accuracy_by_strip": self.by_strip,
                "confusion_by_strip": matrix(self.confusion_by_strip),
                "held_speed_mm_s": None if self.held_speed is None else self.held_speed / MM,
                "accuracy_at_held_speed": self.at_held_speed,
                "confusion_at_held_speed": matrix(self.confusion_at_held_speed), "not_validated": list(self.missing)}


def classify(recordings: list[Recording], window: int, rate: float, seed: int) -> Classification:
    """A random forest (scikit-learn) on :func:`window_features`, validated by strip (grouped folds: no
    strip gives windows to both sides, whatever the speed it was brushed at) and on the fastest speed held
    out, each where the recordings allow it."""
    from sklearn.ensemble import RandomForestClassifier
    from sklearn.metrics import confusion_matrix
    from sklearn.model_selection import GroupKFold, cross_val_predict

    surfaces = tuple(dict.fromkeys(r.surface for r in sorted(recordings, key=lambda r: r.roughness)))
    if len(surfaces) < 2:
        raise DieError("recordings: expected at least two surfaces to tell apart")
    features, labels, strips, speeds = [], [], [], []
    for recording in recordings:
        rows = window_features(recording.readings, window, rate)
        features.append(rows)
        labels += [recording.surface] * len(rows)
        strips += [recording.strip] * len(rows)
        speeds += [recording.speed] * len(rows)
    x, y, strips, speeds = np.concatenate(features), np.array(labels), np.array(strips), np.array(speeds)
    forest = RandomForestClassifier(n_estimators=100, random_state=seed)
    missing = []
    fewest_strips = min(len(set(strips[y == name])) for name in surfaces)
    by_strip = confusion_by_strip = None
    if fewest_strips >= 2:
        predicted = cross_val_predict(forest, x, y, groups=strips, cv=GroupKFold(n_splits=min(3, len(set(strips)))))
        by_strip, confusion_by_strip = float(np.mean(predicted == y)), confusion_matrix(y, predicted, labels=surfaces)
    else:
        missing.append("by strip: a surface was brushed on one strip only (two or more of each are needed)")
    held = float(max(speeds))
    train = speeds != held
    at_held = confusion_at_held = None
    if all(len(set(speeds[y == name])) >= 2 and np.any(~train & (y == name)) for name in surfaces):
        forest.fit(x[train], y[train])
        guessed = forest.predict(x[~train])
        at_held, confusion_at_held = (float(np.mean(guessed == y[~train])),
                                      confusion_matrix(y[~train], guessed, labels=surfaces))
    else:
        missing.append("at a held-out speed: a surface was brushed at one speed only (two or more of each, the "
                       "fastest among them, are needed)")
    return Classification(surfaces, int(len(y)), by_strip, confusion_by_strip,
                          held if at_held is not None else None, at_held, confusion_at_held, tuple(missing))


@dataclass(frozen=True)
class Brushing:
    """One brushing as the lab records it: the :class:`Recording` of the die's first sensor, every sensor's
    readings (V, in the die's order) and the vertical force on the surface (N, averaged over each reading)."""

    recording: Recording
    readings: tuple[NDArray[np.float64], ...]
    force: NDArray[np.float64]


def brush_surfaces(model: CiliaModel, contact: PlateContact, engagement: float, length: float, speed: float,
                   rate: float, speeds: tuple[float, ...], rates: tuple[float, ...], strips: int,
                   rng: np.random.Generator, bridge: bool = False) -> list[Brushing]:
    """The four surfaces brushed ``engagement`` (m) past first contact over ``length`` (m), ``strips``
    strips of each: every strip at ``speed`` and at every one of ``speeds`` (m/s), at ``rate`` (Hz), and the
    first strip at ``speed`` at every one of ``rates`` (each recording once), by every sensor of the die;
    read as published, or with ``bridge`` through a bridge."""
    brushes = Brush.each(model, tuple(m.name for m in model.die.meanders), contact)
    plan = dict.fromkeys([(strip, s, rate) for strip in range(strips) for s in (speed, *speeds)]
                         + [(0, speed, r) for r in rates])
    brushings = []
    for name, rms in SURFACES.items():
        profiles = [surface_profile(rms, max(rms, 2 * SPACING), length, SPACING, rng) for _ in range(strips)]
        for strip, s, r in plan:
            heights = profiles[strip]
            readings = tuple(read_brushing(brush, heights, SPACING, engagement, s, r, rng, bridge) for brush in brushes)
            force = _per_reading(brushes[0].load(heights, SPACING, engagement), SPACING, s, r)
            brushings.append(Brushing(Recording(name, rms, strip, s, r, readings[0]), readings, force))
    return brushings


@dataclass(frozen=True)
class RoughnessStudy:
    """The brushing experiment: per surface the AC rms (V) at the nominal speed and rate (mean over its
    strips) and with the flat surface's floor removed in quadrature, the floor; the slope as published
    (a line with intercept through every surface's AC rms against its roughness, V/m) and softtip's (through
    the origin of the rough surfaces' rms above the floor); the AC rms of every surface against the sampling
    rate at the nominal speed, and against the stage speed (m/s) at the nominal rate (mean over the
    strips); the classifier on the recordings at the nominal rate (None, with the reason in ``unclassified``,
    when they cannot train one)."""

    surfaces: tuple[str, ...]
    roughness: NDArray[np.float64]
    total_rms: NDArray[np.float64]
    above_floor: NDArray[np.float64]
    floor: float
    published_fit: LineFit | None
    origin_fit: LineFit | None
    rates: NDArray[np.float64]
    rms_by_rate: NDArray[np.float64]  # (surfaces, rates)
    speeds: NDArray[np.float64]
    rms_by_speed: NDArray[np.float64]  # (surfaces, speeds)
    classification: Classification | None
    unclassified: str
    recordings: int

    def to_dict(self) -> dict:
        """The study in the units the reports print (µm, µV, mm/s)."""
        def line(fit: LineFit | None) -> dict | None:  # slopes in µV per µm
            return None if fit is None else fit.to_dict(UM, 1e-6)

        return {"recordings": self.recordings, "surfaces": list(self.surfaces),
                "roughness_um": (self.roughness / UM).tolist(), "ac_rms_uV": (self.total_rms * 1e6).tolist(),
                "above_floor_uV": (self.above_floor * 1e6).tolist(), "floor_uV": self.floor * 1e6,
                "slope_as_published_uV_per_um": line(self.published_fit),
                "slope_through_origin_uV_per_um": line(self.origin_fit), "rates_hz": self.rates.tolist(),
                "ac_rms_by_rate_uV": (self.rms_by_rate * 1e6).tolist(), "speeds_mm_s": (self.speeds / MM).tolist(),
                "ac_rms_by_speed_uV": (self.rms_by_speed * 1e6).tolist(),
                "classification": None if self.classification is None else self.classification.to_dict(),
                "unclassified": self.unclassified}


def analyse_roughness(recordings: list[Recording], speed: float, rate: float, seed: int,
                      classifier: bool = True) -> RoughnessStudy:
    """The roughness study of brushing ``recordings`` (a lab dataset's or a table's): the level at ``speed``
    (m/s) and ``rate`` (Hz), the rate curve at ``speed``, the speed curve at ``rate``, and unless
    ``classifier`` is False the classifier at ``rate`` in windows of one second where the recordings allow
    one. The surfaces in order of roughness; the smoothest must be flat (roughness 0: the floor)."""
    if not recordings:
        raise DieError("recordings: expected brushing recordings, found none")
    order = sorted({(r.roughness, r.surface) for r in recordings})
    names = tuple(name for _, name in order)
    if len(names) != len({r.surface for r in recordings}):
        raise DieError("recordings: expected one roughness per surface")
    if order[0][0] != 0:
        raise DieError(f"recordings: expected a flat surface (roughness 0) for the floor; the smoothest is "
                       f"{order[0][1]} at {order[0][0]:g} m")

    def close(a: float, b: float) -> bool:
        return math.isclose(a, b, rel_tol=1e-9)

    def level(name: str, s: float, r: float) -> float:
        found = [ac_rms(x.readings) for x in recordings if x.surface == name and close(x.speed, s) and close(x.rate, r)]
        if not found:
            raise DieError(f"recordings: no brushing of {name} at {s / MM:g} mm/s and {r:g} readings/s")
        return float(np.mean(found))

    total = np.array([level(name, speed, rate) for name in names])
    floor = float(total[0])
    above = np.sqrt(np.clip(total**2 - floor**2, 0.0, None))
    roughness = np.array([value for value, _ in order])
    published = fit_line(roughness, total) if len(names) >= 3 else None
    origin = fit_line(roughness[1:], above[1:], through_origin=True) if len(names) >= 3 else None
    rates = np.array(sorted({x.rate for x in recordings if close(x.speed, speed)}))
    by_rate = np.array([[level(name, speed, r) for r in rates] for name in names])
    at_rate = [x for x in recordings if close(x.rate, rate)]
    speeds = np.array(sorted({x.speed for x in at_rate}))
    by_speed = np.array([[level(name, s, rate) for s in speeds] for name in names])
    window = max(8, int(round(rate)))
    short = [x for x in at_rate if x.readings.size < window]
    classification, unclassified = None, ""
    if not classifier:
        unclassified = "no classifier asked for"
    elif len(names) < 2:
        unclassified = "one surface only: nothing to tell apart"
    elif short:
        unclassified = (f"{short[0].surface}, strip {short[0].strip}: {short[0].readings.size} readings, fewer than "
                        f"one second's window of {window}")
    else:
        classification = classify(at_rate, window, rate, seed)
        if classification.by_strip is None and classification.at_held_speed is None:
            classification, unclassified = None, "; ".join(classification.missing)
    return RoughnessStudy(names, roughness, total, above, floor, published, origin, rates, by_rate, speeds, by_speed,
                          classification, unclassified, len(recordings))


def readout_levels(model: CiliaModel, contact: PlateContact, engagement: float, length: float, speed: float,
                   rate: float, strips: int, seed: int, bridge: bool) -> RoughnessStudy:
    """The levels and slopes alone (``strips`` strips of each surface at ``speed`` and ``rate``, no
    classifier), read with or without a ``bridge``: at one ``seed`` both readouts brush the same profiles."""
    brushings = brush_surfaces(model, contact, engagement, length, speed, rate, (), (), strips,
                               np.random.default_rng(seed), bridge)
    return analyse_roughness([b.recording for b in brushings], speed, rate, seed, classifier=False)
