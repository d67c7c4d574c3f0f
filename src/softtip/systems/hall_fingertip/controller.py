"""Feedback control of an insertion from the fingertips' contact state (S1 §3).

The published loop: grasp part A -> take the baseline -> move to the initial insertion pose ->
tilt the flange -> load the trained models -> move toward the target pose; at every cycle estimate
the contact state; in state 2 or 3 (a clip on part B's rim: a false insertion) stop and move back
to the initial insertion pose; the task is done when the target pose is reached.

The controller only needs a :class:`Robot` (move toward a pose, stop, current pose) and a
``read()`` returning the chips' readings with the baseline subtracted; it works the same on the
simulated robot of :mod:`softtip.systems.hall_fingertip.insertion_world` and on a real arm behind the same three calls.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

FALSE_STATES = (2, 3)


class Robot(Protocol):
    def move_toward(self, pose: np.ndarray, speed: float, dt: float) -> None: ...
    def stop(self) -> None: ...
    def current_pose(self) -> np.ndarray: ...


@dataclass
class Decision:
    cycle: int
    time_s: float
    pose: list[float]
    state: int
    probabilities: list[float]
    force_N: float
    action: str


@dataclass
class InsertionController:
    robot: Robot
    read: Callable[[], np.ndarray]  # (channels,) µT, baseline subtracted
    state_model: object  # predict_proba over states 0-3 (classes_)
    force_model: object  # predict -> normal force (N)
    initial_pose: np.ndarray
    target_pose: np.ndarray
    speed: float = 2e-3  # m/s
    period_s: float = 0.02  # the control cycle (50 Hz, the sensors' rate)
    persistence: int = 2  # cycles a false state must last before the arm stops
    tolerance: float = 1e-5  # m: the target is reached
    max_cycles: int = 5000
    log: list[Decision] = field(default_factory=list)

    def run(self) -> dict:
        """Move toward the target until it is reached or a false insertion is detected."""
        classes = list(np.asarray(self.state_model.classes_).tolist())
        streak, outcome, detected, force_at = 0, "timeout", None, None
        for cycle in range(self.max_cycles):
            x = self.read()
            probabilities = self._proba(x)
            state = int(classes[int(np.argmax(probabilities))])
            force = float(np.ravel(self._force(x))[0])
            pose = self.robot.current_pose()
            streak = streak + 1 if state in FALSE_STATES else 0
            if streak >= self.persistence:
                self.robot.stop()
                outcome, detected, force_at = "retracted", state, force
                self._log(cycle, pose, state, probabilities, force, "stop and retract")
                self._retract()
                break
            if np.linalg.norm(pose - self.target_pose) <= self.tolerance:
                outcome, detected, force_at = "completed", state, force
                self._log(cycle, pose, state, probabilities, force, "target reached")
                break
            self._log(cycle, pose, state, probabilities, force, "approach")
            self.robot.move_toward(self.target_pose, self.speed, self.period_s)
        return {"outcome": outcome, "state_detected": detected, "force_at_detection_N": force_at,
                "cycles": len(self.log)}

    def _proba(self, x: np.ndarray) -> np.ndarray:
        one = getattr(self.state_model, "predict_proba_one", None)
        return np.asarray(one(x) if one else self.state_model.predict_proba(x[None])[0])

    def _force(self, x: np.ndarray):
        one = getattr(self.force_model, "predict_one", None)
        return one(x) if one else self.force_model.predict(x[None])

    def _retract(self) -> None:
        for _ in range(self.max_cycles):
            if np.linalg.norm(self.robot.current_pose() - self.initial_pose) <= self.tolerance:
                return
            self.robot.move_toward(self.initial_pose, self.speed, self.period_s)

    def _log(self, cycle, pose, state, probabilities, force, action) -> None:
        self.log.append(Decision(cycle=cycle, time_s=cycle * self.period_s, pose=[float(v) for v in pose],
                                 state=state, probabilities=[round(float(p), 4) for p in probabilities],
                                 force_N=round(force, 4), action=action))
