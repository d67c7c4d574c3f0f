"""How a fingertip's body answers a load: the engines behind the twin.

An engine turns load cases into magnet poses and the force on the indenter; the twin puts a
readout after it (:class:`softtip.twin.Twin`). Three engines share one interface:

* :class:`FiniteElementEngine` - the full finite-element contact solve (linear or neo-Hookean),
  one load at a time, seconds per load;
* :class:`softtip.twin.influence.InfluenceEngine` - exact small-strain contact on the influence
  matrices of the surface (the lab's presses, the reduced twin's samples), milliseconds;
* :class:`softtip.twin.reduced.ReducedTwin` - networks fitted to exact solves, microseconds per
  load in batch.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Protocol, Sequence

import numpy as np

from softtip._core.progress import SILENT, Progress
from softtip.design.model import MM, Design
from softtip.mechanics.contact import LoadCase, solve_hyperelastic_contact, solve_linear_contact
from softtip.mechanics.fe import BodyModel
from softtip.mechanics.mesh import TetMesh, mesh_design
from softtip.mechanics.poses import MagnetPoses

DEFAULT_MESH_SIZE = 1.0 * MM  # within 1 % of a 0.6 mm mesh for the board push (see the README)
MODELS = ("linear", "neo-hookean")


@dataclass
class Response:
    """The body's answer to N loads: magnet poses (N, M, 3) and the force (N, 3) in N of the body
    on the indenter (its reaction; Fz > 0 when pushing down). ``solutions`` holds each load's
    solver result where the engine has one (contact set, displacements, iterations)."""

    poses: MagnetPoses
    force: np.ndarray
    model: str  # the mechanics that answered: "linear" or "neo-hookean" FE, "influence", "reduced"
    solutions: list[Any] = field(default_factory=list)
    timings: dict = field(default_factory=dict)

    @classmethod
    def of_solutions(cls, solutions: list[Any], model: str, timings: dict | None = None) -> Response:
        """The response assembled from per-load contact results (each with magnet poses and force)."""
        return cls(poses=MagnetPoses.stack([s.magnet_poses for s in solutions]),
                   force=np.array([s.force for s in solutions]), model=model, solutions=solutions,
                   timings=timings or {})


class Engine(Protocol):
    design: Design

    def respond(self, loads: Sequence[LoadCase]) -> Response:
        """Magnet poses and forces for ``loads``."""


class FiniteElementEngine:
    """A design's mesh and body model, solved for every load by finite-element contact."""

    def __init__(self, design: Design, mesh_size: float = DEFAULT_MESH_SIZE, model: str = "linear",
                 use_cache: bool = True):
        self.design, self.mesh_size, self.model = design, mesh_size, _checked_model(model)
        self.timings: dict[str, float] = {}
        start = time.perf_counter()
        self.mesh: TetMesh = mesh_design(design, mesh_size, use_cache=use_cache)
        self.timings["mesh_s"] = time.perf_counter() - start
        self._body: BodyModel | None = None

    @property
    def body(self) -> BodyModel:
        if self._body is None:
            start = time.perf_counter()
            self._body = BodyModel.for_design(self.design, self.mesh)
            self.timings["body_model_s"] = time.perf_counter() - start
        return self._body

    def respond(self, loads: Sequence[LoadCase], model: str | None = None, progress: Progress = SILENT) -> Response:
        model = _checked_model(model or self.model)
        body = self.body
        solutions = [solve_linear_contact(body, load, progress=progress) if model == "linear"
                     else solve_hyperelastic_contact(body, load, progress=progress) for load in loads]
        timings = dict(self.timings)
        for solution in solutions:
            for key, seconds in solution.timings.items():
                timings[key] = timings.get(key, 0.0) + seconds
        return Response.of_solutions(solutions, model, timings)


def _checked_model(model: str) -> str:
    if model not in MODELS:
        raise ValueError(f"model = {model!r}: expected one of {', '.join(MODELS)}")
    return model
