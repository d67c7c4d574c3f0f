"""The demo's force scores: over every sample, rests included, and the estimate where nothing touches."""

from __future__ import annotations

import numpy as np
import pytest

from softtip.systems.hall_fingertip.force_model import force_errors, phase_errors


def test_the_demo_scores_every_sample_and_the_estimate_at_rest_by_hand():
    truth = np.array([0.0, 0.0, 0.0, 0.0, 1.0, 2.0])
    estimate = np.array([0.1, -0.1, 0.3, 0.1, 1.5, 2.0])
    scores = force_errors(truth, estimate)
    # |errors| 0.1 0.1 0.3 0.1 0.5 0 -> 1.1 / 6; at rest the four first: mean 0.1,
    # deviations 0, -0.2, 0.2, 0: spread sqrt(0.08 / 4)
    assert scores["mean_abs_error_N"] == pytest.approx(1.1 / 6)
    assert scores["rest_mean_N"] == pytest.approx(0.1)
    assert scores["rest_sd_N"] == pytest.approx(np.sqrt(0.08 / 4))
    # a reference force below 0.05 N is rest; a stream that never rests has no rest figures
    assert force_errors(np.array([0.04, 1.0]), np.array([0.0, 1.0]))["rest_mean_N"] == 0.0
    assert np.isnan(force_errors(np.array([1.0]), np.array([1.0]))["rest_sd_N"])


def test_the_demo_splits_its_errors_by_phase_by_hand():
    # rest, rest, up, up, held (neither), down, rest; errors 0.1 0.3 0.2 0.4 0.5 0.6 0.1
    truth = np.array([0.0, 0.01, 1.0, 2.0, 2.0, -1.0, 0.0])
    estimate = truth + np.array([0.1, -0.3, 0.2, -0.4, 0.5, 0.6, 0.1])
    phases = phase_errors(truth, estimate)
    assert phases["rest_mean_abs_error_N"] == pytest.approx(0.5 / 3) and phases["rest_share"] == pytest.approx(3 / 7)
    assert phases["loading_mean_abs_error_N"] == pytest.approx(0.3) and phases["loading_share"] == pytest.approx(2 / 7)
    # a shear's force falls in magnitude from 2 to 1 N whatever its sign: unloading
    assert phases["unloading_mean_abs_error_N"] == pytest.approx(0.6) and phases["unloading_share"] == pytest.approx(1 / 7)


@pytest.mark.slow
def test_the_demo_reads_zero_at_rest_within_its_noise_and_live_as_offline():
    from softtip.systems.hall_fingertip.demo import run_main_demo

    result = run_main_demo(seed=1, dashboard=False)
    offline, live = result["calibration"]["validation"]["fz_N"], result["live"]["fz_N"]
    # at rest the normal force reads zero within 0.6 of the estimate's own spread there (the chips' noise
    # through the model): measured offline 0.04 +- 0.23 N, live 0.07 +- 0.17 N (0.43 of it); the network
    # fitted without its anchor read 0.24 +- 0.20 N offline and 0.25 +- 0.15 N live
    for scores in (offline, live):
        assert abs(scores["rest_mean_N"]) <= 0.6 * scores["rest_sd_N"]
    # live, every sample counted: 0.154 N against 0.094 N on the validation trials (1.6 times). The live
    # stream holds what the validation trials do not: rests for 39 % of its samples, where the error is the
    # noise (0.147 N), releases for 33 % (0.166 N: the calibration has none, and the material's hysteresis
    # lowers the force on the way back at the same deformation), and pushes four times the calibration's speed
    assert live["mean_abs_error_N"] <= 1.8 * offline["mean_abs_error_N"]
