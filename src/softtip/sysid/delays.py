"""Input delays: a dead time of whole samples per input channel, declared or estimated.

A model with input delays d_j is the delay-free model driven by u_j[t - d_j]: it is identified on
the shifted inputs (:func:`shift_inputs`, the samples before the record starts at the level the
deviations are taken from, i.e. zero) and runs as one discrete system whose first states are a
shift register per delayed input (:func:`with_input_delays`), so that simulation, prediction and
streaming need nothing else. For a continuous model the delay is exact: e^{-s d ts} with the input
held between samples is a shift of d samples.

:func:`estimate_delays` does what MATLAB's ``delayest`` does: for each candidate delay it fits an
ARX model by least squares (``na`` past outputs, ``nb`` input lags from the delay on) and keeps the
delay with the smallest loss; with several inputs, one channel at a time, the others held at
their current delays, sweep after sweep until no delay changes.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from softtip.sysid.statespace import IdentificationError, StateSpace

ESTIMATE = "estimate"
_SWEEPS = 4  # coordinate sweeps over the inputs (a MIMO search settles in two or three)


def resolve(delay, n_inputs: int) -> tuple[int, ...]:
    """One non-negative integer delay (samples) per input from ``delay`` (an integer for all, or one per input)."""
    values = [delay] * n_inputs if np.ndim(delay) == 0 else list(delay)
    if len(values) != n_inputs or not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 0
                                          for v in values):
        raise IdentificationError(f"delay: expected a non-negative integer number of samples or one per input "
                                  f"({n_inputs}), or {ESTIMATE!r}; got {delay!r}")
    return tuple(int(v) for v in values)


def shift_inputs(u: np.ndarray, delays: Sequence[int]) -> np.ndarray:
    """u_j[t - d_j] for every input j (zero before the record starts)."""
    shifted = np.zeros_like(u)
    for j, d in enumerate(delays):
        if d < len(u):
            shifted[d:, j] = u[:len(u) - d, j]
    return shifted


def with_input_delays(system: StateSpace, delays: Sequence[int]) -> StateSpace:
    """The discrete ``system`` behind a shift register of d_j samples on input j: states [z; x], z the
    registers (z_1[t+1] = u_j[t], z_k[t+1] = z_k-1[t], the system sees z_d), K and the noise
    covariance carried over (the registers take no innovation)."""
    if not any(delays):
        return system
    if not system.is_discrete:
        raise IdentificationError("input delays: expected a discrete system")
    n, nu, ny = system.n_states, system.n_inputs, system.n_outputs
    registers = sum(delays)
    size = registers + n
    A, B = np.zeros((size, size)), np.zeros((size, nu))
    C, D = np.zeros((ny, size)), np.zeros((ny, nu))
    A[registers:, registers:], C[:, registers:] = system.A, system.C
    first = 0
    for j, d in enumerate(delays):
        if d == 0:
            B[registers:, j], D[:, j] = system.B[:, j], system.D[:, j]
            continue
        B[first, j] = 1.0
        for k in range(1, d):
            A[first + k, first + k - 1] = 1.0
        last = first + d - 1
        A[registers:, last], C[:, last] = system.B[:, j], system.D[:, j]
        first += d
    K = None if system.K is None else np.vstack([np.zeros((registers, ny)), system.K])
    return StateSpace(A, B, C, D, system.ts, K, system.noise_covariance)


def _arx_loss(segments, delays: Sequence[int], na: int, nb: int, first: int) -> float:
    """The summed, variance-normalised least-squares loss over outputs of ARX models of every output
    (its own ``na`` past values, ``nb`` lags of every input from its delay on), scored from sample ``first``."""
    total = 0.0
    for i in range(segments[0][1].shape[1]):
        rows, targets = [], []
        for u, y in segments:
            t = np.arange(first, len(u))
            columns = [y[t - k, i] for k in range(1, na + 1)]
            columns += [u[t - d - k, j] for j, d in enumerate(delays) for k in range(nb)]
            rows.append(np.column_stack(columns))
            targets.append(y[t, i])
        regressors, target = np.vstack(rows), np.concatenate(targets)
        residual = target - regressors @ np.linalg.lstsq(regressors, target, rcond=None)[0]
        total += float(residual @ residual) / max(float(np.var(target)) * len(target), np.finfo(float).tiny)
    return total


def estimate_delays(segments: list[tuple[np.ndarray, np.ndarray]], max_delay: int, *, na: int = 2, nb: int = 2,
                    strictly_proper: bool = True) -> tuple[int, ...]:
    """The input delays (samples, 0..``max_delay``) of the trials ``segments`` by ARX loss (see the module notes).

    ``strictly_proper``: the model the delays are for has no direct term (a transfer function with
    fewer zeros than poles), so its response to u[t - d] starts at t = d + 1: the ARX input lags then
    start one sample after the delay.
    """
    nu = segments[0][0].shape[1]
    lead = 1 if strictly_proper else 0
    first = max_delay + lead + nb + na
    if sum(max(len(u) - first, 0) for u, _ in segments) < 4 * (na + nu * nb):
        raise IdentificationError(f"delay = {ESTIMATE!r}: a search up to {max_delay} samples needs trials longer "
                                  f"than {first} samples with at least {4 * (na + nu * nb)} samples after that "
                                  "(lower max_delay, or declare the delay)")
    delays = [0] * nu
    for _ in range(_SWEEPS):
        before = list(delays)
        for j in range(nu):
            losses = [_arx_loss(segments, [lead + (c if k == j else d) for k, d in enumerate(delays)], na, nb, first)
                      for c in range(max_delay + 1)]
            delays[j] = int(np.argmin(losses))
        if delays == before:
            break
    return tuple(delays)


def without_input_delays(system: StateSpace, delays: Sequence[int]) -> StateSpace:
    """The delay-free system behind the shift registers of :func:`with_input_delays` (its inverse)."""
    if not any(delays):
        return system
    registers = sum(delays)
    if system.n_states < registers:
        raise IdentificationError(f"input delays of {registers} samples in all, the system has {system.n_states} states")
    B, D = system.B[registers:].copy(), system.D.copy()
    last = np.cumsum(delays) - 1
    for j, d in enumerate(delays):
        if d:
            B[:, j], D[:, j] = system.A[registers:, last[j]], system.C[:, last[j]]
    K = None if system.K is None else system.K[registers:]
    return StateSpace(system.A[registers:, registers:], B, system.C[:, registers:], D, system.ts, K,
                      system.noise_covariance)
