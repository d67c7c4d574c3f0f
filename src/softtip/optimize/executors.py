"""Where FE runs execute: in this process, a local process pool, or a Dask cluster.

Every executor runs :func:`softtip.optimize.runs.run_design` on :class:`FEJob`
inputs and yields results as they complete. They hold no state about the
study: the client checks the cache before submitting and writes each result
as it arrives, so every executor gives the same results with the same cache
semantics.
"""

from __future__ import annotations

import multiprocessing
import multiprocessing.connection
import os
import threading
import uuid
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from multiprocessing import get_context
from typing import Any, Iterator, Protocol, Sequence

from softtip.optimize.runs import run_design
from softtip.optimize.errors import StudyError


TASKS_PER_WORKER_PROCESS = 10  # a fresh worker process costs ~2 s of imports; 10 designs take ~30 s


@dataclass(frozen=True)
class FEJob:
    tag: int  # the client's reference (the candidate's index)
    design_spec: dict[str, Any]
    simulations: tuple[dict[str, Any], ...]


Outcome = tuple[FEJob, dict[str, Any]]


class Executor(Protocol):
    description: str

    def run(self, jobs: Sequence[FEJob]) -> Iterator[Outcome]:
        """Run ``jobs``; yield (job, run_design's answer) in completion order."""

    def close(self) -> None: ...


class InProcessExecutor:
    """Runs jobs one after another in this process (debugging, tiny studies)."""

    description = "in-process"

    def run(self, jobs: Sequence[FEJob]) -> Iterator[Outcome]:
        for job in jobs:
            yield job, run_design(job.design_spec, list(job.simulations))

    def close(self) -> None:
        pass

    def __enter__(self) -> "InProcessExecutor":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class LocalPoolExecutor:
    """A pool of worker processes on this machine (each limited to one BLAS thread by run_design).

    Jobs are handed out one per idle worker, and the pool is replaced by a fresh one every
    ``TASKS_PER_WORKER_PROCESS`` jobs per worker: PARDISO keeps ~140 MB per solved design (1.5 mm
    mesh) after its solver object is gone, so long-lived workers would grow by gigabytes over a
    sweep. (``ProcessPoolExecutor(max_tasks_per_child=...)`` would do this, but hangs on Python 3.11
    once the first workers retire.) The old pool finishes its running jobs while the new one starts.
    """

    def __init__(self, workers: int = 2):
        if workers < 1:
            raise StudyError(f"--workers {workers}: expected at least 1")
        self.workers = workers
        self.description = f"local pool, {workers} processes"
        self._pool: ProcessPoolExecutor | None = None
        self._submitted_to_pool = 0

    def _submit(self, job: FEJob) -> Future:
        if self._pool is None or self._submitted_to_pool >= self.workers * TASKS_PER_WORKER_PROCESS:
            if self._pool is not None:
                self._pool.shutdown(wait=False)  # its running jobs still complete
            # spawn, not fork: the parent may hold threads (progress display, Dask) that fork would copy mid-lock
            self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=get_context("spawn"),
                                             initializer=_exit_with_parent)
            self._submitted_to_pool = 0
        self._submitted_to_pool += 1
        return self._pool.submit(run_design, job.design_spec, list(job.simulations))

    def run(self, jobs: Sequence[FEJob]) -> Iterator[Outcome]:
        waiting = list(reversed(jobs))
        running: dict[Future, FEJob] = {}
        try:
            while waiting or running:
                while waiting and len(running) < self.workers:
                    job = waiting.pop()
                    running[self._submit(job)] = job
                done, _ = wait(running, return_when=FIRST_COMPLETED)
                for future in done:
                    yield running.pop(future), future.result()
        finally:  # abandoned (error, Ctrl-C): do not start what is still queued
            for future in running:
                future.cancel()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> "LocalPoolExecutor":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _exit_with_parent() -> None:
    """Worker initializer: end this process when the client dies (killed with -9, the pool
    never tells its workers, which would otherwise idle on forever)."""
    parent = multiprocessing.parent_process()

    def watch() -> None:
        multiprocessing.connection.wait([parent.sentinel])
        os._exit(1)

    if parent is not None:
        threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


class DaskExecutor:
    """An existing Dask distributed cluster, reached through its scheduler's address.

    Workers need softtip installed; run them with one thread each
    (``dask worker ADDRESS --nthreads 1 --nworkers N``): the FE solver is
    compiled code that does not share a process well. Like local workers, they
    grow by PARDISO's leftover memory with every design; ``--lifetime 30m
    --lifetime-stagger 5m --lifetime-restart`` renews them.
    """

    def __init__(self, address: str, timeout_s: float = 10.0):
        from dask.distributed import Client

        try:
            self._client = Client(address, timeout=timeout_s, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as error:
            raise StudyError(f"--scheduler {address}: cannot reach the Dask scheduler ({error})") from None
        threads = sum(self._client.nthreads().values())
        self.description = f"Dask cluster at {address}, {threads} worker threads"

    def run(self, jobs: Sequence[FEJob]) -> Iterator[Outcome]:
        from dask.distributed import as_completed

        futures = {self._client.submit(run_design, job.design_spec, list(job.simulations),
                                       key=f"softtip-fe-{job.tag}-{uuid.uuid4().hex[:12]}"): job for job in jobs}
        try:
            for future in as_completed(list(futures), loop=self._client.loop):
                try:
                    answer = future.result()
                except Exception as error:  # noqa: BLE001 - run_design reports FE failures itself
                    raise StudyError(f"a Dask worker could not run softtip ({type(error).__name__}: {error}); "
                                     f"is softtip installed on every worker?") from None
                yield futures[future], answer
        finally:
            self._client.cancel(list(futures))

    def close(self) -> None:
        self._client.close()

    def __enter__(self) -> "DaskExecutor":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def make_executor(scheduler: str | None = None,
                  workers: int = 2) -> InProcessExecutor | LocalPoolExecutor | DaskExecutor:
    """Dask if a scheduler address is given, else a local pool (in this process for one worker)."""
    if scheduler:
        if "://" not in scheduler:
            raise StudyError(f"--scheduler {scheduler}: expected an address such as tcp://HOST:8786")
        return DaskExecutor(scheduler)
    return InProcessExecutor() if workers == 1 else LocalPoolExecutor(workers)
