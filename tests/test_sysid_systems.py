"""State-space systems: subspace identification, refinement, conversions, simulation, prediction, streaming,
each against an independent reference (the true system, nfoursid, scipy, python-control, brute force)."""

from __future__ import annotations

import time

import control
import numpy as np
import pandas as pd
import pytest
import scipy.linalg
import scipy.signal
from nfoursid.nfoursid import NFourSID

from softtip.sysid.realisation import realise
from softtip.sysid import refine as refine_module
from softtip.sysid.refine import _Predictor, refine
from softtip.sysid.simulation import StreamingSimulator, predict, simulate, state_sequence
from softtip.sysid.statespace import IdentificationError, StateSpace
from softtip.sysid.subspace import METHODS, _kalman_gain, order_from_singular_values, subspace_identify


def _known_system(seed=1) -> StateSpace:
    """Four states (poles 0.9, 0.7, 0.5 ± 0.3j) in a random basis, two inputs, two outputs."""
    rng = np.random.default_rng(seed)
    modal = np.array([[0.9, 0, 0, 0], [0, 0.7, 0, 0], [0, 0, 0.5, 0.3], [0, 0, -0.3, 0.5]])
    basis = rng.normal(size=(4, 4))
    return StateSpace(basis @ modal @ np.linalg.inv(basis), rng.normal(size=(4, 2)), rng.normal(size=(2, 4)),
                      rng.normal(size=(2, 2)), 1.0)


# an innovations gain of the known system whose predictor A - KC is stable (largest pole modulus 0.89)
GAIN = 0.2 * np.array([[0.2, -0.1], [0.0, 0.3], [0.1, 0.1], [-0.2, 0.0]])


def _innovations_data(system: StateSpace, K: np.ndarray, noise: float, samples: int, seed: int):
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(samples, system.n_inputs))
    e = noise * rng.normal(size=(samples, system.n_outputs))
    states = state_sequence(system.A, u @ system.B.T + e @ K.T, np.zeros(system.n_states))
    return u, states @ system.C.T + u @ system.D.T + e, e


@pytest.mark.parametrize("method", METHODS)
def test_subspace_recovers_a_known_system_from_noise_free_trials(method):
    true = _known_system()
    rng = np.random.default_rng(2)
    segments = []
    for _ in range(3):  # three trials, each from a state of its own
        u = rng.normal(size=(300, 2))
        segments.append((u, simulate(true, u, rng.normal(size=4))))
    found = subspace_identify(segments, 1.0, "auto", method)
    assert found.order == 4
    np.testing.assert_allclose(np.sort_complex(found.system.poles()), np.sort_complex(true.poles()), atol=1e-9)
    np.testing.assert_allclose(found.system.markov_parameters(20), true.markov_parameters(20), atol=1e-9)


def test_subspace_agrees_with_nfoursid_on_the_same_noisy_data():
    true = StateSpace(np.array([[0.95, 0.2, 0], [0, 0.8, 0], [0, 0, 0.6]]), [[1, 0], [0.5, 1], [0, 1]],
                      [[1, 0, 1], [0, 1, -1]], np.zeros((2, 2)), 1.0)
    K = np.array([[0.3, 0.1], [0, 0.2], [0.1, -0.2]])
    u, y, _ = _innovations_data(true, K, 0.3, 4000, seed=3)
    frame = pd.DataFrame(np.hstack([u, y]), columns=["u0", "u1", "y0", "y1"])
    reference = NFourSID(frame, output_columns=["y0", "y1"], input_columns=["u0", "u1"], num_block_rows=10)
    reference.subspace_identification()
    theirs, _ = reference.system_identification(rank=3)
    theirs = StateSpace(theirs.a, theirs.b, theirs.c, theirs.d, 1.0)
    ours = subspace_identify([(u, y)], 1.0, 3, "moesp", horizon=10).system  # nfoursid is PO-MOESP
    poles = np.sort(ours.poles().real)
    np.testing.assert_allclose(poles, np.sort(theirs.poles().real), atol=0.01)
    np.testing.assert_allclose(poles, [0.6, 0.8, 0.95], atol=0.02)
    omega = np.linspace(0.01, 3.0, 40)
    ours_g, theirs_g = ours.frequency_response(omega), theirs.frequency_response(omega)
    assert np.max(np.abs(ours_g - theirs_g)) < 0.05 * np.max(np.abs(theirs_g))


def test_the_kalman_gain_solves_the_riccati_equation_like_python_control():
    rng = np.random.default_rng(0)
    A, C = np.diag([0.9, 0.5, -0.3]), rng.normal(size=(2, 3))
    covariance = scipy.linalg.block_diag(np.diag([1.0, 0.5, 0.2]), np.diag([0.3, 0.4]))
    K, innovations, _ = _kalman_gain(A, C, covariance, 1.0)
    L, P, _ = control.dlqe(A, np.eye(3), C, covariance[:3, :3], covariance[3:, 3:])
    np.testing.assert_allclose(K, L, rtol=1e-9)
    np.testing.assert_allclose(innovations, C @ P @ C.T + covariance[3:, 3:], rtol=1e-9)


def test_the_kalman_predictor_predicts_an_innovations_model_exactly_one_step_ahead():
    true = _known_system()
    K = GAIN
    u, y, e = _innovations_data(true, K, 0.5, 500, seed=4)
    with_gain = StateSpace(true.A, true.B, true.C, true.D, 1.0, K)
    assert np.max(np.abs(np.linalg.eigvals(true.A - K @ true.C))) < 0.9
    np.testing.assert_allclose(y - predict(with_gain, u, y, 1), e, atol=1e-10)


def test_k_step_prediction_against_a_brute_force_predictor():
    true = _known_system()
    K = GAIN
    u, y, _ = _innovations_data(true, K, 0.5, 60, seed=5)
    system = StateSpace(true.A, true.B, true.C, true.D, 1.0, K)
    k = 4
    expected = np.empty_like(y)
    for t in range(len(y)):  # filter up to t - k, then run the model alone to t
        x = np.zeros(4)
        for s in range(t + 1):
            if s <= t - k:
                x = true.A @ x + true.B @ u[s] + K @ (y[s] - true.C @ x - true.D @ u[s])
            elif s < t:
                x = true.A @ x + true.B @ u[s]
        expected[t] = true.C @ x + true.D @ u[t]
    np.testing.assert_allclose(predict(system, u, y, k), expected, atol=1e-10)
    np.testing.assert_allclose(predict(system, u, y, 10_000), simulate(system, u), atol=1e-12)


def test_simulation_agrees_with_scipy_dlsim_and_python_control():
    system = _known_system()
    rng = np.random.default_rng(6)
    u, x0 = rng.normal(size=(200, 2)), rng.normal(size=4)
    ours = simulate(system, u, x0)
    _, scipy_y, _ = scipy.signal.dlsim((system.A, system.B, system.C, system.D, 1.0), u, x0=x0)
    np.testing.assert_allclose(ours, scipy_y, atol=1e-12)
    response = control.forced_response(control.ss(system.A, system.B, system.C, system.D, 1.0),
                                       np.arange(200), u.T, x0)
    np.testing.assert_allclose(ours, response.outputs.T, atol=1e-12)


def test_zero_order_hold_matches_python_control_and_the_matrix_logarithm_inverts_it():
    rng = np.random.default_rng(7)
    A = np.array([[-1.0, 2.0, 0], [-2.0, -1.0, 0], [0, 0, -5.0]])
    continuous = StateSpace(A, rng.normal(size=(3, 2)), rng.normal(size=(2, 3)), rng.normal(size=(2, 2)))
    discrete = continuous.to_discrete(0.1)
    reference = control.sample_system(control.ss(continuous.A, continuous.B, continuous.C, continuous.D), 0.1, "zoh")
    np.testing.assert_allclose(discrete.A, reference.A, atol=1e-12)
    np.testing.assert_allclose(discrete.B, reference.B, atol=1e-12)
    back = discrete.to_continuous()
    for name in "ABCD":
        np.testing.assert_allclose(getattr(back, name), getattr(continuous, name), atol=1e-9)
    np.testing.assert_allclose(np.sort_complex(discrete.poles()), np.sort_complex(np.exp(continuous.poles() * 0.1)))
    with pytest.raises(IdentificationError, match="a pole at -0.5 on the negative real axis"):
        StateSpace(np.diag([-0.5, 0.3]), np.ones((2, 1)), np.ones((1, 2)), np.zeros((1, 1)), 0.1).to_continuous()


def test_a_transfer_function_matrix_realised_as_state_space_has_its_frequency_response():
    rng = np.random.default_rng(8)
    numerators = [[[0.0, 2.0, 1.0, 30.0], [4.0]], [[1.0, 3.0, 2.0, 5.0], [0.0, 0.0]]]
    denominators = [[np.poly(-rng.uniform(1, 50, 3)), [1.0, 2.0]], [np.poly([-1, -2 + 3j, -2 - 3j]).real, [1.0, 4.0, 3.0]]]
    system = realise(numerators, denominators)
    assert system.n_states == 3 + 1 + 3  # the zero entry adds no state
    omega = np.logspace(-1, 2, 9)
    expected = np.array([[np.polyval(numerators[i][j], 1j * omega) / np.polyval(denominators[i][j], 1j * omega)
                          for j in range(2)] for i in range(2)]).transpose(2, 0, 1)
    np.testing.assert_allclose(system.frequency_response(omega), expected, rtol=1e-10, atol=1e-12)
    single = scipy.signal.StateSpace(*scipy.signal.tf2ss(numerators[1][0], denominators[1][0]))
    _, y_reference, _ = scipy.signal.lsim(single, np.ones(50), np.arange(50) * 0.1)
    y = simulate(system.to_discrete(0.1), np.column_stack([np.ones(50), np.zeros(50)]))
    np.testing.assert_allclose(y[:, 1], y_reference, rtol=1e-6, atol=1e-9)  # lsim: linear interpolation = ZOH for steps


def test_streaming_equals_batch_simulation_and_starts_again_on_reset():
    system = realise([[[1.0, 2.0], [3.0]], [[0.5, 1.0, 0.1], [1.0, 0.0]]],
                     [[[1.0, 3.0, 2.0], [1.0, 1.0]], [[1.0, 2.0, 5.0], [1.0, 4.0]]]).to_discrete(0.1)
    u = np.random.default_rng(9).normal(size=(400, 2))
    batch = simulate(system, u)
    stream = StreamingSimulator(system)
    frames = np.array([stream.step(row) for row in u])
    full_scale = np.ptp(batch, axis=0)
    assert np.max(np.abs(frames - batch) / full_scale) < 1e-9
    stream.reset()
    np.testing.assert_array_equal(stream.state, 0)
    np.testing.assert_allclose(np.array([stream.step(row) for row in u[:10]]), batch[:10], atol=1e-12)


@pytest.mark.realtime
def test_a_streaming_step_of_an_order_10_3x3_model_takes_under_50_microseconds_at_p99():
    rng = np.random.default_rng(10)
    A = rng.normal(size=(10, 10))
    system = StateSpace(0.9 * A / np.max(np.abs(np.linalg.eigvals(A))), rng.normal(size=(10, 3)),
                        rng.normal(size=(3, 10)), rng.normal(size=(3, 3)), 0.1)
    stream = StreamingSimulator(system)
    frames = rng.normal(size=(20_000, 3))
    for frame in frames[:1000]:
        stream.step(frame)
    times = np.empty(len(frames))
    for k, frame in enumerate(frames):
        start = time.perf_counter_ns()
        stream.step(frame)
        times[k] = time.perf_counter_ns() - start
    assert np.percentile(times, 99) / 1e3 <= 50


def test_the_refinement_jacobian_is_exact_and_refinement_recovers_a_perturbed_model():
    true = _known_system()
    K = GAIN
    segments = [_innovations_data(true, K, 0.2, 600, seed)[:2] for seed in (11, 12)]
    scale = np.std(np.vstack([y for _, y in segments]), axis=0)
    problem = _Predictor(segments, 4, scale)
    start = StateSpace(0.9 * true.A, true.B, true.C, true.D, 1.0, 0.5 * K)
    theta = problem.pack(start)
    steps = 1e-6 * np.eye(theta.size)
    numeric = np.array([(problem.residuals(theta + h) - problem.residuals(theta - h)) / 2e-6 for h in steps]).T
    np.testing.assert_allclose(problem.jacobian(theta), numeric, atol=1e-7)
    refined, report = refine(start, segments, max_iterations=100, tolerance=1e-10)
    assert report.used and report.cost_after < 0.2 * report.cost_before
    np.testing.assert_allclose(np.sort_complex(refined.poles()), np.sort_complex(true.poles()), atol=0.03)
    np.testing.assert_allclose(refined.noise_covariance, 0.04 * np.eye(2), atol=0.006)


def test_the_refinement_runs_the_predictor_once_per_parameter_vector(monkeypatch):
    true = _known_system()
    segments = [_innovations_data(true, GAIN, 0.2, 300, seed)[:2] for seed in (21, 22)]
    problem = _Predictor(segments, 4, np.ones(2))
    runs, original = [], refine_module.state_sequence
    monkeypatch.setattr(refine_module, "state_sequence", lambda A, drive, x0: runs.append(len(drive)) or original(A, drive, x0))
    theta = problem.pack(StateSpace(0.9 * true.A, true.B, true.C, true.D, 1.0, 0.5 * GAIN))
    problem.residuals(theta)
    problem.jacobian(theta)
    assert len(runs) == 2  # the errors' states serve the Jacobian: one run per trial
    problem.jacobian(theta + 1e-3)
    assert len(runs) == 4


def test_a_refinement_cut_short_reports_that_it_did_not_converge():
    true = _known_system()
    segments = [_innovations_data(true, np.zeros((4, 2)), 0.2, 400, 13)[:2]]
    start = StateSpace(0.8 * true.A, true.B, true.C, true.D, 1.0, np.zeros((4, 2)))
    _, report = refine(start, segments, max_iterations=2)
    assert not report.converged and "without converging" in report.message


def test_the_order_rule_takes_the_largest_drop_in_the_singular_values():
    assert order_from_singular_values(np.array([10, 5, 4, 0.1, 0.05, 0.04]), 5) == 3
    assert order_from_singular_values(np.array([10, 0.1, 0.09, 0.001, 0.0009]), 2) == 1
