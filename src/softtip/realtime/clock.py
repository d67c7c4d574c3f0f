"""Acquisition times on the host's wall clock, from the device clock."""

from __future__ import annotations

import math
import time

CLOCK_LEAK = 1e-4  # twice the ±50 ppm of a common crystal: the device clock's drift is followed


class AcquisitionClock:
    """Acquisition times on the host's wall clock, from the device clock.

    The arrival time is the acquisition time plus a transport delay that is never
    negative and at its smallest most of the time. So the offset host - device is
    estimated as its running minimum, allowed to grow by ``leak`` seconds per second so
    that a device clock slower than the host's is followed:
    ``t = d (1 + leak) + min_j [h_j - d_j (1 + leak)]``. A device clock that goes back
    (the device restarted) starts a new minimum. Without a device clock the arrival time
    is used. Stamps are strictly increasing (by 1 ns at least).

    Arrival times are on the ``time.perf_counter`` clock; ``wall_minus_perf_ns`` turns them
    into wall-clock time (None: read both clocks now).
    """

    def __init__(self, leak: float = CLOCK_LEAK, wall_minus_perf_ns: int | None = None) -> None:
        self._factor = 1.0 + leak
        self._wall_minus_perf_ns = (time.time_ns() - time.perf_counter_ns() if wall_minus_perf_ns is None
                                    else int(wall_minus_perf_ns))
        self._offset = math.inf
        self._last_device: float | None = None
        self._last_ns = -1

    def stamp_ns(self, host_time_s: float, device_time_s: float | None) -> int:
        if device_time_s is None:
            acquired = host_time_s
        else:
            if self._last_device is not None and device_time_s < self._last_device:
                self._offset = math.inf
            self._last_device = device_time_s
            scaled = device_time_s * self._factor
            self._offset = min(self._offset, host_time_s - scaled)
            acquired = scaled + self._offset
        stamp = round(acquired * 1e9) + self._wall_minus_perf_ns
        if stamp <= self._last_ns:
            stamp = self._last_ns + 1
        self._last_ns = stamp
        return stamp
