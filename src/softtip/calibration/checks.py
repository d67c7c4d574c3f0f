"""Checks of what a model file holds: its arrays and its fitted state."""

from __future__ import annotations

import numpy as np


def stored_array(arrays: dict, name: str, shape: tuple[int, ...], kinds: str = "f") -> np.ndarray:
    """``arrays[name]`` checked for presence, dtype kind, shape and (floats) finiteness."""
    array = arrays.get(name)
    if array is None:
        raise ValueError(f"array {name!r} is missing")
    if array.dtype.kind not in kinds or array.shape != shape:
        raise ValueError(f"array {name!r} has shape {array.shape} and dtype {array.dtype}, expected shape {shape}")
    if array.dtype.kind == "f" and not np.all(np.isfinite(array)):
        raise ValueError(f"array {name!r} holds non-finite values")
    return array


def stored_int(state: dict, name: str, minimum: int) -> int:
    value = state.get(name)
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f"state {name!r} must be an integer >= {minimum}, got {value!r}")
    return value
