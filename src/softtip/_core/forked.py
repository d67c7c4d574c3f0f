"""Independent pieces of one computation solved by processes forked from this one, each on one core.

The processes are forked after the expensive set-up (a factorised matrix, a twin), so they inherit it
without copying or sending it; each writes its results into arrays in memory shared with this process
(:func:`shared_zeros`, allocated before the fork) and reports each finished piece by its number, so this
process shows progress and keeps a finished piece as soon as it is done. Ctrl-C or SIGTERM here stops
the workers (they ignore the Ctrl-C a terminal sends them too: this process ends them), and a worker
whose parent is gone stops after its current piece.
"""

from __future__ import annotations

import mmap
import multiprocessing
import multiprocessing.connection
import os
from collections.abc import Callable, Sequence

import numpy as np

from softtip._core.stopping import as_forked_worker
from softtip._core.threads import single_threaded_blas

_NUMBER = 8  # bytes of a piece's number on the pipe


def shared_zeros(shape: tuple[int, ...]) -> np.ndarray:
    """Float zeros in anonymous shared memory: what a process forked afterwards writes there, this one reads."""
    count = int(np.prod(shape))
    return np.frombuffer(mmap.mmap(-1, max(8 * count, 1)), dtype=np.float64, count=count).reshape(shape)


def default_processes() -> int:
    """The cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def _work_on(solve: Callable[[int], None], pieces: Sequence[int], next_piece, report, parent: int) -> None:
    as_forked_worker()
    with single_threaded_blas():
        while os.getppid() == parent:
            with next_piece.get_lock():
                position = next_piece.value
                next_piece.value += 1
            if position >= len(pieces):
                return
            solve(pieces[position])
            report.send_bytes(int(pieces[position]).to_bytes(_NUMBER, "little"))


def solve_in_processes(solve: Callable[[int], None], pieces: Sequence[int], solved: Callable[[int], None],
                       processes: int | None = None) -> None:
    """``solve(piece)`` for every piece number of ``pieces``, calling ``solved(piece)`` here once it is solved:
    in this process when ``processes`` (default: one per core) is 1 or there is one piece, else in that
    many forked processes, each with one BLAS thread, taking the next unsolved piece as they finish. A
    worker that fails (its error printed by it) raises :class:`RuntimeError` here once the others stop."""
    processes = default_processes() if processes is None else processes
    if processes <= 1 or len(pieces) < 2 or os.name != "posix":
        for piece in pieces:
            solve(piece)
            solved(piece)
        return
    context = multiprocessing.get_context("fork")
    next_piece = context.Value("l", 0)
    receive, report = context.Pipe(duplex=False)
    workers = [context.Process(target=_work_on, args=(solve, pieces, next_piece, report, os.getpid()), daemon=True)
               for _ in range(min(processes, len(pieces)))]
    try:
        for worker in workers:
            worker.start()
        report.close()  # the workers hold its copies: the pipe ends when the last of them does
        for _ in pieces:
            try:
                number = receive.recv_bytes()
            except EOFError:
                for worker in workers:
                    worker.join()
                codes = sorted({worker.exitcode for worker in workers} - {0})
                raise RuntimeError(f"a worker process ended (exit code {codes[0] if codes else 0}) before every "
                                   "piece was solved") from None
            solved(int.from_bytes(number, "little"))
    finally:
        report.close()
        for worker in workers:
            if worker.is_alive():
                worker.terminate()
        for worker in workers:
            if worker.pid is not None:
                worker.join()
        receive.close()
