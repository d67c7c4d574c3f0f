"""The 3-axis force network trained on the twin's force-calibration cycles (design D): what the main
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


def axis_scores(truth: np.ndarray, estimate: np.ndarray) -> dict:
    """One axis's scores over a stream or a set of trials: its errors (:func:`force_errors`) and where they
    come from (:func:`phase_errors`)."""
    return {**force_errors(truth, estimate), "by_phase": phase_errors(truth, estimate)}


def held_out_scores(truth: np.ndarray, estimate: np.ndarray, speeds_mm_s: np.ndarray) -> dict:
    """Every axis's scores on the held-out trials, all of them and at each speed (keys ``"2 mm/s"``)."""
    def scores(rows: np.ndarray) -> dict:
        return {k: {**axis_scores(truth[rows, i], estimate[rows, i]), "r2": float(metrics.r2(truth[rows, i],
                                                                                         estimate[rows, i]))}
                for i, k in enumerate(FORCES)}
    return {**scores(np.ones(len(truth), dtype=bool)),
            "by_speed": {f"{speed:g} mm/s": scores(speeds_mm_s == speed) for speed in np.unique(speeds_mm_s)}}


def calibrate_force_model(seed: int, progress: Progress = SILENT, reuse: bool = False) -> tuple[Path, dict, object]:
    """Run the force calibration (the ``force-cycles`` protocol: the motions the live use plays, pushed and
    released at each of its speeds) on the twin and fit the network (``reuse``: take the model saved by an
    earlier run of this protocol and code, if there is one, with the validation it saved)."""
    protocol = load_protocol("force-cycles").changed(seed=seed)
    path, key = trained_model_path(protocol, "demo-force"), protocol_key(protocol)
    cached = read_file_entry(path, key, "demo-force", load_model) if reuse else None
    if cached is not None:
        with progress.task("twin and calibration: the force network of an earlier run, read from the cache"):
            return path, {"validation": cached[1].extra["validation"], "cached": True}, protocol
    p = protocol.parameters
    trials = len(p.speeds_mm_s) * (int(p.calibration_trials) + int(p.validation_trials))
    with progress.task(f"twin: the 3-axis force calibration on {protocol.design.name}, pushed and released, "
                       f"3 motions x {trials} trials"):
        dataset, timings = run_protocol(protocol, progress)
    X = dataset.X()
    y = np.column_stack([dataset.column(k) for k in FORCES])
    train, test = by_role(dataset)
    # Trained on what the live stream holds: the fingertip in the air (a model trained on contact alone
    # read about 0.5 N untouched), loading and releasing (the material's relaxation lowers the force on
    # the way back at the same deformation) at the stream's speed; anchored, no reading change reads no force.
    with progress.task(f"calibration: a 3-10-3 network on {int(train.sum())} samples of {len(dataset.trials)} trials"):
        model = LMNetwork((10,), anchored=True, random_state=seed).fit(X[train], y[train],
                                                                      groups=dataset.groups[train])
    validation = held_out_scores(y[test], model.predict(X[test]), dataset.column("speed_mm_s")[test])
    write_file_entry(path, key, "demo-force", lambda target: save_model(
        target, model, input_channels=list(dataset.channels), input_units=["uT"] * len(dataset.channels),
        target_names=list(FORCES), target_units=["N"] * 3, extra={"validation": validation}))
    return path, {"validation": validation, "timings_s": timings}, protocol
