"""The influence-matrix engine: exact small-strain contact on a fingertip's surface influence
matrices (:class:`softtip.mechanics.contact.SurfaceInfluence`), milliseconds per load.

The matrices come from one factorisation of the finite-element stiffness, so a press solved on
them is the finite-element solution with contact on the surface's nodes, recorded after every
load step (the lab interpolates time series between these exact states).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence


from softtip._core.progress import SILENT, Progress
from softtip.design.model import Design
from softtip.mechanics.contact import LoadCase, ReducedContactResult, SurfaceInfluence, solve_influence_contact
from softtip.mechanics.fe import BodyModel
from softtip.mechanics.mesh import mesh_design
from softtip.twin.engines import Response


@dataclass
class InfluenceEngine:
    """One fingertip design's contact mechanics on the influence matrices of its surface."""

    design: Design
    influence: SurfaceInfluence

    @classmethod
    def build(cls, design: Design, mesh_size: float, reach: float, curvature_points: int = 10,
              progress: Progress = SILENT) -> InfluenceEngine:
        """Influence matrices of the surface within ``reach`` (m) of the top, on a ``mesh_size`` mesh."""
        body = BodyModel.for_design(design, mesh_design(design, mesh_size, curvature_points=curvature_points))
        influence = SurfaceInfluence.build(body, design.height - reach, progress=progress)
        return cls(design=design, influence=influence)

    def press(self, load: LoadCase, normal_steps: int | None = None, tangential_steps: int = 4) -> ReducedContactResult:
        """One load along its path, with the state after every load step."""
        return solve_influence_contact(self.influence, load, normal_steps=normal_steps,
                                       tangential_steps=tangential_steps)

    def respond(self, loads: Sequence[LoadCase]) -> Response:
        return Response.of_solutions([self.press(load) for load in loads], "influence")
