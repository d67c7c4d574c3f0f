"""The insertion demo: models trained on the inverter protocol, then the feedback loop on the
simulated arm for one case (S1 §3)."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from softtip._core.cache import read_file_entry, write_file_entry
from softtip._core.progress import SILENT, Progress
from softtip._core.units import MM
from softtip.calibration import load_model, save_model
from softtip.lab import Protocol, load_protocol, run_protocol
from softtip.lab.protocols import protocol_key, trained_model_path
from softtip.systems.hall_fingertip.insertion_world import InsertionWorld, SimulatedArm
from softtip.systems.hall_fingertip.controller import InsertionController
from softtip.systems.hall_fingertip.studies import inverter_models

INITIAL_HEIGHT = 3.0 * MM  # the initial insertion pose, above where part A first touches part B
TARGET_DEPTH = 0.6 * MM  # the target pose: the lid seated, its clips flexed by this much


def trained_model_files(protocol: Protocol, progress: Progress = SILENT) -> tuple[Path, Path]:
    """The inverter's state and force networks as softtip model files, trained once per protocol and
    code, and kept in the cache."""
    names = ("inverter-state", "inverter-force")
    paths, key = tuple(trained_model_path(protocol, name) for name in names), protocol_key(protocol)
    if all(read_file_entry(path, key, name, load_model) is not None for path, name in zip(paths, names)):
        return paths
    dataset, _ = run_protocol(protocol, progress)
    with progress.task("training the contact-state and force networks on the inverter protocol"):
        models = inverter_models(dataset, protocol.seed)
    channels = list(dataset.channels)
    for path, name, model, target, unit in zip(paths, names, models, ("state", "normal_force_N"), ("1", "N")):
        write_file_entry(path, key, name, functools.partial(
            save_model, model=model, input_channels=channels, input_units=["uT"] * len(channels),
            target_names=[target], target_units=[unit]))
    return paths


def trained_models(protocol: Protocol, progress: Progress = SILENT):
    """The inverter's state and force networks (see :func:`trained_model_files`)."""
    state, force = trained_model_files(protocol, progress)
    return protocol, load_model(state)[0], load_model(force)[0]


def run_insertion(case: str, seed: int = 1, protocol: Protocol | None = None, progress: Progress = SILENT) -> dict:
    """One insertion; ``protocol`` defaults to the shipped inverter protocol with ``seed``."""
    if protocol is None:
        protocol = load_protocol("inverter").changed(seed=seed)
    protocol, classifier, regressor = trained_models(protocol, progress)
    world = InsertionWorld(protocol, case, np.random.default_rng(seed + 100))
    arm = SimulatedArm(INITIAL_HEIGHT)
    world.take_baseline(INITIAL_HEIGHT)  # grasped, in the air: the initial value
    controller = InsertionController(robot=arm, read=world.reader(arm), state_model=classifier,
                                     force_model=regressor, initial_pose=np.array([INITIAL_HEIGHT]),
                                     target_pose=np.array([-TARGET_DEPTH]))
    outcome = controller.run()
    outcome["case"] = case
    outcome["true_force_at_decision_N"] = round(world.force, 4)
    outcome["final_pose_mm"] = round(float(arm.current_pose()[0]) / MM, 4)
    outcome["decisions"] = [vars(d) for d in controller.log]
    return outcome
