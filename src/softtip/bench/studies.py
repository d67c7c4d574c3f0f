"""``softtip bench studies``: the registered studies reproduced one after another (their trials too, in
one process) and then in a pool of processes (the studies, and the trials within each, on every
core), in the same call, with the wall and CPU time of each run and the load average around them.

Both runs use the cache as it is (warm: what the studies compute themselves), or with ``cold`` each its
own empty cache (the variable ``SOFTTIP_CACHE_DIR``, which the pool's processes inherit)."""

from __future__ import annotations

import contextlib
import os
import resource
import tempfile
import time
from collections.abc import Sequence

from softtip._core.cache import CACHE_VARIABLE
from softtip._core.progress import SILENT, Progress
from softtip.studies.reproduce import reproduce_studies


def _cpu_s() -> float:
    """CPU time (user + system, s) of this process and of its children that have ended."""
    return sum(usage.ru_utime + usage.ru_stime
               for usage in (resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)))


@contextlib.contextmanager
def _empty_cache(cold: bool):
    """An empty cache of its own for the block when ``cold``; the cache as it is otherwise."""
    if not cold:
        yield
        return
    before = os.environ.get(CACHE_VARIABLE)
    with tempfile.TemporaryDirectory(prefix="softtip-bench-cache-") as cache:
        os.environ[CACHE_VARIABLE] = cache
        try:
            yield
        finally:
            if before is None:
                del os.environ[CACHE_VARIABLE]
            else:
                os.environ[CACHE_VARIABLE] = before


def _run(names: Sequence[str], seed: int, quick: bool, workers: int, cold: bool, progress: Progress) -> dict:
    load = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="softtip-bench-studies-") as directory, _empty_cache(cold):
        cpu, start = _cpu_s(), time.perf_counter()
        # the serial run is serial throughout: its trials too run in its one process
        reports = reproduce_studies(names, directory, seed=seed, quick=quick, workers=workers, progress=progress,
                                    trial_processes=1 if workers == 1 else None)
        wall = time.perf_counter() - start
        cpu = _cpu_s() - cpu
    return {"workers": workers, "wall_s": wall, "cpu_s": cpu,
            "study_s": {name: report["seconds"] for name, report in reports.items()},
            "load_average_before": list(load), "load_average_after": list(os.getloadavg())}


def bench_studies(names: Sequence[str], workers: int, seed: int = 1, quick: bool = False, cold: bool = False,
                  progress: Progress = SILENT) -> dict:
    """The studies ``names`` reproduced serially, then by ``workers`` processes: on the cache as it is
    (an empty one is filled by the serial run, which the parallel run then reads: warm it first to time
    both warm), or with ``cold`` each on an empty cache of its own. The speed-up is the serial run's wall
    time over the parallel run's."""
    serial = _run(names, seed, quick, 1, cold, progress)
    parallel = _run(names, seed, quick, workers, cold, progress)
    return {"studies": list(names), "quick": quick, "cold": cold, "seed": seed, "cpus": os.cpu_count(),
            "serial": serial, "parallel": parallel, "speedup": serial["wall_s"] / parallel["wall_s"]}
