"""The force a person means to put on the table sensor in each of S2's seven calibration trials.

Finger frame (:mod:`softtip.systems.wearable.fingerpad`): x radial, y distal, z palmar; the force is the
one the finger applies (Fz > 0 pressing). What the table receives is this force after the pad's
friction limit (the finger slides beyond it); what is drawn here is the intent.

Every trial starts with the finger in the air at the start of the history, places it on the
object in half a second and holds a *tare load* while both sensors are zeroed at the start of the
recording; the motions follow as repeated smooth presses:

- each press rises, holds and falls with minimum-jerk profiles 10s³ − 15s⁴ + 6s⁵ (smooth movement,
  Flash & Hogan, J. Neurosci. 5:1688, 1985; taken over to isometric force), with its own amplitude,
  rise, hold, fall (0.4–1.5 s, 0–1.2 s, 0.4–1.5 s) and pause (0.2–1.0 s), so amplitude and rate vary;
- *palmar* (+Fz): presses of 25–100 % of ``press_peak`` above a light resting load
  (``rest``, ±40 % per trial). Forces of a few newtons are those of everyday fingertip presses
  (Jones & Lederman, Human Hand Function, 2006);
- *dorsal* (−Fz): on a table-mounted sensor the pad can only push, so a negative Fz is read as the
  finger *unloading* from a held press: the participant holds ``dorsal_hold`` (±20 %) while both
  sensors are tared, then extends the finger (dorsal direction) in repeated lifts of 30–130 % of
  that load; a lift beyond it leaves the surface, and the table reads −(the tare load) until the
  pad lands again;
- *radial*, *ulnar*, *distal*, *proximal* (±Fx, ±Fy): the finger presses to ``tilt_normal``
  (±30 %) and tilts repeatedly along the axis, each tilt aiming at a tangential force of 20–110 %
  of ``tangential_effort`` × the friction limit the person expects (× the normal force), so the
  largest tilts of a person whose pad is more slippery than expected slide; the normal force rises
  with the tilt (× 1 + ``normal_coupling`` × |Ft|/Fz), as it does when people push sideways;
- *combined*: presses as in palmar with tilts in random directions on top.

Imperfect axes: each press's direction errs by ``cross_talk`` (standard deviation, as a share of
its size, on each other axis). Force steadiness: a band-limited (1–12 Hz, physiological tremor
included) fluctuation of ``tremor`` × the force's size on each axis (the coefficient of variation
of a held fingertip force is a few percent: Galganski, Fuglevand & Enoka, J. Neurophysiol.
69:2108, 1993). The sensors sample it unfiltered, so its 8–12 Hz part aliases at 10 Hz.
"""

from __future__ import annotations

import functools

from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, sosfiltfilt

MOTIONS = ("palmar", "dorsal", "radial", "ulnar", "distal", "proximal", "combined")
TILT_AXES = {"radial": (1.0, 0.0), "ulnar": (-1.0, 0.0), "distal": (0.0, 1.0), "proximal": (0.0, -1.0)}
PLACE_S = 0.5  # placing the finger on the object
EDGE_S = 1.0  # quiet time after the tare and before the end
MINIMUM_TRIAL_S = 5.0  # between the quiet start (up to 1.5 s) and end (1 s), room for a press


@dataclass(frozen=True)
class Effort:
    """How a person presses in the seven trials (forces in N; see the module notes). The values are the
    protocol's (:class:`softtip.systems.wearable.bench.WearableParameters`, the realism's cross-talk and tremor)."""

    press_peak: float
    rest: float
    dorsal_hold: float
    tilt_normal: float
    tangential_effort: float
    friction_sense: float  # the friction limit the person expects
    normal_coupling: float
    cross_talk: float
    tremor: float


def minimum_jerk(s):
    """10s³ − 15s⁴ + 6s⁵ on [0, 1], 0 before and 1 after."""
    s = np.clip(s, 0.0, 1.0)
    return s ** 3 * (10 - 15 * s + 6 * s ** 2)


def press(times, start, rise, hold, fall):
    """One press of unit height: up over ``rise`` s from ``start``, ``hold`` s, down over ``fall`` s."""
    up = minimum_jerk((times - start) / rise)
    return up - minimum_jerk((times - start - rise - hold) / fall)


def presses(rng, times, start, end) -> list[np.ndarray]:
    """Unit presses one after another from ``start`` until the next would end after ``end``."""
    out, t = [], start
    while True:
        rise, hold, fall = rng.uniform(0.4, 1.5), rng.uniform(0.0, 1.2), rng.uniform(0.4, 1.5)
        if t + rise + hold + fall > end:
            return out
        out.append(press(times, t, rise, hold, fall))
        t += rise + hold + fall + rng.uniform(0.2, 1.0)


def intended_force(motion: str, times: np.ndarray, duration: float, rng: np.random.Generator,
                   effort: Effort) -> np.ndarray:
    """The force (N, 3) the person means to apply over ``times`` (s; the recording runs from 0 to
    ``duration``, earlier times are the placement and settling before it)."""
    placed = minimum_jerk((times - times[0] - 0.2) / PLACE_S)
    start, end = rng.uniform(EDGE_S, 1.5 * EDGE_S), duration - EDGE_S
    force = np.zeros((len(times), 3))
    ratio = np.zeros((len(times), 2))  # the tangential force the person aims for, per unit normal force
    if motion in ("palmar", "dorsal", "combined"):
        hold = effort.dorsal_hold * rng.uniform(0.8, 1.2) if motion == "dorsal" else effort.rest * rng.uniform(0.6, 1.4)
        force[:, 2] = hold * placed
        for unit in presses(rng, times, start, end):
            size = -hold * rng.uniform(0.3, 1.3) if motion == "dorsal" else effort.press_peak * rng.uniform(0.25, 1.0)
            force += size * unit[:, None] * _direction(rng, np.array([0.0, 0.0, 1.0]), effort.cross_talk)
        if motion == "combined":
            for unit in presses(rng, times, start, end):
                angle = rng.uniform(0, 2 * np.pi)
                share = rng.uniform(0.2, 0.8) * effort.tangential_effort * effort.friction_sense
                ratio += share * unit[:, None] * np.array([np.cos(angle), np.sin(angle)])
    else:
        hold = effort.rest * rng.uniform(0.6, 1.4)
        normal = effort.tilt_normal * rng.uniform(0.7, 1.3)
        force[:, 2] = hold * placed + (normal - hold) * press(times, start - 0.5 * EDGE_S, 1.0, end - start, 1.0)
        axis = np.array([*TILT_AXES[motion], 0.0])
        for unit in presses(rng, times, start + 0.5, end - 0.5):
            share = rng.uniform(0.2, 1.1) * effort.tangential_effort * effort.friction_sense
            ratio += share * unit[:, None] * _direction(rng, axis, effort.cross_talk)[:2]
    force[:, 2] *= 1 + effort.normal_coupling * np.linalg.norm(ratio, axis=1)
    force[:, :2] += ratio * force[:, 2:]
    return force + _tremor(rng, times, effort.tremor) * np.linalg.norm(force, axis=1)[:, None]


def _direction(rng: np.random.Generator, axis: np.ndarray, cross_talk: float) -> np.ndarray:
    """``axis`` with an error of ``cross_talk`` (standard deviation) on each other axis."""
    error = rng.normal(0.0, cross_talk, 3) if cross_talk > 0 else np.zeros(3)
    return axis + np.where(axis == 0, error, 0.0)


@functools.lru_cache
def _tremor_band(rate: float) -> np.ndarray:
    """The tremor's 1-12 Hz band-pass at ``rate`` (capped below Nyquist): one design per grid, not per trial."""
    return butter(2, [1.0, min(12.0, 0.45 * rate)], btype="band", fs=rate, output="sos")


def _tremor(rng: np.random.Generator, times: np.ndarray, size: float) -> np.ndarray:
    """Unit-variance noise (N, 3) in 1-12 Hz (the band capped below the grid's Nyquist), times ``size``."""
    if size == 0 or len(times) < 16:
        return np.zeros((len(times), 3))
    noise = sosfiltfilt(_tremor_band(1.0 / np.median(np.diff(times))), rng.normal(size=(len(times), 3)), axis=0)
    return size * noise / noise.std(axis=0)
