"""The adaptive user table: its budget, its choices, and its worth beside a grid of the same size."""

from __future__ import annotations

import numpy as np
import pytest

from softtip.systems.haptics.adaptive import adaptive_user_table
from softtip.systems.haptics.collection import CollectionSettings, motor_grid, sensed_contact
from softtip.systems.haptics.device import load_device
from softtip.systems.haptics.fingertips import FINGERTIP_SENSOR, TEST_FINGERTIPS
from softtip.systems.haptics.personalisation import personalise_data_driven
from softtip.systems.haptics.rendering import NearestNeighbourRenderer

DEVICE = load_device()
SETTINGS = CollectionSettings()


@pytest.fixture(scope="module")
def fs_and_targets():
    rng = np.random.default_rng(7)
    fs = sensed_contact(DEVICE, FINGERTIP_SENSOR, motor_grid(DEVICE, 13), SETTINGS, rng).unsaturated()
    draws = sensed_contact(DEVICE, FINGERTIP_SENSOR, rng.uniform(0, DEVICE.angle_max, (3000, 3)), SETTINGS, rng)
    touching = (np.linalg.norm(draws.finger_wrenches[:, :3], axis=1) > 5 / 320) & ~draws.saturated
    return fs, draws.finger_wrenches[touching][:100]


def median_error(fs, targets, fingertip, user) -> float:
    personal = personalise_data_driven(DEVICE, fs.motor_inputs, fs.platform_wrenches, user.motor_inputs,
                                       user.platform_wrenches)
    motor = NearestNeighbourRenderer().fit(fs.finger_wrenches, personal.motor_inputs).predict(targets)
    produced = sensed_contact(DEVICE, fingertip, motor, SETTINGS, None)
    return float(np.median(np.linalg.norm(targets[:, :3] - produced.finger_wrenches[:, :3], axis=1)))


@pytest.mark.parametrize("fingertip", [TEST_FINGERTIPS[0], TEST_FINGERTIPS[2]], ids=lambda f: f.name)
def test_adaptive_table_beats_a_grid_of_its_size(fs_and_targets, fingertip):
    fs, targets = fs_and_targets
    rng = np.random.default_rng(1)
    adaptive = adaptive_user_table(DEVICE, fingertip, fs.motor_inputs, fs.platform_wrenches, SETTINGS, rng)
    table = adaptive.collection
    assert len(table.motor_inputs) == 64 == sum(adaptive.batches) and adaptive.batches[0] == 27
    assert len(np.unique(table.motor_inputs, axis=0)) == 64  # no configuration driven twice
    grid = sensed_contact(DEVICE, fingertip, motor_grid(DEVICE, 4), SETTINGS, rng)  # 4³ = 64 as well
    # measured on the fitted device: 0.81 (small cast) and 0.90 (large cast) of the grid's median error
    assert median_error(fs, targets, fingertip, table) < 0.95 * median_error(fs, targets, fingertip, grid)
    assert table.duration_s < 0.3 * sensed_contact(DEVICE, fingertip, motor_grid(DEVICE, 7), SETTINGS, None).duration_s


def test_budget_below_the_first_grid_is_refused(fs_and_targets):
    fs, _ = fs_and_targets
    with pytest.raises(ValueError, match="budget = 20: expected at least the first grid's 27"):
        adaptive_user_table(DEVICE, TEST_FINGERTIPS[1], fs.motor_inputs, fs.platform_wrenches, SETTINGS, None,
                            budget=20)
