"""Data-driven rendering: lookup tables of sensor wrenches and motor inputs, and the k-nearest-neighbour
renderer that inverts them.

A table holds, per configuration the device was driven to, the motor inputs m* (servo angles, rad)
and the sensor's wrench f* (N, N·m). To render a wanted wrench f the renderer finds the n table
entries whose f* are nearest to f and averages their m*, weighted by the inverse of their distance
to f (an entry that f matches exactly is returned as it is). The choices, each tested:

- **Features**: the three force components, in N, unscaled. Only the rendered force matters to the
  study and its error is a force distance in N, so the search uses that same metric; the torques
  depend on where each finger's sensor sits and would pull the neighbours towards the FS's geometry.
  Standardising each component would weight a newton of shear above a newton of pressure. With a
  ``torque_length`` L (m) the features are the whole wrench, the torques divided by L (so in N: a
  torque counts as the force that makes it at the distance L): what the published personalisation
  A searches the device-mounted sensor's raw readings by.
- **Search**: scipy's k-d tree (``cKDTree``), exact Euclidean n nearest.
- **Weighting**: 1/d^p with p = ``weighting_power`` (1, the published distance weighting, by
  default; 0 a plain average of the n; 2 inverse-square).
- **Entries without contact**: many configurations do not touch the fingertip and read only noise
  near zero force; left as they are they would form a cloud of near-ties whose motor inputs are
  arbitrary. Every entry whose force is below ``contact_threshold`` is merged into one entry at zero
  force whose motor input is the configuration farthest from contact, the least-wound one (the
  smallest sum of angles; the first in table order on a tie): rendering no force releases.
- **Out of range**: a wanted force outside the table's force range (per component), or farther
  from its nearest entry than the table's widest gap between neighbouring entries, is flagged, never
  silently extrapolated.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import isfinite

import numpy as np
from scipy.spatial import cKDTree

from softtip._core.config import PositiveInteger, PositiveNumber, checked, number

FORCE = slice(0, 3)  # the wrench components the renderer uses without a torque length
# 5 steps of the Nano17's force resolution (1/320 N): above the window-averaged noise of a held
# configuration (one step / √200), below any force a person notices
CONTACT_THRESHOLD = 5 / 320
WeightingPower = number("a number from 0 to 4", ge=0, le=4)


class TableError(ValueError):
    """A lookup table that cannot be rendered from."""


def _checked_table(wrenches, name: str) -> np.ndarray:
    wrenches = np.asarray(wrenches, dtype=float)
    if wrenches.ndim != 2 or wrenches.shape[1] not in (3, 6):
        raise TableError(f"{name} has shape {wrenches.shape}: expected (entries, 6) wrenches or (entries, 3) forces")
    bad = ~np.all(np.isfinite(wrenches), axis=1)
    if bad.any():
        raise TableError(f"{name}: entry {int(np.flatnonzero(bad)[0])} is not finite (NaN or inf)")
    return wrenches


def wrench_features(wrenches: np.ndarray, torque_length: float | None) -> np.ndarray:
    """The search's coordinates of wrenches (..., 6; or (..., 3) forces without ``torque_length``):
    the forces (N), or with a ``torque_length`` L (m) the forces beside the torques over L (N)."""
    if torque_length is None:
        return wrenches[..., FORCE]
    return np.concatenate([wrenches[..., :3], wrenches[..., 3:] / torque_length], axis=-1)


def _first_duplicate(rows: np.ndarray) -> tuple[int, int] | None:
    """The earliest row that repeats an earlier one, as (the earlier one, it); None if every row differs."""
    order = np.lexsort(rows.T[::-1])  # stable: equal rows stay in their order
    ordered = rows[order]
    same = np.all(ordered[1:] == ordered[:-1], axis=1)
    if not same.any():
        return None
    starts = np.concatenate([[True], ~same])
    group_start = np.flatnonzero(starts)[np.cumsum(starts) - 1]  # per sorted row, where its group begins
    repeats = np.flatnonzero(~starts)
    later = repeats[np.argmin(order[repeats])]
    return int(order[group_start[later]]), int(order[later])


@dataclass(frozen=True)
class LookupTable:
    """Table entries: sensor wrenches (entries, 6) in N and N·m and motor inputs (entries, 3) in rad.
    Refused: NaN or infinite values, mismatched lengths, and an entry listed twice. Two wrenches may
    share motor inputs (a personalised table maps several FS entries to one user configuration)."""

    wrenches: np.ndarray
    motor_inputs: np.ndarray

    def __post_init__(self) -> None:
        _checked_table(self.wrenches, "wrenches")
        motor = np.asarray(self.motor_inputs, dtype=float)
        if motor.ndim != 2 or motor.shape[1] != 3 or len(motor) != len(self.wrenches):
            raise TableError(f"motor_inputs has shape {motor.shape}: expected ({len(self.wrenches)}, 3)")
        if not np.all(np.isfinite(motor)):
            raise TableError(f"motor_inputs: entry {int(np.flatnonzero(~np.isfinite(motor).all(1))[0])} is not finite")
        duplicate = _first_duplicate(np.hstack([np.asarray(self.wrenches, dtype=float), motor]))
        if duplicate is not None:
            raise TableError(f"table: entries {duplicate[0]} and {duplicate[1]} are the same entry")

    def __len__(self) -> int:
        return len(self.motor_inputs)


@dataclass(frozen=True)
class Rendering:
    """Motor inputs (..., 3) for wanted wrenches, and which wanted wrenches lay outside the table (...)."""

    motor_inputs: np.ndarray
    outside: np.ndarray


class NearestNeighbourRenderer:
    """The k-nearest-neighbour, inverse-distance-weighted inverse of a lookup table (scikit-learn
    conventions: ``fit(wrenches, motor_inputs)``, ``predict(wrenches)``, ``get_params``). Its
    coordinates are the forces, or with a ``torque_length`` (m) the whole wrench (:func:`wrench_features`)."""

    def __init__(self, n_neighbours: int = 8, contact_threshold: float = CONTACT_THRESHOLD,
                 weighting_power: float = 1.0, torque_length: float | None = None):
        self.n_neighbours = checked(PositiveInteger, "n_neighbours", n_neighbours, TableError)
        self.contact_threshold = checked(PositiveNumber, "contact_threshold", contact_threshold, TableError)
        self.weighting_power = checked(WeightingPower, "weighting_power", weighting_power, TableError)
        self.torque_length = (None if torque_length is None
                              else checked(PositiveNumber, "torque_length", torque_length, TableError))

    def get_params(self, deep: bool = True) -> dict:
        return {"n_neighbours": self.n_neighbours, "contact_threshold": self.contact_threshold,
                "weighting_power": self.weighting_power, "torque_length": self.torque_length}

    def set_params(self, **params) -> NearestNeighbourRenderer:
        self.__init__(**(self.get_params() | params))
        return self

    def fit(self, wrenches, motor_inputs) -> NearestNeighbourRenderer:
        """Index the table (entries, 6, or 3 without a torque length) → (entries, 3), merging the
        entries without contact."""
        table = LookupTable(np.asarray(wrenches, dtype=float), np.asarray(motor_inputs, dtype=float))
        wrenches, motor = _checked_table(table.wrenches, "wrenches"), np.asarray(table.motor_inputs, dtype=float)
        if self.torque_length is not None and wrenches.shape[1] != 6:
            raise TableError(f"wrenches have shape {wrenches.shape}: a torque length needs (entries, 6) wrenches")
        features = wrench_features(wrenches, self.torque_length)
        touching = np.linalg.norm(wrenches[:, FORCE], axis=1) >= self.contact_threshold
        duplicate = _first_duplicate(features[touching])
        if duplicate is not None:
            rows = np.flatnonzero(touching)
            read = "force" if self.torque_length is None else "wrench"
            raise TableError(f"wrenches: entries {rows[duplicate[0]]} and {rows[duplicate[1]]} read the same {read}")
        free = np.flatnonzero(~touching)
        if len(free):
            released = free[np.argmin(motor[free].sum(axis=1))]  # argmin: the first on a tie
            features = np.vstack([np.zeros((1, features.shape[1])), features[touching]])
            motor = np.vstack([motor[released], motor[touching]])
        if len(features) < self.n_neighbours:
            raise TableError(f"n_neighbours = {self.n_neighbours}: the table has only {len(features)} distinct entries")
        self.features_, self.motor_inputs_ = features, motor
        self.tree_ = cKDTree(features)
        self.merged_ = len(free)
        gaps, _ = self.tree_.query(features, k=2)
        self.widest_gap_ = float(gaps[:, 1].max())
        self.lowest_, self.highest_ = features.min(axis=0), features.max(axis=0)
        # what render_one reads each call, precomputed
        self._query, self._k = self.tree_.query, max(self.n_neighbours, 2)
        self._motor_and_ones = np.hstack([motor, np.ones((len(motor), 1))])
        self._uniform = np.ones(self.n_neighbours)
        self._bounds = (tuple(self.lowest_.tolist()), tuple(self.highest_.tolist()))
        return self

    def _wanted(self, wrenches) -> np.ndarray:
        wanted = np.asarray(wrenches, dtype=float)
        shapes = ((3,), (6,)) if self.torque_length is None else ((6,),)
        if wanted.shape[-1:] not in shapes:
            raise ValueError(f"wanted wrenches have shape {wanted.shape}: expected (..., 6)"
                             + (" or (..., 3)" if self.torque_length is None else ""))
        if not np.all(np.isfinite(wanted)):
            raise ValueError("wanted wrenches: expected finite numbers")
        return wrench_features(wanted, self.torque_length)

    def render(self, wrenches) -> Rendering:
        """Motor inputs for wanted wrenches (..., 6 or 3), with the out-of-range flag."""
        wanted = self._wanted(wrenches)
        distances, nearest = self.tree_.query(wanted, k=self.n_neighbours)
        if self.n_neighbours == 1:  # scipy drops the neighbours' axis for k = 1
            distances, nearest = distances[..., None], nearest[..., None]
        return Rendering(self._average(distances, nearest), self._outside(wanted, distances[..., 0]))

    def render_one(self, wrench) -> tuple[np.ndarray, bool]:
        """Motor inputs (3,) for one wanted wrench (6,) or force (3,), and whether it lies outside the
        table: :meth:`render` for the real-time loop. Its arithmetic is :meth:`render`'s on arrays
        precomputed by :meth:`fit` (the motor inputs beside a column of ones, so one product gives
        both the weighted sum and the weights' total) and its checks are on three Python floats: no
        small temporaries besides the k-d tree's answer. With a torque length it is :meth:`render` of one."""
        if self.torque_length is not None:
            one = self.render(np.asarray(wrench, dtype=float)[None])
            return one.motor_inputs[0], bool(one.outside[0])
        force = np.asarray(wrench, dtype=float)
        if force.shape != (6,) and force.shape != (3,):
            raise ValueError(f"wanted wrench has shape {force.shape}: expected 6 (or 3) finite numbers")
        force = force[:3]
        fx, fy, fz = force.tolist()
        if not (isfinite(fx) and isfinite(fy) and isfinite(fz)):
            raise ValueError(f"wanted wrench {wrench!r}: expected 6 (or 3) finite numbers")
        distances, nearest = self._query(force, self._k)
        if self._k != self.n_neighbours:  # k = 1 asked as 2: scipy drops the neighbours' axis for k = 1
            distances, nearest = distances[:1], nearest[:1]
        nearest_distance = float(distances[0])
        if self.weighting_power == 0.0:
            weights = self._uniform
        elif nearest_distance == 0.0:
            weights = (distances == 0.0).astype(float)
        elif self.weighting_power == 1.0:
            weights = 1.0 / distances
        else:
            weights = distances ** -self.weighting_power
        summed = np.dot(weights, self._motor_and_ones.take(nearest, 0))
        (lx, ly, lz), (hx, hy, hz) = self._bounds
        outside = (nearest_distance > self.widest_gap_ or fx < lx or fy < ly or fz < lz or fx > hx or fy > hy
                   or fz > hz)
        return summed[:3] / summed[3], outside

    def predict(self, wrenches) -> np.ndarray:
        """Motor inputs (..., 3) for wanted wrenches; see :meth:`render` for the out-of-range flag."""
        return self.render(wrenches).motor_inputs

    def _average(self, distances: np.ndarray, nearest: np.ndarray) -> np.ndarray:
        if self.weighting_power == 0.0:
            return self.motor_inputs_[nearest].mean(axis=-2)
        exact = distances[..., :1] == 0.0
        inverse = np.where(distances == 0.0, 1.0, distances) ** -self.weighting_power
        weights = np.where(exact, (distances == 0.0).astype(float), inverse)
        weights /= weights.sum(axis=-1, keepdims=True)
        return np.einsum("...k,...kj->...j", weights, self.motor_inputs_[nearest])

    def _outside(self, wanted: np.ndarray, nearest_distance: np.ndarray) -> np.ndarray:
        beyond = np.any((wanted < self.lowest_) | (wanted > self.highest_), axis=-1)
        return beyond | (nearest_distance > self.widest_gap_)
