"""Acquisition times on the host's wall clock, from the device clock; and a loop's deadlines on the
monotonic clock, kept with what Linux offers a user process (:class:`DeadlineClock`, :func:`realtime_thread`)."""

from __future__ import annotations

import gc
import math
import os
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass

CLOCK_LEAK = 1e-4  # twice the ±50 ppm of a common crystal: the device clock's drift is followed


class AcquisitionClock:
    """Acquisition times on the host's wall clock, from the device clock.

    The arrival time is the acquisition time plus a transport delay that is never
    negative and at its smallest most of the time. So the offset host - device is
    estimated as its running minimum, allowed to grow by ``leak`` seconds per second so
    that a device clock slower than the host's is followed:
    ``t = d (1 + leak) + min_j [h_j - d_j (1 + leak)]``. A device clock that goes back
    (the device restarted) starts a new minimum. Without a device clock the arrival time
    is used. Stamps are strictly increasing (by 1 ns at least).

    Arrival times are on the ``time.perf_counter`` clock; ``wall_minus_perf_ns`` turns them
    into wall-clock time (None: read both clocks now).
    """

    def __init__(self, leak: float = CLOCK_LEAK, wall_minus_perf_ns: int | None = None) -> None:
        self._factor = 1.0 + leak
        self._wall_minus_perf_ns = (time.time_ns() - time.perf_counter_ns() if wall_minus_perf_ns is None
                                    else int(wall_minus_perf_ns))
        self._offset = math.inf
        self._last_device: float | None = None
        self._last_ns = -1

    def stamp_ns(self, host_time_s: float, device_time_s: float | None) -> int:
        if device_time_s is None:
            acquired = host_time_s
        else:
            if self._last_device is not None and device_time_s < self._last_device:
                self._offset = math.inf
            self._last_device = device_time_s
            scaled = device_time_s * self._factor
            self._offset = min(self._offset, host_time_s - scaled)
            acquired = scaled + self._offset
        stamp = round(acquired * 1e9) + self._wall_minus_perf_ns
        if stamp <= self._last_ns:
            stamp = self._last_ns + 1
        self._last_ns = stamp
        return stamp


SPIN_S = 2e-4  # the last part of each wait spent spinning: a sleep's wake-up is late by tens of µs
SWITCH_INTERVAL_S = 1e-4  # how long a thread holding the GIL keeps it once a deadline thread asks for it
RT_PRIORITY = 50  # SCHED_FIFO priority: above every normal thread, below the kernel's own (99)
HELPER_PRIORITY_BELOW = 10  # the process's other threads run this far below the loop's


@dataclass(frozen=True)
class Timing:
    """What Linux granted a deadline loop: SCHED_FIFO (its priority) or why not, the CPU it is pinned to
    (None: not pinned, and why), and the GIL's switch interval while it ran."""

    priority: str
    cpu: int | None
    affinity: str
    switch_interval_s: float

    def to_dict(self) -> dict:
        return {"priority": self.priority, "cpu": self.cpu, "affinity": self.affinity,
                "switch_interval_s": self.switch_interval_s, "granted": self.granted}

    @property
    def granted(self) -> str:
        """In a few words: the policy the loop ran under, and its CPU."""
        policy = "SCHED_FIFO" if self.priority.startswith("SCHED_FIFO") else "normal priority"
        return policy + ("" if self.cpu is None else f", CPU {self.cpu}")


def loop_cpu() -> int:
    """The CPU a deadline loop is pinned to: the last this process may run on (so a busy process can be
    kept on the others)."""
    return max(os.sched_getaffinity(0))


def _set_fifo(thread_id: int, priority: int) -> tuple[int, os.sched_param] | None:
    """``thread_id`` (0: the calling thread) at SCHED_FIFO ``priority``: its policy before, or None if
    Linux refused (or the thread has ended)."""
    try:
        before = os.sched_getscheduler(thread_id), os.sched_getparam(thread_id)
        os.sched_setscheduler(thread_id, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError):
        return None
    return before


@contextmanager
def realtime_thread(realtime: bool = True, cpu: int | None = None) -> Iterator[Timing]:
    """For the calling thread: SCHED_FIFO at :data:`RT_PRIORITY` and, once granted, pinned to ``cpu``
    (default :func:`loop_cpu`); the process's other Python threads (sinks' writers ...) at SCHED_FIFO
    just below it, so that none is preempted by another process while it holds the GIL (not pinned:
    kept off the loop's CPU, one holding the GIL waited there behind another in C work, and the loop
    with it); and the GIL handed over within :data:`SWITCH_INTERVAL_S`; the objects alive on entry left out of garbage
    collections until exit (:func:`gc.freeze`). Each where Linux permits it, all undone on exit.
    The thread is pinned only with the priority: without it, a pinned thread waits for its CPU while
    another may be free. ``realtime`` False asks for none of it."""
    previous_interval = sys.getswitchinterval()
    if not realtime:
        yield Timing("normal priority (not asked)", None, "not pinned (not asked)", previous_interval)
        return
    affinity = os.sched_getaffinity(0)
    before = _set_fifo(0, RT_PRIORITY)
    helpers = {}
    if before is None:
        priority = "normal priority (SCHED_FIFO not permitted)"
    else:
        for thread in threading.enumerate():
            if thread is not threading.current_thread() and thread.native_id is not None:
                helpers[thread.native_id] = _set_fifo(thread.native_id, RT_PRIORITY - HELPER_PRIORITY_BELOW)
        priority = (f"SCHED_FIFO {RT_PRIORITY}, the process's {len(helpers)} other threads at "
                    f"{RT_PRIORITY - HELPER_PRIORITY_BELOW}")
    pinned, pinning = None, "not pinned (no real-time priority)"
    if before is not None:
        pinned = loop_cpu() if cpu is None else cpu
        try:
            os.sched_setaffinity(0, {pinned})
            pinning = f"pinned to CPU {pinned}"
        except OSError as problem:
            pinned, pinning = None, f"not pinned (not permitted: {problem.strerror})"
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    # the objects alive now are left out of garbage collections: a collection over the whole heap of a
    # command (tens of ms) holds the GIL, whichever thread runs it
    gc.freeze()
    try:
        yield Timing(priority, pinned, pinning, SWITCH_INTERVAL_S)
    finally:
        gc.unfreeze()
        sys.setswitchinterval(previous_interval)
        if pinned is not None:
            os.sched_setaffinity(0, affinity)
        for thread_id, policy in [(0, before), *helpers.items()]:
            if policy is not None:
                with suppress(OSError):  # a helper that has ended since
                    os.sched_setscheduler(thread_id, *policy)


class DeadlineClock:
    """Ticks every ``period_s`` on the monotonic clock (``time.perf_counter``) from :meth:`start`: each
    :meth:`wait` sleeps until ``spin_s`` before its tick's deadline, then spins to it, and returns the
    time it actually returned (never before the deadline). Deadlines stay on the grid: a late tick
    does not move the next one, so the loop catches up (late ticks run back to back) without drift."""

    def __init__(self, period_s: float, spin_s: float = SPIN_S) -> None:
        if not (math.isfinite(period_s) and period_s > 0):
            raise ValueError(f"period_s = {period_s!r}: expected a finite period > 0 s")
        if not (math.isfinite(spin_s) and 0 <= spin_s <= period_s):
            raise ValueError(f"spin_s = {spin_s!r}: expected from 0 to the period, {period_s:g} s")
        self.period_s, self.spin_s = period_s, spin_s
        self.origin_s = time.perf_counter()

    def start(self) -> float:
        """Tick 0's deadline is now."""
        self.origin_s = time.perf_counter()
        return self.origin_s

    def deadline(self, tick):
        """``tick``'s deadline (s, ``time.perf_counter``); ticks may be an array."""
        return self.origin_s + tick * self.period_s

    def wait(self, tick: int) -> float:
        """Returns at ``tick``'s deadline (or at once if it has passed): the time it returned."""
        deadline = self.deadline(tick)
        asleep = deadline - self.spin_s - time.perf_counter()
        if asleep > 0:
            time.sleep(asleep)
        now = time.perf_counter()
        while now < deadline:
            now = time.perf_counter()
        return now
