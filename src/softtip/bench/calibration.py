"""Speed of the calibration models, each figure beside a baseline measured in the same run.

Measured for a 6-20-2 network (two 3-axis sensors -> orientation and grip force):
single-sample latency of ``LMNetwork.predict_one`` (median and 99th percentile), batch
throughput of ``LMNetwork.predict``, and Levenberg–Marquardt training time on 20,000
samples. Baselines: scikit-learn's ``MLPRegressor.predict`` on one sample and in batch, and
``PolynomialFit`` (the published third-order polynomial), plus the published per-estimate
times (82 ms network, 108 ms polynomial). Batch figures run with BLAS on one thread for
every model alike.
"""

from __future__ import annotations

import os
import platform
import warnings

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.metrics import r2_score
from sklearn.neural_network import MLPRegressor

from softtip._core.threads import single_threaded_blas
from softtip.bench.timing import best_of, latency, timed
from softtip.calibration import LMNetwork, PolynomialFit

PUBLISHED_NETWORK_S = 82e-3
PUBLISHED_POLYNOMIAL_S = 108e-3
NOISE_UT = 2.0  # sensor noise of the readings, of the order of the MLX90393's at moderate gain


def calibration_data(n_samples: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Smooth synthetic calibration set: orientation (deg) and grip force (N) -> two sensors' field changes (µT).

    The readings are a smooth nonlinear function of the two targets and of an unobserved
    contact position, as on the fingertip, with sensor noise; the network must invert it.
    """
    angle = rng.uniform(0, 30, n_samples)
    force = rng.uniform(2, 10, n_samples)  # grasped: without force the orientation leaves no trace
    position = rng.uniform(-1, 1, (n_samples, 2))
    a, f = np.radians(angle), force / 10
    readings = np.column_stack([
        400 * f * np.sin(a) + 60 * position[:, 0] * f,
        300 * f * np.cos(2 * a) * (1 + 0.2 * position[:, 1]),
        900 * np.tanh(1.5 * f) * (1 + 0.1 * np.sin(a)),
        -380 * f * np.sin(a) + 50 * position[:, 1] * f,
        280 * f * np.cos(2 * a) * (1 - 0.2 * position[:, 0]),
        850 * np.tanh(1.4 * f) * (1 + 0.1 * np.cos(a)),
    ])
    return readings + rng.normal(0, NOISE_UT, readings.shape), np.column_stack([angle, force])


def throughput(predict, inputs: np.ndarray, repeats: int = 3) -> float:
    """Samples per second of ``predict`` on a batch, BLAS on one thread."""
    with single_threaded_blas():
        return len(inputs) / best_of(lambda: predict(inputs), repeats)


def bench_calibration(calls: int = 20_000, batch_samples: int = 1_000_000, train: int = 20_000) -> dict:
    """Single-sample latency, batch throughput and training time of a 6-20-2 network beside
    scikit-learn's MLPRegressor, the published polynomial and the published per-estimate times."""
    rng = np.random.default_rng(0)
    x, y = calibration_data(train, rng)
    x_test, y_test = calibration_data(5_000, rng)

    network, training_s = timed(LMNetwork((20,), random_state=0).fit, x, y)
    epochs = len(network.history_["train"]) - 1
    polynomial = PolynomialFit().fit(x, y)
    with warnings.catch_warnings():  # its speed, not its accuracy, is the baseline here
        warnings.simplefilter("ignore", ConvergenceWarning)
        mlp = MLPRegressor(hidden_layer_sizes=(20,), activation="tanh", max_iter=20, random_state=0).fit(x, y)

    sample = x_test[0].copy()
    one = {
        "lm_network_predict_one": latency(network.predict_one, sample, calls),
        "polynomial_predict_one": latency(polynomial.predict_one, sample, calls),
        "mlp_regressor_predict": latency(lambda s: mlp.predict(s[None, :]), sample, calls // 4),
        "lm_network_predict": latency(lambda s: network.predict(s[None, :]), sample, calls // 4),
    }
    batch = calibration_data(batch_samples, rng)[0]
    per_second = {
        "lm_network": throughput(network.predict, batch),
        "mlp_regressor": throughput(mlp.predict, batch),
        "polynomial": throughput(polynomial.predict, batch),
    }
    ours = one["lm_network_predict_one"]["median_us"] * 1e-6
    report = {
        "machine": {"cpus": os.cpu_count(), "processor": platform.processor() or platform.machine(),
                    "numpy": np.__version__},
        "network": "6-20-2, tanh hidden, linear outputs",
        "single_sample_latency": one,
        "batch_samples_per_s": per_second,
        "training": {
            "samples": train, "seconds": training_s, "epochs": epochs, "stop_reason": network.stop_reason_,
            "ms_per_epoch": 1e3 * training_s / max(epochs, 1),
            "held_out_r2": [float(v) for v in r2_score(y_test, network.predict(x_test), multioutput="raw_values")],
            "polynomial_held_out_r2": [float(v) for v in
                                       r2_score(y_test, polynomial.predict(x_test), multioutput="raw_values")],
        },
        "ratios": {
            "mlp_predict_over_predict_one": one["mlp_regressor_predict"]["median_us"] * 1e-6 / ours,
            "polynomial_predict_one_over_network_predict_one": one["polynomial_predict_one"]["median_us"] * 1e-6 / ours,
            "published_network_over_predict_one": PUBLISHED_NETWORK_S / ours,
            "published_polynomial_over_polynomial_predict_one":
                PUBLISHED_POLYNOMIAL_S / (one["polynomial_predict_one"]["median_us"] * 1e-6),
            "batch_network_over_mlp": per_second["lm_network"] / per_second["mlp_regressor"],
        },
    }
    return report
