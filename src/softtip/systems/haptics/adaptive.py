"""An adaptive user table for personalisation A (beyond the publication): choose each next batch of
configurations to drive on the user from what the DS has measured so far.

Personalisation A needs, for every FS entry's DS reading d*, user entries whose readings d*,U lie
near it. A fixed grid spends most of its configurations where the user is not touched, or touched
far harder than any FS entry. Here the user first takes a coarse grid (3³ = 27 configurations);
then, batch by batch, the FS readings d* that lie farthest from every user reading so far are
personalised with the current user table, and the configurations of the FS grid nearest (in motor
space) to the m̃* that gives them, not driven yet, are driven next. It stops at ``budget``
configurations. Each configuration is held and read as in the fixed collection, so its real
collection time follows from the same procedure.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from softtip._core.config import checked, integer
from softtip.systems.haptics.collection import Collection, CollectionSettings, collection_duration, motor_grid, sensed_contact
from softtip.systems.haptics.device import DeviceSpec
from softtip.systems.haptics.fingertips import Fingertip
from softtip.systems.haptics.personalisation import in_device_axes, user_table_renderer
from softtip.systems.haptics.rendering import CONTACT_THRESHOLD, FORCE


@dataclass(frozen=True)
class AdaptiveTable:
    """The user table the adaptive collection drove (in the order driven) and the batches' sizes."""

    collection: Collection
    batches: tuple[int, ...]


def adaptive_user_table(device: DeviceSpec, fingertip: Fingertip, fs_motor_inputs, fs_platform_wrenches,
                        settings: CollectionSettings, rng: np.random.Generator | None, budget: int = 64,
                        batch: int = 8, initial_levels: int = 3, n_neighbours: int = 8,
                        contact_threshold: float = CONTACT_THRESHOLD) -> AdaptiveTable:
    """Drive at most ``budget`` configurations on the user, ``batch`` at a time after a coarse
    ``initial_levels``³ grid, each batch aimed at the FS readings the user table covers worst."""
    budget = checked(integer(1), "budget", budget)
    batch = checked(integer(1), "batch", batch)
    first = motor_grid(device, initial_levels)
    if len(first) > budget:
        raise ValueError(f"budget = {budget}: expected at least the first grid's {len(first)} configurations "
                         f"(initial_levels = {initial_levels})")
    fs_readings = in_device_axes(device, fs_motor_inputs, fs_platform_wrenches)[:, FORCE]
    wanted = fs_readings[np.linalg.norm(fs_readings, axis=1) >= contact_threshold]
    parts = [sensed_contact(device, fingertip, first, settings, rng)]
    batches = [len(first)]
    pool = np.asarray(fs_motor_inputs, dtype=float)
    undriven = np.ones(len(pool), bool)
    undriven[cKDTree(pool).query(first)[1]] = False  # the first grid's configurations, where the pool has them
    while sum(batches) < budget and undriven.any():
        driven = np.vstack([part.motor_inputs for part in parts])
        readings = np.vstack([in_device_axes(device, part.motor_inputs, part.platform_wrenches) for part in parts])
        gaps, _ = cKDTree(readings[:, FORCE]).query(wanted)
        worst = np.argsort(gaps)[::-1]
        distinct = int(np.sum(np.linalg.norm(readings[:, FORCE], axis=1) >= contact_threshold)) + 1
        user = user_table_renderer(device, driven, np.vstack([part.platform_wrenches for part in parts]),
                                   min(n_neighbours, distinct), contact_threshold)
        chosen = _nearest_undriven(pool, undriven, user.predict(wanted[worst]), min(batch, budget - sum(batches)))
        parts.append(sensed_contact(device, fingertip, chosen, settings, rng))
        batches.append(len(chosen))
    motor = np.vstack([part.motor_inputs for part in parts])
    collection = Collection(motor, np.vstack([p.finger_wrenches for p in parts]),
                            np.vstack([p.platform_wrenches for p in parts]), np.concatenate([p.saturated for p in parts]),
                            collection_duration(device, motor, settings.hold_s))
    return AdaptiveTable(collection, tuple(batches))


def _nearest_undriven(pool: np.ndarray, undriven: np.ndarray, aims: np.ndarray, count: int) -> np.ndarray:
    """Up to ``count`` configurations of ``pool`` not driven yet, each the nearest to the next aim in
    turn; marks them driven."""
    chosen = []
    for aim in aims:
        free = np.flatnonzero(undriven)
        if not len(free) or len(chosen) == count:
            break
        nearest = free[np.argmin(np.sum((pool[free] - aim) ** 2, axis=1))]
        undriven[nearest] = False
        chosen.append(nearest)
    return pool[chosen]
