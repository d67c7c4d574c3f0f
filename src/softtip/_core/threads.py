"""Threads: a named daemon thread that runs until it is asked to stop, and BLAS kept to one thread."""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable

from threadpoolctl import ThreadpoolController


class BackgroundThread:
    """Runs ``target`` on a daemon thread; :meth:`stop` sets :attr:`closing`, which the target
    watches (or waits on between passes), and waits for the thread to end."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.closing = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def running(self) -> bool:
        return self._thread is not None

    def start(self, target: Callable[[], None]) -> None:
        self.closing.clear()
        self._thread = threading.Thread(target=target, name=self.name, daemon=True)
        self._thread.start()

    def stop(self) -> bool:
        """Stop the thread and wait for it; False if it was not running."""
        if self._thread is None:
            return False
        self.closing.set()
        self._thread.join()
        self._thread = None
        return True


@functools.cache
def _blas_controller() -> ThreadpoolController:
    """The native thread pools, found once. scipy brings its own OpenBLAS, loaded with ``scipy.linalg``: a
    controller made before that import would leave it on every core (where the identifications' least
    squares run), so it is loaded first."""
    import scipy.linalg  # noqa: F401 (loads scipy's OpenBLAS, for the controller to find)

    return ThreadpoolController()


def single_threaded_blas():
    """Context limiting BLAS to one thread. The products of the iterative fits (network training,
    system identification) are small and thin; on a shared 2-core machine a second BLAS thread made
    them 15-30× slower, not faster."""
    return _blas_controller().limit(limits=1, user_api="blas")


def single_threaded():
    """Context limiting every native thread pool (BLAS and OpenMP) to one thread: scikit-learn's gradient
    boosting on a few thousand samples took 48 s with its OpenMP threads on a shared 2-core machine
    (load average 7), 0.5 s on one."""
    return _blas_controller().limit(limits=1)
