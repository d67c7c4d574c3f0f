"""Design objectives: a registry of named, configurable scores of FE results.

An objective is made by a factory registered under a name, with the schema of its settings::

    from softtip._core.config import PositiveNumber, schema
    from softtip.optimize.objectives import Objective, ObjectiveSettings, objective
    from softtip.optimize.runs import Simulation

    @schema
    class PeakForce(ObjectiveSettings):    # the load-case keys, name, goal, module - and its own
        scale: PositiveNumber = 1.0

    @objective("peak_force", PeakForce)
    def peak_force(settings, design):
        return Objective(name="peak_force", simulations=(Simulation.of(settings),), goal="min", unit="N",
                         score=lambda design, results: settings.scale * float(results[0].force_N[2]))

The study's ``[objective]`` table is validated against the schema (one-line
errors, unknown keys refused); the factory gets the settings and the study's
base design, may refuse a key that does not suit the design by raising
:class:`~softtip._core.config.Refusal`, and returns the FE runs it needs per
design (``simulations``) and a ``score`` of their results. Workers only run
the simulations; scores are computed by the client, from fresh or cached
results alike.

Objectives in other modules are found in two ways: modules listed in
:data:`PLUGIN_MODULES` are imported when an objective is first looked up (so
``softtip.optimize.estimation`` registers itself just by existing), and a study
may name any importable module with ``objective.module``.
"""

from __future__ import annotations

import dataclasses
import importlib
from dataclasses import dataclass
from typing import Annotated, Any, Callable, Literal, Sequence

import numpy as np

from softtip._core.config import Refusal, Text, Whole, choice, expect, parse, refused, schema
from softtip._core.units import MM
from softtip.design.model import Design
from softtip.optimize.errors import StudyError
from softtip.optimize.runs import FEResult, Simulation

GOALS = ("max", "min")
PLUGIN_MODULES = ("softtip.optimize.estimation",)

Score = Callable[[Design, Sequence[FEResult]], float]


@dataclass(frozen=True)
class Objective:
    name: str
    simulations: tuple[Simulation, ...]  # FE runs per design, in the order ``score`` receives their results
    score: Score
    goal: str = "max"  # the factory's natural direction; a study may override it with objective.goal
    unit: str = ""


class Infeasible(StudyError):
    """Raised by a score when a design violates a constraint only its results can reveal
    (a saturated sensor, say): the design is reported infeasible, not failed."""


@schema
class _Choice:
    """Which objective, from which module (imported before the objective is looked up)."""

    name: Text = "feature_displacement"
    module: Text | None = None


@schema
class ObjectiveSettings(Simulation, _Choice):
    """The keys every ``[objective]`` table may hold: which objective (from which module), its goal
    (default: the objective's own), and the load case of a :class:`~softtip.optimize.runs.Simulation`."""

    goal: choice(*GOALS) | None = None


ObjectiveFactory = Callable[[Any, Design], Objective]
_REGISTRY: dict[str, tuple[ObjectiveFactory, type]] = {}
_imported_plugins = False


def objective(name: str, settings: type = ObjectiveSettings) -> Callable[[ObjectiveFactory], ObjectiveFactory]:
    """Register ``factory(settings, base_design) -> Objective`` under ``name``; ``settings`` is the
    schema of its ``[objective]`` table (:class:`ObjectiveSettings` or a schema extending it)."""

    def register(factory: ObjectiveFactory) -> ObjectiveFactory:
        if name in _REGISTRY and _REGISTRY[name][0] is not factory:
            raise ValueError(f"objective {name!r} is already registered by {_REGISTRY[name][0].__module__}")
        _REGISTRY[name] = factory, settings
        return factory

    return register


def _import_plugins() -> None:
    global _imported_plugins
    if _imported_plugins:
        return
    for module in PLUGIN_MODULES:
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as error:
            if error.name != module:  # the plugin exists but is broken: say so
                raise
    _imported_plugins = True


def objective_names() -> list[str]:
    _import_plugins()
    return sorted(_REGISTRY)


def build_objective(table: dict[str, Any], base_design: Design, source: str) -> Objective:
    """The objective described by a study's ``[objective]`` table."""
    chosen = parse(_Choice, {k: table[k] for k in ("name", "module") if k in table}, source, "objective",
                   error=StudyError)
    if chosen.module is not None:
        try:
            importlib.import_module(chosen.module)
        except ImportError as error:
            raise refused(f"cannot import it ({error})", source, "objective", "module", value=chosen.module,
                          error=StudyError) from None
    names = objective_names()
    if chosen.name not in _REGISTRY:
        raise refused(f"expected one of {', '.join(names)}", source, "objective", "name", value=chosen.name,
                      error=StudyError)
    factory, settings_schema = _REGISTRY[chosen.name]
    settings = parse(settings_schema, table, source, "objective", error=StudyError)
    try:
        made = factory(settings, base_design)
    except Refusal as refusal:
        raise refusal.locate(table, source, "objective", error=StudyError) from None
    return dataclasses.replace(made, goal=settings.goal or made.goal)


# --------------------------------------------------------------------------- built-in objectives

COMPONENTS = ("x", "y", "z", "magnitude")
MAGNET_STATISTICS = ("max", "mean")
Magnet = Annotated[Literal[MAGNET_STATISTICS] | Whole, expect("max, mean or a magnet index")]


@schema
class FeatureDisplacementSettings(ObjectiveSettings):
    component: choice(*COMPONENTS) = "z"
    magnet: Magnet = "max"


@objective("feature_displacement", FeatureDisplacementSettings)
def feature_displacement(settings: FeatureDisplacementSettings, design: Design) -> Objective:
    """Displacement (mm) of the feature point - the centre of a magnet's top face - under a load case.

    The published objective: the vertical (``component = "z"``) displacement under a
    1.6 mm board pushed 1 mm down, for the magnet that moves most (``magnet = "max"``,
    the one under the board), maximised. ``magnet`` may also be ``"mean"`` or an
    index; values are magnitudes, so "more displacement" is always larger.
    """
    simulation = Simulation.of(settings)
    component, magnet = settings.component, settings.magnet
    count = len(design.magnets)
    if magnet not in MAGNET_STATISTICS and not 0 <= magnet < count:
        raise Refusal("magnet", f"expected max, mean or a magnet index 0..{count - 1}")

    def score(design: Design, results: Sequence[FEResult]) -> float:
        displacement = results[0].feature_displacements_m
        per_magnet = (np.linalg.norm(displacement, axis=1) if component == "magnitude"
                      else np.abs(displacement[:, "xyz".index(component)]))
        if magnet == "max":
            return float(per_magnet.max() / MM)
        if magnet == "mean":
            return float(per_magnet.mean() / MM)
        if magnet >= len(per_magnet):
            raise StudyError(f"{design.name}: objective.magnet = {magnet}, but the design has "
                             f"{len(per_magnet)} magnets")
        return float(per_magnet[magnet] / MM)

    return Objective(name="feature_displacement", simulations=(simulation,), score=score, goal="max", unit="mm")
