"""The main job, end to end on the built-in simulated sensor: twin -> calibration -> live estimates.

1. the 3-axis force calibration protocol runs on the twin (cylindrical-D): a dataset of trials;
2. a 3-10-3 Levenberg-Marquardt network is fitted on its calibration trials (rests included), scored
   on its validation trials and saved as a softtip model file;
3. an emulated fingertip replays the same motions from the twin over a pseudo-terminal in the
   firmware's protocol; the live pipeline (driver -> baseline -> the saved model) estimates the
   force frame by frame, and the estimates are scored against the twin's true force.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from softtip._core.cache import read_file_entry, write_file_entry
from softtip._core.progress import SILENT, Progress
from softtip import metrics
from softtip.calibration import LMNetwork, load_model, save_model
from softtip.lab import load_protocol, run_protocol
from softtip.data.splits import by_role
from softtip.systems.hall_fingertip.live import cached_scenario
from softtip.systems.hall_fingertip.scenarios import pushing_scenario
from softtip.realtime.session import run_live
from softtip.realtime.sinks.factory import live_sinks
from softtip.lab.protocols import protocol_key, trained_model_path

FORCES = ("fx_N", "fy_N", "fz_N")
DEMO_SPEED_MM_S = 2.0  # faster than the calibration (0.5 mm/s): the three motions loop in about 17 s


REST_N = 0.05  # below this reference force the fingertip is untouched


def force_errors(truth: np.ndarray, estimate: np.ndarray) -> dict[str, float]:
    """One axis's errors over every sample (rests included, as a live stream has them), and the estimate
    where the reference reads no force: its mean and spread (the sensor's noise through the model)."""
    rest = np.abs(truth) < REST_N
    return {"mean_abs_error_N": float(metrics.mean_abs_error(truth, estimate)),
            "rest_mean_N": float(np.mean(estimate[rest])) if rest.any() else float("nan"),
            "rest_sd_N": float(np.std(estimate[rest])) if rest.any() else float("nan")}


def calibrate_force_model(seed: int, progress: Progress = SILENT, reuse: bool = False) -> tuple[Path, dict, object]:
    """Run the force calibration on the twin and fit the network (``reuse``: take the model saved by an
    earlier run of this protocol and code, if there is one, with the validation it saved)."""
    protocol = load_protocol("force3").changed(seed=seed)
    path, key = trained_model_path(protocol, "demo-force"), protocol_key(protocol)
    cached = read_file_entry(path, key, "demo-force", load_model) if reuse else None
    if cached is not None:
        return path, {"validation": cached[1].extra["validation"], "cached": True}, protocol
    dataset, timings = run_protocol(protocol, progress)
    X = dataset.X()
    y = np.column_stack([dataset.column(k) for k in FORCES])
    calibration, validation = by_role(dataset)
    # Every trial starts in the air: those samples are trained on too, or the model has never seen the
    # fingertip untouched and reads a force there (about 0.5 N when it was trained on contact alone).
    train, test = calibration, validation
    with progress.task(f"calibration: a 3-10-3 network on {int(train.sum())} samples of {len(dataset.trials)} trials"):
        model = LMNetwork((10,), random_state=seed).fit(X[train], y[train], groups=dataset.groups[train])
    estimate = model.predict(X[test])
    validation = {k: {**force_errors(y[test, i], estimate[:, i]), "r2": float(metrics.r2(y[test, i], estimate[:, i]))}
                  for i, k in enumerate(FORCES)}
    write_file_entry(path, key, "demo-force", lambda target: save_model(
        target, model, input_channels=list(dataset.channels), input_units=["uT"] * len(dataset.channels),
        target_names=list(FORCES), target_units=["N"] * 3, extra={"validation": validation}))
    return path, {"validation": validation, "timings_s": timings}, protocol


def run_main_demo(seed: int = 1, duration_s: float = 20.0, rate_hz: int = 50, dashboard: bool = True,
                  record: str | None = None, progress: Progress = SILENT) -> dict:
    model_path, calibration, protocol = calibrate_force_model(seed, progress, reuse=True)
    scenario = cached_scenario(protocol, "demo-push", functools.partial(pushing_scenario, speed_mm_s=DEMO_SPEED_MM_S),
                               progress)
    frames = []

    def collect(frame) -> None:
        if frame.estimates is not None and frame.device_time_s is not None:
            frames.append((frame.device_time_s, np.array(frame.estimates[:3])))

    settings = protocol.design.sensor_settings
    summary = run_live("emulator", [model_path], live_sinks(dashboard=dashboard, record=record), duration_s,
                       rate_hz=rate_hz, chips=1, settings=settings, callbacks=[collect],
                       emulator_source=scenario)
    live = {}
    if frames:
        times = np.array([t for t, _ in frames])
        estimates = np.array([e for _, e in frames])
        truth = scenario.force(times)
        live = {k: {**force_errors(truth[:, i], estimates[:, i]), "peak_true_N": float(np.abs(truth[:, i]).max())}
                for i, k in enumerate(FORCES)}
    return {"model": str(model_path), "calibration": calibration, "live": live, "estimated_frames": len(frames),
            "pipeline": summary}
