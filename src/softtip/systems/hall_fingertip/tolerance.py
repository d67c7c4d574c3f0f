"""Tolerance sensitivity of the Hall fingertip: which fabrication and bench errors degrade each estimate most.

Design for manufacture asks which tolerance to tighten first. Each candidate error (:data:`ERRORS`) is
a setting of the fingertip's realism table (the realism module says where each comes from; here each
also has a stated tolerance and its source). The nominal unit has every candidate at its nominal value:
the fabrication spreads at zero (magnets, magnetisation and chip exactly as designed), the bench's
offsets at the protocol's values, the per-trial scatter off; the sensors' noise and the magnets'
temperature walk stay on, as on any bench. Then, one error at a time:

* an *offset* (a fixed bench or material error: the stage's axis, the board's edge, the elastomer's
  stiffness) is set to its nominal value - and + its tolerance;
* a *spread* (a random error: a magnet's or the chip's placement, a magnet's magnetisation, the
  contact's position or the stage's angle from trial to trial) is set to its tolerance as one standard
  deviation, so the unit (or each trial) is drawn with it; its sign is in the draw.

Every run re-runs the calibration and validation its estimate needs, on a coarse version of the shipped
protocol: orientation from the pushing test (polynomial and network fits, as the pushing study), 3-axis
force from the force protocol (the published network, 3-10-3). An error's degradation is its estimate's
validation error minus the nominal unit's, for the same seed (the same trials, noise and draws): over
``seeds`` units its mean and a 95 % t-interval. An interval that contains zero is inside the seed
scatter; two errors whose intervals overlap are not ranked apart. A joint Monte-Carlo sets every error
at once (the spreads at their tolerance, each offset drawn uniformly within its tolerance, seeded).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Literal

import numpy as np

from softtip._core.progress import SILENT, Progress

if TYPE_CHECKING:
    from softtip.design.model import Design
    from softtip.lab import Protocol

# The command checks its arguments against this module's tables before any work: the heavy modules
# (the lab, the studies, the calibration models) are imported where a run needs them.

SHORE_A = 27.0  # the body's photopolymer (the specification, generation 1)
SHORE_A_TOLERANCE = 3.0  # a typical datasheet tolerance of an elastomer's hardness; not published for this body


def gent_modulus_MPa(shore_a: float) -> float:
    """Young's modulus from Shore A hardness by Gent's relation (Gent 1958, Trans. Inst. Rubber Ind. 34)."""
    return 0.0981 * (56 + 7.62336 * shore_a) / (0.137505 * (254 - 2.54 * shore_a))


STIFFNESS_TOLERANCE = (gent_modulus_MPa(SHORE_A + SHORE_A_TOLERANCE) - gent_modulus_MPa(SHORE_A - SHORE_A_TOLERANCE)) / (
    2 * gent_modulus_MPa(SHORE_A))

PUSHING, FORCE = "pushing", "force3"
BOTH = (PUSHING, FORCE)


@dataclass(frozen=True)
class ToleranceError:
    """One candidate error: the realism ``setting`` it moves, ``kind`` (an offset is set to nominal ±
    tolerance, a spread to its tolerance as a standard deviation), its default ``tolerance`` in ``unit``,
    the protocols it acts in and where the tolerance comes from."""

    name: str
    setting: str
    kind: Literal["offset", "spread"]
    tolerance: float
    unit: str
    protocols: tuple[str, ...]
    note: str = ""  # said after the realism module's source of the setting, or instead of it
    cites_realism: bool = True

    def source(self) -> str:
        from softtip.systems.hall_fingertip.realism import REALISM_SOURCES

        return "; ".join(filter(None, (REALISM_SOURCES[self.setting] if self.cites_realism else "", self.note)))


ERRORS = (
    ToleranceError("magnet-position", "magnet_position_sd_mm", "spread", 0.10, "mm", BOTH),
    ToleranceError("magnetisation", "magnetisation_sd", "spread", 0.02, "", BOTH),
    ToleranceError("chip-position", "sensor_position_sd_mm", "spread", 0.10, "mm", BOTH, "about ±0.1 mm"),
    ToleranceError("stiffness", "modulus_change", "offset", round(STIFFNESS_TOLERANCE, 3), "", BOTH,
                   f"the body's Shore A{SHORE_A:g} within ±{SHORE_A_TOLERANCE:g} points (a typical elastomer datasheet "
                   "tolerance), as a relative modulus by Gent's relation", cites_realism=False),
    ToleranceError("stage-axis", "stage_axis_offset_mm", "offset", 1.0, "mm", (PUSHING,),
                   "the tolerance: the same 1 mm, the stage centred under the fingertip by eye"),
    # the pushing study's HALF_BOARD_MM
    ToleranceError("board-edge", "board_edge_offset_mm", "offset", 0.8, "mm", (PUSHING,),
                   "the board clamped by one face on the stage's axis instead of by its mid-plane: half its 1.6 mm",
                   cites_realism=False),
    ToleranceError("contact-position", "position_sd_mm", "spread", 0.20, "mm", BOTH),
    ToleranceError("stage-angle", "angle_sd_deg", "spread", 0.5, "deg", BOTH),
)
ERROR_NAMES = tuple(error.name for error in ERRORS)

ORIENTATION = ("orientation · polynomial", "orientation · network")  # the pushing study's two methods, in order
FORCE_AXES = ("fx_N", "fy_N", "fz_N")
FORCES = ("Fx · network", "Fy · network", "Fz · network")
ESTIMATES = {**dict.fromkeys(ORIENTATION, (PUSHING, "deg")), **dict.fromkeys(FORCES, (FORCE, "N"))}
CONTACT_N = 0.05  # force samples scored: some axis above this (the force study's criterion)
JOINT = "all at once (Monte-Carlo)"
JOINT_STREAM = 8  # the joint draw's random stream beside the seed; the bench draws from the seed's own

# Coarse protocols: the shipped ones with fewer angles and trials (the full command, and --quick for CI)
COARSE = {PUSHING: {"angles_deg": [0.0, 30.0, 60.0, 90.0], "calibration_trials": 3, "validation_trials": 2},
          FORCE: {"calibration_trials": 3, "validation_trials": 2}}
QUICK = {PUSHING: {"angles_deg": [0.0, 45.0, 90.0], "calibration_trials": 2, "validation_trials": 1},
         FORCE: {"calibration_trials": 2, "validation_trials": 1}}


def error_named(name: str) -> ToleranceError:
    for error in ERRORS:
        if error.name == name:
            return error
    raise ValueError(f"error {name!r}: expected one of {', '.join(ERROR_NAMES)}")


def perturbations(error: ToleranceError, tolerance: float, nominal: float) -> dict[str, float]:
    """The runs of one error: a label -> the setting's value."""
    if error.kind == "spread":
        return {f"sd {tolerance:g} {error.unit}".rstrip(): tolerance}
    return {f"{sign}{tolerance:g} {error.unit}".rstrip(): nominal + factor * tolerance
            for sign, factor in (("-", -1.0), ("+", 1.0))}


@dataclass(frozen=True)
class Effect:
    """One error's (or the joint draw's) runs: per run label the degradation of each estimate per seed."""

    name: str
    tolerance: float | None
    degradation: dict[str, dict[str, np.ndarray]]  # run label -> estimate -> (seeds,)


@dataclass(frozen=True)
class Ranked:
    """An error's rank for one estimate: its worst run's mean degradation and 95 % interval over seeds."""

    name: str
    run: str
    mean: float
    low: float
    high: float

    @property
    def inside_scatter(self) -> bool:
        return self.low <= 0.0 <= self.high


def interval(values: np.ndarray) -> tuple[float, float, float]:
    """Mean and 95 % t-interval of the mean over seeds."""
    from scipy import stats

    mean = float(np.mean(values))
    half = float(stats.t.ppf(0.975, len(values) - 1) * np.std(values, ddof=1) / np.sqrt(len(values)))
    return mean, mean - half, mean + half


@dataclass(frozen=True)
class ToleranceStudy:
    design: str
    seeds: tuple[int, ...]
    quick: bool
    estimates: tuple[str, ...]
    nominal: dict[str, np.ndarray]  # estimate -> (seeds,) validation error of the nominal unit
    effects: tuple[Effect, ...]  # the one-at-a-time errors, then the joint draw

    def ranking(self, estimate: str) -> list[Ranked]:
        """The one-at-a-time errors acting on ``estimate``, worst first (by their worst run's mean)."""
        ranked = []
        for effect in self.effects:
            if effect.name == JOINT or estimate not in next(iter(effect.degradation.values())):
                continue
            runs = {run: interval(values[estimate]) for run, values in effect.degradation.items()}
            run = max(runs, key=lambda r: runs[r][0])
            ranked.append(Ranked(effect.name, run, *runs[run]))
        return sorted(ranked, key=lambda r: -r.mean)

    def joint(self, estimate: str) -> tuple[float, float, float]:
        effect = next(e for e in self.effects if e.name == JOINT)
        return interval(effect.degradation[JOINT][estimate])

    def to_dict(self) -> dict:
        estimates = {}
        for estimate in self.estimates:
            ranked = self.ranking(estimate)
            nominal = self.nominal[estimate]
            estimates[estimate] = {
                "unit": ESTIMATES[estimate][1],
                "nominal_error": {"mean": float(nominal.mean()), "sd_over_seeds": float(nominal.std(ddof=1)),
                                  "per_seed": nominal.tolist()},
                "ranking": [{"rank": k + 1, "error": r.name, "worst_run": r.run, "degradation_mean": r.mean,
                             "interval_95": [r.low, r.high], "inside_seed_scatter": r.inside_scatter,
                             "apart_from_next": k + 1 < len(ranked) and r.low > ranked[k + 1].high}
                            for k, r in enumerate(ranked)],
                "joint": dict(zip(("degradation_mean", "interval_low", "interval_high"), self.joint(estimate),
                                  strict=True)),
                "runs": {e.name: {run: values[estimate].tolist() for run, values in e.degradation.items()}
                         for e in self.effects if estimate in next(iter(e.degradation.values()))}}
        return {"design": self.design, "seeds": list(self.seeds), "quick": self.quick,
                "errors": [{"name": e.name, "setting": e.setting, "kind": e.kind,
                            "tolerance": next((x.tolerance for x in self.effects if x.name == e.name), None),
                            "unit": e.unit, "protocols": list(e.protocols), "source": e.source()}
                           for e in ERRORS if any(x.name == e.name for x in self.effects)],
                "estimates": estimates}


def orientation_errors(dataset, seed: int) -> dict[str, float]:
    """Mean orientation error (deg) of each published method on the validation trials."""
    from softtip import metrics
    from softtip.systems.hall_fingertip.studies import orientation_fits

    truth, _, fits = orientation_fits(dataset, seed)
    return {f"orientation · {method}": metrics.mean_abs_error(truth, estimate) for method, (_, estimate) in fits.items()}


def force_errors(dataset, seed: int) -> dict[str, float]:
    """Mean absolute error (N) per axis of the published network on the validation trials, in contact."""
    from softtip import metrics
    from softtip.calibration import LMNetwork, fitted
    from softtip.data.splits import by_role

    X = dataset.X()
    y = np.column_stack([dataset.column(axis) for axis in FORCE_AXES])
    contact = np.abs(y).max(axis=1) > CONTACT_N
    calibration, validation = by_role(dataset)
    train, test = contact & calibration, contact & validation
    model = fitted(LMNetwork((10,), random_state=seed), X[train], y[train], groups=dataset.groups[train])
    errors = metrics.mean_abs_error(y[test], model.predict(X[test]))
    return dict(zip(FORCES, np.atleast_1d(errors).tolist(), strict=True))


SCORES = {PUSHING: orientation_errors, FORCE: force_errors}


def nominal_protocol(name: str, design: Design, seed: int, quick: bool, errors: tuple[ToleranceError, ...]) -> Protocol:
    """The coarse protocol on ``design`` with every candidate error at its nominal value."""
    from softtip.lab import load_protocol

    protocol = replace(load_protocol(name), design=design).changed(seed=seed, **(QUICK if quick else COARSE)[name])
    spreads = {e.setting: 0.0 for e in errors if e.kind == "spread"}
    return replace(protocol, realism=replace(protocol.realism, **spreads))


def protocols_of(estimates: tuple[str, ...]) -> list[str]:
    return [p for p in BOTH if any(ESTIMATES[e][0] == p for e in estimates)]


def check_tolerances(design: Design, chosen: tuple[ToleranceError, ...], tolerances: dict[str, float],
                     protocols: list[str], quick: bool) -> None:
    """Refuse, before any run, a tolerance the realism table refuses (a modulus change of -1 or less)."""
    for name in protocols:
        realism = nominal_protocol(name, design, 0, quick, chosen).realism
        for error in (e for e in chosen if name in e.protocols):
            for value in perturbations(error, tolerances[error.name], getattr(realism, error.setting)).values():
                try:
                    replace(realism, **{error.setting: value})
                except ValueError as problem:
                    raise ValueError(f"tolerance of {error.name} = {tolerances[error.name]:g}: {problem}") from None


def tolerance_study(design: Design, seeds: tuple[int, ...], errors: tuple[str, ...] = ERROR_NAMES,
                    tolerances: dict[str, float] | None = None, estimates: tuple[str, ...] = tuple(ESTIMATES),
                    quick: bool = False, progress: Progress = SILENT) -> ToleranceStudy:
    """The study of the module notes for ``design`` over ``seeds`` (at least two: the interval needs a
    scatter), with ``errors`` (names of :data:`ERRORS`) at ``tolerances`` (name -> value; default each
    error's own) and the ``estimates`` (keys of :data:`ESTIMATES`)."""
    from softtip.lab import run_protocol

    if len(seeds) < 2:
        raise ValueError(f"seeds = {list(seeds)}: expected at least 2 (the interval over seeds needs a scatter)")
    chosen = tuple(error_named(name) for name in errors)
    tolerances = {error.name: error.tolerance for error in chosen} | (tolerances or {})
    for name, value in tolerances.items():
        error_named(name)
        if not np.isfinite(value) or value < 0:
            raise ValueError(f"tolerance of {name} = {value}: expected a finite number >= 0")
    protocols = protocols_of(estimates)
    acting = {p: tuple(e for e in chosen if p in e.protocols) for p in protocols}
    check_tolerances(design, chosen, tolerances, protocols, quick)
    runs = {p: 2 + sum(1 if e.kind == "spread" else 2 for e in acting[p]) for p in protocols}
    nominal = {estimate: np.zeros(len(seeds)) for estimate in estimates}
    degradation: dict[str, dict[str, dict[str, np.ndarray]]] = {e.name: {} for e in chosen}
    degradation[JOINT] = {JOINT: {estimate: np.zeros(len(seeds)) for estimate in estimates}}

    def record(name: str, run: str, k: int, scores: dict[str, float], base: dict[str, float]) -> None:
        per_estimate = degradation[name].setdefault(run, {})
        for estimate, value in scores.items():
            if estimate in estimates:
                per_estimate.setdefault(estimate, np.zeros(len(seeds)))[k] = value - base[estimate]

    with progress.task("tolerance runs", total=len(seeds) * sum(runs.values())) as task:
        for k, seed in enumerate(seeds):
            draw = np.random.default_rng([seed, JOINT_STREAM])  # the joint unit's offsets, one per error
            within = {e.name: draw.uniform(-1, 1) for e in chosen if e.kind == "offset"}
            for name in protocols:
                base_protocol = nominal_protocol(name, design, seed, quick, chosen)

                def scored(settings: dict[str, float], label: str) -> dict[str, float]:
                    protocol = replace(base_protocol, realism=replace(base_protocol.realism, **settings))
                    scores = SCORES[name](run_protocol(protocol)[0], seed)
                    task.advance(note=f"seed {seed} {name}: {label}")
                    return scores

                base = scored({}, "nominal")
                for estimate, value in base.items():
                    if estimate in estimates:
                        nominal[estimate][k] = value
                joint = {}
                for error in acting[name]:
                    value_at = getattr(base_protocol.realism, error.setting)
                    tolerance = tolerances[error.name]
                    for run, value in perturbations(error, tolerance, value_at).items():
                        record(error.name, run, k, scored({error.setting: value}, f"{error.name} {run}"), base)
                    joint[error.setting] = (tolerance if error.kind == "spread"
                                            else value_at + tolerance * within[error.name])
                record(JOINT, JOINT, k, scored(joint, "all at once"), base)
    effects = tuple(Effect(e.name, tolerances[e.name], degradation[e.name]) for e in chosen if degradation[e.name])
    return ToleranceStudy(design.name, tuple(seeds), quick, tuple(estimates), nominal,
                          (*effects, Effect(JOINT, None, degradation[JOINT])))


def plot_tolerance(study: ToleranceStudy):
    """A ranked bar chart per estimate: each error's worst-run degradation with its 95 % interval over
    seeds, the joint draw's below, and the nominal unit's scatter over seeds shaded."""
    from matplotlib.figure import Figure

    columns = min(3, len(study.estimates))
    rows = -(-len(study.estimates) // columns)
    figure = Figure(figsize=(5.2 * columns, rows * (0.4 * len(study.effects) + 2.0) + 0.4), layout="constrained")
    axes = np.ravel(figure.subplots(rows, columns, squeeze=False))
    for ax in axes[len(study.estimates):]:
        ax.set_axis_off()
    for ax, estimate in zip(axes, study.estimates):
        ranked = study.ranking(estimate)
        joint = study.joint(estimate)
        means = np.array([r.mean for r in ranked] + [joint[0]])
        spans = np.array([[r.mean - r.low, r.high - r.mean] for r in ranked] + [[joint[0] - joint[1], joint[2] - joint[0]]])
        rows = np.arange(len(means))
        colours = ["tab:gray" if r.inside_scatter else "tab:red" for r in ranked] + ["tab:purple"]
        ax.barh(rows, means, xerr=spans.T, color=colours, capsize=3)
        ax.set_yticks(rows, [f"{r.name} ({r.run})" for r in ranked] + ["all at once"], fontsize="small")
        ax.invert_yaxis()
        scatter = float(np.std(study.nominal[estimate], ddof=1))
        ax.axvspan(-scatter, scatter, color="tab:blue", alpha=0.12, lw=0)
        ax.axvline(0, color="k", lw=0.8)
        unit = ESTIMATES[estimate][1]
        ax.set_xlabel(f"validation error minus nominal ({unit})")
        ax.set_title(f"{estimate}\nnominal {np.mean(study.nominal[estimate]):.3g} ± {scatter:.2g} {unit}",
                     fontsize="medium")
    figure.suptitle(f"Tolerance sensitivity, design {study.design}, {len(study.seeds)} seeds: bars the mean "
                    "degradation, whiskers its 95 % interval;\nred: outside the seed scatter, grey: inside; "
                    "shaded: the nominal unit's sd over seeds", fontsize="medium")
    return figure


def tolerance_report(study: ToleranceStudy, figure):
    """The HTML report: the errors and their sources, a ranked table and chart per estimate."""
    from softtip.report.document import Figure, Report, Section
    from softtip.report.tables import Table

    data = study.to_dict()
    protocols = {name: "; ".join(f"{key} {value}" for key, value in settings.items())
                 for name, settings in (QUICK if study.quick else COARSE).items()}
    errors = Table("The candidate errors and their tolerances", "error", [e["name"] for e in data["errors"]],
                   ["realism setting", "kind", "tolerance", "acts in", "source"],
                   {**{(e["name"], "realism setting"): e["setting"] for e in data["errors"]},
                    **{(e["name"], "kind"): e["kind"] for e in data["errors"]},
                    **{(e["name"], "tolerance"): f"{e['tolerance']:g} {e['unit']}".strip() for e in data["errors"]},
                    **{(e["name"], "acts in"): ", ".join(e["protocols"]) for e in data["errors"]},
                    **{(e["name"], "source"): e["source"] for e in data["errors"]}},
                   caption="An offset runs at its nominal value - and + its tolerance; a spread runs with its "
                           "tolerance as one standard deviation (the draw carries the sign).")
    tables = []
    for estimate, result in data["estimates"].items():
        unit = result["unit"]
        rows = [f"{r['rank']}. {r['error']}" for r in result["ranking"]]
        cells = {}
        for row, r in zip(rows, result["ranking"], strict=True):
            cells.update({(row, "worst run"): r["worst_run"], (row, "degradation"): r["degradation_mean"],
                          (row, "95 % interval"): f"{r['interval_95'][0]:+.3g} … {r['interval_95'][1]:+.3g}",
                          (row, "verdict"): ("inside the seed scatter" if r["inside_seed_scatter"] else "degrades")
                          + ("; apart from the next" if r["apart_from_next"] else "")})
        joint = result["joint"]
        rows.append(JOINT)
        cells.update({(JOINT, "degradation"): joint["degradation_mean"],
                      (JOINT, "95 % interval"): f"{joint['interval_low']:+.3g} … {joint['interval_high']:+.3g}"})
        nominal = result["nominal_error"]
        tables.append(Table(f"{estimate}: errors ranked by degradation", "error", rows,
                            ["worst run", "degradation", "95 % interval", "verdict"], cells, unit=unit, digits=3,
                            caption=f"Nominal unit's validation error {nominal['mean']:.3g} ± "
                                    f"{nominal['sd_over_seeds']:.2g} {unit} (sd over seeds). Degradation: the "
                                    "error's validation error minus the nominal unit's, same seed; 95 % t-interval "
                                    "over seeds. 'Apart from the next': its interval lies above the next one's; "
                                    "otherwise the two are not ranked apart by these seeds."))
    return Report(f"Tolerance sensitivity of the Hall fingertip, design {study.design}",
                  f"seeds {', '.join(map(str, study.seeds))}; {'quick' if study.quick else 'coarse'} protocols "
                  f"(pushing and 3-axis force); softtip fingertip tolerance", [
                      Section("Method", [
                          "The nominal unit has every candidate error at its nominal value: the fabrication spreads "
                          "at zero, the bench's offsets at the protocol's values, the per-trial scatter off; the "
                          "sensors' noise and the magnets' temperature walk stay on. Each error then runs alone, "
                          "and all of them at once (the spreads at their tolerance, each offset drawn uniformly "
                          "within its tolerance, seeded).",
                          f"Every run re-fits and validates each estimate on its protocol: pushing "
                          f"({protocols[PUSHING]}; polynomial and network, as the pushing study) and 3-axis force "
                          f"({protocols[FORCE]}; the published 3-10-3 network). The degradation is the run's "
                          "validation error minus the nominal unit's for the same seed (the same trials, noise and "
                          "draws); over the seeds, its mean and 95 % t-interval. An interval that holds zero is "
                          "inside the seed scatter."], [errors]),
                      Section("Which errors matter for each estimate", [
                          "A negative degradation is an error that helps: on design D's four-fold symmetric unit "
                          "a fabrication error, like the stage's offset, breaks the symmetry that makes a board at "
                          "a and at a + 90° read alike. A small effect inside the seed scatter is not ranked "
                          "apart from its neighbours; more seeds narrow the intervals.",
                          "The chip's axes in its package (a tilt or rotation of the Hall plate) are not a setting "
                          "of the twin and are not ranked here."], tables,
                          [Figure.of("Ranked degradation per estimate", "The longest red bar is the tolerance to "
                                     "tighten first for that estimate; grey bars are inside the scatter between "
                                     "seeds.", figure)])])
