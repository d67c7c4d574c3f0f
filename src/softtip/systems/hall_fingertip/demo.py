"""The main job, end to end on the built-in simulated sensor: twin -> calibration -> live estimates.

1. twin: the 3-axis force calibration's motions, pushed and released at the speeds the live stream
   plays (the ``force-cycles`` protocol), run on the twin (cylindrical-D): a dataset of trials;
2. calibration: a 3-10-3 Levenberg-Marquardt network is fitted on its calibration trials (rests
   included), scored on its validation trials (by phase and speed) and saved as a softtip model file;
3. live: an emulated fingertip replays the same motions from the twin over a pseudo-terminal in the
   firmware's protocol; the live pipeline (driver -> baseline -> the saved model) estimates the
   force frame by frame, and the estimates are scored against the twin's true force, by phase as the
   validation trials are.
"""

from __future__ import annotations

import contextlib

import numpy as np

from softtip._core.progress import SILENT, Progress
from softtip.realtime.session import BASELINE_FRAMES, run_live
from softtip.realtime.sinks.factory import live_sinks
from softtip.systems.hall_fingertip.force_model import FORCES, axis_scores, calibrate_force_model
from softtip.systems.hall_fingertip.live import PUSH_SPEED_MM_S, live_pushes


def run_main_demo(seed: int = 1, duration_s: float | None = None, rate_hz: int = 50, dashboard: bool = True,
                  record: str | None = None, progress: Progress = SILENT) -> dict:
    """The three steps; ``duration_s``: seconds of live streaming, by default one loop of the twin's three
    motions (about 17 s) after the baseline's second, each with its rest, loading and release."""
    model_path, calibration, protocol = calibrate_force_model(seed, progress, reuse=True)
    with progress.task("live: the twin's pushes the emulated fingertip replays (kept in the cache)"):
        scenario = live_pushes(protocol, progress)  # the push scenario's: the next command finds it cached
    if duration_s is None:  # the baseline's frames estimate nothing; a few frames more for the stream's start
        duration_s = scenario.duration_s + (BASELINE_FRAMES + 5) / rate_hz
    frames = []

    def collect(frame) -> None:
        if frame.estimates is not None and frame.device_time_s is not None:
            frames.append((frame.device_time_s, np.array(frame.estimates[:3])))

    settings = protocol.design.chip_settings
    # the dashboard takes the terminal while it streams; without it, the stream is a stage of its own
    with contextlib.nullcontext() if dashboard else progress.task(f"live: {duration_s:g} s of the emulated "
                                                                   "fingertip through the saved model"):
        summary = run_live("emulator", [model_path], live_sinks(dashboard=dashboard, record=record), duration_s,
                           rate_hz=rate_hz, chips=1, settings=settings, callbacks=[collect],
                           emulator_source=scenario)
    live, whole_loops, window = {}, {}, []
    if frames:
        times = np.array([t for t, _ in frames])
        estimates = np.array([e for _, e in frames])
        truth = scenario.force(times)
        live = {k: {**axis_scores(truth[:, i], estimates[:, i]), "peak_true_N": float(np.abs(truth[:, i]).max())}
                for i, k in enumerate(FORCES)}
        window = [float(times[0]), float(times[-1])]  # which part of the scenario's loop the scores cover
        # a stream longer than its loop counts the loop's start twice; over whole loops each motion counts
        # once, as in the held-out trials
        # each frame stands for one period: half a period of slack against the device clock's rounding
        loops = np.floor((times[-1] - times[0] + 1.5 / rate_hz) / scenario.duration_s)
        covered = times < times[0] + loops * scenario.duration_s
        if loops:
            whole_loops = {k: axis_scores(truth[covered, i], estimates[covered, i]) for i, k in enumerate(FORCES)}
    return {"model": str(model_path), "calibration": calibration, "live": live, "live_whole_loops": whole_loops,
            "live_speed_mm_s": PUSH_SPEED_MM_S, "live_device_times_s": window, "live_loop_s": scenario.duration_s,
            "estimated_frames": len(frames), "pipeline": summary}
