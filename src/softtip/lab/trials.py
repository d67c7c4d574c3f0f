"""A protocol's trials run side by side: each trial a pure function of its plan and its own random
stream, so the dataset is the same whether the trials run in this process or in a pool of processes.

A protocol's runner spawns one stream per trial from its bench's (``rng.spawn``: the same seed gives
the same streams, however the trials are then scheduled), then hands :func:`run_trials` the function
of one trial and the plans. The pool's processes are forked from this
one, so they inherit the bench (the fingertip's influence matrices) without copying it; each runs its
native thread pools on one thread, as the serial run does.

Within :func:`trials_kept_in` (a protocol's run with the cache), each finished trial is kept as a piece of
the protocol's dataset entry as soon as it ends: a run stopped part way (Ctrl-C, SIGTERM) keeps them, and
the next one runs only the trials still missing. Ctrl-C or SIGTERM here stops the pool at once: its queued
trials are dropped and its processes ended (they ignore the Ctrl-C a terminal sends them too).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from softtip._core.cache import EntryPieces
from softtip._core.stopping import as_forked_worker

_PROCESSES: ContextVar[int | None] = ContextVar("trial_processes", default=None)
# what the forked processes inherit: the trial's function and its plans (a closure cannot be sent to them)
_FORKED: dict[str, Any] = {}
# below this many trials a pool costs more to start than it saves
POOL_FROM_TRIALS = 8


@dataclass
class _KeptTrials:
    """Where finished trials go, and how many trials earlier calls of :func:`run_trials` in the same
    protocol run numbered (each call's trials follow them, so every trial has a number of its own)."""

    pieces: EntryPieces
    numbered: int = 0


_KEPT: ContextVar[_KeptTrials | None] = ContextVar("kept_trials", default=None)


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


@contextlib.contextmanager
def trials_kept_in(pieces: EntryPieces) -> Iterator[None]:
    """Within the block, every trial :func:`run_trials` finishes is kept in ``pieces`` (a trial then returns
    a tuple of arrays), and a trial found there is read instead of run again."""
    token = _KEPT.set(_KeptTrials(pieces))
    try:
        yield
    finally:
        _KEPT.reset(token)


def _as_piece(result: Any) -> dict[str, np.ndarray]:
    if not isinstance(result, tuple) or not all(isinstance(item, np.ndarray) for item in result):
        raise TypeError(f"a kept trial returned {type(result).__name__}: expected a tuple of numpy arrays")
    return {str(position): item for position, item in enumerate(result)}


def _of_piece(arrays: dict[str, np.ndarray]) -> tuple[np.ndarray, ...]:
    return tuple(arrays[str(position)] for position in range(len(arrays)))


def _run_forked(index: int) -> tuple[int, Any]:
    with threadpool_limits(limits=1):
        return index, _FORKED["trial"](*_FORKED["plans"][index])


def _run(trial: Callable[..., Any], plans: Sequence[tuple], todo: list[int], processes: int,
         finished: Callable[[int, Any], None]) -> None:
    """``finished(index, trial(*plans[index]))`` for every index of ``todo``, as each trial ends."""
    if processes <= 1 or len(todo) < POOL_FROM_TRIALS or os.name != "posix":
        with threadpool_limits(limits=1):
            for index in todo:
                finished(index, trial(*plans[index]))
        return
    _FORKED.update(trial=trial, plans=plans)
    pool = ProcessPoolExecutor(min(processes, len(todo)), mp_context=multiprocessing.get_context("fork"),
                               initializer=as_forked_worker)
    ended = False
    try:
        for done in as_completed([pool.submit(_run_forked, index) for index in todo]):
            finished(*done.result())
        ended = True
    finally:
        _FORKED.clear()
        # the executor offers no public way to end its workers before Python 3.14 (terminate_workers)
        workers = list(pool._processes.values())
        pool.shutdown(wait=ended, cancel_futures=True)
        if not ended:  # stopped, or a trial failed: the trials under way are not waited for
            for worker in workers:
                worker.terminate()
            for worker in workers:
                worker.join()


def run_trials(trial: Callable[..., Any], plans: Sequence[tuple], processes: int | None = None) -> list:
    """``trial(*plan)`` for every plan, in the plans' order: in this process, or (POSIX, from
    :data:`POOL_FROM_TRIALS` trials on) in a pool of ``processes`` forked processes (default
    :func:`trial_processes`). ``trial`` must draw from nothing but its plan (its random stream in it).
    Within :func:`trials_kept_in`, trials already kept are read back and the others kept as they end."""
    processes = trial_processes() if processes is None else processes
    kept = _KEPT.get()
    results: list[Any] = [None] * len(plans)
    todo = list(range(len(plans)))
    if kept is not None:
        first, kept.numbered = kept.numbered, kept.numbered + len(plans)
        for index in range(len(plans)):
            arrays = kept.pieces.read(first + index)
            if arrays is not None:
                results[index] = _of_piece(arrays)
        todo = [index for index in todo if results[index] is None]

    def finished(index: int, result: Any) -> None:
        if kept is not None:
            kept.pieces.write(first + index, _as_piece(result))
        results[index] = result

    _run(trial, plans, todo, processes, finished)
    return results
