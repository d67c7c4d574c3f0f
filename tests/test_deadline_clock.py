"""The deadline loop of ``softtip.realtime.clock``: ticks never start before their deadline, the
deadlines stay on their grid however late a tick is, and what ``realtime_thread`` changes is undone."""

from __future__ import annotations

import gc
import os
import sys
import threading
import time

import numpy as np
import pytest

from softtip.realtime.clock import RT_PRIORITY, SWITCH_INTERVAL_S, DeadlineClock, loop_cpu, realtime_thread


def test_a_tick_starts_at_its_deadline_never_before():
    clock = DeadlineClock(1e-3)
    origin = clock.start()
    starts = np.array([clock.wait(tick) for tick in range(50)])
    deadlines = origin + np.arange(50) * 1e-3
    assert np.all(starts >= deadlines)
    assert np.array_equal(clock.deadline(np.arange(50)), deadlines)


def test_a_late_tick_does_not_move_the_next_deadlines(monkeypatch):
    clock = DeadlineClock(1e-3)
    origin = clock.start()
    time.sleep(0.0105)  # ten and a half periods of work in tick 0
    sleeps = []
    monkeypatch.setattr(time, "sleep", sleeps.append)
    caught_up = [clock.wait(tick) for tick in range(1, 11)]
    # ticks 1-10 were due already: each returns at once, without a sleep, back to back
    assert sleeps == [] and caught_up == sorted(caught_up)
    start = clock.wait(12)
    assert origin + 0.012 <= start  # and tick 12 waits for its own deadline on the same grid


@pytest.mark.parametrize(("period", "spin"), [(0.0, 0.0), (float("nan"), 0.0), (1e-3, 2e-3), (1e-3, -1e-4)])
def test_bad_periods_and_spins_are_refused(period, spin):
    with pytest.raises(ValueError, match="period_s|spin_s"):
        DeadlineClock(period, spin)


def test_realtime_thread_undoes_what_it_changed():
    before = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority, os.sched_getaffinity(0),
              sys.getswitchinterval(), gc.get_freeze_count())
    helper_stop = threading.Event()
    helper = threading.Thread(target=helper_stop.wait, daemon=True)
    helper.start()
    helper_before = os.sched_getscheduler(helper.native_id)
    try:
        with realtime_thread() as timing:
            assert sys.getswitchinterval() == pytest.approx(SWITCH_INTERVAL_S) and gc.get_freeze_count() > 0
            if timing.priority.startswith("SCHED_FIFO"):  # granted here (root, or CAP_SYS_NICE)
                assert os.sched_getscheduler(0) == os.SCHED_FIFO
                assert os.sched_getparam(0).sched_priority == RT_PRIORITY
                assert os.sched_getaffinity(0) == {loop_cpu()} == {timing.cpu}
                assert os.sched_getscheduler(helper.native_id) == os.SCHED_FIFO
                assert timing.granted == f"SCHED_FIFO, CPU {timing.cpu}"
            else:
                assert timing.cpu is None and "not permitted" in timing.priority
    finally:
        helper_stop.set()
    assert (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority, os.sched_getaffinity(0),
            sys.getswitchinterval(), gc.get_freeze_count()) == before
    assert os.sched_getscheduler(helper.native_id) == helper_before
    helper.join()


def test_without_realtime_nothing_is_asked():
    before = sys.getswitchinterval()
    with realtime_thread(False) as timing:
        assert sys.getswitchinterval() == before and os.sched_getscheduler(0) == os.SCHED_OTHER
    assert timing.granted == "normal priority" and timing.cpu is None
