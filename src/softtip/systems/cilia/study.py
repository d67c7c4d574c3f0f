"""The S4 force study: the twin's force–voltage curves, the publication's fit made again on them (its model,
a clamped uniform cylinder loaded at its tip, fitted to the balance test as performed and to the tip-load
curve) and the publication's causes of its moment gap tried on the twin; softtip's own fit of its own
curve (an identifiability check: what the curve identifies, the recovery of the twin's truth); the smallest
resolved force and the range; the balance test's minimum force from its causes; the layout's weight.

:func:`run_study` is the entry point: pure analysis returning a typed :class:`CiliaStudy` with matplotlib
``Figure`` objects (never pyplot). The "measured" curve is the twin's own: the declared die with a chosen
truth (moment, diameter), read through the computed readout (noise and quantisation of the meter) plus a
stated repeatability of the bench (drift and re-seating between load steps, a fraction of the full-scale
change), at a seed. Which sensor: X, whose strips sense the direction the pillars bend in (the die's
``bend_azimuth_deg``), with the larger magnetoresistance and sensitivity; Y is reported beside it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Annotated

import numpy as np
from matplotlib.colors import SymLogNorm
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Rectangle
from pydantic import Field

from softtip._core.config import (
    Flag,
    Fraction,
    NonNegativeNumber,
    OpenFraction,
    PositiveInteger,
    PositiveNumber,
    Refusal,
    Text,
    choice,
    expect,
    integer,
    number,
    schema,
)
from softtip._core.errors import NotConverged
from softtip._core.progress import SILENT, Progress
from softtip._core.units import MM, MN, UM
from softtip.design.model import ElastomerModulusMPa
from softtip.magnetics.dipoles import dipole_field, frustum_shares
from softtip.mechanics.rod import PlateContact, Rod
from softtip.sensors.gmr import TESLA_PER_OERSTED
from softtip.systems.cilia.fit import (
    CHI2_95,
    CurveError,
    CurveFit,
    CurveModel,
    Identifiability,
    MeasuredCurve,
    Profile,
    fit_curve,
    identifiability,
    profiles,
)
from softtip.systems.cilia.layout import MEMU, SHIPPED_DIE, DieError, pillar_rod, read_die
from softtip.systems.cilia.model import (
    BalanceCurve,
    BalancePlate,
    CiliaModel,
    ConeCells,
    ForceCurve,
    pillar_dipoles,
)
from softtip.systems.cilia.resolution import (
    BUDGET_PARTS,
    GRAM_FORCE,
    ForceBudget,
    Resolution,
    balance_force_budget,
    resolutions,
)
from softtip.systems.cilia.roughness import BRUSH_SPACING_MM

SHIPPED = "shipped"  # the die setting that names the declared layout
DWELL_S = 2.0  # s per load step (chosen: the publication gives no rate); the lab bench's default too


@schema(section="cilia", error=DieError)
class CiliaSettings:
    """The study's settings (forces in mN, lengths in µm, moments in memu as the publication states them)."""

    die: Text = SHIPPED  # the declared layout shipped beside the package, or a die file's path
    sensor: choice("X", "Y") = "X"
    force_max_mN: PositiveNumber = 26.0
    points: integer(5, 400) = 40
    truth_moment_memu: PositiveNumber = 2.8
    truth_diameter_um: PositiveNumber = 200.0
    height_mm: PositiveNumber | None = None  # None: the die file's
    youngs_modulus_MPa: ElastomerModulusMPa | None = None  # None: the die file's
    repeatability: Fraction = 0.01  # of the full-scale voltage change, rms, per load step
    linear_fraction: OpenFraction = 0.1  # raised to hold at least 5 points where the plan is short
    # repeated loadings of the twin: the first is the study's curve; every one is fitted for the recovery
    trials: integer(1, 200) = 6
    chain_count: PositiveInteger = 10
    balance_chain_count: PositiveInteger = 40  # the balance test's: its buckled roots need more than the published 10
    # the pillars' magnet in the balance test's minimum force: "uniform", the composite (PDMS with 14 % v/v NdFeB)
    # magnetised uniformly, each pillar a continuous cone (the moment by volume); "equal", an equal moment per
    # length (a non-uniform material: the published chain of equal dipoles)
    magnetisation: choice("uniform", "equal") = "uniform"
    friction: number("a number >= 0", ge=0.0) = 0.5
    imperfection_deg: number("a root slope in degrees, 0 < slope < 45", gt=0.0, lt=45.0) = 0.5  # the bow (PlateContact)
    # the balance test as performed (softtip.systems.cilia.model.CiliaModel.balance_curve)
    die_tilt_deg: number("an angle in degrees from -10 to 10", ge=-10.0, le=10.0) = 0.0
    plate_stiffness_uNm: PositiveNumber | None = None  # the plate's turn, µN·m per rad; unset: it does not turn
    # the smallest force the balance test resolves (softtip.systems.cilia.resolution.balance_force_budget)
    budget_parts: Annotated[tuple[choice(*BUDGET_PARTS), ...], Field(min_length=1),
                            expect(f"a non-empty list of {', '.join(BUDGET_PARTS)}")] = BUDGET_PARTS
    balance_readability_mg: PositiveNumber = 0.1
    plate_seating_mrad: NonNegativeNumber = 1.0
    warm_up_s: NonNegativeNumber = 60.0
    gap_causes: Flag = True  # the publication's causes of its moment gap tried on the twin and the layout (a fit each)
    # the balance test's unknowns swept: other die tilts (the declared plate), other plates (the first tilt)
    rig_tilts_deg: Annotated[tuple[number("an angle in degrees from -10 to 10", ge=-10.0, le=10.0), ...],
                             expect("a list of angles in degrees from -10 to 10")] = (1.0, 3.0)
    rig_plate_stiffnesses_uNm: Annotated[tuple[PositiveNumber, ...],
                                         expect("a list of positive stiffnesses in µN·m/rad")] = (100.0,)
    depths_um: Annotated[tuple[PositiveNumber, ...], Field(min_length=1),
                         expect("a non-empty list of positive depths")] = (5.0, 10.0, 20.0)
    meander_scales: Annotated[tuple[PositiveNumber, ...], Field(min_length=1),
                              expect("a non-empty list of positive scales")] = (0.9, 1.1)
    # brushing (softtip.systems.cilia.roughness): the die held past first contact, moved over each surface
    brush_engagement_um: PositiveNumber = 150.0
    brush_speed_mm_s: PositiveNumber = 1.0
    brush_rate_hz: PositiveNumber = 50.0
    brush_length_mm: PositiveNumber = 20.0
    brush_strips: integer(2, 50) = 3  # realisations of each surface
    brush_bridge: Flag = False  # the publication's readout has none; a bridge is softtip's addition
    brush_speeds_mm_s: Annotated[tuple[PositiveNumber, ...], Field(min_length=2),
                                 expect("a list of at least two positive speeds")] = (0.5, 1.0, 2.0, 5.0, 10.0)
    brush_rates_hz: Annotated[tuple[PositiveNumber, ...], Field(min_length=2),
                              expect("a list of at least two positive rates")] = (2.0, 5.0, 10.0, 20.0, 50.0, 100.0)

    # the design search on the same die (softtip.systems.cilia.design): the stated force ranges, values per
    # design parameter, evaluations per range, forces along each design's curve
    design_ranges_mN: Annotated[tuple[PositiveNumber, ...], Field(min_length=1),
                                expect("a non-empty list of positive forces in mN")] = (13.0, 26.0, 39.0)
    design_steps: integer(2, 9) = 5
    design_budget: integer(1, 500) = 30
    design_points: integer(5, 200) = 17

    def __post_init__(self) -> None:
        speeds, rates = (self.brush_speed_mm_s, *self.brush_speeds_mm_s), (self.brush_rate_hz, *self.brush_rates_hz)
        if min(speeds) / max(rates) < BRUSH_SPACING_MM:  # a reading must cross at least one profile sample
            raise Refusal("brush_rates_hz", f"expected rates at most {min(speeds) / BRUSH_SPACING_MM:g} /s at "
                                            f"{min(speeds):g} mm/s (the profile is sampled every {BRUSH_SPACING_MM * 1e3:g} µm)")
        if self.brush_length_mm / max(speeds) < 1.0:  # the classifier's windows last one second
            raise Refusal("brush_length_mm", f"expected a stroke of at least one second at {max(speeds):g} mm/s")


@dataclass(frozen=True)
class Recovery:
    """Fits of synthetic curves with known truth: the recovered moments and diameters, one per trial."""

    truth_moment: float
    truth_diameter: float
    moments: np.ndarray
    diameters: np.ndarray

    @property
    def moment_error(self) -> tuple[float, float]:
        """(bias, spread) of the recovered moment relative to the truth."""
        relative = self.moments / self.truth_moment - 1
        return float(relative.mean()), float(relative.std(ddof=1)) if relative.size > 1 else 0.0

    @property
    def diameter_error(self) -> tuple[float, float]:
        relative = self.diameters / self.truth_diameter - 1
        return float(relative.mean()), float(relative.std(ddof=1)) if relative.size > 1 else 0.0


@dataclass(frozen=True)
class LayoutWeight:
    """The moment and diameter fitted to the same curve by dies of other layouts (the layout's weight):
    the sensing plane at other ``depths`` (m), and the meanders scaled by ``scales`` about the centre."""

    depths: np.ndarray
    moments_by_depth: np.ndarray
    diameters_by_depth: np.ndarray
    scales: np.ndarray
    moments_by_scale: np.ndarray
    diameters_by_scale: np.ndarray


@dataclass(frozen=True)
class PublicationFit:
    """The publication's own fit (:func:`publication_model`: a clamped uniform cylinder loaded at its tip,
    height and modulus held, moment and diameter free) of one curve: ``fit``, or why none converged."""

    curve: str
    fit: CurveFit | None
    refusal: str


@dataclass(frozen=True)
class BalanceOutcome:
    """The balance test as performed (die lowered onto a plate) and the publication's fit of its curve."""

    curve: BalanceCurve
    buckling_force: float  # N, all pillars: where the pillars' tips have turned past their rest (buckled)
    first_lying_force: float | None  # N: the balance's reading when the first pillar lies on its side
    all_lying_force: float | None  # N: when every pillar lies
    publication: PublicationFit
    budget: ForceBudget  # the settings' magnetisation's
    chain_budget: ForceBudget  # read with the equal dipoles, along the whole curve
    cone_budget: ForceBudget  # read with continuous cones, at the steps around the chain's best
    finer_chain: BalanceCurve  # the same test with CHAIN_CHECK times the dipoles per pillar: the chain's convergence
    volume_chain: BalanceCurve  # the same dipoles each carrying its slice's volume share (a uniformly magnetised cone)


@dataclass(frozen=True)
class RigCase:
    """The balance test with other values of its unknowns: the die's ``tilt`` (rad), the plate's
    ``stiffness`` (N·m/rad, None: fixed), and what they do to the curve."""

    tilt: float
    stiffness: float | None
    all_lying_force: float | None  # N
    change_at_5mN: float | None  # V
    largest_turn: float  # rad


@dataclass(frozen=True)
class GapCause:
    """One of the publication's causes of its fitted moment being a third of the magnetometer's, tried on
    the twin: the twin changed as ``change`` says, its tip-load curve fitted by the publication's model."""

    cause: str
    change: str
    truth_moment: float
    fit: CurveFit | None
    refusal: str

    @property
    def ratio(self) -> float | None:
        """The twin's moment over the publication model's fitted one (the publication's gap is about 3)."""
        return None if self.fit is None else self.truth_moment / self.fit.moment


@dataclass(frozen=True)
class CiliaFigures:
    curve: Figure
    balance: Figure
    field_map: Figure
    pillars: Figure
    profiles: Figure


@dataclass(frozen=True)
class CiliaStudy:
    settings: CiliaSettings
    seed: int
    truth: ForceCurve
    measured: MeasuredCurve
    fit: CurveFit
    profile_diameter: Profile
    profile_moment: Profile
    identifiability: Identifiability
    recovery: Recovery
    resolution: Resolution
    other_sensor: Resolution | None  # None: the die has one sensor direction
    balance: BalanceOutcome
    publication_tip_load: PublicationFit
    moment_gap: tuple[GapCause, ...]
    rig: tuple[RigCase, ...]
    layout: LayoutWeight
    figures: CiliaFigures


def die_path(name: str, folder: Path | None = None) -> Path:
    """The die file a setting names: ``shipped`` (the declared layout), or a path (relative ones from
    ``folder``, the protocol file's, when given)."""
    if name == SHIPPED:
        return SHIPPED_DIE
    path = Path(name)
    return folder / path if folder is not None and not path.is_absolute() else path


def twin_model(settings: CiliaSettings) -> CiliaModel:
    """The twin's die: the die file's, with the settings' truth (moment, tip diameter) and, where given,
    their pillar height and Young's modulus."""
    die = read_die(die_path(settings.die))
    pillars = die.pillars
    rod = pillars.rod
    template = replace(rod, length=rod.length if settings.height_mm is None else settings.height_mm * MM,
                       youngs_modulus=(rod.youngs_modulus if settings.youngs_modulus_MPa is None
                                       else settings.youngs_modulus_MPa * 1e6))
    pillars = replace(pillars, rod=pillar_rod(template, rod.tip_diameter, rod.base_diameter))
    truth = replace(pillars.with_diameter(settings.truth_diameter_um * UM),
                    moment=math.copysign(settings.truth_moment_memu * MEMU, pillars.moment))
    return CiliaModel(die.with_pillars(truth), chain_count=settings.chain_count,
                      balance_chain_count=settings.balance_chain_count)


def paper_forces(settings: CiliaSettings) -> np.ndarray:
    """The paper-mode load plan: ``points`` equal steps up to ``force_max_mN`` (N)."""
    return np.linspace(settings.force_max_mN * MN / settings.points, settings.force_max_mN * MN, settings.points)


def balance_descent(model: CiliaModel, settings: CiliaSettings) -> np.ndarray:
    """The balance test's plan: ``points`` steps of the die's descent past first contact, to 70 % of the
    pillars' height."""
    return np.linspace(0.0, 0.7 * model.die.pillars.rod.length, settings.points)


def balance_contact(settings: CiliaSettings) -> PlateContact:
    return PlateContact(settings.friction, math.radians(settings.imperfection_deg), math.radians(settings.die_tilt_deg))


def balance_plate(settings: CiliaSettings, seated: float = 0.0) -> BalancePlate:
    """The balance's plate of ``settings``, seated at a turn of ``seated`` (rad)."""
    stiffness = settings.plate_stiffness_uNm
    return BalancePlate(None if stiffness is None else stiffness * 1e-6, seated)


PUBLISHED_HEIGHT, PUBLISHED_MODULUS = 1e-3, 1e6  # m, Pa: what the publication held in its fit


def publication_model(model: CiliaModel) -> CiliaModel:
    """The publication's model of ``model``'s die: each pillar a uniform cylinder 1 mm tall of E = 1 MPa,
    clamped at its base (no compliant film, no bonded-root correction), loaded at its tip perpendicular to
    its axis, its moment shared equally by the chain's dipoles; the diameter (the die's tip diameter here)
    and the moment are what a fit sets."""
    pillars = model.die.pillars
    rod = pillars.rod
    cylinder = Rod(length=PUBLISHED_HEIGHT, base_diameter=rod.tip_diameter, tip_diameter=rod.tip_diameter,
                   youngs_modulus=PUBLISHED_MODULUS, poisson_ratio=rod.poisson_ratio, segments=rod.segments)
    return CiliaModel(model.die.with_pillars(replace(pillars, rod=cylinder)), chain_count=model.chain_count)


def publication_fit(model: CiliaModel, curve: MeasuredCurve, name: str) -> PublicationFit:
    """The publication's fit of ``curve`` (its forces above zero), from the twin's own moment and diameter."""
    pillars = model.die.pillars
    try:
        fit = fit_curve(publication_model(model), curve.part(curve.force > 0),
                        start=(abs(pillars.moment), pillars.rod.tip_diameter))
        return PublicationFit(name, fit, "")
    except (NotConverged, CurveError) as problem:  # the report says why the model cannot fit this curve
        return PublicationFit(name, None, f"{type(problem).__name__}: {problem}")


def run_study(settings: CiliaSettings, seed: int, progress: Progress = SILENT) -> CiliaStudy:
    """The whole force study of the die in ``settings`` at ``seed`` (see the module notes): the twin's
    curves read through the bench, then :func:`analyse_curves`."""
    model = twin_model(settings)
    rng = np.random.default_rng(seed)
    truth = model.curve(paper_forces(settings), settings.sensor)
    measured = [measure(model, truth, settings.repeatability, rng) for _ in range(settings.trials)]
    balance = model.balance_curve(balance_descent(model, settings), balance_contact(settings), settings.sensor,
                                  balance_plate(settings))
    return analyse_curves(settings, seed, model, truth, measured, balance,
                          measure(model, balance, settings.repeatability, rng), progress)


def analyse_curves(settings: CiliaSettings, seed: int, model: CiliaModel, truth: ForceCurve,
                   measured: list[MeasuredCurve], balance: BalanceCurve, balance_measured: MeasuredCurve,
                   progress: Progress = SILENT, dwell: float = DWELL_S) -> CiliaStudy:
    """The force study of measured curves of ``model``'s twin: the first paper-mode curve fitted in full
    (profiles, identifiability, layout weight), every one fitted for the recovery of the twin's truth,
    and the paper-mode fit of the balance test's curve."""
    first = measured[0]
    force = first.force
    with progress.task("fit, profiles and identifiability", total=2) as task:
        predictor = CurveModel(model, force, first.sensor)
        fitted = fit_curve(model, first, cache=predictor)
        task.advance(note=f"moment {fitted.moment / MEMU:.3f} memu")
        profile_d, profile_m = profiles(fitted, predictor, first)
        fraction = max(settings.linear_fraction, min(0.99, (5 + 1e-9) / force.size))
        identified = identifiability(model, first, fraction, cache=predictor, whole=fitted)
        task.advance(note="profiles")
    trials_m, trials_d = [fitted.moment], [fitted.diameter]
    with progress.task("recovery of the twin's truth", total=len(measured) - 1) as task:
        for curve in measured[1:]:
            trial = fit_curve(model, curve, cache=predictor)
            trials_m.append(trial.moment)
            trials_d.append(trial.diameter)
            task.advance()
    recovery = Recovery(abs(model.die.pillars.moment), model.die.pillars.rod.tip_diameter, np.array(trials_m),
                        np.array(trials_d))
    with progress.task("resolution, balance, the publication's fit, layout", total=5) as task:
        on_die = tuple(m.name for m in model.die.meanders)  # the study's sensor first, the other if the die has it
        resolved, *other = resolutions(model, (first.sensor, *(s for s in on_die if s != first.sensor)),
                                       1.5 * settings.force_max_mN * MN)
        task.advance()
        balanced = _balance(model, balance, balance_measured, settings, dwell)
        task.advance(note="balance test")
        tip_load = publication_fit(model, first, "tip load")
        gap = _moment_gap(model, settings) if settings.gap_causes else ()
        rig = _rig_cases(model, settings)
        task.advance(note="the publication's fit, the moment gap's causes, the rig's unknowns")
        layout = _layout_weight(model, first, fitted, settings)
        task.advance()
    figures = CiliaFigures(curve=_curve_figure(truth, first, fitted, balanced),
                           balance=_balance_figure(balanced, balance_measured, resolved.noise.total, settings),
                           field_map=_field_map_figure(model, truth),
                           pillars=_pillars_figure(truth, balanced),
                           profiles=_profiles_figure(profile_d, profile_m, fitted, recovery))
    return CiliaStudy(settings, seed, truth, first, fitted, profile_d, profile_m, identified, recovery, resolved,
                      other[0] if other else None, balanced, tip_load, gap, rig, layout, figures)


def measure(model: CiliaModel, truth: ForceCurve, repeatability: float, rng: np.random.Generator) -> MeasuredCurve:
    """The twin's curve as a bench reads it: each reading through the meter (noise, quantisation), the
    tare from a reading at zero force, and the bench's repeatability on top (``repeatability`` of the
    full-scale change, rms, per load step)."""
    readout = model.die.meander(truth.sensor).readout
    rest = truth.volts[0] - truth.change[0]
    readings = readout.read(truth.volts, rng) - readout.read(np.array([rest]), rng)[0]
    scatter = repeatability * float(np.abs(truth.change).max())
    return MeasuredCurve(truth.force, readings + rng.normal(0.0, scatter, readings.shape), truth.sensor)


def _balance(model: CiliaModel, curve: BalanceCurve, measured: MeasuredCurve, settings: CiliaSettings,
             dwell: float) -> BalanceOutcome:
    tilt = math.radians(settings.imperfection_deg)
    buckled = np.flatnonzero(np.abs(curve.shapes.tip_angle) > 2 * tilt + 0.05)
    buckling = float(curve.force[buckled[0]]) if buckled.size else float(curve.force.max())
    first, every = (np.flatnonzero(curve.lying_count >= count) for count in (1, len(curve.gaps[0])))
    within = measured.part(measured.force <= settings.force_max_mN * MN)  # the range the publication fitted
    count = settings.balance_chain_count
    rod = model.die.pillars.rod
    by_volume = tuple(float(v) for v in frustum_shares(rod.base_diameter, rod.tip_diameter, count))
    finer, volume = (variant.balance_curve(balance_descent(model, settings), balance_contact(settings), curve.sensor,
                                           balance_plate(settings))
                     for variant in (replace(model, balance_chain_count=CHAIN_CHECK * count),
                                     replace(model, chain_count=count, chain_shares=by_volume, balance_chain_count=None)))
    descent = balance_descent(model, settings)
    chain = _budget(model, descent, curve, settings, dwell)
    # the cone's field costs about 50 times the chain's: it is read at the steps around the chain's best
    steps = np.searchsorted(curve.force, chain.force)[max(0, chain.best - CONE_STEPS):chain.best + CONE_STEPS + 1]
    plan = np.unique(np.concatenate([[0.0], descent[steps]]))
    cone = replace(model, balance_magnet="cone", cells=CONE_CELLS)
    cone_curve = cone.balance_curve(plan, balance_contact(settings), curve.sensor, balance_plate(settings))
    uniform = _budget(cone, plan, cone_curve, settings, dwell, keep=np.searchsorted(plan, descent[steps]))
    return BalanceOutcome(curve, buckling, float(curve.force[first[0]]) if first.size else None,
                          float(curve.force[every[0]]) if every.size else None,
                          publication_fit(model, within, "balance test"),
                          uniform if settings.magnetisation == "uniform" else chain, chain, uniform, finer, volume)


CHAIN_CHECK = 4  # the balance test read again with this many times the dipoles: is its chain enough?
# the continuous cones of the balance test's minimum force: cells twice their height over the sensing plane. At the
# buckling, on a clamped root, the slope within 1 % of cells their height and 6 % of half of it; on the shipped
# root (turned 8°, cells below the die left out) 28 % and 22 % steeper: finer cells cost 4 and 14 times as much
CONE_CELLS = ConeCells(slices=64, size=2.0)
CONE_STEPS = 2  # the steps either side of the chain's best at which the cones are read
GAP_POINTS = 13  # load steps of each noise-free curve the moment gap's causes are tried on
SEATING_STEP = 1e-3  # rad: the plate's seating turn either side for its effect on the voltage


def _budget(model: CiliaModel, descent: np.ndarray, curve: BalanceCurve, settings: CiliaSettings, dwell: float,
            keep: np.ndarray | None = None) -> ForceBudget:
    """The balance test's force budget along its ``curve`` (of the plan ``descent``): at the steps ``keep``, or
    the steps up to the stated range while the force rises (the budget needs the force increasing; a turning
    plate can make it dip)."""
    if keep is None:
        rising = np.concatenate([[True], np.diff(curve.force) > 0]) & (curve.force <= settings.force_max_mN * MN)
        keep = np.flatnonzero(np.cumprod(rising))
    seated = [model.balance_curve(descent, balance_contact(settings), curve.sensor, balance_plate(settings, turn))
              for turn in (-SEATING_STEP, SEATING_STEP)]
    force = curve.force[keep]
    low, high = (np.interp(force, other.force[np.argsort(other.force)], other.change[np.argsort(other.force)])
                 for other in seated)
    readout = model.die.meander(curve.sensor).readout
    return balance_force_budget(force, curve.change[keep], float(curve.volts[0] - curve.change[0]), readout,
                                (low, high, SEATING_STEP), settings.balance_readability_mg * 1e-3 * GRAM_FORCE,
                                settings.plate_seating_mrad * 1e-3, settings.warm_up_s, dwell,
                                float(np.prod(model.die.size)), settings.budget_parts)


def _rig_cases(model: CiliaModel, settings: CiliaSettings) -> tuple[RigCase, ...]:
    """The balance test at the other tilts with the declared plate, and on the other plates at the first
    of those tilts (or the declared one)."""
    tilted = settings.rig_tilts_deg[0] if settings.rig_tilts_deg else settings.die_tilt_deg
    cases = ([replace(settings, die_tilt_deg=tilt) for tilt in settings.rig_tilts_deg]
             + [replace(settings, die_tilt_deg=tilted, plate_stiffness_uNm=k) for k in settings.rig_plate_stiffnesses_uNm])
    found = []
    for case in cases:
        plate = balance_plate(case)
        curve = model.balance_curve(balance_descent(model, case), balance_contact(case), settings.sensor, plate)
        every = np.flatnonzero(curve.lying_count >= len(curve.gaps[0]))
        found.append(RigCase(math.radians(case.die_tilt_deg), plate.rotation_stiffness,
                             float(curve.force[every[0]]) if every.size else None,
                             float(np.interp(5 * MN, curve.force, curve.change)) if curve.force.max() >= 5 * MN else None,
                             float(np.abs(curve.rotation).max())))
    return tuple(found)


def _moment_gap(model: CiliaModel, settings: CiliaSettings) -> tuple[GapCause, ...]:
    """The publication's causes of its 3 × moment gap that the twin can test: its tip-load curve (noise-free,
    :data:`GAP_POINTS` steps over the range) with each cause on or off, fitted by the publication's model."""
    forces = paper_forces(replace(settings, points=GAP_POINTS))
    pillars = model.die.pillars
    rod = pillars.rod
    count = model.chain_count
    mean = 0.5 * (rod.tip_diameter + rod.base_diameter)
    uniform = replace(model, die=model.die.with_pillars(replace(pillars, rod=pillar_rod(rod, mean, mean))))
    rising = tuple(float(v) for v in (2 * np.arange(count) + 1) / count**2)  # ∝ height: particles settled to the tip
    heated = model.die.meanders
    hot = replace(model, die=replace(model.die, meanders=tuple(
        replace(m, readout=replace(m.readout, thermal_resistance=100 * m.readout.thermal_resistance)) for m in heated)))
    variants = [
        ("none (the twin as declared)", "a cone 200 → 320 µm on a film of its own material, uniform material, "
         "self-heating at 100 µA", model),
        ("the cone", f"a uniform cylinder of the cone's mean diameter ({mean / UM:.0f} µm)", uniform),
        ("the cone", "the cone magnetised uniformly: each dipole its slice's share of the volume",
         replace(model, chain_shares=tuple(float(v) for v in frustum_shares(rod.base_diameter, rod.tip_diameter, count)))),
        ("non-uniform material", "the moment rising linearly from base to tip (particles settled to the tip)",
         replace(model, chain_shares=rising)),
        ("non-uniform material", "the moment falling linearly from base to tip (settled to the base)",
         replace(model, chain_shares=rising[::-1])),
        ("spin-valve heating", "the die's thermal resistance × 100 (its warming 100 times the computed)", hot),
    ]
    # the layout, which the publication shows only in figures: the twin as declared, its curve fitted by the
    # publication's model on a die whose meanders are scaled about the centre (a fit's layout off the die's)
    scaled = [("the layout (softtip's; not a published cause)",
               f"the fit's meanders scaled by {scale:g} about the die's centre (the twin's as declared)",
               replace(model, die=model.die.with_meanders_scaled(scale))) for scale in settings.meander_scales]
    causes = []
    for cause, change, twin, fitter in [(*variant, model) for variant in variants] + [
            (cause, change, model, fitter) for cause, change, fitter in scaled]:
        curve = twin.curve(forces, settings.sensor)
        found = publication_fit(fitter, MeasuredCurve(curve.force, curve.change, curve.sensor), cause)
        causes.append(GapCause(cause, change, abs(pillars.moment), found.fit, found.refusal))
    return tuple(causes)


def _layout_weight(model: CiliaModel, measured: MeasuredCurve, fitted: CurveFit, settings: CiliaSettings) -> LayoutWeight:
    def refits(dies: list) -> tuple[np.ndarray, np.ndarray]:
        found = [fit_curve(replace(model, die=die), measured, start=(fitted.moment, fitted.diameter)) for die in dies]
        return np.array([f.moment for f in found]), np.array([f.diameter for f in found])

    depths = np.array(settings.depths_um) * UM
    scales = np.array(settings.meander_scales)
    by_depth = refits([model.die.with_depth(depth) for depth in depths])
    by_scale = refits([model.die.with_meanders_scaled(scale) for scale in scales])
    return LayoutWeight(depths, *by_depth, scales, *by_scale)


# ---------------------------------------------------------------------------------------------- figures


def _curve_figure(truth: ForceCurve, measured: MeasuredCurve, fit: CurveFit, balance: BalanceOutcome) -> Figure:
    figure = Figure(figsize=(6.4, 4.2), layout="constrained")
    axes = figure.add_subplot()
    axes.plot(measured.force / MN, measured.change * 1e3, "o", ms=3, label="measured (twin + readout + bench)")
    axes.plot(truth.force / MN, truth.change * 1e3, "-", lw=1, label="truth (paper mode)")
    axes.plot(measured.force / MN, fit.prediction * 1e3, "--", lw=1.5,
              label=f"softtip's own fit (identifiability): {fit.moment / MEMU:.3f} memu, {fit.diameter / UM:.1f} µm")
    axes.plot(balance.curve.force / MN, balance.curve.change * 1e3, "-", lw=1, label="balance mode (plate)")
    axes.set_xlabel("force on the die (mN)")
    axes.set_ylabel(f"voltage change, sensor {measured.sensor} (mV)")
    axes.legend(fontsize=8)
    return figure


def _balance_figure(balance: BalanceOutcome, measured: MeasuredCurve, sigma: float, settings: CiliaSettings) -> Figure:
    """The balance test at its own scale: the twin's curve, its reading, the meter's noise, where the pillars
    buckle and lie, and what the publication's model fitted to it predicts."""
    figure = Figure(figsize=(6.4, 4.2), layout="constrained")
    axes = figure.add_subplot()
    curve = balance.curve
    axes.axhspan(-3e6 * sigma, 3e6 * sigma, color="0.9", label="± 3σ of one reading")
    axes.plot(measured.force / MN, measured.change * 1e6, "o", ms=3, label="read (meter + bench)")
    axes.plot(curve.force / MN, curve.change * 1e6, "-", lw=1, label="twin")
    fit = balance.publication.fit
    if fit is not None:
        within = measured.force[(measured.force > 0) & (measured.force <= settings.force_max_mN * MN)]
        axes.plot(within / MN, fit.prediction * 1e6, "--", lw=1.5,
                  label="the publication's model fitted" + (" (on a bound)" if fit.at_bound else ""))
    axes.axvline(balance.buckling_force / MN, color="k", ls=":", lw=0.8, label="the pillars buckle")
    if balance.all_lying_force is not None:
        axes.axvline(balance.all_lying_force / MN, color="k", ls="--", lw=0.8, label="every pillar lies")
    axes.axvline(settings.force_max_mN, color="C3", ls="-.", lw=0.8, label="the published range's end")
    axes.set_xlabel("the balance's reading (mN)")
    axes.set_ylabel(f"voltage change, sensor {curve.sensor} (µV)")
    axes.legend(fontsize=7)
    return figure


def _field_map_figure(model: CiliaModel, truth: ForceCurve) -> Figure:
    """The in-plane field along the sensor's axis in the sensing plane, at rest and at the largest force,
    with the strips' banks and the pillars' bases."""
    die = model.die
    meander = die.meander(truth.sensor)
    xs = np.linspace(-die.size[0] / 2, die.size[0] / 2, 121)
    ys = np.linspace(-die.size[1] / 2, die.size[1] / 2, 121)
    grid_x, grid_y = np.meshgrid(xs, ys, indexing="xy")
    points = np.column_stack([grid_x.ravel(), grid_y.ravel(), np.full(grid_x.size, -die.depth)])
    states = model.shapes(np.array([0.0, truth.force[-1]]))
    dipoles = pillar_dipoles(die.pillars, states, model.chain_count)
    field = dipole_field(points, dipoles.positions, dipoles.moments)[..., meander.axis] / TESLA_PER_OERSTED  # gauss (≙ Oe)
    figure = Figure(figsize=(9.0, 4.2), layout="constrained")
    low, high = (meander.readout.sensor.field_low / TESLA_PER_OERSTED,
                 meander.readout.sensor.field_high / TESLA_PER_OERSTED)
    norm = SymLogNorm(linthresh=max(abs(low), abs(high)), vmin=-3000, vmax=3000)
    for index, title in enumerate(("at rest", f"at {truth.force[-1] / MN:.1f} mN")):
        axes = figure.add_subplot(1, 2, index + 1)
        image = axes.pcolormesh(xs / 1e-3, ys / 1e-3, field[index].reshape(grid_x.shape), cmap="RdBu_r", norm=norm,
                                shading="auto")
        for (x0, x1), (y0, y1) in _bank_outlines(meander.strips.x, meander.strips.y, meander.axis):
            axes.add_patch(Rectangle((x0 / 1e-3, y0 / 1e-3), (x1 - x0) / 1e-3, (y1 - y0) / 1e-3, fill=False, lw=0.8))
        for x, y in die.pillars.positions:
            axes.add_patch(Circle((x / 1e-3, y / 1e-3), die.pillars.rod.base_diameter / 2 / 1e-3, fill=False,
                                  ls="--", lw=0.8))
        axes.set_aspect("equal")
        axes.set_title(f"B_{'xy'[meander.axis]} at {die.depth / UM:.0f} µm below the bases, {title}", fontsize=9)
        axes.set_xlabel("x (mm)")
        axes.set_ylabel("y (mm)")
    figure.colorbar(image, ax=figure.axes, label=f"field (Oe; linear range {low:g} .. {high:g})")
    return figure


def _bank_outlines(x: np.ndarray, y: np.ndarray, axis: int) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """The bounding boxes of the banks: runs of strips that share their extent along the strips (strips
    sensing x run along y, and the other way round), split where a gap across them exceeds twice their pitch."""
    keys = np.round(y if axis == 0 else x, 12)
    outlines = []
    for key in np.unique(keys, axis=0):
        members = np.flatnonzero(np.all(keys == key, axis=1))
        across = (x if axis == 0 else y)[members]
        members = members[np.argsort(across[:, 0])]
        starts = np.sort(across[:, 0])
        steps = np.diff(starts)
        breaks = np.flatnonzero(steps > 2 * np.median(steps)) + 1 if steps.size else np.array([], dtype=int)
        for bank in np.split(members, breaks):
            outlines.append(((float(x[bank].min()), float(x[bank].max())),
                             (float(y[bank].min()), float(y[bank].max()))))
    return outlines


def _pillars_figure(truth: ForceCurve, balance: BalanceOutcome) -> Figure:
    figure = Figure(figsize=(8.0, 3.8), layout="constrained")
    for index, (curve, title) in enumerate(((truth, "paper mode (tip load perpendicular to the axis)"),
                                            (balance.curve, "balance mode (plate, friction)"))):
        axes = figure.add_subplot(1, 2, index + 1)
        rows = np.unique(np.linspace(0, len(curve.force) - 1, 8).astype(int))
        for row in rows:
            axes.plot(curve.shapes.x[row] / 1e-3, curve.shapes.z[row] / 1e-3, lw=1,
                      label=f"{curve.force[row] / MN:.1f} mN" + (" (lying)" if curve.lying[row] else ""))
        axes.axhline(0, color="k", lw=0.8)
        axes.set_xlim(-0.35, 1.1)
        axes.set_aspect("equal")
        axes.set_title(title, fontsize=9)
        axes.set_xlabel("along the bend (mm)")
        axes.set_ylabel("height (mm)")
        axes.legend(fontsize=7)
    return figure


def _profiles_figure(profile_d: Profile, profile_m: Profile, fit: CurveFit, recovery: Recovery) -> Figure:
    figure = Figure(figsize=(8.0, 3.6), layout="constrained")
    for index, (profile, scale, unit, best) in enumerate(((profile_d, UM, "tip diameter (µm)", fit.diameter),
                                                          (profile_m, MEMU, "moment per pillar (memu)", fit.moment))):
        axes = figure.add_subplot(1, 2, index + 1)
        rss_min = min(profile_d.rss.min(), profile_m.rss.min())
        axes.plot(profile.values / scale, fit.points * np.log(profile.rss / rss_min), "o-", ms=3)
        axes.axhline(CHI2_95, color="k", ls=":", lw=0.8, label="95 % (χ²₁)")
        axes.axvline(best / scale, color="C1", lw=0.8, label="fit")
        axes.set_xlabel(unit)
        axes.set_ylabel("n ln(RSS / RSS_min)")
        axes.legend(fontsize=8)
    return figure
