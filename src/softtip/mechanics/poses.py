"""The one representation of where the magnets are: their rigid motion from rest.

Mechanics produces it (FE unknowns, contact solves, the reduced twin's networks), the twin's
readout consumes it. Arrays carry any leading batch shape: (..., M, 3) for M magnets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MagnetPoses:
    """Rigid motion of every magnet from its rest pose: ``translation`` (..., M, 3) in m of its
    centre and ``rotvec`` (..., M, 3), the small rotation about its centre in rad."""

    translation: np.ndarray
    rotvec: np.ndarray

    def __post_init__(self):
        if np.shape(self.translation) != np.shape(self.rotvec) or np.shape(self.translation)[-1:] != (3,):
            raise ValueError(f"magnet poses: translation {np.shape(self.translation)} and rotvec "
                             f"{np.shape(self.rotvec)} must have the same shape (..., M, 3)")

    @classmethod
    def from_rigid(cls, rigid: np.ndarray) -> MagnetPoses:
        """From stacked rigid coordinates (..., M, 6): translation then rotation vector."""
        rigid = np.asarray(rigid, dtype=float)
        return cls(rigid[..., :3], rigid[..., 3:])

    @classmethod
    def at_rest(cls, magnets: int, batch: tuple[int, ...] = ()) -> MagnetPoses:
        zeros = np.zeros((*batch, magnets, 3))
        return cls(zeros, zeros.copy())

    @classmethod
    def stack(cls, poses: list[MagnetPoses]) -> MagnetPoses:
        """One batch (N, M, 3) from N pose sets (M, 3)."""
        return cls(np.array([p.translation for p in poses]), np.array([p.rotvec for p in poses]))

    @property
    def rigid(self) -> np.ndarray:
        """Stacked rigid coordinates (..., M, 6)."""
        return np.concatenate([self.translation, self.rotvec], axis=-1)

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return np.shape(self.translation)[:-2]

    def batched(self) -> MagnetPoses:
        """With one leading batch axis: (N, M, 3)."""
        return MagnetPoses(np.reshape(self.translation, (-1, *np.shape(self.translation)[-2:])),
                           np.reshape(self.rotvec, (-1, *np.shape(self.rotvec)[-2:])))

    def displacement_of(self, arms: np.ndarray) -> np.ndarray:
        """Displacement (..., M, 3) of a point fixed to each magnet at ``arms`` (M, 3) from its
        centre (small rotation: t + theta x r)."""
        return self.translation + np.cross(self.rotvec, arms)
