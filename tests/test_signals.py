"""Signal kernels against loops worked by hand."""

from __future__ import annotations

import numpy as np
import pytest

from softtip._core.signals import hysteresis_percent


def test_hysteresis_of_a_hand_made_loop():
    # loading (F, z): (0, 0) (3, 2) (7, 6) (10, 10); unloading: (6, 8) (2, 3) (0, 0). Mid force 5:
    # Z_up = 2 + (5 − 3)/(7 − 3)·(6 − 2) = 4, Z_down = 8 + (6 − 5)/(6 − 2)·(3 − 8) = 6.75 -> 2.75 / 10
    force = np.array([0.0, 3, 7, 10, 6, 2, 0])
    sensor_z = np.array([0.0, 2, 6, 10, 8, 3, 0])
    assert hysteresis_percent(sensor_z, force) == pytest.approx(27.5, abs=1e-12)
    # the mid force is midway between the minimum and the maximum; the scale and sign of Z do not matter
    assert hysteresis_percent(-3 * sensor_z, force + 2) == pytest.approx(27.5, abs=1e-12)


def test_hysteresis_averages_the_crossings_of_a_noisy_branch():
    # loading crosses F = 5 three times: (4→6, z 4→5) at 4.5, (6→4.5, z 5→5.2) at 5 + 2/3·0.2,
    # (4.5→5.5, z 5.2→5.6) at 5.4; unloading passes through (5, 7) exactly
    force = np.array([0.0, 4, 6, 4.5, 5.5, 10, 5, 0])
    sensor_z = np.array([0.0, 4, 5, 5.2, 5.6, 10, 7, 0])
    z_up = (4.5 + (5 + 2 / 3 * 0.2) + 5.4) / 3
    assert hysteresis_percent(sensor_z, force) == pytest.approx(abs(z_up - 7) / 10 * 100, abs=1e-12)


def test_hysteresis_refuses_what_is_not_a_cycle():
    with pytest.raises(ValueError, match="never reaches the mid force"):
        hysteresis_percent(np.array([3.0, 2, 1, 0]), np.array([10.0, 8, 4, 0]))  # unloading only
    with pytest.raises(ValueError, match="same length"):
        hysteresis_percent(np.zeros(5), np.zeros(4))
