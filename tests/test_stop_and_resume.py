"""Work stopped part way, by Ctrl-C or by the SIGTERM a robot's launch system sends, keeps what it finished
and the next run does only the rest: the twin's live scenarios motion by motion, a protocol's trials trial by
trial (its pool ended at once); a rendering or a live
stream ends as on Ctrl-C, its recording closed and readable."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from softtip._core.cache import cache_dir

HANG_GUARD_S = 900.0

# The twin's push scenario computed in a process of its own (its motions by two processes it forks), stopped
# by SIGTERM (as the command line takes it: like Ctrl-C) once its first motion is finished.
INTERRUPTED_SCENARIO = """
import os, signal, sys
from softtip._core.progress import Progress, Task
from softtip._core.stopping import stop_as_ctrl_c
from softtip.lab import load_protocol
from softtip.systems.hall_fingertip.live import live_pushes

stop_as_ctrl_c()

class StopAfterTheFirstMotion(Progress):
    def task(self, description, total=None):
        class Motions(Task):
            def advance(self, steps=1, note=None):
                if description.startswith("the pushes"):
                    os.kill(os.getpid(), signal.SIGTERM)
        return Motions()

live_pushes(load_protocol(sys.argv[1]), StopAfterTheFirstMotion())
"""


@pytest.mark.slow  # the coarse fingertip's influence matrices, then the scenario twice: 22 s at a load average of 3
def test_a_scenario_stopped_by_sigterm_keeps_its_finished_motions_and_the_next_run_computes_the_rest(
        coarse_protocol, written_pieces):
    from softtip.lab import load_protocol
    from softtip.systems.hall_fingertip.live import PUSH_SPEED_MM_S, live_pushes
    from softtip.systems.hall_fingertip.scenarios import pushing_scenario

    path = coarse_protocol("force3", "cylindrical-D")
    stopped = subprocess.run([sys.executable, "-c", INTERRUPTED_SCENARIO, str(path)], capture_output=True,
                             text=True, timeout=HANG_GUARD_S)
    assert stopped.returncode != 0 and "KeyboardInterrupt: SIGTERM" in stopped.stderr
    # the first motion finished, and the one the other process was computing if it was stored first
    kept = {int(piece.stem) for piece in (cache_dir() / "models").glob("scenario-push-*.pieces/*.npz")}
    assert 1 <= len(kept) <= 2
    computed = written_pieces  # the motions written in this test's process, so computed in this run
    protocol = load_protocol(path)
    resumed = live_pushes(protocol)
    # the finished motions were read back, not computed again
    assert computed() == sorted({0, 1, 2} - kept)
    assert not list((cache_dir() / "models").glob("scenario-push-*.pieces"))  # gone with the whole entry stored
    whole = pushing_scenario(protocol, protocol.seed, speed_mm_s=PUSH_SPEED_MM_S)
    assert np.array_equal(resumed.times_s, whole.times_s)
    for name in ("field_uT", "force_N"):  # the first motion came from another process: equal to round-off
        resumed_array, whole_array = getattr(resumed, name), getattr(whole, name)
        assert np.max(np.abs(resumed_array - whole_array)) <= 1e-10 * np.max(np.abs(whole_array))


# the renderer's table and a loop until its recording holds 20 kB: 5.9 s at a load average of 3 (53 s at 20)
def test_sigterm_ends_an_endless_rendering_as_ctrl_c_does_and_keeps_the_recording(tmp_path):
    """``haptics render`` without --duration runs until stopped; a launch system stops it with SIGTERM."""
    from softtip.realtime.recording.reader import read_recording

    path = tmp_path / "endless.mcap"
    child = subprocess.Popen([sys.executable, "-m", "softtip", "haptics", "render", "--fs-levels", "5", "--record",
                              str(path), "--fast", "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        deadline = time.monotonic() + HANG_GUARD_S
        while (not path.exists() or path.stat().st_size < 20_000) and time.monotonic() < deadline:
            assert child.poll() is None, child.stderr.read()
            time.sleep(0.05)
        child.send_signal(signal.SIGTERM)
        stdout, stderr = child.communicate(timeout=HANG_GUARD_S)
    finally:
        if child.poll() is None:
            child.kill()
            child.communicate()
    assert child.returncode == 0, stderr
    summary = json.loads(stdout)
    assert summary["interrupted"] and summary["ticks"] > 0
    recording = read_recording(path)  # closed with its summary: every tick the loop ran is in it
    assert not recording.truncated and len(recording.topics["/fingertip/estimates"].data) == summary["ticks"]


# A protocol's trials run by a pool of two processes in a process of their own, stopped by SIGTERM once the
# third trial is kept; every trial a worker starts is logged (the file named by the second argument).
INTERRUPTED_TRIALS = """
import os, signal, sys
from softtip._core.cache import EntryPieces
from softtip._core.stopping import stop_as_ctrl_c
from softtip.lab import load_protocol, run_protocol, trials

stop_as_ctrl_c()
run, write = trials._run_forked, EntryPieces.write

def logged(index):
    with open(sys.argv[2], "a") as file:
        file.write(f"{index}\\n")
    return run(index)

def write_then_stop(self, index, arrays):
    write(self, index, arrays)
    if self.kind == "protocol trials piece" and len(list(self.folder.glob("*.npz"))) == 3:
        os.kill(os.getpid(), signal.SIGTERM)

trials._run_forked, EntryPieces.write = logged, write_then_stop
with trials.processes_for_trials(2):
    run_protocol(load_protocol(sys.argv[1]))
"""


@pytest.mark.slow  # the coarse fingertip's influence matrices, then 13 trials three times: 20 s alone at a load average of 4.4, 38 s
# beside two other test files at 6
def test_trials_stopped_by_sigterm_keep_the_finished_ones_and_the_next_run_runs_the_rest(
        coarse_protocol, written_pieces, tmp_path):
    from softtip.lab import load_protocol, run_protocol
    from softtip.lab.protocols import trials_path
    from softtip.lab.trials import processes_for_trials

    path = coarse_protocol("grasp-positions", "rectangular", extra="""
        positions_mm = [-3.0, 3.0]
        angles_deg = [0.0]
        calibration_trials = 1
        validation_trials = 1
        other_thicknesses_mm = [4.0]
    """)
    started = tmp_path / "started-trials"
    stopped = subprocess.run([sys.executable, "-c", INTERRUPTED_TRIALS, str(path), str(started)],
                             capture_output=True, text=True, timeout=HANG_GUARD_S)
    assert stopped.returncode != 0 and "KeyboardInterrupt: SIGTERM" in stopped.stderr
    protocol = load_protocol(path)
    pieces = trials_path(protocol).with_name(trials_path(protocol).name + ".pieces")
    kept = {int(piece.stem) for piece in pieces.glob("*.npz")}
    assert len(kept) == 3
    # the pool ended with the parent: the trials still queued were never started
    assert len(started.read_text().split()) < 13
    with processes_for_trials(2):
        resumed, _ = run_protocol(protocol)
    assert len(resumed.trials) == 13
    assert written_pieces() == sorted(set(range(13)) - kept)  # only the missing trials were run
    assert not pieces.exists()  # gone with the whole dataset stored
    with processes_for_trials(1):
        whole, _ = run_protocol(protocol, reuse=False)
    assert list(resumed.columns) == list(whole.columns)
    for name in whole.columns:
        assert resumed.columns[name].dtype == whole.columns[name].dtype, name
        np.testing.assert_array_equal(resumed.columns[name], whole.columns[name], err_msg=name)


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="the kernel's view of the signals is Linux's")
def test_gmsh_leaves_sigpipe_ignored_so_a_pool_ended_on_a_stop_cannot_end_this_process():
    """gmsh makes SIGPIPE end the process; ending a pool's workers on Ctrl-C then broke its pipe and ended the
    process before it could keep what it finished."""
    from softtip.mechanics.mesh import gmsh_session

    def sigpipe_ignored() -> bool:  # as the kernel has it, not Python's record of the handler
        with open("/proc/self/status") as status:
            ignored = next(line for line in status if line.startswith("SigIgn:")).split()[1]
        return bool(int(ignored, 16) >> (signal.SIGPIPE - 1) & 1)

    assert sigpipe_ignored()
    with gmsh_session("signals"):
        assert sigpipe_ignored()
    assert sigpipe_ignored()
