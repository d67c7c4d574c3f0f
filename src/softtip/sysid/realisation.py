"""A matrix of continuous transfer functions realised as one state-space system.

Entry G_ij(s) = b(s) / a(s) (descending powers of s, a monic) becomes the controller canonical
form of scipy.signal.tf2ss: A_ij the companion matrix of a (first row -a_1 .. -a_n, ones below
the diagonal), B_ij = e_1, C_ij = b_1..n - b_0 a_1..n, D_ij = b_0 (:func:`companion` and
:func:`output_map`, whose states s^k/A run the other way, reversed); each companion block is then
scaled by a diagonal similarity (scipy.linalg.matrix_balance, powers of 2: exact) because the
coefficients of a sixth-order polynomial span many decades. The blocks are stacked
block-diagonally: input j drives the blocks of column j, output i sums the blocks of row i. An
entry with a zero numerator adds no state.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.linalg

from softtip.sysid.statespace import IdentificationError, StateSpace


def companion(a: np.ndarray) -> np.ndarray:
    """The controller canonical state matrix of 1/A, A monic with ascending lower coefficients ``a``
    (a_0 .. a_n-1): ones above the diagonal, last row -a; its states are s^k/A v, k = 0..n-1."""
    n = len(a)
    matrix = np.eye(n, k=1)
    matrix[-1] = -a
    return matrix


def output_map(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, float]:
    """C and D of B/A v = C xi + D v on the states xi_k = s^k/A v of :func:`companion` (``b`` ascending,
    of degree n at most): a biproper B (degree n) adds b_n s^n/A v = b_n (v - a . xi)."""
    n = len(a)
    if len(b) > n:
        return b[:n] - b[n] * a, float(b[n])
    return np.concatenate([b, np.zeros(n - len(b))]), 0.0


def _entry(numerator: np.ndarray, denominator: np.ndarray, where: str
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(A, B (n,), C (n,), D) of one entry in balanced controller canonical form."""
    denominator = np.trim_zeros(np.atleast_1d(np.asarray(denominator, dtype=np.float64)), "f")
    numerator = np.trim_zeros(np.atleast_1d(np.asarray(numerator, dtype=np.float64)), "f")
    if not denominator.size or not (np.all(np.isfinite(denominator)) and np.all(np.isfinite(numerator))):
        raise IdentificationError(f"transfer function {where}: expected finite coefficients and a non-zero denominator")
    numerator, denominator = numerator / denominator[0], denominator / denominator[0]
    n = len(denominator) - 1
    if len(numerator) > n + 1:
        raise IdentificationError(f"transfer function {where}: improper ({len(numerator) - 1} zeros, {n} poles)")
    ascending = denominator[:0:-1]
    output, feedthrough = output_map(ascending, numerator[::-1])
    if n == 0:
        return np.zeros((0, 0)), np.zeros(0), np.zeros(0), feedthrough
    A = companion(ascending)[::-1, ::-1]
    B = np.zeros(n)
    B[0] = 1.0
    C = output[::-1]
    A, (scaling, _) = scipy.linalg.matrix_balance(A, permute=False, separate=True)
    return A, B / scaling, C * scaling, feedthrough


def realise(numerators: Sequence[Sequence[np.ndarray]], denominators: Sequence[Sequence[np.ndarray]]) -> StateSpace:
    """The continuous state-space realisation of the transfer-function matrix given as
    ``numerators[i][j]`` and ``denominators[i][j]`` (output i, input j)."""
    ny = len(numerators)
    nu = len(numerators[0]) if ny else 0
    if not ny or not nu or len(denominators) != ny or any(len(row) != nu for row in (*numerators, *denominators)):
        raise IdentificationError("transfer function: numerators and denominators must be equal [output][input] tables")
    entries = [(i, j, _entry(numerators[i][j], denominators[i][j], f"[{i}][{j}]"))
               for i in range(ny) for j in range(nu)]
    dynamic = [(i, j, e) for i, j, e in entries if len(e[0]) and np.any(e[2])]
    n = sum(len(e[0]) for _, _, e in dynamic)
    A, B, C, D = np.zeros((n, n)), np.zeros((n, nu)), np.zeros((ny, n)), np.zeros((ny, nu))
    first = 0
    for i, j, (a, b, c, _) in dynamic:
        block = slice(first, first + len(a))
        A[block, block], B[block, j], C[i, block] = a, b, c
        first += len(a)
    for i, j, (_, _, _, d) in entries:
        D[i, j] = d
    return StateSpace(A, B, C, D)
