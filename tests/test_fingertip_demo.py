"""The demo's force scores: over every sample, rests included, and the estimate where nothing touches."""

from __future__ import annotations

import numpy as np
import pytest

from softtip.systems.hall_fingertip.force_model import force_errors


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
