"""The Hall fingertip's protocols: the published experiments (S1) as protocol files, on its bench.

A protocol file names the experiment, the design, the seed, and overrides any of the protocol's
parameters (every key and its default is in :data:`DEFAULTS`; the shipped files under ``protocols/``
list them all, with units in their names)::

    protocol = "pushing"
    design = "cylindrical-A"     # a shipped design or a design TOML file
    seed = 1

    [parameters]
    angles_deg = [0, 15, 30, 45, 60, 75, 90]

    [realism]                    # see softtip.systems.hall_fingertip.realism; all on by default
    position_sd_mm = 0.2

    [viscoelastic]               # the material's relaxation, set from one published cycle
    rest_s = 1.0
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import time
from dataclasses import field
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import Field

from softtip._core.config import (Flag, NonNegativeNumber, Numbers, PositiveNumber, Real, Text, expect, integer,
                                  refused, schema)
from softtip._core.progress import SILENT, Progress
from softtip._core.units import MM
from softtip.design.model import Design, load_design
from softtip.lab.protocols import BenchKind, Protocol, Size, protocol_file_schema
from softtip.published import published_table
from softtip.systems.hall_fingertip import experiments
from softtip.systems.hall_fingertip.realism import REALISM_SOURCES, Realism
from softtip.twin.influence import InfluenceEngine

GEN1 = {"rate_hz": 20.0, "mesh_size_mm": 1.5, "curvature_points": 10, "reach_mm": 4.5, "pre_contact_s": 0.5,
        "board_thickness_mm": 1.6}
GEN2 = {"rate_hz": 50.0, "mesh_size_mm": 2.5, "curvature_points": 3, "reach_mm": 3.5, "pre_contact_s": 0.2}

PointsMM = Annotated[list[Annotated[list[Real], Field(min_length=2, max_length=2)]], Field(min_length=1),
                     expect("a list of [x, y] pairs in mm")]


def _parameter_type(key: str, default: Any) -> Any:
    """What a fingertip protocol's parameter may be, from its default: true/false, an integer >= 0, a
    number >= 0 (the rate > 0), a list of numbers or a list of [x, y] pairs."""
    if isinstance(default, bool):
        return Flag
    if isinstance(default, int):
        return integer()
    if isinstance(default, float):
        return PositiveNumber if key == "rate_hz" else NonNegativeNumber
    return PointsMM if isinstance(default[0], list) else Numbers


def _parameters_schema(defaults: dict[str, Any]) -> type:
    """The schema of a ``[parameters]`` table whose keys are those of ``defaults``, each typed by its default."""
    fields = [(key, _parameter_type(key, default), field(default_factory=functools.partial(copy.deepcopy, default)))
              for key, default in defaults.items()]
    return schema(dataclasses.make_dataclass("ProtocolParameters", fields, frozen=True))


# the fingertip protocols' parameters and their defaults
DEFAULTS: dict[str, dict[str, Any]] = {
    "pushing": {**GEN1, "angles_deg": [0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0], "calibration_trials": 10,
                "validation_trials": 5, "depth_mm": 3.0, "speed_mm_s": 1.0},
    "force3": {**GEN1, "calibration_trials": 10, "validation_trials": 5, "normal_depth_mm": 3.0,
               "shear_depth_mm": 2.0, "shear_mm": 2.0, "speed_mm_s": 0.5},
    # force3's motions as the live use plays them: each released along its path after 2 s in the air
    "force-cycles": {**GEN1, "pre_contact_s": 2.0, "calibration_trials": 10, "validation_trials": 5,
                     "normal_depth_mm": 3.0, "shear_depth_mm": 2.0, "shear_mm": 2.0, "speeds_mm_s": [2.0]},
    # the thesis's test on generation 2 (1 mm/s, 3 s rest, 50 Hz; its board a 1.7 mm PCB), and two slower speeds
    "hysteresis": {**GEN2, "rate_hz": 50.0, "board_thickness_mm": 1.7, "speeds_mm_s": [0.25, 0.5, 1.0],
                   "trials": 10, "depth_mm": 3.0, "rest_s": 3.0},
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
PARAMETER_SCHEMAS: dict[str, type] = {name: _parameters_schema(defaults) for name, defaults in DEFAULTS.items()}
RUNNERS = {"pushing": experiments.pushing, "force3": experiments.force3, "force-cycles": experiments.force_cycles,
           "hysteresis": experiments.hysteresis, "grasp-two": experiments.grasp_two,
           "grasp-positions": experiments.grasp_positions, "contact-states": experiments.contact_states,
           "inverter": experiments.inverter}


_HYSTERESIS = published_table("hysteresis")
THESIS_CYCLE = "1 mm/s, 3 s rest"  # the cycle the thesis measured its hysteresis on (its table's column)
PUBLISHED_HYSTERESIS_PERCENT = _HYSTERESIS.value("hysteresis", THESIS_CYCLE).low


@schema(section="viscoelastic")
class Viscoelastic:
    """The material's relaxation: set so one centred board cycle on the protocol's design shows this
    hysteresis (default: the thesis's figure, on the generation-1 article's own hysteresis cycle, the
    slowest published; the hysteresis study runs the thesis's cycle beside it as a prediction)."""

    hysteresis_percent: NonNegativeNumber = PUBLISHED_HYSTERESIS_PERCENT
    depth_mm: NonNegativeNumber = 3.0
    speed_mm_s: NonNegativeNumber = 0.25
    rest_s: NonNegativeNumber = 1.0


# ``design``: a shipped design or a design TOML file (beside the protocol file first)
_FingertipProtocolFile = protocol_file_schema(Realism, Viscoelastic, design=Text)


_FINGERTIPS: dict[tuple, InfluenceEngine] = {}


def fingertip_for(design: Design, parameters: Any, progress: Progress = SILENT) -> InfluenceEngine:
    """The design's lab mechanics, built once per process for each design and mesh."""
    key = (repr(design.spec), parameters.mesh_size_mm, parameters.curvature_points, parameters.reach_mm)
    if key not in _FINGERTIPS:
        _FINGERTIPS[key] = InfluenceEngine.build(design, parameters.mesh_size_mm * MM, parameters.reach_mm * MM,
                                                 curvature_points=parameters.curvature_points, progress=progress)
    return _FINGERTIPS[key]


def _design(file: _FingertipProtocolFile, parameters: Any, source: str, base: Path | None) -> Design:
    """The file's design: a shipped one or a design file, found beside the protocol file first."""
    try:
        return load_design(file.design if base is None or not (base / file.design).is_file() else base / file.design)
    except ValueError as error:
        raise refused(str(error), source, "design", value=file.design) from None


def _bench(protocol: Protocol, progress: Progress, timings: dict) -> tuple[experiments.Bench, dict, str]:
    """The design's mechanics (``mechanics_s``) and its material's relaxation, set from the ``[viscoelastic]``
    cycle; the dataset records that relaxation."""
    start = time.perf_counter()
    fingertip = fingertip_for(protocol.design, protocol.parameters, progress)
    timings["mechanics_s"] = time.perf_counter() - start
    v = protocol.viscoelastic
    prony = experiments.material_prony(fingertip, v.hysteresis_percent, v.depth_mm * MM, v.speed_mm_s * MM, v.rest_s)
    bench = experiments.Bench(fingertip=fingertip, prony=prony, realism=protocol.realism,
                              rng=np.random.default_rng(protocol.seed), rate_hz=protocol.parameters.rate_hz)
    return (bench, {"prony": {"g": list(prony.g), "tau_s": list(prony.tau)}},
            f"{protocol.name}: trials on {protocol.design.name}")


# a dataset of 20 million frames: some 2 GB in memory, and hours of the twin's readings
FRAMES_LIMIT = 2e7
_TRAVELS = ("depth_mm", "shear_mm", "travel_mm", "displacement_mm")  # the distances a trial moves at its speed


def _size(protocol: str, p: Any) -> Size:
    """An upper estimate of a fingertip protocol's frames, from its parameters alone: every list of
    conditions crossed with every other, each condition run as often as all the trial counts together,
    each trial as long as the protocol's pauses plus its travels at its slowest speed."""
    table = dataclasses.asdict(p)
    conditions = np.prod([len(value) for value in table.values() if isinstance(value, list)])
    trials = sum(value for key, value in table.items() if key.endswith("trials"))
    speeds = [min(np.atleast_1d(value)) for key, value in table.items() if "speed" in key]
    travel = sum(value for key, value in table.items() if key.endswith(_TRAVELS))
    pauses = sum(value for key, value in table.items() if key.endswith("_s") and "speed" not in key)
    trial_s = pauses + (travel / min(speeds) if speeds and min(speeds) > 0 else 0.0)
    return Size(float(conditions) * trials * trial_s * p.rate_hz, FRAMES_LIMIT, "frames",
                "conditions x trials x (pauses + travels / slowest speed) x rate_hz")


BENCH = BenchKind(
    protocol_file=_FingertipProtocolFile, parameters=PARAMETER_SCHEMAS, runners=RUNNERS, device=_design, setup=_bench,
    realism_sources=REALISM_SOURCES, viscoelastic_sources={
        "hysteresis_percent": f"published: {_HYSTERESIS.source} ({_HYSTERESIS.system})",
        **{key: "the calibration cycle: the article's hysteresis test" for key in ("depth_mm", "speed_mm_s", "rest_s")}},
    size=_size)
