"""What a contact solve returns, and how it tells that it did not converge.

Every solver works load step by load step, iterating within each until its own
criterion holds, and keeps a :class:`ConvergenceLog` of the steps. A step that
reaches the iteration cap first raises :class:`ContactNotConverged`, unless the
caller asked for non-convergence to be reported: then the solve goes on from
the last iterate and its result says ``converged=False``. A result never looks
converged when a step was not.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from softtip._core.errors import NotConverged
from softtip.mechanics.contact.load import LoadCase
from softtip.mechanics.poses import MagnetPoses


@dataclass(kw_only=True)
class Convergence:
    """The record every contact result carries."""

    converged: bool  # every load step met its solver's criterion
    iterations: int  # over all load steps
    residual: float  # the largest residual a load step ended with, in its solver's measure


@dataclass(kw_only=True)
class ContactResult(Convergence):
    """A contact solve on the finite-element body: its whole displacement field."""

    unknowns: np.ndarray
    magnet_poses: MagnetPoses  # (M, 3)
    force: np.ndarray  # (3,) N, force of the body on the indenter (its reaction); Fz > 0 when pushing down
    contact_nodes: np.ndarray  # indices of nodes in contact at the end
    displacements: np.ndarray  # (n_nodes, 3) m
    factorizations: int
    timings: dict = field(default_factory=dict)


@dataclass(kw_only=True)
class ReducedContactResult(Convergence):
    """A contact solve on a reduced view of the body (its surface compliance)."""

    magnet_poses: MagnetPoses  # (M, 3)
    force: np.ndarray  # (3,) N, the fingertip's reaction on the indenter
    contact_nodes: np.ndarray  # nodes in contact, as the solver numbers them
    path: list[tuple[np.ndarray, MagnetPoses, np.ndarray]]  # (travel (3,), magnet poses, force) after every step


class StepOutcome(NamedTuple):
    """How the iteration of one load step ended."""

    converged: bool
    iterations: int
    residual: float


class ContactNotConverged(NotConverged):
    """A contact solver reached its iteration cap in a load step before its criterion held."""

    def __init__(self, solver: str, load: LoadCase, step: int, steps: int, outcome: StepOutcome, measure: str):
        self.solver, self.load, self.step, self.steps, self.measure = solver, load, step, steps, measure
        self.iterations, self.residual = outcome.iterations, outcome.residual
        super().__init__(f"{solver} did not converge in load step {step} of {steps}: {outcome.iterations} "
                         f"iteration(s) left a residual of {outcome.residual:.3g} ({measure}); load: {load}")

    def __reduce__(self):  # rebuilt from its parts where it crosses a process boundary
        outcome = StepOutcome(False, self.iterations, self.residual)
        return type(self), (self.solver, self.load, self.step, self.steps, outcome, self.measure)


class ConvergenceLog:
    """The load steps of one solve, each iterated at most ``max_iterations`` times: raises on the
    first that did not converge, unless ``report``; :meth:`record` is the result's
    :class:`Convergence` fields."""

    def __init__(self, solver: str, measure: str, load: LoadCase, steps: int, max_iterations: int, report: bool):
        if not max_iterations >= 1:
            raise ValueError(f"max_iterations = {max_iterations}: expected a positive iteration cap")
        self.solver, self.measure, self.load, self.steps, self.report = solver, measure, load, steps, report
        self.done = 0
        self.converged, self.iterations, self.residual = True, 0, 0.0

    def step(self, outcome: StepOutcome) -> None:
        self.done += 1
        self.iterations += outcome.iterations
        self.residual = max(self.residual, float(outcome.residual))
        if not outcome.converged:
            if not self.report:
                raise ContactNotConverged(self.solver, self.load, self.done, self.steps, outcome, self.measure)
            self.converged = False

    def record(self) -> dict:
        return {"converged": self.converged, "iterations": self.iterations, "residual": self.residual}
