"""A protocol's trials run side by side: each trial a pure function of its plan and its own random
stream, so the dataset is the same whether the trials run in this process or in a pool of processes.

A protocol's runner spawns one stream per trial from its bench's (``rng.spawn``: the same seed gives
the same streams, however the trials are then scheduled), then hands :func:`run_trials` the function
of one trial and the plans. The pool's processes are forked from this
one, so they inherit the bench (the fingertip's influence matrices) without copying it; each runs its
native thread pools on one thread, as the serial run does.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from contextvars import ContextVar
from typing import Any

from threadpoolctl import threadpool_limits

_PROCESSES: ContextVar[int | None] = ContextVar("trial_processes", default=None)
# what the forked processes inherit: the trial's function and its plans (a closure cannot be sent to them)
_FORKED: dict[str, Any] = {}
# below this many trials a pool costs more to start than it saves
POOL_FROM_TRIALS = 8


def trial_processes() -> int:
    """How many processes run a protocol's trials: one per core unless :func:`processes_for_trials` says."""
    chosen = _PROCESSES.get()
    return chosen if chosen is not None else os.cpu_count() or 1


@contextlib.contextmanager
def processes_for_trials(count: int) -> Iterator[None]:
    """Trials run by ``count`` processes within the block (1: in this process), e.g. in a process that a
    pool of studies already runs on one of the cores."""
    if count < 1:
        raise ValueError(f"processes for trials = {count}: expected at least 1")
    token = _PROCESSES.set(count)
    try:
        yield
    finally:
        _PROCESSES.reset(token)


def _run_forked(index: int) -> Any:
    with threadpool_limits(limits=1):
        return _FORKED["trial"](*_FORKED["plans"][index])


def run_trials(trial: Callable[..., Any], plans: Sequence[tuple], processes: int | None = None) -> list:
    """``trial(*plan)`` for every plan, in the plans' order: in this process, or (POSIX, from
    :data:`POOL_FROM_TRIALS` trials on) in a pool of ``processes`` forked processes (default
    :func:`trial_processes`). ``trial`` must draw from nothing but its plan (its random stream in it)."""
    processes = trial_processes() if processes is None else processes
    if processes <= 1 or len(plans) < POOL_FROM_TRIALS or os.name != "posix":
        with threadpool_limits(limits=1):
            return [trial(*plan) for plan in plans]
    _FORKED.update(trial=trial, plans=plans)
    try:
        with ProcessPoolExecutor(min(processes, len(plans)), mp_context=multiprocessing.get_context("fork")) as pool:
            return list(pool.map(_run_forked, range(len(plans)), chunksize=max(1, len(plans) // (8 * processes))))
    finally:
        _FORKED.clear()
