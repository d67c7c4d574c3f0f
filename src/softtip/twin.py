"""The physics twin of a fingertip: design -> mechanics -> magnetics -> sensor.

:class:`FingertipTwin` meshes a design once, solves a load case with the
finite-element contact model, poses the rigid magnets, evaluates their exact
field at every Hall sensor and reads it through the MLX90393 model. Readings
are changes from the unloaded state ("initial value subtracted"), per sensor
and axis; with noise on, both the baseline and the loaded reading go through
the sensor model (quantisation, noise, clipping) like a real acquisition.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from softtip._core.units import MM
from softtip.design.model import Design, DesignError
from softtip.magnetics import magnet_field_at_sensors
from softtip.mechanics.contact import ContactResult, LoadCase, solve_hyperelastic_contact, solve_linear_contact
from softtip.mechanics.fe import BodyModel
from softtip.mechanics.mesh import TetMesh, mesh_design
from softtip.sensors import MLX90393, MLX90393Settings

DEFAULT_MESH_SIZE = 1.0 * MM  # within 1 % of a 0.6 mm mesh for the board push (see the README)
MODELS = ("linear", "neo-hookean")


@dataclass
class TwinResult:
    design: Design
    load: LoadCase
    model: str
    contact: ContactResult
    magnet_positions: np.ndarray  # (M, 3) m, centres after loading
    magnet_rotvecs: np.ndarray  # (M, 3) rad
    feature_displacements: np.ndarray  # (M, 3) m, centre of each magnet's top face
    field_change: np.ndarray  # (S, 3) T, noiseless change of flux density at each sensor
    reading_change_uT: np.ndarray  # (S, 3) what the sensors report (noisy if noise was on)
    reading_counts: np.ndarray  # (S, 3) raw register words of the loaded reading
    mesh: TetMesh
    timings: dict = field(default_factory=dict)

    @property
    def force(self) -> np.ndarray:
        return self.contact.force


class Readout:
    """The sensing stage of a design: the exact field of its magnets at its Hall sensors,
    read through the MLX90393 model, relative to the unloaded state."""

    def __init__(self, design: Design, ambient_field: np.ndarray | None = None):
        try:
            self.sensor = MLX90393(MLX90393Settings.from_dict(design.sensor_readout))
        except ValueError as error:
            raise DesignError(f"{design.name}: {error}") from None
        self.design = design
        self.ambient_field = np.zeros(3) if ambient_field is None else np.asarray(ambient_field, dtype=float)
        self.rest_positions = np.array([m.center for m in design.magnets])
        self.rest_field = self.field(self.rest_positions[None], np.zeros((1, len(design.magnets), 3)))[0]

    def field(self, magnet_positions: np.ndarray, magnet_rotvecs: np.ndarray) -> np.ndarray:
        """Absolute flux density (N, S, 3) in T at the sensors for N sets of magnet poses."""
        magnets = self.design.magnets
        return magnet_field_at_sensors(
            self.design.sensor_positions, magnet_positions, magnet_rotvecs,
            np.array([m.diameter / 2 for m in magnets]), np.array([m.height for m in magnets]),
            np.array([m.polarization for m in magnets]), ambient=self.ambient_field)

    def readings(self, magnet_positions: np.ndarray, magnet_rotvecs: np.ndarray, noise: bool = True,
                 rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Sensor readings for N pose sets: (change from rest in µT (N, S, 3), raw counts (N, S, 3)).

        Without noise the change is the exact field difference (no quantisation).
        """
        return self.read_field(self.field(magnet_positions, magnet_rotvecs), noise, rng)

    def read_field(self, loaded: np.ndarray, noise: bool = True,
                   rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
        """What the sensors report for absolute fields ``loaded`` (N, S, 3) in T; see :meth:`readings`."""
        if not noise:
            return (loaded - self.rest_field) * 1e6, self.sensor.to_counts(loaded, noise=False)
        rng = rng or np.random.default_rng()
        counts = self.sensor.to_counts(loaded, rng=rng)
        baseline = self.sensor.read_uT(np.broadcast_to(self.rest_field, loaded.shape), rng=rng)
        return self.sensor.counts_to_uT(counts) - baseline, counts


class FingertipTwin(Readout):
    """A design's mesh, body model and sensors, reused across load cases."""

    def __init__(self, design: Design, mesh_size: float = DEFAULT_MESH_SIZE, use_cache: bool = True,
                 ambient_field: np.ndarray | None = None):
        super().__init__(design, ambient_field)
        self.mesh_size = mesh_size
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

    # ------------------------------------------------------------------ one load case

    def simulate(self, load: LoadCase, model: str = "linear", noise: bool = True,
                 rng: np.random.Generator | None = None, progress=None) -> TwinResult:
        if model not in MODELS:
            raise ValueError(f"model = {model!r}: expected one of {', '.join(MODELS)}")
        body = self.body
        if model == "linear":
            contact = solve_linear_contact(body, load)
        else:
            contact = solve_hyperelastic_contact(body, load, progress=progress)
        rest = self.rest_positions
        translations = np.array([p.translation for p in contact.magnet_poses])
        rotvecs = np.array([p.rotvec for p in contact.magnet_poses])
        arms = np.array([m.top_center for m in self.design.magnets]) - rest
        features = translations + np.cross(rotvecs, arms)
        positions = rest + translations
        start = time.perf_counter()
        loaded = self.field(positions[None], rotvecs[None])
        change_uT, counts = self.read_field(loaded, noise=noise, rng=rng)
        field_change = loaded[0] - self.rest_field
        timings = dict(self.timings)
        timings.update(contact.timings)
        timings["magnetics_sensor_s"] = time.perf_counter() - start
        return TwinResult(design=self.design, load=load, model=model, contact=contact, magnet_positions=positions,
                          magnet_rotvecs=rotvecs, feature_displacements=features, field_change=field_change,
                          reading_change_uT=change_uT[0], reading_counts=counts[0], mesh=self.mesh,
                         timings=timings)
