"""The sensing stage of a fingertip: the exact field of its posed magnets at its Hall sensors,
read through the model of the design's registered chip (its noise, output step and clip), relative to
the unloaded state.

The geometry is the design's (nominal) unless a fabricated unit's own magnet centres,
polarisations and chip positions are given (a fabricated unit of a design).
"""

from __future__ import annotations

import numpy as np

from softtip._core.units import UT_PER_T
from softtip.design.model import Design
from softtip.magnetics import magnet_field_at_sensors
from softtip.mechanics.poses import MagnetPoses


class Readout:
    def __init__(self, design: Design, *, magnet_centers: np.ndarray | None = None,
                 polarizations: np.ndarray | None = None, sensor_positions: np.ndarray | None = None,
                 ambient_field: np.ndarray | None = None):
        self.chips = design.chip_settings
        self.sensor = self.chips.kind.model(self.chips.values)
        magnets = design.magnets
        self.design = design
        self.rest_positions = (np.array([m.center for m in magnets]) if magnet_centers is None
                               else np.asarray(magnet_centers, dtype=float))
        self.polarizations = (np.array([m.polarization for m in magnets]) if polarizations is None
                              else np.asarray(polarizations, dtype=float))
        self.sensor_positions = (design.sensor_positions if sensor_positions is None
                                 else np.asarray(sensor_positions, dtype=float))
        self.ambient_field = np.zeros(3) if ambient_field is None else np.asarray(ambient_field, dtype=float)
        self._radii = np.array([m.diameter / 2 for m in magnets])
        self._heights = np.array([m.height for m in magnets])
        self.rest_field = self.field(MagnetPoses.at_rest(len(magnets), (1,)))[0]

    def field(self, poses: MagnetPoses) -> np.ndarray:
        """Absolute flux density (N, S, 3) in T at the sensors for N pose sets (N, M, 3)."""
        return magnet_field_at_sensors(self.sensor_positions, self.rest_positions + poses.translation,
                                       poses.rotvec, self._radii, self._heights, self.polarizations,
                                       ambient=self.ambient_field)

    def field_change(self, poses: MagnetPoses) -> np.ndarray:
        """Noiseless change of flux density (N, S, 3) in T from the unloaded state."""
        return self.field(poses) - self.rest_field

    def saturated(self, raw: np.ndarray) -> np.ndarray:
        """Where the chips' raw output (..., 3), words or values as the chip sends them, is at its clip."""
        kind, settings = self.chips.kind, self.chips.values
        return kind.decode(settings, raw)[1] if kind.decode is not None else kind.saturated(raw, settings)

    def readings(self, poses: MagnetPoses, noise: bool = True,
                 rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Sensor readings for N pose sets: (change from rest in µT (N, S, 3), raw output (N, S, 3):
        the chip's words, or its values if it sends values).

        Without noise the change is the exact field difference (no quantisation).
        """
        return self.read_field(self.field(poses), noise, rng)

    def read_field(self, loaded: np.ndarray, noise: bool = True,
                   rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
        """What the sensors report for absolute fields ``loaded`` (N, S, 3) in T; see :meth:`readings`.

        With noise, both the baseline and the loaded reading go through the sensor model
        (quantisation, noise, clipping) like a real acquisition."""
        if not noise:
            return (loaded - self.rest_field) * UT_PER_T, self.sensor.acquire(loaded).raw
        rng = rng or np.random.default_rng()
        read = self.sensor.acquire(loaded, rng)
        baseline = self.sensor.acquire(np.broadcast_to(self.rest_field, loaded.shape), rng).values
        return read.values - baseline, read.raw
