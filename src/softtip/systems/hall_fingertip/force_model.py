"""The 3-axis force network trained on the twin's force-calibration protocol (design D): what the main
demo saves and scores, and what the ``push`` live scenario estimates with; kept in the cache."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from softtip import metrics
from softtip._core.cache import read_file_entry, write_file_entry
from softtip._core.progress import SILENT, Progress
from softtip.calibration import LMNetwork, load_model, save_model
from softtip.data.splits import by_role
from softtip.lab import load_protocol, run_protocol
from softtip.lab.protocols import protocol_key, trained_model_path

FORCES = ("fx_N", "fy_N", "fz_N")
REST_N = 0.05  # below this reference force the fingertip is untouched


def force_errors(truth: np.ndarray, estimate: np.ndarray) -> dict[str, float]:
    """One axis's errors over every sample (rests included, as a live stream has them), and the estimate
    where the reference reads no force: its mean and spread (the sensor's noise through the model)."""
    rest = np.abs(truth) < REST_N
    return {"mean_abs_error_N": float(metrics.mean_abs_error(truth, estimate)),
            "rest_mean_N": float(np.mean(estimate[rest])) if rest.any() else float("nan"),
            "rest_sd_N": float(np.std(estimate[rest])) if rest.any() else float("nan")}


def phase_errors(truth: np.ndarray, estimate: np.ndarray) -> dict[str, float]:
    """One axis's mean absolute error over its rests (the reference below :data:`REST_N`), its loading
    (the reference's magnitude growing from one sample to the next) and its unloading (falling), and
    each phase's share of the samples: where a stream's error comes from."""
    rest = np.abs(truth) < REST_N
    change = np.diff(np.abs(truth), prepend=np.abs(truth[:1]))
    error = np.abs(estimate - truth)
    phases = {"rest": rest, "loading": ~rest & (change > 0), "unloading": ~rest & (change < 0)}
    return {f"{name}_{figure}": value for name, where in phases.items() for figure, value in (
        ("mean_abs_error_N", float(error[where].mean()) if where.any() else float("nan")),
        ("share", float(where.mean())))}


def calibrate_force_model(seed: int, progress: Progress = SILENT, reuse: bool = False) -> tuple[Path, dict, object]:
    """Run the force calibration on the twin and fit the network (``reuse``: take the model saved by an
    earlier run of this protocol and code, if there is one, with the validation it saved)."""
    protocol = load_protocol("force3").changed(seed=seed)
    path, key = trained_model_path(protocol, "demo-force"), protocol_key(protocol)
    cached = read_file_entry(path, key, "demo-force", load_model) if reuse else None
    if cached is not None:
        with progress.task("twin and calibration: the force network of an earlier run, read from the cache"):
            return path, {"validation": cached[1].extra["validation"], "cached": True}, protocol
    trials = int(protocol.parameters.calibration_trials) + int(protocol.parameters.validation_trials)
    with progress.task(f"twin: the 3-axis force calibration on {protocol.design.name}, 3 motions x {trials} trials"):
        dataset, timings = run_protocol(protocol, progress)
    X = dataset.X()
    y = np.column_stack([dataset.column(k) for k in FORCES])
    calibration, validation = by_role(dataset)
    # Every trial starts in the air: those samples are trained on too, or the model has never seen the
    # fingertip untouched and reads a force there (about 0.5 N when it was trained on contact alone).
    # They are 7 % of the samples, and the network fitted to the pushes still read 0.20 N at a zero
    # reading change; anchored, its output layer is refitted so that no change reads no force.
    train, test = calibration, validation
    with progress.task(f"calibration: a 3-10-3 network on {int(train.sum())} samples of {len(dataset.trials)} trials"):
        model = LMNetwork((10,), anchored=True, random_state=seed).fit(X[train], y[train],
                                                                      groups=dataset.groups[train])
    estimate = model.predict(X[test])
    validation = {k: {**force_errors(y[test, i], estimate[:, i]), "r2": float(metrics.r2(y[test, i], estimate[:, i]))}
                  for i, k in enumerate(FORCES)}
    write_file_entry(path, key, "demo-force", lambda target: save_model(
        target, model, input_channels=list(dataset.channels), input_units=["uT"] * len(dataset.channels),
        target_names=list(FORCES), target_units=["N"] * 3, extra={"validation": validation}))
    return path, {"validation": validation, "timings_s": timings}, protocol
