"""Estimation-quality objectives: how precisely a design's readings determine what a robot needs.

The published study maximised a proxy, the displacement of one magnet. What a
calibrated fingertip delivers is an *estimate* - of the board's orientation, of
the 3-axis force - and its precision is bounded by the Cramér-Rao bound of the
load parameters given the sensor's noise:

    I = J^T Sigma^-1 J,   Cov(p_hat) >= I^-1

with J = d(readings)/d(load parameters) from finite differences of FE solves
around an operating point, and Sigma the design's registered sensor's noise at
its settings (for the MLX90393: datasheet noise at its averaging), plus one output
step's quantisation, step^2 / 12, per axis. No estimator - polynomial, network or
otherwise - can be more precise on average, so the bound ranks designs by
what any calibration could achieve, not by how far one magnet moves.

``orientation_bound``  standard deviation (deg) of the board angle estimated
                       from the readings of a push whose depth is unknown:
                       parameters (angle, depth).
``force_bound``        largest per-axis standard deviation (mN) of the 3-axis
                       force estimated from the readings: parameters (depth,
                       tangential x, tangential y), mapped to force by the
                       FE's force Jacobian: Cov(F) = G I^-1 G^T.

Both share one set of FE runs per design (so they are cached together):
the operating point, +-angle and +-depth steps, x and y tangential steps, and
the deepest push of the range for the **saturation constraint**: a design whose
rest field plus its largest change exceeds the sensor's full scale on any
axis at its register settings is infeasible, whatever its bound.
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

from softtip._core.config import NonNegativeNumber, Number, PositiveNumber, Refusal, schema
from softtip._core.units import MM, UT_PER_T
from softtip.design.model import Design
from softtip.optimize.objectives import Infeasible, Objective, ObjectiveSettings, objective
from softtip.optimize.runs import FEResult, Simulation
from softtip.sensors.registry import ChipSettings

# the pushing test: a board across the top, pushed at the centre; 22.5 deg lies between the
# magnets' symmetry lines (0 and 45 deg), where neither sensitivity vanishes by symmetry
OPERATING_POINT = Simulation(depth_mm=1.5, angle_deg=22.5)


@dataclasses.dataclass(frozen=True)
class Steps:
    angle_deg: float = 5.0
    depth_mm: float = 0.25
    tangential_mm: float = 0.25
    max_depth_mm: float = 3.0  # the deepest push of the calibration range, for saturation


def _simulations(base: Simulation, steps: Steps) -> tuple[Simulation, ...]:
    replace = dataclasses.replace
    return (base,
            replace(base, angle_deg=base.angle_deg + steps.angle_deg),
            replace(base, angle_deg=base.angle_deg - steps.angle_deg),
            replace(base, depth_mm=base.depth_mm + steps.depth_mm),
            replace(base, depth_mm=base.depth_mm - steps.depth_mm),
            replace(base, tangential_mm=(base.tangential_mm[0] + steps.tangential_mm, base.tangential_mm[1])),
            replace(base, tangential_mm=(base.tangential_mm[0], base.tangential_mm[1] + steps.tangential_mm)),
            replace(base, depth_mm=steps.max_depth_mm))


def reading_covariance_uT2(chips: ChipSettings, sensors: int) -> np.ndarray:
    """Diagonal noise variance (µT^2) of every reading, sensor-major (x, y, z of sensor 0, ...): the
    registered sensor's noise and output step at its settings."""
    per_axis = chips.variance()
    if per_axis is None:
        raise ValueError(f"sensor {chips.kind.name!r} declares no noise: the estimation bounds need it")
    return np.tile(per_axis, sensors)


def cramer_rao(jacobian: np.ndarray, variance: np.ndarray) -> np.ndarray:
    """Lower bound on the covariance of the parameters, inv(J^T diag(variance)^-1 J).

    ``jacobian`` (readings, parameters); an unidentifiable direction gives an infinite bound."""
    fisher = jacobian.T @ (jacobian / variance[:, None])
    try:
        return np.linalg.inv(fisher) if np.linalg.cond(fisher) < 1e14 else np.full_like(fisher, np.inf)
    except np.linalg.LinAlgError:
        return np.full_like(fisher, np.inf)


@dataclasses.dataclass(frozen=True)
class EstimationBounds:
    orientation_deg: float
    force_mN: np.ndarray  # (3,) per axis
    saturation_margin: float  # smallest (full scale - |field|) / full scale over sensors and axes


def estimation_bounds(design: Design, results: Sequence[FEResult], steps: Steps) -> EstimationBounds:
    """Both bounds from the results of :func:`_simulations`, in that order."""
    base, angle_up, angle_down, deeper, shallower, shear_x, shear_y, deepest = results
    readings = [r.field_change_T.ravel() * UT_PER_T for r in results]  # µT, sensor-major
    chips = design.chip_settings
    variance = reading_covariance_uT2(chips, len(base.field_change_T))
    d_angle = (readings[1] - readings[2]) / np.radians(2 * steps.angle_deg)
    d_depth = (readings[3] - readings[4]) / (2 * steps.depth_mm * MM)
    d_tx = (readings[5] - readings[0]) / (steps.tangential_mm * MM)
    d_ty = (readings[6] - readings[0]) / (steps.tangential_mm * MM)
    orientation = cramer_rao(np.column_stack([d_angle, d_depth]), variance)
    force_jacobian = np.column_stack([(deeper.force_N - shallower.force_N) / (2 * steps.depth_mm * MM),
                                      (shear_x.force_N - base.force_N) / (steps.tangential_mm * MM),
                                      (shear_y.force_N - base.force_N) / (steps.tangential_mm * MM)])
    covariance = cramer_rao(np.column_stack([d_depth, d_tx, d_ty]), variance)
    force_cov = force_jacobian @ covariance @ force_jacobian.T if np.isfinite(covariance).all() else covariance
    peak = np.abs((deepest.field_rest_T + deepest.field_change_T) * UT_PER_T)
    full_scale = chips.kind.full_scale(chips.values)
    margin = float(((full_scale - peak) / full_scale).min())
    return EstimationBounds(orientation_deg=float(np.degrees(np.sqrt(orientation[0, 0]))),
                            force_mN=np.sqrt(np.abs(np.diag(force_cov))) * 1e3, saturation_margin=margin)


@schema
class BoundSettings(ObjectiveSettings):
    """The ``[objective]`` table of the bounds: the operating point (the load-case keys, by default
    :data:`OPERATING_POINT`) and the finite-difference steps around it."""

    angle_deg: Number = OPERATING_POINT.angle_deg
    depth_mm: NonNegativeNumber = OPERATING_POINT.depth_mm
    angle_step_deg: PositiveNumber = Steps.angle_deg
    depth_step_mm: PositiveNumber = Steps.depth_mm
    tangential_step_mm: PositiveNumber = Steps.tangential_mm
    max_depth_mm: PositiveNumber = Steps.max_depth_mm

    def __post_init__(self):
        super().__post_init__()
        if not self.depth_step_mm < self.depth_mm:
            raise Refusal("depth_step_mm", f"expected less than depth_mm = {self.depth_mm}")


def _bound_objective(name: str, unit: str, pick, settings: BoundSettings) -> Objective:
    base = Simulation.of(settings)
    steps = Steps(angle_deg=settings.angle_step_deg, depth_mm=settings.depth_step_mm,
                  tangential_mm=settings.tangential_step_mm, max_depth_mm=settings.max_depth_mm)

    def score(design: Design, results: Sequence[FEResult]) -> float:
        bounds = estimation_bounds(design, results, steps)
        if bounds.saturation_margin < 0:
            raise Infeasible(f"{design.name}: the sensor saturates at a {steps.max_depth_mm} mm push "
                             f"({-100 * bounds.saturation_margin:.0f} % over full scale at its register settings)")
        return pick(bounds)

    return Objective(name=name, simulations=_simulations(base, steps), score=score, goal="min", unit=unit)


@objective("orientation_bound", BoundSettings)
def orientation_bound(settings: BoundSettings, design: Design) -> Objective:
    """Cramér-Rao bound (deg, 1 sigma) of the board angle from one push's readings, depth unknown."""
    return _bound_objective("orientation_bound", "deg", lambda b: b.orientation_deg, settings)


@objective("force_bound", BoundSettings)
def force_bound(settings: BoundSettings, design: Design) -> Objective:
    """Cramér-Rao bound (mN, 1 sigma, worst axis) of the 3-axis force from the readings."""
    return _bound_objective("force_bound", "mN", lambda b: float(b.force_mN.max()), settings)
