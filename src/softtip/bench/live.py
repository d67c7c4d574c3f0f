"""The soak benchmark of the live pipeline: an emulated fingertip at full rate through the
driver, the baseline, a 12-20-4 network and the MCAP recorder, with an exact account of
every frame.

The emulator runs in a child process, so the CPU time measured (``time.process_time`` of
this process over the streaming time) is the pipeline's alone: the driver's reader
thread (reading, decoding, conversion, then baseline and estimate) and the recorder's
writer thread. It is also reported per thread (Linux).
Latency is from the arrival of a frame's last bytes (the driver's host timestamp) to its
estimate. The emulator's log of every generated frame and its fate (sent intact,
corrupted, truncated, not sent) is compared frame by frame with the sequence numbers the
pipeline received: every frame sent intact must arrive, in order, and every damaged one
must be counted as lost by the driver.
"""

from __future__ import annotations

import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import threading
import time
from array import array
from collections.abc import Callable
from pathlib import Path

import numpy as np
from mcap.reader import make_reader

from softtip._core.cache import CACHE_VARIABLE
from softtip._core.channels import channel_names
from softtip._core.progress import SILENT, Progress
from softtip.hardware import FaultPlan, FrameFate, PressCycle
from softtip.realtime.baseline import Baseline
from softtip.realtime.estimator import Estimator
from softtip.realtime.frames import FrameResult
from softtip.realtime.session import EMULATOR, LiveSession
from softtip.realtime.sinks.recorder import RecorderSink

SOAK_TARGETS = ("Fx", "Fy", "Fz", "grip_force")
LATENCY_TARGET_P99_MS = 2.0
CPU_TARGET_PERCENT = 15.0
START_TARGETS_S = {"cold": 60.0, "warm": 5.0}  # to the first frame, on an idle machine (issue 40)
START_STREAM_S = 1.0  # what each start streams once it has its first frame


class StartFailed(RuntimeError):
    """A ``softtip live`` started by :func:`start_times` ended with an error."""


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def start_times(scenario: str = "push", progress: Progress = SILENT) -> dict:
    """Seconds from the start of ``softtip live --emulate --scenario SCENARIO`` to its first frame, run twice
    in child processes one after the other: cold, on an empty cache folder of its own, then warm, on the
    same folder as the cold run left it. Each with its CPU time (the command's process and its emulator),
    its wall time to the end, and the load average just before it (the first frame is the command's own
    ``first_frame_s``, measured from the process's start)."""
    command = [sys.executable, "-m", "softtip", "live", "--emulate", "--scenario", scenario,
               "--duration", f"{START_STREAM_S:g}", "--json"]
    runs = {}
    with tempfile.TemporaryDirectory(prefix="softtip-start-") as cache:
        for kind, waits_for in (("cold", "the twin's run and the models computed into an empty cache"),
                                ("warm", "the same, read from the cache")):
            with progress.task(f"start of live --emulate --scenario {scenario}, {kind}: {waits_for}"):
                load = os.getloadavg()
                cpu_before, wall_before = _children_cpu_s(), time.perf_counter()
                child = subprocess.run(command, env=os.environ | {CACHE_VARIABLE: cache}, capture_output=True,
                                       text=True)
                wall_s, cpu_s = time.perf_counter() - wall_before, _children_cpu_s() - cpu_before
            if child.returncode != 0:
                said = (child.stderr.strip().splitlines() or ["nothing on stderr"])[-1]
                raise StartFailed(f"{' '.join(command[2:])} ({kind} start) ended with exit code "
                                  f"{child.returncode}: {said}")
            first_frame_s = json.loads(child.stdout)["first_frame_s"]
            runs[kind] = {"first_frame_s": first_frame_s, "cpu_s": cpu_s, "wall_s": wall_s,
                          "load_average_1_5_15_min": list(load),
                          "target_s": START_TARGETS_S[kind],
                          "target_met": first_frame_s is not None and first_frame_s <= START_TARGETS_S[kind]}
    return {"scenario": scenario, "streamed_s": START_STREAM_S, "cpus": os.cpu_count(), **runs}


def soak_network(chips: int = 4, hidden: int = 20, seed: int = 0) -> Estimator:
    """A network of 3 chips inputs, ``hidden`` tanh neurons and 4 linear outputs
    (Fx, Fy, Fz, grip force in N), fitted by Levenberg–Marquardt for a few epochs to a
    smooth map of synthetic changes: the real model class and its real-time path."""
    from softtip.calibration.network import LMNetwork

    rng = np.random.default_rng(seed)
    changes_uT = rng.normal(0.0, 200.0, (400, 3 * chips))
    mixing = rng.normal(0.0, 1.0 / (200.0 * math.sqrt(3 * chips)), (3 * chips, len(SOAK_TARGETS)))
    forces_N = 5.0 * np.tanh(changes_uT @ mixing)
    network = LMNetwork((hidden,), max_epochs=5, random_state=seed).fit(changes_uT, forces_N)
    return Estimator(network, channel_names(chips), target_names=SOAK_TARGETS, target_units="N", name="soak-network")


class DeliveryLog:
    """A pipeline callback keeping each frame's sequence number and device time."""

    def __init__(self) -> None:
        self.seq = array("l")
        self.device_time_s = array("d")

    def __call__(self, frame: FrameResult) -> None:
        self.seq.append(frame.seq)
        self.device_time_s.append(math.nan if frame.device_time_s is None else frame.device_time_s)


def _thread_cpu_s() -> dict[str, float]:
    """CPU time (user + system) of each thread of this process, by thread name (Linux)."""
    names = {thread.native_id: thread.name for thread in threading.enumerate()}
    ticks = os.sysconf("SC_CLK_TCK")
    times = {}
    for native_id, name in names.items():
        try:
            with open(f"/proc/self/task/{native_id}/stat") as stat:
                fields = stat.read().rsplit(")", 1)[1].split()
        except OSError:  # no /proc (not Linux), or the thread just ended
            continue
        times[name] = (int(fields[11]) + int(fields[12])) / ticks  # utime, stime
    return times


def _recording_counts(path: Path) -> dict:
    with path.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    statistics = summary.statistics
    by_topic = {summary.channels[c].topic: n for c, n in statistics.channel_message_counts.items()}
    return {"path": str(path), "bytes": path.stat().st_size, "messages": statistics.message_count,
            "chunks": statistics.chunk_count, "messages_by_topic": by_topic}


def _interval_stats_ms(times_s: np.ndarray, period_s: float) -> dict:
    intervals = np.diff(times_s[np.isfinite(times_s)])
    if intervals.size == 0:
        return {"p50": math.nan, "p99": math.nan, "max": math.nan, "late": 0}
    p50, p99, top = np.percentile(intervals, [50, 99, 100]) * 1e3
    return {"p50": float(p50), "p99": float(p99), "max": float(top),
            "late": int(np.count_nonzero(intervals > 1.5 * period_s))}


def soak(duration_s: float = 20.0, rate_hz: int = 500, chips: int = 4, faults: FaultPlan | None = None, *,
         record_path: str | Path | None = None, drift_time_constant_s: float | None = None, seed: int = 0,
         progress: Callable[[str], None] | None = None) -> dict:
    """Run the soak benchmark for ``duration_s`` seconds (module notes) and return its figures.

    ``faults``: damage injected by the emulator; ``record_path``: keep the recording there
    (default: a temporary file, removed); ``drift_time_constant_s``: also track drift.
    """
    if isinstance(duration_s, bool) or not isinstance(duration_s, (int, float)) or not duration_s > 0:
        raise ValueError(f"duration_s = {duration_s!r}: expected a positive number of seconds")
    say = progress or (lambda message: None)
    faults = FaultPlan() if faults is None else faults
    estimator = soak_network(chips, seed=seed)
    deliveries = DeliveryLog()
    with tempfile.TemporaryDirectory(prefix="softtip-soak-") as scratch:
        path = Path(record_path) if record_path is not None else Path(scratch) / "soak.mcap"
        baseline = Baseline(max(1, rate_hz // 2), drift_time_constant_s=drift_time_constant_s)
        session = LiveSession(EMULATOR, [estimator], [RecorderSink(path)], rate_hz=rate_hz, chips=chips,
                              baseline=baseline, callbacks=[deliveries], emulator_source=PressCycle(chips, seed=seed),
                              emulator_faults=faults, emulator_seed=seed)
        say(f"soak: {chips} chips at {rate_hz} frames/s for {duration_s:g} s, recording to {path}")
        with session:
            threads_before = _thread_cpu_s()
            session.wait(duration_s)
            threads_after = _thread_cpu_s()
        summary = session.summary()
        recording = _recording_counts(path)

    log = session.emulator_log
    sent = log.fate == log.FATES.index(FrameFate.SENT)
    delivered_seq = np.array(deliveries.seq, dtype=np.int64)
    every_good_delivered = bool(np.array_equal(delivered_seq, log.seq[sent]))
    damaged = log.count(FrameFate.CORRUPTED) + log.count(FrameFate.TRUNCATED)
    not_sent = log.count(FrameFate.NOT_SENT)
    # The driver knows a frame was lost when a later one arrives: those after the last
    # intact frame cannot be counted.
    countable = int(np.count_nonzero(~sent[:np.flatnonzero(sent)[-1]])) if sent.any() else 0
    generation = np.arange(len(log.seq))
    chip_error_frames = (int(np.count_nonzero(sent & ((generation + 1) % faults.chip_error_every == 0)))
                         if faults.chip_error_every else 0)
    period_s = 1.0 / rate_hz
    device_times = np.array(deliveries.device_time_s, dtype=np.float64)
    streaming_s = summary["streaming_s"]
    latency = summary["latency_ms"]
    report = {
        "duration_s": duration_s, "rate_hz": rate_hz, "chips": chips,
        "faults": {name: getattr(faults, name) for name in faults.__dataclass_fields__},
        "frames": {
            "generated": len(log.seq), "sent_intact": int(np.count_nonzero(sent)), "damaged": damaged,
            "not_sent": not_sent, "delivered": summary["frames"],
            "lost": int(np.count_nonzero(sent)) - summary["frames"],
            "counted_lost_by_driver": summary["lost_in_transit"], "crc_errors": summary["crc_errors"],
            "malformed": summary["malformed"], "chip_fault_frames": summary["with_chip_fault"],
            "chip_fault_frames_injected": chip_error_frames, "estimated": summary["estimated"],
            "every_intact_frame_delivered_in_order": every_good_delivered,
            "every_damaged_frame_counted": summary["lost_in_transit"] == countable,
        },
        "latency_ms": latency,
        "cpu_percent_of_one_core": summary["cpu_percent"],
        # The reader thread runs the driver (read, decode, convert) and then the pipeline.
        "cpu_percent_by_thread": {name: 100.0 * (cpu_s - threads_before.get(name, 0.0)) / streaming_s
                                  for name, cpu_s in threads_after.items() if cpu_s > threads_before.get(name, 0.0)},
        "streaming_s": streaming_s,
        "emulator": {"frames_per_s": len(log.seq) / streaming_s if streaming_s > 0 else math.nan,
                     "cpu_percent_of_one_core": 100.0 * log.cpu_s / streaming_s if streaming_s > 0 else math.nan,
                     "interval_ms": _interval_stats_ms(device_times, period_s)},
        "recording": recording | {
            "complete": recording["messages_by_topic"].get("/fingertip/chip0/field") == summary["frames"]},
        "sink_errors": summary["sink_errors"],
    }
    report["targets_met"] = {
        "no_intact_frame_lost": every_good_delivered,
        "latency_p99_le_2_ms": bool(latency["p99"] <= LATENCY_TARGET_P99_MS),
        "cpu_below_15_percent": bool(summary["cpu_percent"] < CPU_TARGET_PERCENT),
    }
    say(f"soak: delivered {summary['frames']} of {report['frames']['sent_intact']} intact frames, "
        f"latency p50/p99/max {latency['p50']:.3f}/{latency['p99']:.3f}/{latency['max']:.3f} ms, "
        f"CPU {summary['cpu_percent']:.1f} % of one core")
    return report
