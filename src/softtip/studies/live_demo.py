"""The main job, end to end on the built-in simulated sensor: twin -> calibration -> live estimates;
and the wearable sensor's (:func:`wearable_live_setup`, :func:`run_wearable_demo`).

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
from softtip import metrics
from softtip.calibration import LMNetwork, save_model
from softtip.lab import load_protocol, run_protocol
from softtip.lab.experiments import CALIBRATION, VALIDATION
from softtip.hardware import PacedSource
from softtip.lab.scenario import pushing_scenario
from softtip.realtime.session import run_live
from softtip.realtime.sinks.base import Sink
from softtip.realtime.sinks.factory import live_sinks
from softtip.sensors import MLX90393Settings
from softtip.studies.insertion import trained_model_path
from softtip.sysid import Recording, TransferFunctionModel
from softtip.sysid import save_model as save_system
from softtip.sysid.metrics import score_outputs

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
    calibration runs (``system``; ``model``: its file), and a further seating of the ring to stream.

    ``readings`` (N, 1, 3): the side chip's absolute readings (N) of that seating's seven trials, one
    after the other, at ``rate_hz``; ``trial_starts``: the first frame of each trial; ``force_N``
    (N, 3): the table force, tared per trial as the study's is; ``validation``: the model's offline
    scores on that seating, trial by trial (the study's metrics)."""

    system: TransferFunctionModel
    model: Path
    readings: np.ndarray
    trial_starts: np.ndarray
    force_N: np.ndarray
    rate_hz: float
    validation: dict

    def source(self, loop: bool = True) -> PacedSource:
        """The emulated wearable sensor playing ``readings`` at ``rate_hz``."""
        return PacedSource(self.readings, self.rate_hz, reading=FORCE, loop=loop, name="emulated wearable sensor")

    def frame(self, device_time_s: float) -> int:
        """The row of ``readings`` a frame of the source plays."""
        return round(device_time_s * self.rate_hz) % len(self.readings)


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
    # what the chip read: each trial's tare added back to its tared readings
    readings = np.column_stack([streamed.column(name) + streamed.column(f"side_tare_{name.removeprefix('side_')}")
                                for name in WEARABLE_INPUTS])
    starts = np.flatnonzero(np.r_[True, streamed.groups[1:] != streamed.groups[:-1]])
    return WearableStream(model, path, readings[:, None, :], starts, streamed.y(list(FORCES)),
                          protocol.parameters["rate_hz"], scores.to_dict())


class _TareEachTrial(Sink):
    """Asks for a baseline on the frame before each trial starts, so the trial's first frame is its tare,
    as in the protocol (the pipeline takes a baseline from the frame after the request)."""

    def __init__(self, stream: WearableStream) -> None:
        self.before_start = set(((stream.trial_starts - 1) % len(stream.readings)).tolist())
        self.stream = stream

    def open(self, info) -> None:
        self.take_baseline = info.take_baseline

    def write(self, frame) -> None:
        if self.stream.frame(frame.device_time_s) in self.before_start:
            self.take_baseline()

    def close(self) -> None:
        pass


def run_wearable_demo(seed: int = 1, duration_s: float | None = None, dashboard: bool = True,
                      record: str | None = None, progress: Progress = SILENT) -> dict:
    """The wearable sensor end to end: its twin's calibration seatings, the identified model, and the
    emulated chip streaming a further seating through the live pipeline (``duration_s``: default the
    whole seating once), tared at each trial's first frame as the protocol does (a baseline taken on
    command). Scores the live estimates against the table force, and against the offline simulation of
    the same frames by the same model from each tare (what real time may lose: nothing)."""
    stream = wearable_live_setup(seed, progress)
    duration_s = len(stream.readings) / stream.rate_hz if duration_s is None else duration_s
    live = []

    def collect(frame) -> None:
        if frame.estimates is not None:
            live.append((stream.frame(frame.device_time_s), frame.change[0].copy(), frame.estimates.copy()))

    with progress.task(f"live: the emulated wearable chip for {duration_s:g} s at {stream.rate_hz:g} Hz"):
        summary = run_live(stream.source(), [stream.model],
                           [_TareEachTrial(stream), *live_sinks(dashboard=dashboard, record=record)],
                           duration_s, baseline_frames=1, callbacks=[collect])
    report = {"model": str(stream.model), "offline_next_seating": stream.validation, "pipeline": summary,
              "estimated_frames": len(live)}
    if len(live) > 1:
        rows = np.array([k for k, _, _ in live])
        changes, estimates = np.array([c for _, c, _ in live]), np.array([e for _, _, e in live])
        # A trial's first frame is its tare: estimated before the baseline is taken from it, it ends the
        # previous segment; the model restarts from rest on the next frame.
        tared = np.isin(rows, stream.trial_starts)
        model = stream.system
        segments = np.split(np.arange(len(rows)), np.flatnonzero(tared) + 1)
        offline = np.vstack([model.simulate(changes[segment]) for segment in segments if len(segment)])
        scored = ~tared
        report["live"] = score_outputs(stream.force_N[rows[scored]], estimates[scored], FORCES, ("N",) * 3).to_dict()
        report["live_minus_offline_over_full_scale"] = (np.abs(estimates - offline).max(axis=0)
                                                         / (offline.max(axis=0) - offline.min(axis=0))).tolist()
    return report
