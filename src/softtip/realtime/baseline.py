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
* optionally re-zeroes at rest (``rest_s``): when for ``rest_s`` seconds of sound, free frames
  every channel stayed within a band of ``rest_band`` (peak to peak: the fingertip is still) and
  within ``drift_threshold`` of the baseline in use (a press is larger), the mean of those frames
  becomes the baseline, as if it had been taken on command (offsets that moved with temperature,
  creep that has not recovered, a magnet that moved). A held press is still too, but larger than
  the threshold, and with a contact-state classifier only free states count. A new rest period
  starts after each re-zero, after a frame outside the band or the threshold, and after a frame
  that is faulty or in contact; a mean within ``step`` of the baseline in use replaces nothing.
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
    """The baseline in use, shape (chips, axes), in the unit of ``reading``; see the module notes.
    ``drift_threshold`` and ``step`` default to the reading's, ``rest_band`` to half the drift
    threshold.

    ``update`` is called for every frame from the acquisition thread; ``take`` may be
    called from any thread.
    """

    def __init__(self, frames: int = 50, *, drift_time_constant_s: float | None = None,
                 drift_threshold: float | None = None, step: float | None = None,
                 rest_s: float | None = None, rest_band: float | None = None,
                 reading: Reading = MAGNETIC) -> None:
        self.reading = reading
        drift_threshold = reading.drift_threshold if drift_threshold is None else drift_threshold
        step = reading.baseline_step if step is None else step
        self.frames = checked(PositiveInteger, "baseline frames", frames)
        self.drift_time_constant_s = (None if drift_time_constant_s is None
                                      else checked(PositiveNumber, "drift_time_constant_s", drift_time_constant_s))
        self.drift_threshold = checked(PositiveNumber, "drift_threshold", drift_threshold)
        self.step = checked(PositiveNumber, "step", step)
        self.rest_s = None if rest_s is None else checked(PositiveNumber, "rest_s", rest_s)
        self.rest_band = checked(PositiveNumber, "rest_band",
                                 self.drift_threshold / 2 if rest_band is None else rest_band)
        self.version = 0  # baselines used so far, drift steps included
        self.taken = 0  # baselines taken from frames (at start, on command and at rest)
        self.rezeroed_at_rest = 0
        self._rest: _RestPeriod | None = None
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
            self._rest = None
            return self._use(self._filtered)
        if self.rest_s is not None and self._value is not None and self._at_rest(reading, sound and free, dt_s):
            return True
        if self.drift_time_constant_s is None or self._value is None or not sound or not free or dt_s <= 0:
            return False
        alpha = -math.expm1(-dt_s / self.drift_time_constant_s)
        self._filtered, moved = drift_step(self._filtered, reading, alpha, self.drift_threshold)
        if moved and np.abs(self._filtered - self._value).max() > self.step:
            return self._use(self._filtered)
        return False

    def _at_rest(self, reading: np.ndarray, free: bool, dt_s: float) -> bool:
        """Accounts for one frame in the rest period; re-zeroes and returns True once it is long enough."""
        rest = self._rest
        if not free or not np.abs(reading - self._value).max() < self.drift_threshold:
            self._rest = None
            return False
        if rest is None or not rest.add(reading, dt_s, self.rest_band):
            self._rest = _RestPeriod(reading)
            return False
        if rest.duration_s < self.rest_s:
            return False
        self._rest = None
        mean = rest.mean
        if not np.abs(mean - self._value).max() > self.step:
            return False
        self.taken += 1
        self.rezeroed_at_rest += 1
        self._filtered = mean
        return self._use(mean)

    def _use(self, value: np.ndarray) -> bool:
        in_use = value.copy()
        in_use.setflags(write=False)
        self._value = in_use
        self.version += 1
        return True


class _RestPeriod:
    """The frames of a rest period so far: their sum, count, span and per-channel range."""

    def __init__(self, reading: np.ndarray) -> None:
        self.low = reading.astype(np.float64)
        self.high = self.low.copy()
        self.sum = self.low.copy()
        self.count = 1
        self.duration_s = 0.0

    def add(self, reading: np.ndarray, dt_s: float, band: float) -> bool:
        """Adds a frame; False (and nothing added) if it takes a channel's range beyond ``band``."""
        low, high = np.minimum(self.low, reading), np.maximum(self.high, reading)
        if not (high - low).max() <= band:
            return False
        self.low, self.high = low, high
        self.sum += reading
        self.count += 1
        self.duration_s += max(dt_s, 0.0)
        return True

    @property
    def mean(self) -> np.ndarray:
        return self.sum / self.count
