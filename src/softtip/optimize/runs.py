"""One finite-element run of the twin, as plain data that crosses process boundaries.

A :class:`Simulation` says what to compute (load case, model, mesh size), a
:class:`FEResult` holds what came out, and :func:`run_design` is the only
function executed by workers: it takes a design's TOML-level spec and a list
of simulations as JSON-able dicts and returns JSON-able dicts, so local
processes and Dask workers need nothing but softtip installed, and results can
be cached as JSON.

Sensor noise is always off here: results are deterministic and the objectives
that need noise draw it themselves from the exact field.
"""

from __future__ import annotations

import contextlib
import logging
import time
from dataclasses import asdict, dataclass, fields
from typing import TYPE_CHECKING, Annotated, Any, ClassVar, Iterator

import numpy as np

from softtip._core.config import NonNegativeNumber, Number, PositiveNumber, Real, choice, expect, schema
from softtip._core.units import MM
from softtip.mechanics.contact import FRICTION_MODES, LoadCase
from softtip.mechanics.indenters import make_indenter

if TYPE_CHECKING:
    from softtip.twin import Twin, TwinResult

INDENTERS = ("board", "plate", "sphere")
MODELS = ("linear", "neo-hookean")
# 1.5 mm: the feature displacement of the magnet under a 1 mm board push is within 0.4 % of a
# 0.6 mm mesh, at a third of the cost of the twin's 1.0 mm default - the right mesh for sweeps.
SWEEP_MESH_SIZE_MM = 1.5

PointMM = Annotated[tuple[Real, Real], expect("[x, y] in mm")]
Indenter = choice(*INDENTERS)
Friction = choice(*FRICTION_MODES)
SolidModel = choice(*MODELS)


@schema
class Simulation:
    """A load case on the twin with the solver settings that determine its result (lengths in mm).

    Its keys are also the load-case keys of a study's ``[objective]`` table."""

    indenter: Indenter = "board"
    thickness_mm: PositiveNumber = 1.6
    angle_deg: Number = 0.0
    radius_mm: PositiveNumber = 5.0
    depth_mm: NonNegativeNumber = 1.0
    position_mm: PointMM = (0.0, 0.0)
    tangential_mm: PointMM = (0.0, 0.0)
    friction: Friction = "stick"
    model: SolidModel = "linear"
    mesh_size_mm: PositiveNumber = SWEEP_MESH_SIZE_MM

    def __post_init__(self):
        self.load_case()  # refuses what the contact mechanics would

    @classmethod
    def of(cls, settings: "Simulation") -> "Simulation":
        """The simulation part of settings that extend it (an objective's)."""
        return cls(**{f.name: getattr(settings, f.name) for f in fields(cls)})

    def load_case(self) -> LoadCase:
        indenter = make_indenter(self.indenter, thickness=self.thickness_mm * MM, angle_deg=self.angle_deg,
                                 radius=self.radius_mm * MM)
        return LoadCase(indenter=indenter, depth=self.depth_mm * MM,
                        tangential=(self.tangential_mm[0] * MM, self.tangential_mm[1] * MM),
                        position=(self.position_mm[0] * MM, self.position_mm[1] * MM), friction=self.friction)

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data["position_mm"], data["tangential_mm"] = list(self.position_mm), list(self.tangential_mm)
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "Simulation":
        return cls(**data)


@dataclass(frozen=True, eq=False)  # arrays: compare fields with numpy, not ==
class FEResult:
    """What one simulation gives, in SI units; the inputs of every objective."""

    feature_displacements_m: np.ndarray  # (M, 3) centre of each magnet's top face
    magnet_positions_m: np.ndarray  # (M, 3) centres after loading
    magnet_rotvecs_rad: np.ndarray  # (M, 3)
    force_N: np.ndarray  # (3,) on the indenter, Fz > 0 pushing
    field_rest_T: np.ndarray  # (S, 3) absolute flux density at each sensor before loading
    field_change_T: np.ndarray  # (S, 3) exact change under the load
    contact_nodes: int
    tetrahedra: int
    unknowns: int

    ARRAY_FIELDS: ClassVar[tuple[str, ...]] = ("feature_displacements_m", "magnet_positions_m", "magnet_rotvecs_rad",
                                               "force_N", "field_rest_T", "field_change_T")
    COUNT_FIELDS: ClassVar[tuple[str, ...]] = ("contact_nodes", "tetrahedra", "unknowns")

    def to_dict(self) -> dict[str, Any]:
        # float() of a float64 round-trips exactly through JSON, so a cached result equals a fresh one
        return {**{k: getattr(self, k).tolist() for k in self.ARRAY_FIELDS},
                **{k: int(getattr(self, k)) for k in self.COUNT_FIELDS}}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "FEResult":
        return cls(**{k: np.asarray(data[k], dtype=float) for k in cls.ARRAY_FIELDS},
                   **{k: int(data[k]) for k in cls.COUNT_FIELDS})


def run_design(design_spec: dict[str, Any], simulations: list[dict[str, Any]]) -> dict[str, Any]:
    """Worker entry point: run ``simulations`` on one design; never raises for a bad design.

    Returns ``{"results": [FEResult dicts, one per simulation] | None, "error": str | None,
    "seconds": [wall time per simulation]}``. A failure (meshing, solver) is returned as a
    one-line error so one bad design cannot end a sweep of thousands.
    """
    from threadpoolctl import threadpool_limits

    from softtip.design.model import design_from_dict
    from softtip.twin import Twin  # loads MKL, so the limit below reaches it

    seconds: list[float] = []
    # one BLAS/PARDISO thread per worker: the workers themselves fill the cores
    with threadpool_limits(limits=1), _quiet("skfem"):
        try:
            design = design_from_dict(design_spec, source=design_spec.get("name", "design"))
            twins: dict[float, Twin] = {}
            results = []
            for data in simulations:
                start = time.perf_counter()
                simulation = Simulation.from_dict(data)
                size = simulation.mesh_size_mm
                if size not in twins:  # one mesh and stiffness per size, shared by the design's load cases
                    twins[size] = Twin.finite_element(design, mesh_size=size * MM)
                twin = twins[size]
                results.append(fe_result(twin, twin.simulate(simulation.load_case(), model=simulation.model,
                                                             noise=False)).to_dict())
                seconds.append(time.perf_counter() - start)
        except Exception as error:  # noqa: BLE001 - reported per design, see the docstring
            message = " ".join(str(error).split()) or "no message"
            return {"results": None, "error": f"{type(error).__name__}: {message}", "seconds": seconds}
    return {"results": results, "error": None, "seconds": seconds}


@contextlib.contextmanager
def _quiet(logger_name: str) -> Iterator[None]:
    """Silence a library's warnings for a while (scikit-fem's note on array layout, once per
    design, would bury a sweep's progress display)."""
    logger = logging.getLogger(logger_name)
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(level)


def fe_result(twin: Twin, result: TwinResult) -> FEResult:
    return FEResult(feature_displacements_m=result.feature_displacements, magnet_positions_m=result.magnet_positions,
                    magnet_rotvecs_rad=result.poses.rotvec, force_N=result.force,
                    field_rest_T=twin.readout.rest_field, field_change_T=result.field_change,
                    contact_nodes=len(result.solution.contact_nodes), tetrahedra=int(twin.engine.mesh.tets.shape[1]),
                    unknowns=int(twin.engine.body.size))
