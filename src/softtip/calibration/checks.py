"""Checks of estimator hyper-parameters, run at fit time (scikit-learn stores them unchanged)."""

from __future__ import annotations

import numbers

import numpy as np


def integer(name: str, value, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def real(name: str, value, *, above: float | None = None, at_least: float | None = None) -> float:
    valid = isinstance(value, numbers.Real) and not isinstance(value, bool) and np.isfinite(value)
    if valid and above is not None:
        valid = value > above
    if valid and at_least is not None:
        valid = value >= at_least
    if not valid:
        bound = f"> {above}" if above is not None else f">= {at_least}" if at_least is not None else "finite"
        raise ValueError(f"{name} must be a real number {bound}, got {value!r}")
    return float(value)


def layer_sizes(value) -> tuple[int, ...]:
    sizes = (value,) if isinstance(value, numbers.Integral) and not isinstance(value, bool) else value
    try:
        sizes = tuple(integer("hidden_layer_sizes", size, 1) for size in sizes)
    except (TypeError, ValueError):
        raise ValueError(f"hidden_layer_sizes must be one or more positive integers, got {value!r}") from None
    if not sizes:
        raise ValueError("hidden_layer_sizes must name at least one hidden layer, got ()")
    return sizes


def division(value) -> tuple[float, float, float]:
    """(train, validation, test) fractions: non-negative, train > 0, summing to 1."""
    try:
        fractions = tuple(float(f) for f in value)
    except (TypeError, ValueError):
        fractions = ()
    if (len(fractions) != 3 or not all(np.isfinite(fractions)) or min(fractions) < 0
            or fractions[0] <= 0 or abs(sum(fractions) - 1.0) > 1e-9):
        raise ValueError(f"division must be (train, validation, test) fractions >= 0 summing to 1 "
                         f"with train > 0, got {value!r}")
    return fractions


def generator(random_state) -> np.random.Generator:
    """A numpy Generator from None, an int seed or a Generator."""
    if random_state is None or isinstance(random_state, np.random.Generator) or (
            isinstance(random_state, numbers.Integral) and not isinstance(random_state, bool)):
        return np.random.default_rng(random_state)
    raise ValueError(f"random_state must be None, an int or a numpy Generator, got {random_state!r}")


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
