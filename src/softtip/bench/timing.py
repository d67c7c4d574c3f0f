"""Timing helpers shared by the benchmarks."""

from __future__ import annotations

import time
from typing import Callable

import numpy as np


def timed(function: Callable, *args, **kwargs):
    """``function(*args, **kwargs)`` and its wall time in seconds."""
    start = time.perf_counter()
    value = function(*args, **kwargs)
    return value, time.perf_counter() - start


def best_of(function: Callable, repeats: int = 3) -> float:
    """The shortest wall time (s) of ``repeats`` calls: the least disturbed by other work."""
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        best = min(best, time.perf_counter() - start)
    return best


def latency(function: Callable, sample: np.ndarray, calls: int) -> dict:
    """Median and 99th percentile (µs) of single calls, after a warm-up."""
    for _ in range(min(calls, 1000)):  # warm caches and allocators
        function(sample)
    times = np.empty(calls)
    clock = time.perf_counter_ns
    for i in range(calls):
        start = clock()
        function(sample)
        times[i] = clock() - start
    return {"median_us": float(np.median(times) / 1e3), "p99_us": float(np.percentile(times, 99) / 1e3)}
