"""The insertion loop on the simulated arm: it completes a good insertion and retracts from both
false ones, with models trained on the inverter protocol (a coarse, small version of it)."""

from __future__ import annotations

import numpy as np
import pytest

from softtip.lab import load_protocol
from softtip.lab.insertion import SimulatedArm
from softtip.control.insertion import InsertionController
from softtip.studies.insertion import INITIAL_HEIGHT, run_insertion


@pytest.fixture(scope="module")
def protocol():
    protocol = load_protocol("inverter")  # the shipped protocol: its calibration trials train the models
    protocol.parameters.update(validation_trials=0, untrained_trials=0)
    return protocol


@pytest.mark.parametrize("case, outcome, state", [("good", "completed", None), ("left-clip", "retracted", 2),
                                                  ("right-clip", "retracted", 3)])
def test_insertion_cases(protocol, case, outcome, state):
    result = run_insertion(case, protocol=protocol)
    assert result["outcome"] == outcome
    if state is not None:
        assert result["state_detected"] == state
        # it stopped early: well before the force a full stroke would reach, and back at the start
        assert 0 < result["true_force_at_decision_N"] < 2.0
        assert result["final_pose_mm"] == pytest.approx(INITIAL_HEIGHT * 1e3)
        assert result["decisions"][-1]["action"] == "stop and retract"
    else:
        assert result["final_pose_mm"] == pytest.approx(-0.6)


class _Always:
    """A model that always answers one state, to check the loop's own logic."""

    def __init__(self, state):
        self.classes_ = np.array([0, 1, 2, 3])
        self.state = state

    def predict_proba(self, x):
        return np.eye(4)[[self.state]]

    def predict(self, x):
        return np.array([0.0])


def test_one_false_reading_does_not_stop_the_arm_but_two_do():
    readings = iter([2, 0, 2, 2] + [0] * 1000)
    model = _Always(0)
    model.predict_proba = lambda x: np.eye(4)[[next(readings)]]
    arm = SimulatedArm(1e-3)
    controller = InsertionController(robot=arm, read=lambda: np.zeros(12), state_model=model, force_model=_Always(0),
                                     initial_pose=np.array([1e-3]), target_pose=np.array([0.0]))
    result = controller.run()
    assert result["outcome"] == "retracted" and result["cycles"] == 4
    assert arm.current_pose()[0] == pytest.approx(1e-3)


def test_the_emulated_insertion_replays_the_three_cases_with_both_fingertips(protocol):
    from softtip.lab.scenario import insertion_scenario

    scenario = insertion_scenario(protocol, seed=1)
    assert scenario.field_uT.shape[1:] == (4, 3)
    thirds = np.array_split(np.arange(len(scenario.times_s)), 3)
    rest = scenario.field_uT[0]
    for rows in thirds:
        force = scenario.force_N[rows, 2]
        # in the air at the start and the end of each case, pressed in the middle
        assert force[0] == 0 and force[-1] == 0 and force.max() > 0.3
        change = np.abs(scenario.field_uT[rows] - rest).max()
        assert change > 1.0  # µT: the chips see the part's push
    # the left and right clips are mirror images through the part's x = 0 plane, and so are each pad's
    # two chips (at x = -6 and +6 mm): chip 0 in one case reads chip 1 of the other with Bx reversed
    # (up to the fabrication tolerances of the units)
    left, right = (scenario.field_uT[rows[len(rows) // 2]] - rest for rows in thirds[1:])
    mirror = np.array([-1.0, 1.0, 1.0])
    np.testing.assert_allclose(left[[0, 2]], right[[1, 3]] * mirror, rtol=0.25, atol=0.05 * np.abs(left).max())
