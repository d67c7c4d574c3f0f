"""Protocol files: a validated TOML per experiment, reproducible from the file and its seed.

A protocol file names the experiment, the design, the seed, and overrides any of the protocol's
parameters (every key and its default is in :data:`DEFAULTS`; the shipped files under
``softtip/lab/protocols/`` list them all, with units in their names)::

    protocol = "pushing"
    design = "cylindrical-A"     # a shipped design or a design TOML file
    seed = 1

    [parameters]
    angles_deg = [0, 15, 30, 45, 60, 75, 90]

    [realism]                    # see softtip.lab.realism; all on by default
    position_sd_mm = 0.2

    [viscoelastic]               # the material's relaxation, set from one published cycle
    hysteresis_percent = 7.3
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Callable

import numpy as np
from threadpoolctl import threadpool_limits

from softtip.data import Dataset
from softtip.design.model import MM, Design, load_design
from softtip.lab import experiments
from softtip.lab.realism import Realism
from softtip.settings import ConfigError, SettingsReader
from softtip.twin.influence import InfluenceEngine
from softtip.tomlfile import read_toml

GEN1 = {"rate_hz": 20.0, "mesh_size_mm": 1.5, "curvature_points": 10, "reach_mm": 4.5, "pre_contact_s": 0.5,
        "board_thickness_mm": 1.6}
GEN2 = {"rate_hz": 50.0, "mesh_size_mm": 2.5, "curvature_points": 3, "reach_mm": 3.5, "pre_contact_s": 0.2}

DEFAULTS: dict[str, dict[str, Any]] = {
    "pushing": {**GEN1, "angles_deg": [0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0], "calibration_trials": 10,
                "validation_trials": 5, "depth_mm": 3.0, "speed_mm_s": 1.0},
    "force3": {**GEN1, "calibration_trials": 10, "validation_trials": 5, "normal_depth_mm": 3.0,
               "shear_depth_mm": 2.0, "shear_mm": 2.0, "speed_mm_s": 0.5},
    "hysteresis": {**GEN1, "rate_hz": 50.0, "speeds_mm_s": [0.25, 0.5, 1.0], "trials": 10, "depth_mm": 3.0,
                   "rest_s": 1.0},
    "grasp-two": {**GEN1, "trained_angles_deg": [0.0, 10.0, 20.0, 30.0],
                  "untrained_angles_deg": [5.0, 15.0, 25.0], "calibration_trials": 7, "validation_trials": 3,
                  "untrained_trials": 3, "grasp_displacement_mm": 4.0, "grasp_speed_mm_s": 5.0, "hold_s": 1.0},
    "grasp-positions": {**GEN2, "rate_hz": 20.0, "positions_mm": [-9.0, -6.0, -3.0, 0.0, 3.0, 6.0, 9.0],
                        "angles_deg": [0.0, 10.0, 20.0, 30.0], "untrained_angles_deg": [5.0, 15.0, 25.0],
                        "calibration_trials": 7, "validation_trials": 3, "board_thickness_mm": 1.7,
                        "other_thicknesses_mm": [1.0, 2.0, 4.0, 8.0], "grasp_displacement_mm": 4.0,
                        "grasp_speed_mm_s": 5.0, "hold_s": 0.5},
    "contact-states": {**GEN2, "phi_deg": [10.0, 20.0, 30.0], "psi_deg": [5.0, 10.0, 15.0],
                       "untrained_phi_deg": [15.0, 25.0, 35.0], "untrained_psi_deg": [7.0, 12.0, 17.0],
                       "approach_inclines_deg": [45.0, 60.0], "approach_phi_deg": 20.0,
                       "positions_mm": [[0.0, 0.0], [5.0, 5.0], [-5.0, 5.0], [-5.0, -5.0], [5.0, -5.0]],
                       "calibration_trials": 5, "validation_trials": 3, "untrained_trials": 1,
                       "grip_depth_mm": 1.0, "board_thickness_mm": 1.7, "board_width_mm": 80.0,
                       "stick_out_mm": 60.0, "travel_mm": 3.0, "speed_mm_s": 5.0},
    "inverter": {**GEN2, "calibration_trials": 7, "validation_trials": 3, "untrained_trials": 3,
                 "tilt_y_deg": 10.0, "untrained_tilt_y_deg": 15.0, "untrained_tilt_x_deg": 5.0,
                 "untrained_offsets_mm": [-5.0, 5.0], "grip_depth_mm": 1.0, "part_thickness_mm": 3.0,
                 "clip_spacing_mm": 60.0, "part_depth_mm": 50.0, "travel_mm": 1.5, "speed_mm_s": 5.0,
                 "seat_compliance_mm_per_N": 1.0, "rim_compliance_mm_per_N": 0.2},
}
RUNNERS: dict[str, Callable] = {
    "pushing": experiments.pushing, "force3": experiments.force3, "hysteresis": experiments.hysteresis,
    "grasp-two": experiments.grasp_two, "grasp-positions": experiments.grasp_positions,
    "contact-states": experiments.contact_states, "inverter": experiments.inverter,
}
VISCOELASTIC = {"hysteresis_percent": 7.3, "depth_mm": 3.0, "speed_mm_s": 0.25, "rest_s": 1.0}


@dataclass
class Protocol:
    name: str
    design: Design
    seed: int
    parameters: dict[str, Any]
    realism: Realism = field(default_factory=Realism)
    viscoelastic: dict[str, float] = field(default_factory=lambda: dict(VISCOELASTIC))

    def to_dict(self) -> dict:
        return {"protocol": self.name, "design": self.design.name, "seed": self.seed, "parameters": self.parameters,
                "realism": self.realism.to_dict(), "viscoelastic": self.viscoelastic}


def shipped_protocol_path(name: str) -> Path:
    return Path(str(resources.files("softtip.lab") / "protocols" / f"{name}.toml"))


def protocol_from_dict(table: dict, source: str, base: Path | None = None) -> Protocol:
    top = SettingsReader(source, table, "")
    name = top.choice("protocol", sorted(RUNNERS))
    design_name = top.string("design")
    try:
        design = load_design(design_name if base is None or not (base / design_name).is_file()
                             else base / design_name)
    except ValueError as error:
        raise ConfigError(f"{source}: design = {design_name!r}: {error}") from None
    seed = top.integer("seed", 0)
    parameters = {}
    reader = SettingsReader(source, top.raw("parameters", {}), "parameters")
    for key, default in DEFAULTS[name].items():
        parameters[key] = reader.like(key, copy.deepcopy(default))
    reader.finish()
    if parameters["rate_hz"] <= 0:
        raise ConfigError(f"{source}: parameters.rate_hz = {parameters['rate_hz']}: expected a positive rate")
    realism_reader = SettingsReader(source, top.raw("realism", {}), "realism")
    realism = Realism.read(realism_reader)
    realism_reader.finish()
    visco_reader = SettingsReader(source, top.raw("viscoelastic", {}), "viscoelastic")
    viscoelastic = {k: visco_reader.number(k, v, non_negative=True) for k, v in VISCOELASTIC.items()}
    visco_reader.finish()
    top.finish()
    return Protocol(name=name, design=design, seed=seed, parameters=parameters, realism=realism,
                    viscoelastic=viscoelastic)


def load_protocol(path: str | Path) -> Protocol:
    """A protocol file, or the name of a shipped protocol (``pushing``, ``inverter`` ...)."""
    path = Path(path)
    if not path.suffix and str(path) in RUNNERS:
        path = shipped_protocol_path(str(path))
    table = read_toml(path, "protocol", ConfigError)
    return protocol_from_dict(table, str(path), path.parent)


_FINGERTIPS: dict[tuple, InfluenceEngine] = {}


def fingertip_for(design: Design, parameters: dict, progress=None) -> InfluenceEngine:
    """The design's lab mechanics, built once per process for each design and mesh."""
    key = (repr(design.spec), parameters["mesh_size_mm"], parameters["curvature_points"], parameters["reach_mm"])
    if key not in _FINGERTIPS:
        _FINGERTIPS[key] = InfluenceEngine.build(design, parameters["mesh_size_mm"] * MM, parameters["reach_mm"] * MM,
                                           curvature_points=parameters["curvature_points"], progress=progress)
    return _FINGERTIPS[key]


def run_protocol(protocol: Protocol, progress=None) -> tuple[Dataset, dict]:
    """Run one experiment; returns its dataset and timings (s)."""
    say = progress or (lambda message: None)
    timings = {}
    start = time.perf_counter()
    say(f"{protocol.name}: influence matrices of {protocol.design.name}")
    fingertip = fingertip_for(protocol.design, protocol.parameters)
    timings["mechanics_s"] = time.perf_counter() - start
    start = time.perf_counter()
    v = protocol.viscoelastic
    prony = experiments.material_prony(fingertip, v["hysteresis_percent"], v["depth_mm"] * MM,
                                       v["speed_mm_s"] * MM, v["rest_s"])
    bench = experiments.Bench(fingertip=fingertip, prony=prony, realism=protocol.realism,
                              rng=np.random.default_rng(protocol.seed), rate_hz=protocol.parameters["rate_hz"])
    say(f"{protocol.name}: trials")
    # the trials' dense solves are small: a second BLAS thread only fights for a shared core
    with threadpool_limits(limits=1):
        dataset = RUNNERS[protocol.name](bench, {**protocol.parameters, "viscoelastic": protocol.viscoelastic,
                                                 "prony": {"g": list(prony.g), "tau_s": list(prony.tau)},
                                                 "realism": protocol.realism.to_dict()}, protocol.seed)
    timings["trials_s"] = time.perf_counter() - start
    return dataset, timings
