"""The insertion loop on the simulated arm: it completes a good insertion and retracts from both
false ones, with models trained on the inverter protocol (a coarse, small version of it)."""

from __future__ import annotations

import numpy as np
import pytest

from softtip.lab import load_protocol
from softtip.lab.insertion import SimulatedArm
from softtip.realtime.control import InsertionController
from softtip.studies.insertion import INITIAL_HEIGHT, run_insertion


@pytest.fixture(scope="module")
def protocol():
    protocol = load_protocol("inverter")  # the shipped protocol: its calibration trials train the models
    protocol.parameters.update(validation_trials=0, untrained_trials=0)
    return protocol


@pytest.mark.parametrize("case, outcome, state", [("good", "completed", None), ("left-clip", "retracted", 2),
                                                  ("right-clip", "retracted", 3)])
def test_insertion_cases(protocol, case, outcome, state):
    result = run_insertion(case, protocol=protocol, say=lambda message: None)
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
