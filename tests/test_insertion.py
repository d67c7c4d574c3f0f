"""The insertion loop on the simulated arm: it completes a good insertion and retracts from both
false ones, with models trained on the inverter protocol (a coarse, small version of it)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from softtip.lab import load_protocol
from softtip.systems.hall_fingertip.controller import InsertionController
from softtip.systems.hall_fingertip.insertion_world import InsertionWorld, SimulatedArm
from softtip.systems.hall_fingertip.realism import Realism
from softtip.systems.hall_fingertip.insertion import INITIAL_HEIGHT, TARGET_DEPTH, run_insertion


@pytest.fixture(scope="module")
def protocol():
    # the shipped protocol: its calibration trials train the models
    return load_protocol("inverter").changed(validation_trials=0, untrained_trials=0)


@pytest.fixture(scope="module")
def insertion(protocol):
    """One run of each case, made when first asked for (the first trains the models: over a minute)."""
    runs = {}

    def run(case: str) -> dict:
        if case not in runs:
            runs[case] = run_insertion(case, protocol=protocol)
        return runs[case]

    return run


@pytest.mark.slow
def test_a_good_insertion_reaches_the_target(insertion):
    result = insertion("good")
    assert result["outcome"] == "completed" and result["decisions"][-1]["action"] == "target reached"
    assert result["final_pose_mm"] == pytest.approx(-TARGET_DEPTH * 1e3)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "the seated lid is read as in the air. Measured (the same run without fabrication tolerances): the "
    "state-1 calibration window (0.3-0.5 N) holds 14 samples, two a trial (the lid crosses it in 0.04 s at "
    "5 mm/s and 50 Hz), against 178 in the air; the target pose (0.6 mm) loads the seat with 0.56 N, beyond "
    "the window. Noiseless the classifier reads state 1 there (p = 0.96) but state 3 at 0.75 N, and one noisy "
    "reading at the target tips it to state 0 (p = 0.90)"))
def test_at_the_target_the_seated_lid_is_detected(insertion):
    assert insertion("good")["state_detected"] == 1


@pytest.mark.slow
@pytest.mark.parametrize("case, state", [("left-clip", 2), ("right-clip", 3)])
def test_a_false_insertion_is_stopped_early_and_retracted(protocol, insertion, case, state):
    result = insertion(case)
    assert result["outcome"] == "retracted" and result["state_detected"] == state
    assert result["decisions"][-1]["action"] == "stop and retract"
    assert result["final_pose_mm"] == pytest.approx(INITIAL_HEIGHT * 1e3)
    # it stopped early: less than two thirds of the way from the first touch (pose 0) to the target, and
    # below two thirds of the force the clip on the rim takes at the target (measured: 0.53 and 0.40 of
    # the way at 0.53 and 0.40 of that force)
    world = InsertionWorld(protocol, case, np.random.default_rng(0))
    world.absolute_uT(-TARGET_DEPTH)
    assert -2 / 3 * TARGET_DEPTH < result["decisions"][-1]["pose"][0] < 0
    assert 0 < result["true_force_at_decision_N"] < 2 / 3 * world.force


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


@pytest.mark.slow
def test_the_emulated_insertion_replays_the_three_cases_with_both_fingertips(protocol):
    from softtip.systems.hall_fingertip.scenarios import insertion_scenario

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


@pytest.mark.slow
def test_the_left_and_right_clip_cases_are_mirror_images(protocol):
    """The clips sit at x = -30 and +30 mm of the part, the flange's tilt keeps the approach in the
    part's y-z plane, the pads' magnets and chips sit at x = -6 and +6 mm and both pads' frames keep
    the part's x axis: the two clip cases are mirror images through x = 0. All magnets are
    polarised along +z, so in the mirror image chip 0 reads what chip 1 of the other case reads with
    Bx reversed (mirroring a z-polarised magnet and the point it is seen from through x = 0 turns its
    field (Bx, By, Bz) into (-Bx, By, Bz)).

    Only the nominal fingertips are mirror images: with fabrication tolerances (0.1 mm magnet and chip
    placement, 2 % magnetisation) chip 0 and chip 1 of a unit differ, and most in Bz: a chip midway
    between two magnets along y, which the clip's push moves along y, sees Bz change only to second
    order of the motion, so a 0.1 mm offset changes Bz by as much as the push does (at the peak force
    chip 2 reads -11.5 µT in the left case, chip 3 -4.4 µT in the right). Realism is therefore off."""
    from softtip.systems.hall_fingertip.scenarios import insertion_scenario

    nominal = insertion_scenario(replace(protocol, realism=Realism.off()), seed=1)
    thirds = np.array_split(np.arange(len(nominal.times_s)), 3)
    left, right = (nominal.field_uT[rows] - nominal.field_uT[0] for rows in thirds[1:])
    # every sample of the stroke, to the asymmetry of the unstructured mesh: the pads' stiffness matrices
    # are mirror symmetric to 1e-4 of their largest term, the forces to 0.1 %, the field change to 4 %
    # or 0.2 µT
    assert nominal.force_N[thirds[1], 2].max() > 1.0
    np.testing.assert_allclose(nominal.force_N[thirds[1]], nominal.force_N[thirds[2]], rtol=2e-3)
    mirror = np.array([-1.0, 1.0, 1.0])
    np.testing.assert_allclose(left[:, [0, 2]], right[:, [1, 3]] * mirror, rtol=0.05, atol=0.2)
    np.testing.assert_allclose(left[:, [1, 3]], right[:, [0, 2]] * mirror, rtol=0.05, atol=0.2)
