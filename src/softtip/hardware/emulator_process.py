"""An emulated fingertip in a spawned child process, and a field source for it.

:class:`EmulatorProcess` runs an :class:`~softtip.hardware.emulator.Emulator` in a child
process, so that its work neither counts in the host process's CPU time nor competes for
its interpreter lock; :class:`PressCycle` is a picklable field source of repeated presses.
"""

from __future__ import annotations

import contextlib
import math
import multiprocessing
import resource
import signal
from collections.abc import Callable
from dataclasses import dataclass
from typing import Self

import numpy as np

from softtip.hardware.emulator import Emulator, FaultPlan, FrameFate
from softtip.sensors.mlx90393 import MLX90393Settings


@dataclass(frozen=True)
class PressCycle:
    """A field source for the emulator: each chip's resting field plus repeated presses.

    Every ``period_s`` a press rises and falls as a raised cosine over ``press_s``;
    chip k's axes change by ``amplitude_uT`` times fixed gains in [-1, 1] (drawn from
    ``seed``), on resting fields of a few hundred µT (x, y) and 2-3 mT (z).
    """

    chips: int = 4
    period_s: float = 2.0
    press_s: float = 1.0
    amplitude_uT: float = 400.0
    seed: int = 0

    def __post_init__(self) -> None:
        rng = np.random.default_rng(self.seed)
        resting = np.column_stack([rng.uniform(-400, 400, self.chips), rng.uniform(-400, 400, self.chips),
                                   rng.uniform(2000, 3000, self.chips)])
        object.__setattr__(self, "_resting", resting)
        object.__setattr__(self, "_gains", rng.uniform(-1, 1, (self.chips, 3)))

    def press(self, t_s: float) -> float:
        """Press depth in [0, 1] at time t_s."""
        phase = t_s % self.period_s
        return 0.5 * (1.0 - math.cos(2 * math.pi * phase / self.press_s)) if phase < self.press_s else 0.0

    def __call__(self, t_s: float) -> np.ndarray:
        return self._resting + self.amplitude_uT * self.press(t_s) * self._gains


_FATES = tuple(FrameFate)


@dataclass(frozen=True)
class EmulatorLog:
    """The frames an emulator generated, in order: session, sequence number and fate."""

    session: np.ndarray
    seq: np.ndarray
    fate: np.ndarray  # index into FATES
    cpu_s: float

    FATES = _FATES

    def count(self, fate: FrameFate) -> int:
        return int(np.count_nonzero(self.fate == _FATES.index(fate)))


def _serve_emulator(connection, source, rate_hz: int, chips: int, settings, faults, seed) -> None:
    """Child process: run an Emulator until told to stop, then send its log back. A parent that is
    gone (killed) ends it quietly; Ctrl-C, sent to the terminal's whole process group, is the
    parent's to handle: it stops the child by the pipe."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        emulator = Emulator(source, rate_hz=rate_hz, chips=chips, settings=settings, faults=faults, seed=seed)
        emulator.start()
    except Exception as error:
        connection.send(("error", f"{type(error).__name__}: {error}"))
        return
    try:
        connection.send(("port", emulator.port))
        connection.recv()
    except (EOFError, OSError):  # the parent died: nobody to report to
        with contextlib.suppress(RuntimeError):  # a failure of its source: nobody to report that to either
            emulator.close()
        return
    try:
        emulator.close()
        error = None
    except RuntimeError as failure:
        error = str(failure)
    log = emulator.log
    usage = resource.getrusage(resource.RUSAGE_SELF)
    connection.send(("log", np.array([f.session for f in log], dtype=np.int32),
                     np.array([f.seq for f in log], dtype=np.int32),
                     np.array([_FATES.index(f.fate) for f in log], dtype=np.uint8),
                     usage.ru_utime + usage.ru_stime, error))


class EmulatorProcess:
    """An :class:`~softtip.hardware.Emulator` in a spawned child process: its work neither
    counts in the pipeline process's CPU time nor competes for its interpreter lock.

    ``source`` must be picklable (a module-level function or a :class:`PressCycle`).
    ``close()`` returns the :class:`EmulatorLog`.
    """

    def __init__(self, source: Callable[[float], np.ndarray], rate_hz: int = 50, chips: int = 4,
                 settings: MLX90393Settings | None = None, faults: FaultPlan | None = None,
                 seed: int | None = 0, start_timeout_s: float = 60.0) -> None:
        self._arguments = (source, rate_hz, chips, settings, faults, seed)
        self._start_timeout_s = start_timeout_s
        self._process: multiprocessing.process.BaseProcess | None = None
        self._connection = None
        self.port: str | None = None

    def start(self) -> EmulatorProcess:
        context = multiprocessing.get_context("spawn")
        parent, child = context.Pipe()
        process = context.Process(target=_serve_emulator, args=(child, *self._arguments),
                                  name="softtip-emulator", daemon=True)
        try:
            process.start()
        finally:
            child.close()
        self._process, self._connection = process, parent
        if not parent.poll(self._start_timeout_s):
            self._kill()
            raise RuntimeError(f"the emulator process did not start within {self._start_timeout_s:g} s")
        kind, value = parent.recv()
        if kind != "port":
            self._kill()
            raise RuntimeError(f"the emulator process failed: {value}")
        self.port = value
        return self

    def close(self) -> EmulatorLog | None:
        if self._process is None:
            return None
        try:
            self._connection.send("stop")
            _, session, seq, fate, cpu_s, error = self._connection.recv()
        except (EOFError, OSError) as problem:
            self._kill()
            raise RuntimeError(f"the emulator process died: {problem}") from None
        self._process.join(10.0)
        self._kill()
        if error:
            raise RuntimeError(error)
        return EmulatorLog(session, seq, fate, cpu_s)

    def _kill(self) -> None:
        if self._process is not None and self._process.is_alive():
            self._process.kill()
            self._process.join()
        self._process = None
        if self._connection is not None:
            self._connection.close()
            self._connection = None

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        if self._process is not None:
            self._kill()
