"""Signals that stop a command as Ctrl-C does: SIGTERM (kill, a robot's launch system or a service manager
stopping it) and SIGHUP (its terminal closed) raise :class:`KeyboardInterrupt` in the main thread, so a
long step keeps the pieces it finished and a stream closes its sinks (a recording gets its summary)."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name))


def interrupt(number: int, _frame) -> None:
    """A stop signal's handler: what Ctrl-C raises, naming the signal."""
    raise KeyboardInterrupt(signal.Signals(number).name)


def stop_as_ctrl_c() -> None:
    """From now on, in this process, a stop signal ends the work as Ctrl-C does (from the main thread only:
    elsewhere Python cannot set a handler). Processes forked afterwards inherit it unless they reset it."""
    if threading.current_thread() is threading.main_thread():
        for number in STOP_SIGNALS:
            signal.signal(number, interrupt)


@contextlib.contextmanager
def stop_handlers_kept() -> Iterator[None]:
    """Puts back this process's handlers of the stop signals after a library that resets them (gmsh sets
    SIGTERM back to ending the process at once, which would lose what Ctrl-C keeps), and of SIGPIPE (gmsh
    makes it end the process, where Python ignores it: a pool's pipe to a worker ended on Ctrl-C would
    then end this process before it keeps its pieces)."""
    kept = STOP_SIGNALS + ((signal.SIGPIPE,) if hasattr(signal, "SIGPIPE") else ())
    handlers = {number: signal.getsignal(number) for number in kept}
    try:
        yield
    finally:
        if threading.current_thread() is threading.main_thread():
            for number, handler in handlers.items():
                if handler is not None:
                    signal.signal(number, handler)


def as_forked_worker() -> None:
    """In a process forked to work for this one: Ctrl-C reaches the terminal's whole group, but the parent
    stops its workers itself, and a stop handler it installed must not outlive the fork."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
