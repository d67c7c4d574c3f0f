"""The physics twin of a fingertip: design -> mechanics -> magnetics -> sensor, composed once.

:class:`Twin` puts a readout (the exact field at the Hall sensors, read through the model of the
design's chip) after an engine (the body's answer to loads, :mod:`softtip.twin.engines`). Readings are
changes from the unloaded state, per sensor and axis; with noise on, both the baseline and the
loaded reading go through the sensor model like a real acquisition.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from softtip.design.model import Design
from softtip.mechanics.contact import LoadCase
from softtip.mechanics.motion import Motion
from softtip.mechanics.poses import MagnetPoses
from softtip.mechanics.viscoelastic import PronySeries, qlv_response
from softtip.twin.engines import DEFAULT_MESH_SIZE, Engine, FiniteElementEngine, Response
from softtip.twin.readout import Readout


@dataclass
class TwinResult:
    """One load case through the twin (one magnet pose set, M magnets, S sensors)."""

    design: Design
    load: LoadCase
    model: str  # the mechanics that answered (see :class:`softtip.twin.engines.Response`)
    poses: MagnetPoses  # (M, 3) rigid motion of each magnet from rest
    force: np.ndarray  # (3,) N, the body's reaction on the indenter
    magnet_positions: np.ndarray  # (M, 3) m, centres after loading
    feature_displacements: np.ndarray  # (M, 3) m, centre of each magnet's top face
    field_change: np.ndarray  # (S, 3) T, noiseless change of flux density at each sensor
    reading_change_uT: np.ndarray  # (S, 3) what the sensors report (noisy if noise was on)
    reading_counts: np.ndarray  # (S, 3) the chip's raw output (its words) of the loaded reading
    solution: Any = None  # the engine's solver result, where it has one
    timings: dict = field(default_factory=dict)


class Twin:
    """An engine followed by a readout."""

    def __init__(self, engine: Engine, readout: Readout | None = None):
        self.engine = engine
        self.design = engine.design
        self.readout = readout or Readout(engine.design)

    @classmethod
    def finite_element(cls, design: Design, mesh_size: float = DEFAULT_MESH_SIZE, model: str = "linear",
                       use_cache: bool = True, ambient_field: np.ndarray | None = None) -> Twin:
        """The full finite-element twin (the readout is checked first: it is the cheap part)."""
        readout = Readout(design, ambient_field=ambient_field)
        return cls(FiniteElementEngine(design, mesh_size, model=model, use_cache=use_cache), readout)

    def respond(self, loads: Sequence[LoadCase] | np.ndarray, **engine_options) -> Response:
        """The engine's answer to load cases, or to an (N, 6) array of load parameters
        (x, y, angle, depth, tx, ty in m and rad) for an engine of one indenter family
        (:class:`softtip.twin.reduced.ReducedTwin`): its batch path."""
        if isinstance(loads, np.ndarray):
            if not hasattr(self.engine, "respond_parameters"):
                raise TypeError(f"{type(self.engine).__name__} answers load cases, not load parameters")
            return self.engine.respond_parameters(loads)
        return self.engine.respond(loads, **engine_options)

    def readings(self, loads: Sequence[LoadCase] | np.ndarray, noise: bool = True,
                 rng: np.random.Generator | None = None, **engine_options) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Readings (change from rest, µT) (N, S, 3), raw counts (N, S, 3) and force (N, 3) for N loads."""
        response = self.respond(loads, **engine_options)
        change, counts = self.readout.readings(response.poses, noise=noise, rng=rng)
        return change, counts, response.force

    def series(self, motion: Motion, rate_hz: float, position: tuple[float, float] = (0.0, 0.0), angle: float = 0.0,
               prony: PronySeries | None = None, noise: bool = True, rng: np.random.Generator | None = None) -> dict:
        """Time series of a motion at ``rate_hz`` (an engine with load parameters): times, depth,
        tangential travel, readings (µT), raw counts and force. With ``prony`` the force is
        quasi-linear viscoelastic: the magnets follow the imposed motion while the force relaxes
        (normal force clipped at zero: contact does not pull). ``slides`` marks the samples where
        the indenter would slide: outside a sticking engine's domain."""
        times, depth, tangential = motion.sample(rate_hz)
        params = np.column_stack([np.full_like(times, position[0]), np.full_like(times, position[1]),
                                  np.full_like(times, angle), depth, tangential])
        change, counts, elastic = self.readings(params, noise=noise, rng=rng)
        force = elastic if prony is None else qlv_response(times, elastic, prony)
        if prony is not None:
            force[:, 2] = np.maximum(force[:, 2], 0.0)
        return {"times_s": times, "depth_m": depth, "tangential_m": tangential, "readings_uT": change,
                "counts": counts, "force_N": force, "elastic_force_N": elastic,
                "slides": self.engine.family.slides(elastic) & (depth > 0)}

    def simulate(self, load: LoadCase, noise: bool = True, rng: np.random.Generator | None = None,
                 **engine_options) -> TwinResult:
        """One load case: magnet poses, feature displacements, field change, readings, force."""
        response = self.engine.respond([load], **engine_options)
        poses = MagnetPoses(response.poses.translation[0], response.poses.rotvec[0])
        magnets = self.design.magnets
        arms = np.array([m.top_center for m in magnets]) - np.array([m.center for m in magnets])
        start = time.perf_counter()
        loaded = self.readout.field(response.poses)
        change_uT, counts = self.readout.read_field(loaded, noise=noise, rng=rng)
        timings = dict(response.timings)
        timings["magnetics_sensor_s"] = time.perf_counter() - start
        return TwinResult(design=self.design, load=load, model=response.model, poses=poses, force=response.force[0],
                          magnet_positions=self.readout.rest_positions + poses.translation,
                          feature_displacements=poses.displacement_of(arms),
                          field_change=loaded[0] - self.readout.rest_field, reading_change_uT=change_uT[0],
                          reading_counts=counts[0], solution=response.solutions[0] if response.solutions else None,
                          timings=timings)
