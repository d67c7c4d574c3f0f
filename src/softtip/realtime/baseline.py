"""The baseline subtracted from the live readings: initial values, retaken on command, with
optional slow drift tracking.

Readings are changes from a baseline taken before contact (of flux density for the fingertip's Hall
chips, of force for a force chip; :class:`~softtip._core.channels.Reading`). :class:`Baseline`

* takes the mean of ``frames`` readings in which every chip is sound (per chip and axis):
  at start, and again whenever :meth:`Baseline.take` is called (for instance after a grasp,
  before the insertion moves). Until a new baseline is complete the previous one stays in
  use, so the estimates never stop.
* optionally tracks slow drift (``drift_time_constant_s``): the Hall offsets and the
  magnets' remanence move with temperature by a few µT over minutes, a force chip's offset
  creeps under the ring's preload. A first-order
  exponential filter ``b <- b + a (x - b)``, ``a = 1 - exp(-dt / tau)``, pulls the baseline
  toward the reading, but only while the fingertip is free: every channel's change
  ``|x - b|`` is below ``drift_threshold`` and the caller says the estimated contact
  state is a free one. A contact (a larger change, or a contact state) freezes the filter,
  so it is never absorbed into the baseline. A ramp of slope r is followed with the lag
  ``r dt (1 - a) / a`` (about ``r tau``).
* changes the baseline in use in steps: the filter's value replaces it once they differ by
  more than ``step`` on some channel (the reading's default: 0.01 µT, a fifteenth of the
  Hall chip's finest LSB; 0.1 mN, a twelfth of the force chip's step).
  Every baseline in use gets a new :attr:`Baseline.version`, so a recorder can store each
  one and the recorded changes can be reproduced exactly.
"""

from __future__ import annotations

import math

import numpy as np

from softtip._core.channels import MAGNETIC, Reading
from softtip._core.config import PositiveInteger, PositiveNumber, checked


def drift_step(filtered: np.ndarray, reading: np.ndarray, alpha: float,
               threshold: float) -> tuple[np.ndarray, bool]:
    """One step of the gated exponential filter: ``filtered + alpha (reading - filtered)``
    if every channel's change is below ``threshold``, else ``filtered`` unchanged; also
    returns whether it moved."""
    change = reading - filtered
    if not np.abs(change).max() < threshold:
        return filtered, False
    return filtered + alpha * change, True


class Baseline:
    """The baseline in use, shape (chips, 3), in the unit of ``reading``; see the module notes.
    ``drift_threshold`` and ``step`` default to the reading's.

    ``update`` is called for every frame from the acquisition thread; ``take`` may be
    called from any thread.
    """

    def __init__(self, frames: int = 50, *, drift_time_constant_s: float | None = None,
                 drift_threshold: float | None = None, step: float | None = None,
                 reading: Reading = MAGNETIC) -> None:
        self.reading = reading
        drift_threshold = reading.drift_threshold if drift_threshold is None else drift_threshold
        step = reading.baseline_step if step is None else step
        self.frames = checked(PositiveInteger, "baseline frames", frames)
        self.drift_time_constant_s = (None if drift_time_constant_s is None
                                      else checked(PositiveNumber, "drift_time_constant_s", drift_time_constant_s))
        self.drift_threshold = checked(PositiveNumber, "drift_threshold", drift_threshold)
        self.step = checked(PositiveNumber, "step", step)
        self.version = 0  # baselines used so far, drift steps included
        self.taken = 0  # baselines taken from frames (at start and on command)
        self._value: np.ndarray | None = None
        self._filtered: np.ndarray | None = None
        # take() only writes these two, update() only reads them: no lock on the frame path.
        self._requests = 1  # the baseline at start
        self._requested_frames = self.frames
        self._served = 0
        self._target = 0
        self._sum: np.ndarray | None = None
        self._count = 0

    @property
    def value(self) -> np.ndarray | None:
        """The baseline in use (read-only), or None before the first one is complete."""
        return self._value

    @property
    def ready(self) -> bool:
        return self._value is not None

    @property
    def collecting(self) -> bool:
        """Whether a baseline is being taken (the previous one, if any, is still in use)."""
        return self._target > 0 or self._requests != self._served

    def take(self, frames: int | None = None) -> None:
        """Take a new baseline from the next ``frames`` sound frames (default: as configured)."""
        self._requested_frames = self.frames if frames is None else checked(PositiveInteger, "frames", frames)
        self._requests += 1

    def update(self, reading: np.ndarray, sound: bool, dt_s: float, free: bool = True) -> bool:
        """Account for one frame (``sound``: every chip read without fault; ``dt_s``: time
        since the previous frame; ``free``: the contact state allows drift tracking).
        Returns whether the baseline in use changed."""
        if self._requests != self._served:
            self._served = self._requests
            self._target = self._requested_frames
            self._sum = np.zeros_like(reading, dtype=np.float64)
            self._count = 0
        if self._target:
            if sound:
                self._sum += reading
                self._count += 1
            if self._count < self._target:
                return False
            self._target = 0
            self.taken += 1
            self._filtered = self._sum / self._count
            return self._use(self._filtered)
        if self.drift_time_constant_s is None or self._value is None or not sound or not free or dt_s <= 0:
            return False
        alpha = -math.expm1(-dt_s / self.drift_time_constant_s)
        self._filtered, moved = drift_step(self._filtered, reading, alpha, self.drift_threshold)
        if moved and np.abs(self._filtered - self._value).max() > self.step:
            return self._use(self._filtered)
        return False

    def _use(self, value: np.ndarray) -> bool:
        in_use = value.copy()
        in_use.setflags(write=False)
        self._value = in_use
        self.version += 1
        return True
