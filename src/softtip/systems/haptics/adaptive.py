"""An adaptive user table for personalisation A (beyond the publication): choose each next batch of
configurations to drive on the user from what the DS has measured so far.

Personalisation A needs user entries wherever the user is touched without the sensor saturating:
that band of the motor space is all its table can use, and where it lies depends on the finger.
A fixed grid spends most of its configurations outside it. Here the user first takes a coarse grid
(3³ = 27 configurations); every configuration driven is then known to be without contact, in
contact, or saturated. Each batch takes, among a fine grid's configurations not driven yet (the FS
grid's, saturated ones included: a smaller finger's band lies where the FS saturates), half
aimed and half filling. Aimed: the FS readings d* that lie farthest from every user reading so far
are rendered with the current user table, and the configurations nearest (in motor space) to the
inputs it gives are driven. Filling: configurations in the band as measured so far (a nearest
driven one in contact, or the two nearest on both sides of it: one without contact and one
saturated; else one of the four nearest in contact), farthest first from everything driven, so the
band is covered evenly even where the current table aims poorly (a finger it barely touches).
It stops at ``budget`` configurations. Each configuration is held and read as in the fixed
collection, so its real collection time follows from the same procedure.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from softtip._core.config import checked, integer
from softtip.systems.haptics.collection import (
    Collection,
    CollectionSettings,
    collection_duration,
    motor_grid,
    sensed_contact,
)
from softtip.systems.haptics.device import DeviceSpec
from softtip.systems.haptics.fingertips import Fingertip
from softtip.systems.haptics.personalisation import in_device_axes, readings_renderer
from softtip.systems.haptics.rendering import CONTACT_THRESHOLD, FORCE

NO_CONTACT, CONTACT, SATURATED = 0, 1, 2
Drive = Callable[[np.ndarray], Collection]  # configurations (entries, 3, rad) driven on the user and read
_NEIGHBOURS = 4  # driven configurations consulted about each candidate


@dataclass(frozen=True)
class AdaptiveTable:
    """The user table the adaptive collection drove (in the order driven) and the batches' sizes."""

    collection: Collection
    batches: tuple[int, ...]


def contact_states(collection: Collection, contact_threshold: float = CONTACT_THRESHOLD) -> np.ndarray:
    """Each entry's state: :data:`NO_CONTACT`, :data:`CONTACT` or :data:`SATURATED`."""
    touching = np.linalg.norm(collection.platform_wrenches[:, FORCE], axis=1) >= contact_threshold
    return np.where(collection.saturated, SATURATED, np.where(touching, CONTACT, NO_CONTACT))


def adaptive_user_table(device: DeviceSpec, fingertip: Fingertip, fs_motor_inputs, fs_platform_wrenches,
                        settings: CollectionSettings, rng: np.random.Generator | None, budget: int = 64,
                        batch: int = 8, initial_levels: int = 3, candidate_levels: int = 13, n_neighbours: int = 8,
                        contact_threshold: float = CONTACT_THRESHOLD, drive: Drive | None = None) -> AdaptiveTable:
    """Drive at most ``budget`` configurations on the user, ``batch`` at a time after a coarse
    ``initial_levels``³ grid, chosen among a ``candidate_levels``³ grid, aimed at the FS table's
    entries (``fs_motor_inputs`` and their unsaturated DS readings ``fs_platform_wrenches``);
    ``drive``: how each batch is driven and read (a real device), else on the device model with
    ``fingertip`` in it, read by ``settings`` and ``rng``."""
    if drive is None:
        def drive(motor_inputs: np.ndarray) -> Collection:
            return sensed_contact(device, fingertip, motor_inputs, settings, rng)

    budget = checked(integer(1), "budget", budget)
    batch = checked(integer(1), "batch", batch)
    first = motor_grid(device, initial_levels)
    if len(first) > budget:
        raise ValueError(f"budget = {budget}: expected at least the first grid's {len(first)} configurations "
                         f"(initial_levels = {initial_levels})")
    pool = motor_grid(device, candidate_levels)
    fs_readings = in_device_axes(device, fs_motor_inputs, fs_platform_wrenches)[:, FORCE]
    wanted = fs_readings[np.linalg.norm(fs_readings, axis=1) >= contact_threshold]
    parts = [drive(first)]
    batches = [len(first)]
    while sum(batches) < budget:
        driven = np.vstack([part.motor_inputs for part in parts])
        states = np.concatenate([contact_states(part, contact_threshold) for part in parts])
        count = min(batch, budget - sum(batches))
        aimed = _aimed(device, parts, wanted, pool, driven, count - count // 2, n_neighbours, contact_threshold)
        filling = _next_batch(pool, np.vstack([driven, aimed]), np.concatenate([states, np.full(len(aimed), CONTACT)]),
                              count - len(aimed))
        chosen = np.vstack([aimed, filling])
        if not len(chosen):
            break  # every candidate has been driven
        parts.append(drive(chosen))
        batches.append(len(chosen))
    motor = np.vstack([part.motor_inputs for part in parts])
    collection = Collection(motor, np.vstack([p.finger_wrenches for p in parts]),
                            np.vstack([p.platform_wrenches for p in parts]),
                            np.concatenate([p.saturated for p in parts]),
                            collection_duration(device, motor, settings.hold_s))
    return AdaptiveTable(collection, tuple(batches))


def _aimed(device: DeviceSpec, parts: list[Collection], wanted: np.ndarray, pool: np.ndarray, driven: np.ndarray,
           count: int, n_neighbours: int, contact_threshold: float) -> np.ndarray:
    """Up to ``count`` undriven configurations of ``pool``, each nearest (in motor space) to where the
    current user table renders the FS readings it covers worst; none while it has no contact entry."""
    usable = [part.unsaturated() for part in parts]
    readings = np.vstack([in_device_axes(device, part.motor_inputs, part.platform_wrenches) for part in usable])
    touching = int(np.sum(np.linalg.norm(readings[:, FORCE], axis=1) >= contact_threshold))
    if not touching or not len(wanted):
        return np.zeros((0, 3))
    user = readings_renderer(readings, np.vstack([part.motor_inputs for part in usable]),
                             min(n_neighbours, touching + 1), contact_threshold)
    gaps, _ = cKDTree(readings[:, FORCE]).query(wanted)
    aims = user.predict(wanted[np.argsort(gaps)[::-1]])
    free = np.ones(len(pool), bool)
    distance, index = cKDTree(pool).query(driven)
    free[index[distance < 1e-9]] = False
    chosen = []
    for aim in aims:
        candidates = np.flatnonzero(free)
        if not len(candidates) or len(chosen) == count:
            break
        nearest = candidates[np.argmin(np.sum((pool[candidates] - aim) ** 2, axis=1))]
        free[nearest] = False
        chosen.append(nearest)
    return pool[chosen].reshape(-1, 3)


def _next_batch(pool: np.ndarray, driven: np.ndarray, states: np.ndarray, count: int) -> np.ndarray:
    """Up to ``count`` configurations of ``pool`` not driven yet: those in the contact band as measured
    (else any), farthest first from everything driven and from each other."""
    distance, nearest = cKDTree(driven).query(pool, k=min(_NEIGHBOURS, len(driven)))
    distance, nearest = distance.reshape(len(pool), -1), nearest.reshape(len(pool), -1)
    if count <= 0:
        return np.zeros((0, 3))
    undriven = distance[:, 0] > 1e-9
    around = states[nearest]
    closest_two = around[:, :2]
    straddling = (closest_two == NO_CONTACT).any(axis=1) & (closest_two == SATURATED).any(axis=1)
    in_band = (around[:, 0] == CONTACT) | straddling
    near_band = (around == CONTACT).any(axis=1)
    eligible = next((np.flatnonzero(undriven & where) for where in (in_band, near_band, undriven)
                     if np.any(undriven & where)), np.zeros(0, int))
    gap = distance[eligible, 0].copy()
    chosen = []
    while len(chosen) < count and len(eligible) and gap.max() > 1e-9:
        pick = int(np.argmax(gap))  # the first on a tie
        chosen.append(eligible[pick])
        gap = np.minimum(gap, np.linalg.norm(pool[eligible] - pool[eligible[pick]], axis=1))
    return pool[chosen]
