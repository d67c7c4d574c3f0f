"""The insertion demo: models trained on the inverter protocol, then the feedback loop on the
simulated arm for one case (S1 §3)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from softtip._core.progress import SILENT, Progress
from softtip._core.units import MM
from softtip.calibration import load_model, save_model
from softtip.lab import Protocol, load_protocol, run_protocol
from softtip.lab.protocols import trained_model_path
from softtip.systems.hall_fingertip.insertion_world import InsertionWorld, SimulatedArm
from softtip.systems.hall_fingertip.controller import InsertionController
from softtip.systems.hall_fingertip.studies import inverter_models

INITIAL_HEIGHT = 3.0 * MM  # the initial insertion pose, above where part A first touches part B
TARGET_DEPTH = 0.6 * MM  # the target pose: the lid seated, its clips flexed by this much


def trained_model_files(protocol: Protocol, progress: Progress = SILENT) -> tuple[Path, Path]:
    """The inverter's state and force networks as softtip model files, trained once per protocol and
    code, and kept in the cache."""
    paths = trained_model_path(protocol, "inverter-state"), trained_model_path(protocol, "inverter-force")
    if all(p.is_file() for p in paths):
        return paths
    dataset, _ = run_protocol(protocol, progress)
    with progress.task("training the contact-state and force networks on the inverter protocol"):
        classifier, regressor = inverter_models(dataset, protocol.seed)
    paths[0].parent.mkdir(parents=True, exist_ok=True)
    channels = list(dataset.channels)
    save_model(paths[0], classifier, input_channels=channels, input_units=["uT"] * len(channels),
               target_names=["state"], target_units=["1"])
    save_model(paths[1], regressor, input_channels=channels, input_units=["uT"] * len(channels),
               target_names=["normal_force_N"], target_units=["N"])
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
