"""Continuous-time transfer-function identification against independent references: scipy.signal's
and python-control's ZOH discretisations, exact ZOH recursions worked by hand, known systems."""

from __future__ import annotations

import control
import numpy as np
import pytest
from scipy import signal

from softtip.sysid import transfer
from softtip.sysid.statespace import IdentificationError
from softtip.sysid.transfer import TransferFunctionMatrix, fit, simulate

TS = 0.1


def _pair(natural: float, damping: float) -> list[complex]:
    pole = complex(-damping * natural, natural * np.sqrt(1 - damping**2))
    return [pole, pole.conjugate()]


def _known_system() -> tuple[list, list]:
    """3 x 3, six poles per entry, all distinct: two real poles and a well damped pair with time
    constants 0.2-0.4 s (a few sample times), a lightly damped pair (damping 0.2, natural frequency
    3-5 rad/s); five zeros, all stable and none near a pole."""
    numerators, denominators = [], []
    for i in range(3):
        numerators.append([]), denominators.append([])
        for j in range(3):
            poles = (_pair(3.0 + 0.7 * i + 0.4 * j, 0.2) + _pair(6.0 + 0.5 * i - 0.3 * j, 0.6)
                     + [-2.5 - 0.3 * i - 0.2 * j, -4.5 + 0.25 * i + 0.35 * j])
            zeros = [-1.2 - 0.1 * i, -5.2 + 0.2 * j, -7.0 - 0.5 * (i + j)] + _pair(3.6 + 0.1 * i, 0.55 + 0.02 * j)
            denominator, numerator = np.poly(poles).real, np.poly(zeros).real
            gain = (1.0 + 0.3 * i - 0.2 * j) * (-1) ** (i + j) * denominator[-1] / numerator[-1]
            numerators[-1].append(gain * numerator)
            denominators[-1].append(denominator)
    return numerators, denominators


def _scipy_response(numerators, denominators, u: np.ndarray, ts: float = TS) -> np.ndarray:
    """y from scipy.signal: each entry to a state-space model, cont2discrete (ZOH), dlsim, summed."""
    y = np.zeros((len(u), len(numerators)))
    for i, (row_b, row_a) in enumerate(zip(numerators, denominators)):
        for j, (b, a) in enumerate(zip(row_b, row_a)):
            discrete = signal.cont2discrete(signal.tf2ss(b, a), ts, method="zoh")
            y[:, i] += signal.dlsim(discrete[:4] + (ts,), u[:, j])[1][:, 0]
    return y


def _multilevel(rng, samples: int, inputs: int) -> np.ndarray:
    """Random levels in [-1, 1] held for 1-3 samples."""
    holds = rng.integers(1, 4, size=samples)
    levels = rng.uniform(-1.0, 1.0, size=(samples, inputs))
    return np.repeat(levels, holds, axis=0)[:samples]


def _prbs(rng, samples: int) -> np.ndarray:
    return np.where(rng.random(samples) < 0.5, -1.0, 1.0)


def _relative_error(model: TransferFunctionMatrix, numerators, denominators, omega: np.ndarray) -> np.ndarray:
    truth = TransferFunctionMatrix(numerators, denominators).frequency_response(omega)
    return np.abs(model.frequency_response(omega) - truth) / np.abs(truth)


# ------------------------------------------------------------------------------------------ simulate


def _small_system() -> tuple[list, list]:
    """2 x 2 of orders 3, 2 / 3, 3; the last entry biproper, one lightly damped pair."""
    numerators = [[[1.0, 2.0], [3.0]], [[0.5, 1.0, 2.0], [1.0, 0.0, 1.0, 1.0]]]
    denominators = [[np.poly([-2, -3 + 4j, -3 - 4j]).real, np.poly([-1.0, -5.0])],
                    [np.poly([-2.0, -3.0, -4.0]), np.poly([-1.0, -0.5 + 3j, -0.5 - 3j]).real]]
    return numerators, denominators


def test_simulate_agrees_with_scipy_and_python_control():
    numerators, denominators = _small_system()
    u = np.random.default_rng(1).standard_normal((700, 2))
    y = simulate(TransferFunctionMatrix(numerators, denominators), u, TS)
    by_scipy = _scipy_response(numerators, denominators, u)
    by_control = np.zeros_like(y)
    for i, (row_b, row_a) in enumerate(zip(numerators, denominators)):
        for j, (b, a) in enumerate(zip(row_b, row_a)):
            by_control[:, i] += control.forced_response(control.c2d(control.tf(b, a), TS, "zoh"), U=u[:, j]).outputs
    scale = np.abs(by_scipy).max()
    assert np.abs(y - by_scipy).max() < 1e-10 * scale
    assert np.abs(y - by_control).max() < 1e-10 * scale


def test_a_long_record_is_simulated_in_chunks(monkeypatch):
    numerators, denominators = _small_system()
    u = np.random.default_rng(8).standard_normal((500, 2))
    monkeypatch.setattr(transfer, "_CHUNK", 37)
    y = simulate(TransferFunctionMatrix(numerators, denominators), u, TS)
    reference = _scipy_response(numerators, denominators, u)
    assert np.abs(y - reference).max() < 1e-10 * np.abs(reference).max()


def test_first_order_against_the_exact_zoh_recursion():
    # G = K/(s + p): y[k+1] = e^{-p ts} y[k] + K/p (1 - e^{-p ts}) u[k]; (b1 s + b0)/(s + p) adds
    # b1 u[k] to the response of (b0 - b1 p)/(s + p)
    gain, pole, b1 = 2.5, 3.0, 0.7
    u = _multilevel(np.random.default_rng(2), 400, 1)
    decay = np.exp(-pole * TS)
    strictly = np.zeros(len(u))
    for k in range(len(u) - 1):
        strictly[k + 1] = decay * strictly[k] + gain / pole * (1 - decay) * u[k, 0]
    model = TransferFunctionMatrix([[[gain]]], [[[1.0, pole]]])
    assert np.abs(simulate(model, u, TS)[:, 0] - strictly).max() < 1e-13
    b0 = gain + b1 * pole  # (b1 s + b0)/(s + p) = b1 + K/(s + p)
    biproper = TransferFunctionMatrix([[[b1, b0]]], [[[1.0, pole]]])
    assert np.abs(simulate(biproper, u, TS)[:, 0] - (strictly + b1 * u[:, 0])).max() < 1e-13

    fitted, report = fit([(u, strictly[:, None])], TS, 1)
    assert report.converged
    assert fitted.denominators[0][0] == pytest.approx([1.0, pole], rel=1e-9)
    assert fitted.numerators[0][0] == pytest.approx([gain], rel=1e-9)
    fitted, report = fit([(u, (strictly + b1 * u[:, 0])[:, None])], TS, 1, n_zeros=1)
    assert report.converged
    assert fitted.numerators[0][0] == pytest.approx([b1, b0], rel=1e-9)


def test_transfer_function_matrix_against_scipy():
    numerators, denominators = _small_system()
    model = TransferFunctionMatrix(numerators, denominators)
    omega = np.linspace(0.0, 40.0, 57)
    response = model.frequency_response(omega)
    assert response.shape == (57, 2, 2) and model.shape == (2, 2)
    for i in range(2):
        for j in range(2):
            assert np.allclose(response[:, i, j], signal.freqs(numerators[i][j], denominators[i][j], omega)[1],
                               rtol=1e-12, atol=0)
            assert np.sort_complex(model.poles()[i][j]) == pytest.approx(np.sort_complex(np.roots(denominators[i][j])))
    assert np.array_equal(model.n_poles, [[3, 2], [3, 3]]) and np.array_equal(model.n_zeros, [[1, 0], [2, 3]])
    assert model.dc_gain() == pytest.approx(response[0].real)
    assert model.is_stable()
    assert not TransferFunctionMatrix([[[1.0]]], [[[1.0, -0.1]]]).is_stable()
    with pytest.raises(ValueError, match=r"^denominators\[0\]\[0\]: expected a monic"):
        TransferFunctionMatrix([[[1.0]]], [[[2.0, 1.0]]])
    with pytest.raises(ValueError, match=r"^numerators\[0\]\[0\]: degree 2 exceeds"):
        TransferFunctionMatrix([[[1.0, 0.0, 0.0]]], [[[1.0, 1.0]]])


# ------------------------------------------------------------------------------------------------ fit


@pytest.fixture(scope="module")
def noise_free_fit():
    numerators, denominators = _known_system()
    rng = np.random.default_rng(3)
    segments = []
    for _ in range(3):
        u = np.column_stack([_multilevel(rng, 500, 2), _prbs(rng, 500)])
        segments.append((u, _scipy_response(numerators, denominators, u)))
    return numerators, denominators, *fit(segments, TS, 6)


def test_noise_free_data_give_the_system_back(noise_free_fit):
    numerators, denominators, model, report = noise_free_fit
    assert report.converged and report.reflected_poles == 0
    assert np.all(report.per_output_fit_percent > 100 - 1e-6)
    assert np.array_equal(model.n_poles, np.full((3, 3), 6)) and np.array_equal(model.n_zeros, np.full((3, 3), 5))
    for i in range(3):
        for j in range(3):
            found, true = np.sort_complex(model.poles()[i][j]), np.sort_complex(np.roots(denominators[i][j]))
            assert np.abs(found - true).max() < 1e-6 * np.abs(true).min()
    omega = np.linspace(0.0, np.pi / TS, 300)  # up to the Nyquist frequency
    assert _relative_error(model, numerators, denominators, omega).max() < 1e-6


def test_srivc_alone_gives_noise_free_systems_back():
    # the Rao-Garnier benchmark (4th order, two resonances, a non-minimum-phase zero) from a PRBS
    # held 15 samples at 100 Hz: SRIVC converges on its own, without the refinement
    u = np.repeat(_prbs(np.random.default_rng(9), 270), 15)[:4000, None]
    numerator, denominator = [-6400.0, 1600.0], [1.0, 5.0, 408.0, 416.0, 1600.0]
    y = _scipy_response([[numerator]], [[denominator]], u, ts=0.01)
    model, report = fit([(u, y)], 0.01, 4, 1, refine=False)
    assert report.converged and report.iterations == 0
    assert model.numerators[0][0] == pytest.approx(numerator, rel=1e-8)
    assert model.denominators[0][0] == pytest.approx(denominator, rel=1e-8)
    # 2 x 2, a denominator of its own per entry: the backfitting converges on its own too
    numerators = [[[2.0, 3.0], [-1.0, 4.0]], [[0.5, 6.0], [1.0, 1.0]]]
    denominators = [[np.poly(_pair(3.0, 0.3)).real, np.poly([-1.0, -4.0])],
                    [np.poly([-2.0, -6.0]), np.poly(_pair(5.0, 0.5)).real]]
    rng = np.random.default_rng(10)
    inputs = [_multilevel(rng, 300, 2) for _ in range(2)]
    model, report = fit([(v, _scipy_response(numerators, denominators, v)) for v in inputs], TS, 2, refine=False)
    assert report.converged and report.srivc_iterations > 1
    assert _relative_error(model, numerators, denominators, np.linspace(0.0, np.pi / TS, 200)).max() < 1e-6


def test_the_error_shrinks_as_the_data_grow():
    # white output noise, about 30 dB below the outputs: four times the data about halve the typical
    # relative error of the frequency response (from the lowest frequency one 50 s segment resolves
    # to the Nyquist frequency), averaged over three noise and input draws
    numerators, denominators = _known_system()
    omega = np.linspace(2 * np.pi / 50.0, np.pi / TS, 200)
    errors = {2: [], 8: []}
    for seed in range(3):
        rng = np.random.default_rng(10 + seed)
        segments = []
        for _ in range(8):
            u = np.column_stack([_multilevel(rng, 500, 2), _prbs(rng, 500)])
            y = _scipy_response(numerators, denominators, u)
            segments.append((u, y + 0.1 * rng.standard_normal(y.shape)))
        for count, found in errors.items():
            model, report = fit(segments[:count], TS, 6)
            assert report.converged and model.is_stable()
            found.append(np.median(_relative_error(model, numerators, denominators, omega)))
    small, large = np.mean(errors[2]), np.mean(errors[8])
    assert small < 0.03
    assert large < 0.7 * small


def test_per_entry_orders():
    # entries of orders 1, 2 / 3, 2 with 0, 1 / 2, 2 zeros (the last biproper)
    numerators = [[[2.0], [1.0, 3.0]], [[0.5, 1.0, 4.0], [1.0, 0.4, 9.0]]]
    denominators = [[[1.0, 2.0], np.poly(_pair(4.0, 0.3)).real],
                    [np.poly([-2.0] + _pair(5.0, 0.5)).real, np.poly([-1.5, -6.0])]]
    rng = np.random.default_rng(4)
    # two trials of different lengths
    segments = [(u, _scipy_response(numerators, denominators, u)) for u in (_multilevel(rng, 300, 2),
                                                                            _multilevel(rng, 220, 2))]
    model, report = fit(segments, TS, np.array([[1, 2], [3, 2]]), np.array([[0, 1], [2, 2]]))
    assert report.converged
    assert np.array_equal(model.n_poles, [[1, 2], [3, 2]]) and np.array_equal(model.n_zeros, [[0, 1], [2, 2]])
    omega = np.linspace(0.0, np.pi / TS, 200)
    assert _relative_error(model, numerators, denominators, omega).max() < 1e-8


def test_unstable_estimates_are_reflected_and_reported():
    # the data come from 2/(s - 0.5); 8 s from rest grow about e^4
    u = _multilevel(np.random.default_rng(5), 80, 1)
    y = _scipy_response([[[2.0]]], [[[1.0, -0.5]]], u)
    model, report = fit([(u, y)], TS, 1, enforce_stability=False)
    assert model.poles()[0][0] == pytest.approx([0.5], rel=1e-8)
    assert not model.is_stable() and report.reflected_poles == 0 and "unstable" in report.message
    model, report = fit([(u, y)], TS, 1)
    assert model.is_stable() and report.reflected_poles == 1 and "mirrored" in report.message
    # refined among stable models from the mirror image b/(s + 0.5), b by least squares: no worse than it
    mirrored = _scipy_response([[[1.0]]], [[[1.0, 0.5]]], u)
    gain = np.linalg.lstsq(mirrored, y, rcond=None)[0]
    assert report.cost <= 0.5 * np.sum((y - gain * mirrored) ** 2)


def test_the_report_scores_the_returned_model():
    # the cost and MATLAB's NRMSE fit, over both trials together, from scipy's simulation of the model
    numerators, denominators = _small_system()
    rng = np.random.default_rng(6)
    segments = []
    for samples in (400, 300):
        u = rng.standard_normal((samples, 2))
        y = _scipy_response(numerators, denominators, u)
        segments.append((u, y + 0.05 * rng.standard_normal(y.shape)))
    model, report = fit(segments, TS, np.array([[3, 2], [3, 3]]), np.array([[1, 0], [2, 3]]))
    assert report.converged
    y = np.concatenate([y for _, y in segments])
    simulated = np.concatenate([_scipy_response(model.numerators, model.denominators, u) for u, _ in segments])
    assert report.cost == pytest.approx(0.5 * np.sum((y - simulated) ** 2), rel=1e-9)
    expected = 100 * (1 - np.linalg.norm(y - simulated, axis=0) / np.linalg.norm(y - y.mean(axis=0), axis=0))
    assert report.per_output_fit_percent == pytest.approx(expected, rel=1e-9)
    # the simulation error is minimised: the returned model fits at least as well as the true system
    truth = np.concatenate([_scipy_response(numerators, denominators, u) for u, _ in segments])
    assert np.all(report.per_output_fit_percent
                  >= 100 * (1 - np.linalg.norm(y - truth, axis=0) / np.linalg.norm(y - y.mean(axis=0), axis=0)))

    _, capped = fit(segments, TS, np.array([[3, 2], [3, 3]]), max_iterations=2)
    assert not capped.converged and "did not converge" in capped.message


@pytest.mark.parametrize(("call", "argument"), [
    (lambda u, y: fit([(u, y)], 0.0, 2), "ts"),
    (lambda u, y: fit([(u, y)], -0.1, 2), "ts"),
    (lambda u, y: fit([(u, y)], float("nan"), 2), "ts"),
    (lambda u, y: fit([(np.where(np.arange(100)[:, None] == 5, np.nan, u), y)], TS, 2), r"segments\[0\]"),
    (lambda u, y: fit([(u[:, 0], y)], TS, 2), r"segments\[0\]"),
    (lambda u, y: fit([(u, y[:-1])], TS, 2), r"segments\[0\]"),
    (lambda u, y: fit([(u, y), (u[:, :1], y)], TS, 2), r"segments\[1\]"),
    (lambda u, y: fit([(u, y)], TS, 2, 3), "n_zeros"),
    (lambda u, y: fit([(u, y)], TS, 0), "n_poles"),
    (lambda u, y: fit([(u, y)], TS, 2.5), "n_poles"),
    (lambda u, y: fit([(u, y)], TS, np.ones((3, 3), dtype=int)), "n_poles"),
    (lambda u, y: fit([(u[:4], y[:4])], TS, 2), "segments"),
    (lambda u, y: fit([(np.column_stack([u[:, 0], np.ones(100)]), y)], TS, 2), "segments"),
    (lambda u, y: fit([], TS, 2), "segments"),
    (lambda u, y: fit([(u, y)], TS, 2, max_iterations=0), "max_iterations"),
    (lambda u, y: fit([(u, y)], TS, 2, tolerance=0.0), "tolerance"),
    (lambda u, y: simulate(TransferFunctionMatrix([[[1.0]]], [[[1.0, 1.0]]]), u, TS), "u"),
])
def test_bad_arguments_get_one_line_naming_them(call, argument):
    rng = np.random.default_rng(7)
    u, y = rng.standard_normal((100, 2)), rng.standard_normal((100, 1))
    with pytest.raises(ValueError, match=f"^{argument}") as raised:
        call(u, y)
    assert "\n" not in str(raised.value)


@pytest.mark.parametrize(("segment", "message"), [
    (lambda u, y: (u[:4], y[:4]), r"^segments: 4 samples in all, fewer than the 8 parameters of one output's model$"),
    (lambda u, y: (np.column_stack([u[:, 0], np.full(100, 2.0)]), y),
     r"^segments: input 1 is constant \(2\) in every segment: expected a signal that varies$"),
])
def test_data_that_cannot_identify_the_model_is_an_identification_error(segment, message):
    rng = np.random.default_rng(7)
    u, y = rng.standard_normal((100, 2)), rng.standard_normal((100, 1))
    with pytest.raises(IdentificationError, match=message):
        fit([segment(u, y)], TS, 2)
