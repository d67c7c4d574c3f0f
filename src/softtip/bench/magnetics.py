"""Throughput of the magnet field kernel, beside magpylib's on the same batch.

One reading is one sensor's three field components for one set of magnet poses.
"""

from __future__ import annotations

import numpy as np

from softtip.bench.timing import best_of
from softtip.magnetics import magnet_field_at_sensors

MAGPYLIB_POSES = 20_000  # magpylib's path API on a sub-batch: its per-pose cost is flat


def fingertip_like_batch(n_poses: int, n_magnets: int, n_sensors: int, seed: int = 0) -> dict:
    """Magnets (Ø4 x 2 mm, J = 1.2 T, alternating up/down) on a circle of radius 2.5 mm, 4 mm above
    the sensors (4 mm apart along x), each displaced by up to 1 mm per axis and tilted by up to
    0.3 rad."""
    rng = np.random.default_rng(seed)
    angles = 2.0 * np.pi * np.arange(n_magnets) / n_magnets
    rest = np.stack([2.5e-3 * np.cos(angles), 2.5e-3 * np.sin(angles), np.full(n_magnets, 4e-3)], axis=1)
    sensors = np.zeros((n_sensors, 3))
    sensors[:, 0] = 4e-3 * (np.arange(n_sensors) - 0.5 * (n_sensors - 1))
    return {"sensors": sensors, "positions": rest + rng.uniform(-1e-3, 1e-3, (n_poses, n_magnets, 3)),
            "rotvecs": rng.uniform(-0.3, 0.3, (n_poses, n_magnets, 3)) / np.sqrt(3.0),
            "polarization": 1.2 * (-1.0) ** np.arange(n_magnets)}


def bench_magnetics(n_poses: int, n_magnets: int = 4, n_sensors: int = 1, repeats: int = 3, seed: int = 0) -> dict:
    """Readings per second of :func:`magnet_field_at_sensors` (best of ``repeats``) and of magpylib's
    ``getB`` on the first poses of the same batch, and their ratio."""
    import magpylib
    from scipy.spatial.transform import Rotation

    batch = fingertip_like_batch(n_poses, n_magnets, n_sensors, seed)
    sensors, positions, rotvecs = batch["sensors"], batch["positions"], batch["rotvecs"]
    ours = best_of(lambda: magnet_field_at_sensors(sensors, positions, rotvecs, 2e-3, 2e-3, batch["polarization"]),
                   repeats)
    sub = min(n_poses, MAGPYLIB_POSES)
    magnets = [magpylib.magnet.Cylinder(polarization=(0, 0, j), dimension=(4e-3, 2e-3), position=positions[:sub, i],
                                        orientation=Rotation.from_rotvec(rotvecs[:sub, i]))
               for i, j in enumerate(batch["polarization"])]
    theirs = best_of(lambda: magpylib.getB(magnets, sensors, sumup=True), 1)
    readings = n_poses * n_sensors
    return {"n_poses": n_poses, "n_magnets": n_magnets, "n_sensors": n_sensors, "seconds": ours,
            "readings_per_second": readings / ours, "cylinder_evaluations_per_second": readings * n_magnets / ours,
            "magpylib_readings_per_second": sub * n_sensors / theirs,
            "speedup_vs_magpylib": readings / ours / (sub * n_sensors / theirs)}
