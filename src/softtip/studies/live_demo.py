"""The main job, end to end on the built-in simulated sensor: twin -> calibration -> live estimates;
and the wearable sensor's live scenario (:func:`wearable_live_setup`).

1. the 3-axis force calibration protocol runs on the twin (cylindrical-D): a dataset of trials;
2. a 3-10-3 Levenberg-Marquardt network is fitted on its calibration trials, scored on its
   validation trials and saved as a softtip model file;
3. an emulated fingertip replays the same motions from the twin over a pseudo-terminal in the
   firmware's protocol; the live pipeline (driver -> baseline -> the saved model) estimates the
   force frame by frame, and the estimates are scored against the twin's true force.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from softtip._core.channels import FORCE
from softtip._core.progress import SILENT, Progress
from softtip.calibration import LMNetwork, metrics, save_model
from softtip.lab import load_protocol, run_protocol
from softtip.lab.experiments import CALIBRATION, VALIDATION
from softtip.hardware import PacedSource
from softtip.lab.scenario import pushing_scenario
from softtip.realtime.session import run_live
from softtip.realtime.sinks.factory import live_sinks
from softtip.sensors import MLX90393Settings
from softtip.studies.insertion import trained_model_path
from softtip.sysid import Recording, TransferFunctionModel
from softtip.sysid import save_model as save_system

FORCES = ("fx_N", "fy_N", "fz_N")
DEMO_SPEED_MM_S = 2.0  # faster than the calibration (0.5 mm/s): the three motions loop in about 17 s


def calibrate_force_model(seed: int, progress: Progress = SILENT, reuse: bool = False) -> tuple[Path, dict, object]:
    """Run the force calibration on the twin and fit the network (``reuse``: take the model saved by an
    earlier run of this protocol and code, if there is one)."""
    protocol = load_protocol("force3")
    protocol.seed = seed
    path = trained_model_path(protocol, "demo-force")
    if reuse and path.is_file():
        return path, {}, protocol
    dataset, timings = run_protocol(protocol, progress)
    X = dataset.X()
    y = np.column_stack([dataset.column(k) for k in FORCES])
    contact = np.abs(y).max(axis=1) > 0.05
    role = dataset.column("role")
    train, test = contact & (role == CALIBRATION), contact & (role == VALIDATION)
    with progress.task(f"calibration: a 3-10-3 network on {int(train.sum())} samples of {len(dataset.trials)} trials"):
        model = LMNetwork((10,), random_state=seed).fit(X[train], y[train], groups=dataset.groups[train])
    estimate = model.predict(X[test])
    validation = {k: {"mean_abs_error_N": float(metrics.mean_abs_error(y[test, i], estimate[:, i])),
                      "r2": float(metrics.r2(y[test, i], estimate[:, i]))} for i, k in enumerate(FORCES)}
    path.parent.mkdir(parents=True, exist_ok=True)
    save_model(path, model, input_channels=list(dataset.channels), input_units=["uT"] * len(dataset.channels),
               target_names=list(FORCES), target_units=["N"] * 3, extra={"validation": validation})
    return path, {"validation": validation, "timings_s": timings}, protocol


def run_main_demo(seed: int = 1, duration_s: float = 20.0, rate_hz: int = 50, dashboard: bool = True,
                  record: str | None = None, progress: Progress = SILENT) -> dict:
    model_path, calibration, protocol = calibrate_force_model(seed, progress)
    with progress.task(f"live: the twin's pushes for {duration_s:g} s of emulated streaming"):
        scenario = pushing_scenario(protocol, seed, speed_mm_s=DEMO_SPEED_MM_S)
    frames = []

    def collect(frame) -> None:
        if frame.estimates is not None and frame.device_time_s is not None:
            frames.append((frame.device_time_s, np.array(frame.estimates[:3])))

    settings = MLX90393Settings.from_dict(protocol.design.sensor_readout)
    summary = run_live("emulator", [model_path], live_sinks(dashboard=dashboard, record=record), duration_s,
                       rate_hz=rate_hz, chips=1, settings=settings, callbacks=[collect],
                       emulator_source=scenario)
    live = {}
    if frames:
        times = np.array([t for t, _ in frames])
        estimates = np.array([e for _, e in frames])
        truth = scenario.force(times)
        live = {k: {"mean_abs_error_N": float(metrics.mean_abs_error(truth[:, i], estimates[:, i])),
                    "peak_true_N": float(np.abs(truth[:, i]).max())} for i, k in enumerate(FORCES)}
    return {"model": str(model_path), "calibration": calibration, "live": live, "estimated_frames": len(frames),
            "pipeline": summary}


WEARABLE_INPUTS = FORCE.channel_names(1)
WEARABLE_CALIBRATION_RUNS = 3  # seatings of the ring the model is identified on; one more is streamed


@dataclass(frozen=True)
class WearableStream:
    """The wearable live scenario: a 6th-order transfer-function model identified on one participant's
    calibration runs (``model``: its file), and a further seating of the ring to stream.

    ``readings`` (N, 1, 3): the side chip's absolute readings (N) of that seating's seven trials, one
    after the other, at ``rate_hz``; ``force_N`` (N, 3): the table force over the same samples, tared
    at the first sample as the live baseline is; ``validation``: the model's per-trial offline scores
    on that seating (the study's metrics)."""

    model: Path
    readings: np.ndarray
    force_N: np.ndarray
    rate_hz: float
    validation: dict

    def source(self, loop: bool = True) -> PacedSource:
        """The emulated wearable sensor playing ``readings`` at ``rate_hz``."""
        return PacedSource(self.readings, self.rate_hz, reading=FORCE, loop=loop, name="emulated wearable sensor")


def _absolute(dataset, names: tuple[str, ...], tares: tuple[str, ...]) -> np.ndarray:
    """Tared columns with each trial's tare added back: what the sensor read."""
    return np.column_stack([dataset.column(n) + dataset.column(t) for n, t in zip(names, tares, strict=True)])


def wearable_live_setup(seed: int | None = None, progress: Progress = SILENT) -> WearableStream:
    """Run the wearable protocol (``seed``: default the protocol's) for one participant on one more
    seating than the calibration, identify the model on the calibration seatings and keep the last one
    to stream (see :class:`WearableStream`)."""
    protocol = load_protocol("wearable")
    protocol.seed = protocol.seed if seed is None else seed
    protocol.parameters.update(participants=1, runs=WEARABLE_CALIBRATION_RUNS + 1, contacts=["flat"])
    dataset, _ = run_protocol(protocol, progress)
    live = dataset.column("run") == WEARABLE_CALIBRATION_RUNS
    calibration = Recording.from_dataset(dataset.select(rows=~live), WEARABLE_INPUTS, FORCES,
                                         source="wearable calibration runs")
    streamed = dataset.select(rows=live)
    with progress.task(f"identification: a 3 x 3 transfer function of order 6 on {calibration.n_samples} samples"):
        model = TransferFunctionModel(6).fit(calibration)
    scores = model.evaluate(Recording.from_dataset(streamed, WEARABLE_INPUTS, FORCES, source="wearable live run"))
    path = trained_model_path(protocol, "wearable-force")
    path.parent.mkdir(parents=True, exist_ok=True)
    save_system(path, model)
    readings = _absolute(streamed, WEARABLE_INPUTS, tuple(f"side_tare_{n.removeprefix('side_')}" for n in
                                                           WEARABLE_INPUTS))
    table = _absolute(streamed, FORCES, tuple(f"table_tare_{n}" for n in FORCES))
    return WearableStream(path, readings[:, None, :], table - table[0], protocol.parameters["rate_hz"], scores.to_dict())
