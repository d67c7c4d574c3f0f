"""A design search on the same die: which pillars resolve the smallest force over a stated force range.

The question a designer asks before fabrication: with this die (its meanders, its readout and noise), what
pillar diameter, height, taper, moment, placement and number of pillars resolve the smallest force over
the range the application needs? The figure of merit of a design for a stated range R is the largest
3σ minimum force over forces 0..R (:mod:`softtip.systems.cilia.resolution`: three standard deviations
of one reading over the local slope): what the sensor can promise everywhere in its range. A curve whose
slope changes sign within R reads two forces alike: such a design has no figure for that range. The
load is paper mode's (a tip force perpendicular to each pillar, as the published simulation and fit).

The design space (each parameter on ``steps`` equal values):

* ``tip_diameter_um`` 100–300; ``taper`` (base / tip diameter) 1–2; ``height_mm`` 0.5–1.5;
* ``moment_memu`` 0.5–4.5 per pillar, at most the published composite's magnetisation times the pillar's
  volume (14 % v/v NdFeB: 2.8 memu in the nominal 1 mm, 200/320 µm cone; a design may be magnetised less,
  not more);
* the placement: ``pattern`` (one pillar at the centre; four at the corners of a square; four and one at
  the centre, as published; a 3 × 3 grid), ``pitch_mm`` 0.4–1.2 (the corner pillars' distance from the
  centre along x and y) and ``offset_mm`` −0.6–0.6 (the whole array moved along y, across the X meander's
  edges).

Candidates whose bases leave the die or overlap, whose pillars are wider than long, or whose moment the
composite cannot carry are refused before the search, with the reason (the die file's own checks,
:func:`softtip.systems.cilia.layout.placement_problem`). The search is softtip's optimiser
(:class:`softtip.optimize.bayes.BayesianSearch`: Gaussian-process expected improvement on the discrete
candidate grid, :mod:`softtip.optimize.space` for the grid), run once per stated range on log10 of the
figure of merit, smallest range first; each range's search is told every design the earlier ones
evaluated (a design's curve gives its figure at every range). With ``descend`` the global search is
followed by a descent on the grid from its best design, one neighbour at a time (one parameter one step up
or down, or another placement), to the first neighbour that is better, until none is: each range's search
then ends in a local minimum of the grid, every one of whose neighbours it has evaluated (at five values per
parameter about as many evaluations again as the global search's). The trade-off curve is the lower envelope of
every evaluated design's figure against the range; each range's best is the best at that range of every
design evaluated (a later range's search may find a better one for an earlier range), so it lies on that
curve, and the report says whether it beats the published design.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from softtip._core.errors import NotConverged
from softtip._core.progress import SILENT, Progress
from softtip._core.units import MM, MN, UM, UN
from softtip.optimize.bayes import BayesianSearch
from softtip.optimize.space import ParameterRange, grid_candidates, normalised_points
from softtip.report.tables import Table
from softtip.systems.cilia.layout import MEMU, Die, DieError, Pillars, pillar_rod, placement_problem
from softtip.systems.cilia.model import CiliaModel
from softtip.systems.cilia.resolution import resolution

INITIAL = 10  # the space-filling start of a range's search, at most half its budget (optimize's 2 x 7 + 1 is too many)
PATTERNS = ("centre", "corners", "corners and centre", "3 x 3")
SPACE = (("tip_diameter_um", 100.0, 300.0), ("taper", 1.0, 2.0), ("height_mm", 0.5, 1.5),
         ("moment_memu", 0.5, 4.5), ("pitch_mm", 0.4, 1.2), ("offset_mm", -0.6, 0.6))


@dataclass(frozen=True)
class PillarDesign:
    """One candidate, in the units its parameters are named in."""

    pattern: int
    pitch_mm: float
    offset_mm: float
    tip_diameter_um: float
    taper: float
    height_mm: float
    moment_memu: float

    @classmethod
    def of(cls, params: dict[str, float]) -> PillarDesign:
        return cls(int(params["pattern"]), params["pitch_mm"], params["offset_mm"], params["tip_diameter_um"],
                   params["taper"], params["height_mm"], params["moment_memu"])

    @property
    def positions(self) -> NDArray[np.float64]:
        """(P, 2) base positions (m)."""
        p = self.pitch_mm
        corners = [(-p, -p), (p, -p), (-p, p), (p, p)]
        layout = {0: [(0.0, 0.0)], 1: corners, 2: [*corners, (0.0, 0.0)],
                  3: [(x, y) for y in (-p, 0.0, p) for x in (-p, 0.0, p)]}[self.pattern]
        return (np.array(layout) + np.array([0.0, self.offset_mm])) * MM

    @property
    def base_diameter(self) -> float:
        return self.taper * self.tip_diameter_um * UM

    @property
    def volume(self) -> float:
        """m³ of one conical pillar."""
        tip, base = self.tip_diameter_um * UM, self.base_diameter
        return math.pi * self.height_mm * MM / 12 * (tip**2 + tip * base + base**2)

    def to_dict(self) -> dict:
        return {"pillars": len(self.positions), "pattern": PATTERNS[self.pattern],
                "pitch_mm": self.pitch_mm if self.pattern else None,
                "offset_mm": self.offset_mm, "tip_diameter_um": self.tip_diameter_um, "taper": self.taper,
                "height_mm": self.height_mm, "moment_memu": self.moment_memu}


def published_design(die: Die) -> PillarDesign:
    """The die file's pillars as a candidate (on the shipped die: the published corners and centre); a die
    whose pillars are none of the search's placements is refused."""
    pillars = die.pillars
    rod = pillars.rod
    positions = pillars.positions / MM
    offset = float(positions[:, 1].mean())
    pitch = float(np.abs(positions - [0.0, offset]).max())
    for pattern in range(len(PATTERNS)):
        design = PillarDesign(pattern, pitch, offset, rod.tip_diameter / UM, rod.base_diameter / rod.tip_diameter,
                              rod.length / MM, abs(pillars.moment) / MEMU)
        if design.positions.shape == pillars.positions.shape and np.allclose(
                np.sort(design.positions, axis=0), np.sort(pillars.positions, axis=0), rtol=0, atol=1e-9):
            return design
    raise DieError(f"{die.source}: pillars.positions_mm: expected one of the design search's placements "
                   f"({', '.join(PATTERNS)}, centred in x)")


def magnetisation_limit(die: Die) -> float:
    """A/m: the published composite's magnetisation, the die file's moment over its pillar's volume."""
    return abs(die.pillars.moment) / published_design(die).volume


def refusal(die: Die, design: PillarDesign, limit: float) -> str:
    """Why ``design`` cannot be built on ``die``; '' when it can."""
    if design.base_diameter > design.height_mm * MM or design.tip_diameter_um * UM > design.height_mm * MM:
        return "the pillar is wider than long"
    problem = placement_problem(design.positions, design.base_diameter, die.size)
    if problem:
        return problem.split(": ", 1)[1]  # what is wrong, without the pillar it names
    if design.moment_memu * MEMU > limit * design.volume * (1 + 1e-9):
        return "more moment than the composite carries in its volume"
    return ""


def design_model(die: Die, design: PillarDesign, chain_count: int) -> CiliaModel:
    """``die`` with ``design``'s pillars (Young's modulus, Poisson's ratio, base and bend direction kept)."""
    pillars = die.pillars
    template = replace(pillars.rod, length=design.height_mm * MM)
    rod = pillar_rod(template, design.tip_diameter_um * UM, design.base_diameter)
    moment = math.copysign(design.moment_memu * MEMU, pillars.moment)
    return CiliaModel(die.with_pillars(Pillars(design.positions, rod, moment, pillars.bend_azimuth)),
                      chain_count=chain_count)


@dataclass(frozen=True)
class Evaluation:
    """One design's figures along its curve: ``force`` (N) from 0 to the largest stated range (or the span
    its rod solved), the largest 3σ minimum force over 0..force (``worst``, N; inf once the slope has
    changed sign), the one at rest, the slope-criterion range (N, capped at the span) and the sensitivity
    (V/N)."""

    design: PillarDesign
    force: NDArray[np.float64]
    worst: NDArray[np.float64]
    at_rest: float
    range_end: float
    sensitivity: float

    def over(self, force_range: float) -> float:
        """The largest minimum force over 0..``force_range`` (N), the curve's samples and its value at the
        end of the range (log-interpolated between samples)."""
        finite = np.isfinite(self.worst)
        if not finite[0] or force_range > self.force[finite][-1] * (1 + 1e-9):
            return math.inf
        return float(np.exp(np.interp(force_range, self.force[finite], np.log(self.worst[finite]))))


def evaluate(die: Die, design: PillarDesign, sensor: str, force_top: float, points: int,
             chain_count: int, attempts: int = 3) -> Evaluation:
    """``design``'s figures on ``die`` along ``points`` forces up to ``force_top`` (N). Where the rod does
    not converge that far (a slender pillar far past lying over), the span is halved, up to ``attempts``
    times: the design then has no figure for ranges beyond the span it solved (:meth:`Evaluation.over`)."""
    model = design_model(die, design, chain_count)
    for attempt in range(attempts):
        try:
            resolved = resolution(model, sensor, force_top / 2**attempt, points=points)
            break
        except NotConverged:
            if attempt == attempts - 1:
                raise
    flipped = np.sign(resolved.slope) != np.sign(resolved.slope[0])
    minimum = np.where(np.cumsum(flipped) > 0, np.inf, resolved.minimum_force)
    worst = np.maximum.accumulate(minimum)
    return Evaluation(design, resolved.force, worst, resolved.minimum_force_at_rest, resolved.range[1],
                      resolved.sensitivity)


@dataclass(frozen=True)
class RangeSearch:
    """The search for one stated range: the best design found for it among every design evaluated (None:
    none has a figure), the evaluations its own global search asked for, why that search stopped, the
    designs its descent evaluated and where it ended (a local minimum of the grid: no neighbour better; None
    without a descent)."""

    force_range: float
    best: Evaluation | None
    evaluations: int
    stop_reason: str
    descent_evaluations: int
    local_minimum: Evaluation | None

    def beats(self, reference: Evaluation) -> bool:
        """The best design found resolves a smaller force over this range than ``reference``."""
        return self.best is not None and self.best.over(self.force_range) < reference.over(self.force_range)


@dataclass(frozen=True)
class DesignSearch:
    """Every stated range's search, every design evaluated (and how many did not converge), the published
    design, the candidates refused by reason, the wall time (s) and the trade-off figure."""

    sensor: str
    ranges: tuple[RangeSearch, ...]
    evaluated: tuple[Evaluation, ...]
    not_converged: int  # designs whose rod did not converge even to a quarter of the largest range
    published: Evaluation
    candidates: int
    refused: dict[str, int]
    steps: int
    seed: int
    seconds: float
    figure: Figure

    def envelope(self, ranges: NDArray) -> NDArray[np.float64]:
        """The trade-off curve: the smallest figure of any evaluated design at each range in ``ranges`` (N)."""
        return np.array([min((e.over(r) for e in self.evaluated), default=math.inf) for r in ranges])

    def to_dict(self) -> dict:
        def figures(e: Evaluation, force_range: float) -> dict:
            return {**e.design.to_dict(), "minimum_force_at_rest_uN": e.at_rest / UN,
                    "worst_minimum_force_uN": e.over(force_range) / UN if math.isfinite(e.over(force_range)) else None,
                    "range_end_mN": e.range_end / MN, "sensitivity_mV_per_mN": e.sensitivity}

        grid = np.linspace(self.ranges[0].force_range * 0.25, self.ranges[-1].force_range, 16)
        return {"sensor": self.sensor, "candidates": self.candidates, "refused": self.refused,
                "steps": self.steps, "seed": self.seed, "evaluated": len(self.evaluated),
                "not_converged": self.not_converged,
                "seconds": self.seconds,
                "ranges": [{"range_mN": s.force_range / MN, "evaluations": s.evaluations, "stop": s.stop_reason,
                            "descent_evaluations": s.descent_evaluations,
                            "beats_published": s.beats(self.published),
                            "best": None if s.best is None else figures(s.best, s.force_range),
                            "published": figures(self.published, s.force_range)} for s in self.ranges],
                "tradeoff": {"range_mN": (grid / MN).tolist(),
                             "minimum_force_uN": [None if not math.isfinite(v) else v / UN
                                                  for v in self.envelope(grid)]}}


def search_designs(die: Die, force_ranges: tuple[float, ...], sensor: str = "X", steps: int = 5,
                   budget: int = 30, points: int = 17, chain_count: int = 10, seed: int = 0,
                   progress: Progress = SILENT, descend: bool = False) -> DesignSearch:
    """Search the design space (``steps`` values per parameter) for the smallest figure of merit at each
    of ``force_ranges`` (N), ``budget`` evaluations each, every design's curve sampled at ``points``
    forces; with ``descend``, each range's search then descends to a local minimum of the grid."""
    ranges = tuple(sorted(float(r) for r in force_ranges))
    if not ranges or not all(math.isfinite(r) and r > 0 for r in ranges):
        raise DieError(f"force_ranges = {force_ranges!r}: expected one or more positive forces in N")
    if not 2 <= steps <= 9:
        raise DieError(f"steps = {steps!r}: expected 2 to 9 values per parameter")
    if budget < 1 or points < 5:
        raise DieError(f"budget = {budget!r}, points = {points!r}: expected a budget >= 1 and >= 5 points")
    start = time.perf_counter()
    force_top = ranges[-1]
    published = evaluate(die, published_design(die), sensor, force_top, points, chain_count)  # refuses a die first
    space = tuple(ParameterRange(name, low, high, (high - low) / (steps - 1)) for name, low, high in SPACE)
    space += (ParameterRange("pattern", 0, len(PATTERNS) - 1, 1, integer=True),)
    limit = magnetisation_limit(die)
    candidates, refused = [], {}
    for params in grid_candidates(space):
        design = PillarDesign.of(params)
        reason = refusal(die, design, limit)
        if reason:
            refused[reason] = refused.get(reason, 0) + 1
        else:
            candidates.append((params, design))
    if not candidates:
        raise DieError("the design space holds no design that fits the die")
    points_ = normalised_points(space, [params for params, _ in candidates])
    known: dict[PillarDesign, Evaluation | None] = {}  # None: the rod did not converge

    def evaluated(design: PillarDesign) -> Evaluation | None:
        key = replace(design, pitch_mm=0.0) if design.pattern == 0 else design  # one pillar: no pitch
        if key not in known:
            try:
                known[key] = evaluate(die, design, sensor, force_top, points, chain_count)
            except NotConverged:  # reported as failed: the search goes elsewhere
                known[key] = None
        return known[key]

    def figure_of(result: Evaluation | None, force_range: float) -> float:
        return math.inf if result is None else result.over(force_range)

    # a candidate's neighbours: one parameter one grid step away, or the same design in another placement
    step = np.array([1.0 / (steps - 1)] * len(SPACE) + [math.inf])  # the placement is a category

    def neighbours(index: int) -> NDArray[np.int_]:
        change = np.abs(points_ - points_[index])
        moved = change > 1e-9
        return np.flatnonzero((moved.sum(axis=1) == 1) & np.all(change <= step * (1 + 1e-9), axis=1))

    asked: dict[int, Evaluation | None] = {}  # every candidate evaluated, by its index
    searches = []
    for force_range in ranges:
        search = BayesianSearch(points_, budget=budget, seed=seed, initial=min(INITIAL, max(1, budget // 2)))
        for index, result in asked.items():  # the earlier ranges' evaluations inform this range's model
            figure = figure_of(result, force_range)
            search.tell(index, -math.log10(figure) if math.isfinite(figure) else None)
        with progress.task(f"design search, range {force_range / MN:g} mN", total=search.budget) as task:
            while picks := search.ask():
                for index in picks:
                    asked[index] = evaluated(candidates[index][1])
                    figure = figure_of(asked[index], force_range)
                    search.tell(index, -math.log10(figure) if math.isfinite(figure) else None)
                    best = min(asked.values(), key=lambda e: figure_of(e, force_range))
                    task.advance(note="best " + (f"{best.over(force_range) / UN:.3g} µN" if best else "-"))
        current = min(asked, key=lambda i: figure_of(asked[i], force_range))
        descended = 0
        if descend:
            with progress.task(f"descent on the grid, range {force_range / MN:g} mN", total=None) as task:
                while math.isfinite(figure_of(asked[current], force_range)):
                    for index in neighbours(current):
                        if index not in asked:
                            asked[index] = evaluated(candidates[index][1])
                            descended += 1
                            task.advance()
                        if figure_of(asked[index], force_range) < figure_of(asked[current], force_range):
                            current = index
                            break
                    else:  # no neighbour is better
                        break
        searches.append(RangeSearch(force_range, None, len(search.asked), search.stop_reason, descended,
                                    asked[current] if descend else None))
    evaluations = tuple(e for e in known.values() if e is not None)
    # each range's best among every design evaluated, the later ranges' included: what the trade-off curve
    # draws, so no range's best sits above it
    for index, found in enumerate(searches):
        best = min(evaluations, key=lambda e: e.over(found.force_range), default=None)
        if best is not None and math.isfinite(best.over(found.force_range)):
            searches[index] = replace(found, best=best)
    outcome = DesignSearch(sensor, tuple(searches), evaluations, len(known) - len(evaluations), published,
                           len(candidates) + sum(refused.values()), refused, steps, seed, 0.0, Figure())
    figure = tradeoff_figure(outcome)
    return replace(outcome, seconds=time.perf_counter() - start, figure=figure)


def tradeoff_figure(search: DesignSearch) -> Figure:
    """The smallest figure of merit against the stated range: the envelope of every evaluated design, the
    best design for each stated range (on the envelope), and the published design's own curve."""
    figure = Figure(figsize=(6.4, 4.2), layout="constrained")
    axes = figure.add_subplot()
    grid = np.linspace(search.ranges[0].force_range * 0.25, search.ranges[-1].force_range, 60)
    axes.semilogy(grid / MN, search.envelope(grid) / UN, "-", lw=1.5,
                  label=f"best of {len(search.evaluated)} evaluated designs")
    axes.semilogy(grid / MN, [search.published.over(r) / UN for r in grid], "--", lw=1.2, label="published design")
    for index, found in enumerate(search.ranges):
        if found.best is not None:
            design = found.best.design
            axes.semilogy(found.force_range / MN, found.best.over(found.force_range) / UN, "o", ms=7,
                          label=f"best for 0-{found.force_range / MN:g} mN: {len(design.positions)} pillar(s), "
                                f"{design.tip_diameter_um:g} µm, {design.height_mm:g} mm",
                          color=f"C{index + 2}")
    axes.set_xlabel("stated force range, 0 to (mN)")
    axes.set_ylabel(f"largest 3σ minimum force in range, {search.sensor} (µN)")
    axes.legend(fontsize=7)
    return figure


DESIGN_CAPTION = ("The largest 3σ minimum force over 0 to each stated range, against the range: the envelope of every "
                  "design the search evaluated, the best design of each range's search, and the published design's "
                  "own curve. The published design's figure rises steeply past its range (the slope-criterion end), "
                  "where its pillars have turned over.")
DESIGN_COLUMNS = ("pillars", "tip diameter (µm)", "taper", "height (mm)", "moment (memu)", "pitch (mm)",
                  "offset (mm)", "minimum force at rest (µN)", "largest minimum force over the range (µN)",
                  "range end (mN)")


def design_table(search: DesignSearch) -> Table:
    """The best design found for each range beside the published design at the same range, and whether it
    beats it."""
    rows, cells, notes = [], {}, {}
    for found in search.ranges:
        for who, evaluation in (("best found", found.best), ("published", search.published)):
            row = f"0–{found.force_range / MN:g} mN: {who}"
            rows.append(row)
            if who == "best found":
                notes[row] = ("beats the published design" if found.beats(search.published) else
                              "does not beat the published design: the search found nothing better in its budget")
            if evaluation is None:
                continue
            design, worst = evaluation.design, evaluation.over(found.force_range)
            values = (len(design.positions), design.tip_diameter_um, design.taper, design.height_mm,
                      design.moment_memu, design.pitch_mm if design.pattern else "—", design.offset_mm, evaluation.at_rest / UN,
                      worst / UN if math.isfinite(worst) else "ambiguous (slope changes sign)",
                      evaluation.range_end / MN)
            cells.update({(row, column): value for column, value in zip(DESIGN_COLUMNS, values)})
    refused = ", ".join(f"{count} {reason}" for reason, count in search.refused.items()) or "none"
    stops = "; ".join(f"{s.force_range / MN:g} mN: {s.evaluations} evaluations, {s.stop_reason}"
                      + (f", then {s.descent_evaluations} in the descent to a local minimum of the grid"
                         if s.local_minimum is not None else "") for s in search.ranges)
    return Table("Design search on the same die (softtip's addition)", "range and design", rows, list(DESIGN_COLUMNS),
                 cells, digits=3, notes=notes,
                 caption=f"Sensor {search.sensor}; {search.candidates} candidates ({search.steps} values per "
                         f"parameter, 4 placements); refused before the search: {refused}. Gaussian-process "
                         f"expected improvement (softtip.optimize), seed {search.seed}: {stops}. "
                         f"{len(search.evaluated)} designs evaluated, {search.not_converged} whose rods did not "
                         f"converge even to a quarter of the largest range; {search.seconds:.1f} s. The range end is where the slope "
                         "has fallen to a tenth (capped at the largest stated range).")
