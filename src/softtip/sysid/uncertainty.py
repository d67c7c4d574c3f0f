"""Confidence intervals of an identified transfer-function matrix, its Bode plot with the band, and the
empirical transfer-function estimate from the recording.

From the coefficients' covariance Σ (:func:`softtip.sysid.transfer.parameter_covariance`, the
output-error Jacobian at the optimum) every derived quantity gets its standard deviation to first
order (the delta method, Ljung 1999 §9.4: σ²_f = ∇f Σ ∇fᵀ):

- a root r of P(s) = Σ c_k s^(d-k): dr/dc_k = -r^(d-k) / P'(r), for the poles (the denominator
  after its leading 1) and the zeros (the numerator), real and imaginary parts apart;
- G(jω) = B/A: dG/da_k = -B s^(n-k)/A², dG/db_k = s^(m-k)/A, and from them the magnitude,
  d|G| = Re(conj(G) dG)/|G|, and the phase, dφ = Im(dG/G).

An interval is the value ± z σ, z the two-sided normal quantile of the ``confidence``.

:func:`empirical_transfer_function` is MATLAB's ``etfe``/``spa`` in its Welch form: G(ω) =
S_yu(ω) S_uu(ω)⁻¹ from averaged, windowed cross-spectra (the H1 estimate; with several inputs the
input spectral matrix is inverted per frequency).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from statistics import NormalDist

import numpy as np

from softtip.sysid.refine import StateSpaceCovariance
from softtip.sysid.statespace import IdentificationError, StateSpace
from softtip.sysid.transfer import TransferFunctionMatrix

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def normal_quantile(confidence: float) -> float:
    """z of a two-sided ``confidence`` interval of a normal variable (1.96 for 0.95); refuses a confidence
    outside (0, 1)."""
    if not 0 < confidence < 1:
        raise IdentificationError(f"confidence: expected a fraction between 0 and 1, got {confidence!r}")
    return NormalDist().inv_cdf(0.5 + confidence / 2)


def _entry_slices(tf: TransferFunctionMatrix, i: int) -> list[tuple[slice, slice]]:
    """Where entry (i, j)'s denominator (after its 1) and numerator coefficients sit in output i's covariance."""
    slices, first = [], 0
    for a, b in zip(tf.denominators[i], tf.numerators[i]):
        n, m = len(a) - 1, len(b)
        slices.append((slice(first, first + n), slice(first + n, first + n + m)))
        first += n + m
    return slices


def _check(tf: TransferFunctionMatrix, covariances: list[np.ndarray]) -> None:
    ny, _ = tf.shape
    if len(covariances) != ny:
        raise IdentificationError(f"covariances: expected one matrix per output ({ny}), got {len(covariances)}")
    for i, covariance in enumerate(covariances):
        size = sum(len(a) - 1 + len(b) for a, b in zip(tf.denominators[i], tf.numerators[i]))
        if np.shape(covariance) != (size, size):
            raise IdentificationError(f"covariances[{i}]: expected ({size}, {size}), got {np.shape(covariance)}")


def _root_spread(coefficients: np.ndarray, covariance: np.ndarray, leading: bool) -> tuple[np.ndarray, np.ndarray,
                                                                                             np.ndarray]:
    """Roots of the descending polynomial ``coefficients`` and the standard deviations of their real and
    imaginary parts; ``leading``: the first coefficient is a fixed 1 outside ``covariance``."""
    roots = np.roots(coefficients)
    if not roots.size:
        return roots, np.zeros(0), np.zeros(0)
    degree = len(coefficients) - 1
    slope = np.polyval(np.polyder(coefficients), roots)
    powers = degree - np.arange(1 if leading else 0, degree + 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        gradient = -(roots[:, None] ** powers[None, :]) / slope[:, None]  # (roots, free coefficients)
    spread = []
    for part in (gradient.real, gradient.imag):
        spread.append(np.sqrt(np.maximum(np.einsum("rk,kl,rl->r", part, covariance, part), 0.0)))
    return roots, spread[0], spread[1]


@dataclass(frozen=True)
class Band:
    """One entry's frequency response on ``omega`` (rad/s) with the standard deviations of its magnitude and
    phase (rad), and the interval's quantile z."""

    omega: np.ndarray
    response: np.ndarray
    magnitude_std: np.ndarray
    phase_std: np.ndarray
    z: float


def frequency_band(tf: TransferFunctionMatrix, covariances: list[np.ndarray], omega: np.ndarray, i: int, j: int,
                   confidence: float = 0.95) -> Band:
    """Entry (i, j)'s response G(jω) and its magnitude and phase spread (see the module notes)."""
    _check(tf, covariances)
    z = normal_quantile(confidence)
    omega = np.asarray(omega, dtype=np.float64)
    s = 1j * omega
    a, b = tf.denominators[i][j], tf.numerators[i][j]
    A, B = np.polyval(a, s), np.polyval(b, s)
    G = B / A
    n, m = len(a) - 1, len(b) - 1
    gradient = np.hstack([-(B / A**2)[:, None] * s[:, None] ** (n - np.arange(1, n + 1))[None, :],
                          (1 / A)[:, None] * s[:, None] ** (m - np.arange(m + 1))[None, :]])
    den, num = _entry_slices(tf, i)[j]
    block = covariances[i][np.ix_(np.r_[den, num], np.r_[den, num])]
    with np.errstate(divide="ignore", invalid="ignore"):
        magnitude = np.real(np.conj(G)[:, None] * gradient) / np.abs(G)[:, None]
        phase = np.imag(gradient / G[:, None])
    spread = [np.sqrt(np.maximum(np.einsum("wk,kl,wl->w", part, block, part), 0.0)) for part in (magnitude, phase)]
    return Band(omega, G, spread[0], spread[1], z)


def intervals(tf: TransferFunctionMatrix, covariances: list[np.ndarray], confidence: float = 0.95) -> dict:
    """JSON-able: per entry, every coefficient, pole and zero with its standard deviation and interval."""
    _check(tf, covariances)
    z = normal_quantile(confidence)
    entries = []
    for i, (row_b, row_a) in enumerate(zip(tf.numerators, tf.denominators)):
        for j, ((den, num), a, b) in enumerate(zip(_entry_slices(tf, i), row_a, row_b)):
            covariance = covariances[i]
            entry = {"output": i, "input": j}
            for name, values, where in (("denominator", a[1:], den), ("numerator", b, num)):
                std = np.sqrt(np.maximum(np.diag(covariance)[where], 0.0))
                entry[name] = [{"value": float(v), "std": float(e), "low": float(v - z * e), "high": float(v + z * e)}
                               for v, e in zip(values, std)]
            for name, coefficients, where, leading in (("poles", a, den, True), ("zeros", b, num, False)):
                roots, real_std, imag_std = _root_spread(np.asarray(coefficients), covariance[where, where], leading)
                entry[name] = [{"real": float(r.real), "imag": float(r.imag), "real_std": float(sr),
                                "imag_std": float(si)} for r, sr, si in zip(roots, real_std, imag_std)]
            entries.append(entry)
    return {"confidence": confidence, "z": z, "entries": entries,
            "method": "output-error covariance σ² (JᵀJ)⁻¹ at the optimum; roots and responses to first order"}


def empirical_transfer_function(u: np.ndarray, y: np.ndarray, ts: float, segment: int | None = None
                                ) -> tuple[np.ndarray, np.ndarray]:
    """(ω in rad/s, G (len(ω), ny, nu)): the Welch H1 estimate S_yu S_uu⁻¹ of one record (see the module notes);
    ``segment``: samples per averaged window (default: an eighth of the record, at least 16)."""
    u, y = np.asarray(u, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if u.ndim != 2 or y.ndim != 2 or len(u) != len(y):
        raise IdentificationError(f"empirical transfer function: expected u (N, nu) and y (N, ny), got {u.shape} "
                                  f"and {y.shape}")
    segment = max(16, len(u) // 8) if segment is None else int(segment)
    if len(u) < segment:
        raise IdentificationError(f"empirical transfer function: {len(u)} samples, fewer than one window ({segment})")
    u, y = u - u.mean(axis=0), y - y.mean(axis=0)
    nu, ny = u.shape[1], y.shape[1]

    def cross(a, b):
        import scipy.signal  # only here: it takes a third of a second to import

        return scipy.signal.csd(a, b, fs=1 / ts, nperseg=segment)

    frequency = cross(u[:, 0], u[:, 0])[0]
    inputs = np.empty((len(frequency), nu, nu), dtype=complex)
    outputs = np.empty((len(frequency), ny, nu), dtype=complex)
    for k in range(nu):
        for j in range(nu):
            inputs[:, j, k] = cross(u[:, k], u[:, j])[1]  # S_{u_j u_k}: E[U_j conj(U_k)]
        for i in range(ny):
            outputs[:, i, k] = cross(u[:, k], y[:, i])[1]
    keep = frequency > 0
    response = np.linalg.solve(np.swapaxes(inputs[keep], 1, 2), np.swapaxes(outputs[keep], 1, 2))
    return 2 * np.pi * frequency[keep], np.swapaxes(response, 1, 2)


def bode_figure(response: np.ndarray, omega: np.ndarray, *, band=None, confidence: float = 0.95,
                delays_s: np.ndarray | None = None, measured: tuple[np.ndarray, np.ndarray] | None = None,
                names: tuple[list[str], list[str]] | None = None,
                units: tuple[Sequence[str], Sequence[str]] | None = None) -> Figure:
    """Magnitude (dB, of the output's ``units`` per the input's when given) and phase (degrees) of every entry of ``response`` (len(ω), ny, nu) against ω (rad/s),
    with the ``confidence`` band of ``band(i, j)`` (a :class:`Band`, see :func:`frequency_band`) when given,
    input delays ``delays_s`` (s) not in the response added to the phase, and ``measured`` (ω, G) points of
    :func:`empirical_transfer_function` beside it."""
    from matplotlib.figure import Figure

    _, ny, nu = response.shape
    delays_s = np.zeros(nu) if delays_s is None else np.asarray(delays_s, dtype=np.float64)
    inputs, outputs = names if names is not None else ([f"u{j}" for j in range(nu)], [f"y{i}" for i in range(ny)])
    figure = Figure(figsize=(4.5 * nu, 4.0 * ny), constrained_layout=True)
    axes = figure.subplots(2 * ny, nu, squeeze=False, sharex=True)
    for i in range(ny):
        for j in range(nu):
            magnitude_axis, phase_axis = axes[2 * i, j], axes[2 * i + 1, j]
            G = response[:, i, j]
            phase = np.unwrap(np.angle(G)) - omega * delays_s[j]
            if band is not None:
                spread = band(i, j)
                magnitude, angle = spread.z * spread.magnitude_std, spread.z * spread.phase_std
                low = np.maximum(np.abs(G) - magnitude, np.abs(G) * 1e-6)
                magnitude_axis.fill_between(omega, 20 * np.log10(low), 20 * np.log10(np.abs(G) + magnitude),
                                            alpha=0.3, label=f"{100 * confidence:g} % band")
                phase_axis.fill_between(omega, np.degrees(phase - angle), np.degrees(phase + angle), alpha=0.3)
            magnitude_axis.semilogx(omega, 20 * np.log10(np.abs(G)), label="model")
            phase_axis.semilogx(omega, np.degrees(phase))
            if measured is not None:
                w, H = measured
                magnitude_axis.semilogx(w, 20 * np.log10(np.abs(H[:, i, j])), ".", markersize=3, label="ETFE")
                # each measured phase on the model's branch (the nearest multiple of 360°)
                model_phase = np.interp(w, omega, phase)
                wrapped = model_phase + np.angle(H[:, i, j] * np.exp(-1j * model_phase))
                phase_axis.semilogx(w, np.degrees(wrapped), ".", markersize=3)
            magnitude_axis.set_title(f"{inputs[j]} → {outputs[i]}")
            magnitude_axis.set_ylabel(f"magnitude (dB{gain_unit(units, i, j)})")
            phase_axis.set_ylabel("phase (°)")
            phase_axis.set_xlabel("ω (rad/s)")
            magnitude_axis.grid(True, which="both", alpha=0.3)
            phase_axis.grid(True, which="both", alpha=0.3)
    axes[0, 0].legend(loc="best", fontsize="small")
    return figure


def gain_unit(units: tuple[Sequence[str], Sequence[str]] | None, output: int, input: int) -> str:
    """The unit of the gain from input ``input`` to output ``output`` for a dB axis (" re 1 V/N"); empty
    without units."""
    if units is None or not (units[0][input] or units[1][output]):
        return ""
    return f" re 1 {units[1][output] or '1'}/{units[0][input] or '1'}"


# ------------------------------------------------------------------------------- state-space models


def _state_space_gradient(system: StateSpace, covariance: StateSpaceCovariance, omega: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray]:
    """G(e^{jω ts}) (W, ny, nu) of the discrete ``system`` and its derivatives along the parameters
    (p, W, ny, nu): dG = dC R B + C R dA R B + C R dB + dD, R = (zI - A)⁻¹."""
    dA, dB, dC, dD = covariance.derivatives
    z = np.exp(1j * np.asarray(omega, dtype=np.float64) * system.ts)
    n = system.n_states
    resolvent = np.linalg.inv(z[:, None, None] * np.eye(n) - system.A)
    right, left = resolvent @ system.B, system.C @ resolvent  # R B (W, n, nu), C R (W, ny, n)
    response = system.C @ right + system.D
    gradient = (np.einsum("pyn,wnu->pwyu", dC, right) + np.einsum("wyn,pnm,wmu->pwyu", left, dA, right)
                + np.einsum("wyn,pnu->pwyu", left, dB) + dD[:, None])
    return response, gradient


def _spread(gradient: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    """Standard deviations (W,) of W real quantities with gradients (p, W)."""
    return np.sqrt(np.maximum(np.einsum("pw,pq,qw->w", gradient, covariance, gradient), 0.0))


def state_space_bands(system: StateSpace, covariance: StateSpaceCovariance, omega: np.ndarray,
                      confidence: float = 0.95) -> Callable[[int, int], Band]:
    """``band(i, j)``: entry (i, j)'s discrete response on ``omega`` (rad/s) with its magnitude and phase
    spread, every entry sliced from one computation of the response's gradient."""
    z = normal_quantile(confidence)
    omega = np.asarray(omega, dtype=np.float64)
    response, gradient = _state_space_gradient(system, covariance, omega)

    def band(i: int, j: int) -> Band:
        G, dG = response[:, i, j], gradient[:, :, i, j]
        with np.errstate(divide="ignore", invalid="ignore"):
            magnitude = np.real(np.conj(G) * dG) / np.abs(G)
            phase = np.imag(dG / G)
        return Band(omega, G, _spread(magnitude, covariance.covariance), _spread(phase, covariance.covariance), z)

    return band


def state_space_intervals(system: StateSpace, covariance: StateSpaceCovariance, confidence: float = 0.95,
                          continuous: bool = False) -> dict:
    """JSON-able: every pole (discrete, or continuous s = ln z / ts) with the standard deviations of its real
    and imaginary parts (dλ = (V⁻¹ dA V)_ii, V the eigenvectors of A) and every entry's DC gain with its
    standard deviation and interval."""
    z = normal_quantile(confidence)
    values, vectors = np.linalg.eig(system.A)
    derivatives = np.einsum("in,pnm,mi->pi", np.linalg.inv(vectors), covariance.derivatives[0], vectors)
    if continuous:
        derivatives = derivatives / (values * system.ts)
        values = np.log(values.astype(complex)) / system.ts
    order = np.argsort(-np.abs(values), kind="stable")
    # d|λ| = Re(conj(λ) dλ) / |λ|: how near the unit circle a discrete pole may be
    modulus = np.real(np.conj(values) * derivatives) / np.abs(values)
    poles = [{"real": float(values[k].real), "imag": float(values[k].imag),
              "real_std": float(_spread(derivatives.real[:, [k]], covariance.covariance)[0]),
              "imag_std": float(_spread(derivatives.imag[:, [k]], covariance.covariance)[0])} |
             ({} if continuous else {"modulus_std": float(_spread(modulus[:, [k]], covariance.covariance)[0])})
             for k in order]
    response, gradient = _state_space_gradient(system, covariance, np.zeros(1))
    gains = []
    for i in range(system.n_outputs):
        for j in range(system.n_inputs):
            value = float(response[0, i, j].real)
            std = float(_spread(gradient[:, :, i, j].real, covariance.covariance)[0])
            gains.append({"output": i, "input": j, "value": value, "std": std, "low": value - z * std,
                          "high": value + z * std})
    return {"confidence": confidence, "z": z, "poles": poles, "poles_domain": "continuous" if continuous else
            "discrete", "dc_gains": gains,
            "method": "prediction-error covariance H⁻¹ (Σ Jᵀ W Λ W J) H⁻¹ in local coordinates; poles and "
                      "responses to first order",
            "assumption": "assumes white one-step prediction errors (the Kalman predictor's innovations): the "
                          "residual whiteness test checks it"}
