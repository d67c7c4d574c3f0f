"""A protocol's trials in a pool of processes are the trials of one process, bit for bit, a trial kept in
the cache is read back instead of run again, and a protocol run again reads its dataset from the cache
instead of running its trials a second time."""

from __future__ import annotations

import os
import signal
import time
from concurrent.futures.process import BrokenProcessPool

import numpy as np
import pytest

from softtip.lab import load_protocol, run_protocol
from softtip.lab.trials import POOL_FROM_TRIALS, processes_for_trials, run_trials


def _same(a, b) -> None:
    assert list(a.columns) == list(b.columns)
    for name in a.columns:
        assert a.columns[name].dtype == b.columns[name].dtype, name
        np.testing.assert_array_equal(a.columns[name], b.columns[name], err_msg=name)


# at least as many trials as a pool takes, on coarse meshes: grasp-positions 13 on a 2 x 2 grid (POOL_FROM_TRIALS
# is 8), grasp-two 3 trials of two pads with the pool taking them from 3 - each of its trials presses two pads
# in four load steps, and whether pooled trials are the serial ones does not depend on how many there are
POOL_FROM = {"grasp-two": 3, "grasp-positions": POOL_FROM_TRIALS}
PROTOCOLS = {"grasp-two": ("cylindrical-D", """
    trained_angles_deg = [0.0]
    untrained_angles_deg = [10.0]
    calibration_trials = 1
    validation_trials = 1
    untrained_trials = 1
"""), "grasp-positions": ("rectangular", """
    positions_mm = [-3.0, 3.0]
    angles_deg = [0.0]
    calibration_trials = 1
    validation_trials = 1
    other_thicknesses_mm = [4.0]
""")}


@pytest.mark.parametrize("name", PROTOCOLS)
def test_trials_run_by_a_pool_of_processes_are_the_serial_trials(coarse_protocol, monkeypatch, name):
    design, extra = PROTOCOLS[name]
    monkeypatch.setattr("softtip.lab.trials.POOL_FROM_TRIALS", POOL_FROM[name])
    protocol = load_protocol(coarse_protocol(name, design, extra=extra))
    with processes_for_trials(1):
        serial, _ = run_protocol(protocol, reuse=False)
    with processes_for_trials(2):
        pooled, _ = run_protocol(protocol, reuse=False)
    assert len(serial.trials) >= POOL_FROM[name]  # enough trials for the pool to run them
    _same(serial, pooled)
    # each trial draws from a stream of its own: no two trials of one condition read the same
    first = [serial.X()[serial.groups == trial][-1] for trial in serial.trials[:2]]
    assert not np.array_equal(*first)


def test_a_pool_returns_every_trial_in_the_plans_order():
    plans = [(k, k + 0.5) for k in range(3 * POOL_FROM_TRIALS)]
    assert run_trials(np.hypot, plans, processes=2) == [np.hypot(*plan) for plan in plans]
    with pytest.raises(ValueError, match="processes for trials = 0: expected at least 1"):
        with processes_for_trials(0):
            pass


def test_a_protocol_run_again_reads_its_trials_from_the_cache(coarse_protocol):
    protocol = load_protocol(coarse_protocol("haptics", ""))
    first, timings = run_protocol(protocol)
    again, read = run_protocol(protocol)
    assert "trials_s" in timings and set(read) == {"cache_read_s"}
    _same(first, again)
    assert again.metadata == first.metadata
    # another seed is another dataset, run afresh; so is any run told not to reuse
    other, timings = run_protocol(protocol.changed(seed=protocol.seed + 1))
    assert "trials_s" in timings and not np.array_equal(other.X(), first.X())
    fresh, timings = run_protocol(protocol, reuse=False)
    assert "trials_s" in timings
    _same(first, fresh)


def test_a_file_the_protocol_names_edited_under_its_name_makes_other_trials(tmp_path):
    from softtip.lab.protocols import protocol_from_dict, protocol_key

    finger = tmp_path / "mine.toml"
    table = {"protocol": "haptics", "seed": 3, "fingertip_files": ["mine.toml"],
             "parameters": {"trials": 4, "fs_levels": 5, "user_levels": 4, "fingertips": ["human 3 (10 mm)"],
                            "variations": [], "curve_n_neighbours": [], "curve_weighting_powers": [],
                            "curve_fs_levels": [], "curve_user_levels": []}}
    finger.write_text('[fingertip]\nname = "mine"\nradius_mm = 10.0\n')
    first = protocol_from_dict(table, "test.toml", tmp_path)
    key = protocol_key(first)
    ten, _ = run_protocol(first)
    finger.write_text('[fingertip]\nname = "mine"\nradius_mm = 7.0\n')  # another finger, the same file name
    second = protocol_from_dict(table, "test.toml", tmp_path)
    assert protocol_key(second) != key
    seven, timings = run_protocol(second)
    assert "trials_s" in timings  # run, not read
    assert not np.array_equal(seven.column("motor1_rad"), ten.column("motor1_rad"))


def _spread(low: float, high: float) -> tuple[np.ndarray, np.ndarray]:
    return np.linspace(low, high, 5), np.arange(3, dtype=np.int32) + int(low)


def test_kept_trials_are_numbered_across_a_runs_calls_and_read_back_instead_of_run(tmp_path):
    from softtip._core.cache import EntryPieces
    from softtip.lab.trials import trials_kept_in

    pieces = EntryPieces(tmp_path / "dataset.parquet", "key", "protocol trials")
    first, second = [(k, k + 0.5) for k in range(3)], [(10.0 + k, 11.0) for k in range(2)]
    with trials_kept_in(pieces):
        made = run_trials(_spread, first, processes=1), run_trials(_spread, second, processes=1)
    assert sorted(int(piece.stem) for piece in pieces.folder.glob("*.npz")) == [0, 1, 2, 3, 4]
    (pieces.folder / "1.npz").unlink()  # as if the run had stopped before its second trial ended
    calls = []

    def counted(low, high):
        calls.append(low)
        return _spread(low, high)

    with trials_kept_in(pieces):
        again = run_trials(counted, first, processes=1), run_trials(counted, second, processes=1)
    assert calls == [1]  # only the missing trial ran
    for made_trials, again_trials in zip(made, again, strict=True):
        for made_trial, again_trial in zip(made_trials, again_trials, strict=True):
            for made_array, again_array in zip(made_trial, again_trial, strict=True):
                assert made_array.dtype == again_array.dtype
                np.testing.assert_array_equal(made_array, again_array)
    others = EntryPieces(tmp_path / "other.parquet", "key", "protocol trials")
    with trials_kept_in(others), pytest.raises(TypeError, match="a kept trial returned float: expected a tuple"):
        run_trials(lambda low, high: low + high, [(20.0, 1.0)], processes=1)


def _started_then_asleep(log: str, seconds: float) -> None:
    with open(log, "a") as file:
        file.write(f"{os.getpid()}\n")
    time.sleep(seconds)


def _fails_on_two(k: int) -> int:
    if k == 2:
        raise ValueError("trial 2 failed")
    return k


def _ends_its_process(k: int) -> int:
    os._exit(3)


def test_a_stop_ends_the_pool_at_once_and_a_failed_trial_or_worker_is_raised(tmp_path):
    """A stop (Ctrl-C, or SIGTERM as the commands take it) neither waits for the queued trials nor for those
    under way: their processes are ended."""
    log = tmp_path / "workers"
    previous = signal.signal(signal.SIGALRM, lambda *_: (_ for _ in ()).throw(KeyboardInterrupt("SIGTERM")))
    signal.setitimer(signal.ITIMER_REAL, 0.5)
    start = time.monotonic()
    try:
        with pytest.raises(KeyboardInterrupt):
            run_trials(_started_then_asleep, [(str(log), 10.0)] * POOL_FROM_TRIALS, processes=2)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    # 0.55 s measured at a load average of 4 (0.5 s of it before the stop); each trial sleeps 10 s
    assert time.monotonic() - start < 2.0
    workers = [int(pid) for pid in log.read_text().split()]  # the processes of the trials under way
    assert 1 <= len(workers) <= 2
    for pid in workers:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
    with pytest.raises(ValueError, match="trial 2 failed"):
        run_trials(_fails_on_two, [(k,) for k in range(POOL_FROM_TRIALS)], processes=2)
    with pytest.raises(BrokenProcessPool):
        run_trials(_ends_its_process, [(k,) for k in range(POOL_FROM_TRIALS)], processes=2)
