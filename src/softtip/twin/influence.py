"""The influence-matrix engine: exact small-strain contact on a fingertip's surface influence
matrices (:class:`softtip.mechanics.contact.SurfaceInfluence`), milliseconds per load.

The matrices come from one factorisation of the finite-element stiffness, so a press solved on
them is the finite-element solution with contact on the surface's nodes, recorded after every
load step (the lab interpolates time series between these exact states).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Sequence


from softtip._core.cache import (EntryPieces, artefact_key, cache_dir, code_hash, computing, read_entry,
                                 write_entry)
from softtip._core.progress import SILENT, Progress
from softtip.design.model import Design
from softtip.mechanics.contact import LoadCase, ReducedContactResult, SurfaceInfluence, solve_influence_contact
from softtip.mechanics.fe import BodyModel
from softtip.mechanics.mesh import mesh_design
from softtip.twin.engines import Response

_KIND = "surface influence"
_ARRAYS = tuple(field.name for field in fields(SurfaceInfluence))


def _influence(design: Design, mesh_size: float, reach: float, curvature_points: int,
               progress: Progress, pieces: EntryPieces | None = None) -> SurfaceInfluence:
    body = BodyModel.for_design(design, mesh_design(design, mesh_size, curvature_points=curvature_points))
    return SurfaceInfluence.build(body, design.height - reach, progress=progress, pieces=pieces)


@dataclass
class InfluenceEngine:
    """One fingertip design's contact mechanics on the influence matrices of its surface."""

    design: Design
    influence: SurfaceInfluence

    @classmethod
    def build(cls, design: Design, mesh_size: float, reach: float, curvature_points: int = 10,
              progress: Progress = SILENT, use_cache: bool = True) -> InfluenceEngine:
        """Influence matrices of the surface within ``reach`` (m) of the top, on a ``mesh_size`` mesh;
        kept in the cache, where every study and process on the same design and mesh finds them (one
        process computes them while the others wait for the entry). A build stopped part way keeps the
        back-substitutions it finished, and the next one resumes from them."""
        if not use_cache:
            return cls(design=design, influence=_influence(design, mesh_size, reach, curvature_points, progress))
        key = artefact_key({"design": design.spec, "mesh_size": mesh_size, "reach": reach,
                            "curvature_points": curvature_points},
                           code_hash("softtip.design", "softtip.mechanics", "softtip.twin.influence"))
        path = cache_dir() / "influence" / f"{key}.npz"
        entry = read_entry(path, key, _KIND)
        if entry is None:
            with computing(path):
                entry = read_entry(path, key, _KIND)  # stored meanwhile by a process this one waited for
                if entry is None:
                    pieces = EntryPieces(path, key, _KIND)
                    influence = _influence(design, mesh_size, reach, curvature_points, progress, pieces)
                    if write_entry(path, key, _KIND, {}, {name: getattr(influence, name) for name in _ARRAYS}):
                        pieces.clear()
                    return cls(design=design, influence=influence)
        return cls(design=design, influence=SurfaceInfluence(**{name: entry[1][name] for name in _ARRAYS}))

    def press(self, load: LoadCase, normal_steps: int | None = None, tangential_steps: int = 4) -> ReducedContactResult:
        """One load along its path, with the state after every load step."""
        return solve_influence_contact(self.influence, load, normal_steps=normal_steps,
                                       tangential_steps=tangential_steps)

    def respond(self, loads: Sequence[LoadCase]) -> Response:
        return Response.of_solutions([self.press(load) for load in loads], "influence")
