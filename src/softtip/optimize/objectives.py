"""Design objectives: a registry of named, configurable scores of FE results.

An objective is made by a factory registered under a name::

    from softtip.optimize.objectives import Objective, objective, read_simulation

    @objective("peak_force")
    def peak_force(settings, design):
        simulation = read_simulation(settings)          # the load-case keys of [objective]
        return Objective(name="peak_force", simulations=(simulation,), goal="min", unit="N",
                         score=lambda design, results: float(results[0].force_N[2]))

The factory reads its settings from the study's ``[objective]`` table through a
:class:`~softtip.optimize.settings.SettingsReader` (unknown keys are refused
after it returns), may check them against the study's base design, and
returns the FE runs it needs per design (``simulations``) and a ``score`` of
their results. Workers only run the simulations; scores are computed by the
client, from fresh or cached results alike.

Objectives in other modules are found in two ways: modules listed in
:data:`PLUGIN_MODULES` are imported when an objective is first looked up (so
``softtip.optimize.estimation`` registers itself just by existing), and a study
may name any importable module with ``objective.module``.
"""

from __future__ import annotations

import dataclasses
import importlib
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from softtip.design.model import MM, Design
from softtip.optimize.runs import FEResult, Simulation, read_simulation
from softtip.optimize.settings import SettingsReader, StudyError

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


ObjectiveFactory = Callable[[SettingsReader, Design], Objective]
_REGISTRY: dict[str, ObjectiveFactory] = {}
_imported_plugins = False


def objective(name: str) -> Callable[[ObjectiveFactory], ObjectiveFactory]:
    """Register ``factory(settings, base_design) -> Objective`` under ``name``."""

    def register(factory: ObjectiveFactory) -> ObjectiveFactory:
        if name in _REGISTRY and _REGISTRY[name] is not factory:
            raise ValueError(f"objective {name!r} is already registered by {_REGISTRY[name].__module__}")
        _REGISTRY[name] = factory
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


def build_objective(table: Any, base_design: Design, source: str) -> Objective:
    """The objective described by a study's ``[objective]`` table."""
    settings = SettingsReader(source, table, "objective")
    if settings.has("module"):
        module = settings.string("module")
        try:
            importlib.import_module(module)
        except ImportError as error:
            raise settings.fail("module", f"cannot import it ({error})") from None
    names = objective_names()
    name = settings.string("name", "feature_displacement")
    if name not in _REGISTRY:
        raise settings.fail("name", f"expected one of {', '.join(names)}")
    made = _REGISTRY[name](settings, base_design)
    goal = settings.choice("goal", GOALS, made.goal)
    settings.finish()
    return dataclasses.replace(made, goal=goal)


# --------------------------------------------------------------------------- built-in objectives

COMPONENTS = ("x", "y", "z", "magnitude")
MAGNET_STATISTICS = ("max", "mean")


@objective("feature_displacement")
def feature_displacement(settings: SettingsReader, design: Design) -> Objective:
    """Displacement (mm) of the feature point - the centre of a magnet's top face - under a load case.

    The published objective: the vertical (``component = "z"``) displacement under a
    1.6 mm board pushed 1 mm down, for the magnet that moves most (``magnet = "max"``,
    the one under the board), maximised. ``magnet`` may also be ``"mean"`` or an
    index; values are magnitudes, so "more displacement" is always larger.
    """
    simulation = read_simulation(settings)
    component = settings.choice("component", COMPONENTS, "z")
    magnet = settings.raw("magnet", "max")
    count = len(design.magnets)
    if magnet not in MAGNET_STATISTICS and not (isinstance(magnet, int) and not isinstance(magnet, bool)
                                                and 0 <= magnet < count):
        raise settings.fail("magnet", f"expected max, mean or a magnet index 0..{count - 1}")

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
