"""The wearable sensor live: the emulated side chip streaming a seating of the ring through the live
pipeline with the model identified on the twin's calibration seatings (:func:`wearable_live_setup`,
:func:`run_wearable_demo`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from softtip._core.cache import read_entry, read_file_entry, write_entry, write_file_entry
from softtip._core.progress import SILENT, Progress
from softtip.hardware import PacedSource
from softtip.lab import load_protocol, run_protocol
from softtip.lab.protocols import protocol_key, trained_model_path
from softtip.realtime.session import run_live
from softtip.realtime.sinks.base import Sink
from softtip.realtime.sinks.factory import live_sinks
from softtip.sysid import Recording, TransferFunctionModel
from softtip.realtime.scenario import LiveScenario, StreamCheck, accept_any_stream
from softtip.sysid import load_model as load_system
from softtip.sysid import save_model as save_system
from softtip.sysid.metrics import score_outputs
from softtip.systems.wearable.reading import FORCE

FORCES = ("fx_N", "fy_N", "fz_N")

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
    protocol = load_protocol("wearable").changed(seed=seed, participants=1, runs=WEARABLE_CALIBRATION_RUNS + 1,
                                                 contacts=["flat"])
    path, stream_path = trained_model_path(protocol, "wearable-force"), trained_model_path(protocol, "wearable-stream")
    key = protocol_key(protocol)
    # computed before by this code for this protocol: kept in the cache
    entry = read_entry(stream_path, key, "wearable stream")
    system = None if entry is None else read_file_entry(path, key, "wearable-force", load_system)
    if system is not None:
        metadata, arrays = entry
        return WearableStream(system, path, arrays["readings"], arrays["trial_starts"], arrays["force_N"],
                              metadata["rate_hz"], metadata["validation"])
    dataset, _ = run_protocol(protocol, progress)
    live = dataset.column("run") == WEARABLE_CALIBRATION_RUNS
    calibration = Recording.from_dataset(dataset.select(rows=~live), WEARABLE_INPUTS, FORCES,
                                         source="wearable calibration runs")
    streamed = dataset.select(rows=live)
    with progress.task(f"identification: a 3 x 3 transfer function of order 6 on {calibration.n_samples} samples"):
        model = TransferFunctionModel(6).fit(calibration)
    scores = model.evaluate(Recording.from_dataset(streamed, WEARABLE_INPUTS, FORCES, source="wearable live run"))
    write_file_entry(path, key, "wearable-force", lambda file: save_system(file, model))
    # what the chip read: each trial's tare added back to its tared readings
    readings = np.column_stack([streamed.column(name) + streamed.column(f"side_tare_{name.removeprefix('side_')}")
                                for name in WEARABLE_INPUTS])
    starts = np.flatnonzero(np.r_[True, streamed.groups[1:] != streamed.groups[:-1]])
    stream = WearableStream(model, path, readings[:, None, :], starts, streamed.y(list(FORCES)),
                            protocol.parameters.rate_hz, scores.to_dict())
    write_entry(stream_path, key, "wearable stream", {"rate_hz": stream.rate_hz, "validation": stream.validation},
                {"readings": stream.readings, "trial_starts": stream.trial_starts, "force_N": stream.force_N})
    return stream


def wearable_scenario(progress: Progress = SILENT, check: StreamCheck = accept_any_stream) -> LiveScenario:
    """The emulated side chip streaming the seating after the calibration at its 10 Hz, with the model
    identified on the calibration seatings; the baseline is the first frame, as the protocol tares."""
    check(1, load_protocol("wearable").parameters.rate_hz)  # the one side chip, at the protocol's rate
    stream = wearable_live_setup(progress=progress)
    return LiveScenario("the side chip on the seating after the calibration", stream.source(), (stream.model,),
                        chips=1, rate_hz=stream.rate_hz, baseline_frames=1)


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
