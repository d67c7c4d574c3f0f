"""Fitting the pillars' moment and diameter to a measured force–voltage curve, with honest uncertainties.

As published, the pillars' height and Young's modulus are held and their magnetic moment and diameter are
fitted (the diameter is the tip's; the base keeps the die's taper ratio) by least squares on the voltage
change (scipy's trust-region reflective method, in log parameters so both stay positive). Uncertainties:

* the covariance s²(JᵀJ)⁻¹ at the optimum (s² = RSS/(n − 2)), its 95 % intervals (Student t) and the
  parameters' correlation;
* profile likelihoods: for each diameter on a grid the best moment, and for each moment the best diameter
  (from the same grid), and the 95 % likelihood-ratio intervals n ln(RSS/RSS_min) ≤ χ²₁(0.95) (Gaussian
  noise of unknown variance); an interval that reaches the grid's edge is open there (None).

What the curve identifies: while the pillars bend little, the voltage change is linear in the force with a
slope ∝ moment × compliance ∝ moment / diameter⁴ (the bending stiffness), so the linear part fixes only
that ratio (the log parameters are then almost perfectly correlated, +1); the saturating part, where the
shape stops following the force, depends on the diameter through the load at which the pillars turn over,
and separates the two. :func:`identifiability` fits both parts and says so in numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import optimize, stats

from softtip._core.errors import NotConverged
from softtip.systems.cilia.layout import DieError
from softtip.systems.cilia.model import CiliaModel

CHI2_95 = float(stats.chi2.ppf(0.95, 1))  # 3.841: one parameter's 95 % likelihood-ratio threshold
SECANT_SPAN = 0.05  # log units: the fit's diameter derivative is a secant through a curve kept this near
SECANT_FLOOR = 1e-7  # and at least this far


class CurveError(DieError):
    """A measured curve that cannot be fitted."""


@dataclass(frozen=True)
class MeasuredCurve:
    """A force–voltage curve: total forces (N, ≥ 0) and the voltage change from zero force (V)."""

    force: NDArray[np.float64]
    change: NDArray[np.float64]
    sensor: str = "X"

    def __post_init__(self) -> None:
        force = np.asarray(self.force, dtype=np.float64)
        change = np.asarray(self.change, dtype=np.float64)
        if force.ndim != 1 or force.shape != change.shape:
            raise CurveError(f"curve: expected forces and voltages of one 1-D shape, got {force.shape} and {change.shape}")
        if not (np.all(np.isfinite(force)) and np.all(np.isfinite(change))):
            raise CurveError("curve: expected finite forces and voltages (no NaN)")
        if force.size < 3:
            raise CurveError(f"curve: expected at least 3 points for 2 parameters, got {force.size}")
        if np.any(force < 0):
            raise CurveError("curve: expected forces >= 0 N")
        object.__setattr__(self, "force", force)
        object.__setattr__(self, "change", change)

    def part(self, keep: NDArray[np.bool_]) -> MeasuredCurve:
        return MeasuredCurve(self.force[keep], self.change[keep], self.sensor)


class CurveModel:
    """Predicted voltage changes at a curve's forces for any moment and diameter. The element fields are
    linear in the moment, so they are computed once per diameter (and kept) and rescaled."""

    def __init__(self, model: CiliaModel, force: ArrayLike, sensor: str):
        self.model, self.sensor = model, sensor
        self.force = np.asarray(force, dtype=np.float64)
        self._loads = np.concatenate([[0.0], self.force])
        self._fields: dict[float, NDArray[np.float64]] = {}
        model.die.meander(sensor)  # an unknown sensor is refused here

    def unit_fields(self, diameter: float) -> NDArray[np.float64]:
        """(1 + N, n) element fields per unit moment at zero force and at each force."""
        key = float(diameter)
        if key not in self._fields:
            die = self.model.die
            resized = replace(self.model, die=die.with_pillars(die.pillars.with_diameter(key)))
            self._fields[key] = resized.unit_fields(resized.shapes(self._loads), self.sensor)
        return self._fields[key]

    def predict(self, moment: float, diameter: float) -> NDArray[np.float64]:
        """(N,) voltage changes for pillars of ``moment`` (A·m², magnitude) and tip ``diameter`` (m)."""
        volts = self.model.volts(moment * self.unit_fields(diameter), self.sensor)
        return volts[1:] - volts[0]

    def jacobian(self, log_parameters: NDArray, secant_span: float = 0.0) -> NDArray[np.float64]:
        """(N, 2) derivatives of :meth:`predict` in the log moment and the log diameter at
        ``log_parameters``, by forward differences of relative size 1e-5 (scipy's ``diff_step`` in
        ``least_squares``). The moment's costs nothing (the fields at this diameter are kept). With
        ``secant_span`` > 0 the diameter's is the secant through the nearest diameter already computed when
        that one lies within ``secant_span`` in log units and beyond 1e-7 (where the rods' 1e-10 tolerance
        is still a thousandth of the difference): no new curve."""
        steps = 1e-5 * np.maximum(1.0, np.abs(log_parameters))
        moment, diameter = np.exp(log_parameters)
        here = self.predict(moment, diameter)
        by_moment = (self.predict(moment * math.exp(steps[0]), diameter) - here) / steps[0]
        gaps = [math.log(known / diameter) for known in self._fields if known != diameter]
        nearest = min(gaps, key=abs, default=math.inf)
        step = nearest if SECANT_FLOOR <= abs(nearest) <= secant_span else steps[1]
        by_diameter = (self.predict(moment, diameter * math.exp(step)) - here) / step
        return np.stack([by_moment, by_diameter], axis=-1)


@dataclass(frozen=True)
class Profile:
    """A profile likelihood: ``values`` of one parameter, the residual sum of squares with the other at
    its best, and the 95 % likelihood-ratio interval (None where it reaches the grid's edge)."""

    values: NDArray[np.float64]
    rss: NDArray[np.float64]
    interval: tuple[float | None, float | None]


@dataclass(frozen=True)
class CurveFit:
    """A fit of moment (A·m², per pillar) and tip diameter (m) to a curve.

    ``interval_*``: 95 % Wald intervals from the covariance (in log parameters, so asymmetric);
    ``correlation``: of the log parameters; ``ratio``: moment / diameter⁴ (A·m² per m⁴, what the linear part
    identifies) and its 95 % interval; ``noise``: the residuals' rms (V)."""

    moment: float
    diameter: float
    interval_moment: tuple[float, float]
    interval_diameter: tuple[float, float]
    correlation: float
    ratio: float
    interval_ratio: tuple[float, float]
    noise: float
    points: int
    evaluations: int
    at_bound: bool  # a parameter ended on its bound: the curve does not hold it, its interval means little
    prediction: NDArray[np.float64] = field(repr=False)


def fit_curve(model: CiliaModel, curve: MeasuredCurve, start: tuple[float, float] = (2.8e-6, 200e-6),
              cache: CurveModel | None = None) -> CurveFit:
    """Least-squares fit of the pillars' moment and tip diameter to ``curve`` (paper-mode ``model``, height
    and modulus held). ``start``: (moment A·m², diameter m). Raises :class:`NotConverged` if the solver
    stops without meeting its tolerances."""
    if not (len(start) == 2 and all(math.isfinite(v) and v > 0 for v in start)):
        raise CurveError(f"start = {start!r}: expected a positive (moment, diameter)")
    predictor = cache or CurveModel(model, curve.force, curve.sensor)

    def residual(log_parameters: NDArray) -> NDArray:
        moment, diameter = np.exp(log_parameters)
        return predictor.predict(moment, diameter) - curve.change

    # moments from 1 nA·m² to 1 mA·m²; tip diameters from 2 % of the height to where the base (taper kept)
    # would be half the height: the pillar stays a rod
    rod = model.die.pillars.rod
    taper = rod.base_diameter / rod.tip_diameter
    bounds = (np.log([1e-9, 0.02 * rod.length]), np.log([1e-3, 0.5 * rod.length / max(taper, 1.0)]))
    # every new diameter costs a curve (rods and fields); the moment's derivative costs none: on the way the
    # diameter's is a secant through the last diameters computed (a Broyden-like update), and at the
    # optimum a forward difference, for the covariance. Tolerances: a step under 1e-7 of the log parameters'
    # norm (~1.5e-6 relative) or a cost changing by under 1e-9 ends it, a thousandth of a 95 % interval's width
    # on the bench's curve: tighter ones took twice the curves to move the figures by under 1e-5
    solved = optimize.least_squares(residual, np.log(start), jac=lambda x: predictor.jacobian(x, SECANT_SPAN),
                                    bounds=bounds, method="trf", x_scale=1.0, xtol=1e-7, ftol=1e-9, gtol=1e-9,
                                    max_nfev=200)
    if solved.status <= 0:
        raise NotConverged(f"fit: least squares stopped without converging ({solved.message})")
    on_bound = np.isclose(solved.x, bounds[0], atol=1e-6) | np.isclose(solved.x, bounds[1], atol=1e-6)
    fit = _summary(solved.x, solved.fun, predictor.jacobian(solved.x), curve, solved.nfev, bool(np.any(on_bound)))
    # a fit that runs towards a bound stops short of it by the tolerances: its 95 % interval then reaches the
    # bound, and the curve does not hold that parameter either
    low, high = np.exp(bounds[0]), np.exp(bounds[1])
    reaches = [interval[0] <= low[index] or interval[1] >= high[index]
               for index, interval in enumerate((fit.interval_moment, fit.interval_diameter))]
    return replace(fit, at_bound=fit.at_bound or any(reaches))


def _summary(log_parameters: NDArray, residuals: NDArray, jacobian: NDArray, curve: MeasuredCurve,
             evaluations: int, at_bound: bool) -> CurveFit:
    points = curve.force.size
    dof = points - 2
    rss = float(residuals @ residuals)
    variance = rss / dof if dof > 0 else float("nan")
    try:
        covariance = variance * np.linalg.inv(jacobian.T @ jacobian)
    except np.linalg.LinAlgError:
        covariance = np.full((2, 2), np.inf)
    spread = np.sqrt(np.clip(np.diag(covariance), 0, np.inf))
    quantile = float(stats.t.ppf(0.975, max(dof, 1)))
    log_ratio = log_parameters[0] - 4 * log_parameters[1]
    ratio_spread = math.sqrt(max(covariance[0, 0] - 8 * covariance[0, 1] + 16 * covariance[1, 1], 0.0))
    moment, diameter = np.exp(log_parameters)

    def interval(centre: float, half: float) -> tuple[float, float]:
        with np.errstate(over="ignore"):  # an unidentified parameter's interval is unbounded: (0, inf)
            return float(np.exp(centre - quantile * half)), float(np.exp(centre + quantile * half))

    return CurveFit(moment=float(moment), diameter=float(diameter),
                    interval_moment=interval(log_parameters[0], spread[0]),
                    interval_diameter=interval(log_parameters[1], spread[1]),
                    correlation=float(covariance[0, 1] / (spread[0] * spread[1])) if np.all(spread > 0) else 1.0,
                    ratio=float(math.exp(log_ratio)), interval_ratio=interval(log_ratio, ratio_spread),
                    noise=math.sqrt(rss / points), points=points, evaluations=evaluations, at_bound=at_bound,
                    prediction=residuals + curve.change)


def best_moment(predictor: CurveModel, curve: MeasuredCurve, diameter: float, guess: float) -> tuple[float, float]:
    """(moment, RSS) of the best moment at a held ``diameter`` (a one-parameter fit on cached fields)."""
    solved = optimize.least_squares(lambda lm: predictor.predict(math.exp(lm[0]), diameter) - curve.change,
                                    [math.log(guess)], method="trf", diff_step=1e-6, xtol=1e-12, ftol=1e-14)
    if solved.status <= 0:
        raise NotConverged(f"profile: the moment at diameter {diameter:.4g} m did not converge")
    return float(math.exp(solved.x[0])), float(solved.fun @ solved.fun)


def profiles(fit: CurveFit, predictor: CurveModel, curve: MeasuredCurve, points: int = 15) -> tuple[Profile, Profile]:
    """Profile likelihoods of the diameter and of the moment around ``fit``, over ± 2.5 times each one's
    95 % Wald half-width in log units (at least ± 0.1 %, at most ± 50 %).

    The diameter's: the best moment at each diameter of a grid. The moment's: at each moment of a grid,
    the best over the same diameters (the RSS is smooth in the diameter: a parabola through the grid's
    three lowest points refines it)."""
    if points < 5:
        raise CurveError(f"points = {points}: expected at least 5 grid points")
    span_d, span_m = (float(np.clip(1.25 * math.log(high / low), 1e-3, 0.5)) if 0 < low < high < math.inf else 0.5
                      for low, high in (fit.interval_diameter, fit.interval_moment))
    diameters = fit.diameter * np.exp(np.linspace(-span_d, span_d, points))
    moments_at = np.empty(points)
    rss_d = np.empty(points)
    for index, diameter in enumerate(diameters):
        moments_at[index], rss_d[index] = best_moment(predictor, curve, diameter, fit.moment)
    rss_min = min(float(rss_d.min()), fit.noise**2 * fit.points)
    moments = fit.moment * np.exp(np.linspace(-span_m, span_m, points))
    table = np.array([[_rss(predictor, curve, m, d) for d in diameters] for m in moments])  # (M, D)
    rss_m = np.array([_parabola_minimum(np.log(diameters), row) for row in table])
    n = fit.points
    return (Profile(diameters, rss_d, _interval(diameters, rss_d, rss_min, n)),
            Profile(moments, rss_m, _interval(moments, rss_m, rss_min, n)))


def _rss(predictor: CurveModel, curve: MeasuredCurve, moment: float, diameter: float) -> float:
    residual = predictor.predict(moment, diameter) - curve.change
    return float(residual @ residual)


def _parabola_minimum(x: NDArray, y: NDArray) -> float:
    best = int(np.argmin(y))
    if best in (0, len(y) - 1):
        return float(y[best])
    a, b, c = np.polyfit(x[best - 1:best + 2], y[best - 1:best + 2], 2)
    return float(min(y[best], c - b * b / (4 * a))) if a > 0 else float(y[best])


def _interval(values: NDArray, rss: NDArray, rss_min: float, n: int) -> tuple[float | None, float | None]:
    """Where n ln(RSS/RSS_min) crosses χ²₁(0.95), by linear interpolation in log values."""
    deviance = n * np.log(rss / rss_min) - CHI2_95
    best = int(np.argmin(deviance))
    logs = np.log(values)

    def crossing(indices: range) -> float | None:
        previous = best
        for index in indices:
            if deviance[index] > 0:
                t = -deviance[previous] / (deviance[index] - deviance[previous])
                return float(np.exp(logs[previous] + t * (logs[index] - logs[previous])))
            previous = index
        return None

    return crossing(range(best - 1, -1, -1)), crossing(range(best + 1, len(values)))


@dataclass(frozen=True)
class Identifiability:
    """Fits of the linear part alone and of the whole curve: what each pins down."""

    linear_part_limit: float  # N: the forces fitted as the linear part are up to this
    linear: CurveFit
    whole: CurveFit


def identifiability(model: CiliaModel, curve: MeasuredCurve, linear_fraction: float = 0.3,
                    cache: CurveModel | None = None, whole: CurveFit | None = None) -> Identifiability:
    """Fit the forces up to ``linear_fraction`` of the largest (the linear part) and the whole curve
    (``whole``: its fit, if already made)."""
    if not 0 < linear_fraction < 1:
        raise CurveError(f"linear_fraction = {linear_fraction!r}: expected a number strictly between 0 and 1")
    limit = linear_fraction * float(curve.force.max())
    keep = curve.force <= limit
    if keep.sum() < 5:
        raise CurveError(f"linear_fraction = {linear_fraction!r}: {keep.sum()} points up to {limit:.4g} N, "
                         "expected at least 5 for the linear part")
    part = curve.part(keep)
    if whole is None:
        whole = fit_curve(model, curve, cache=cache)
    linear = fit_curve(model, part, start=(whole.moment, whole.diameter))
    return Identifiability(limit, linear, whole)
