"""The inverter insertion as a live world: a simulated arm holding part A between two sensorised
fingertips, part B below it, and the chips read one cycle at a time.

Geometry and materials are the inverter protocol's (:func:`softtip.systems.hall_fingertip.experiments.inverter`),
so models trained on that protocol's dataset read this world the way they would read the bench.
The arm's pose is the height (m) of part A's lowest feature above where it first touches part B,
along the approach; the case decides what touches: the lid's seat (``good``), the left clip on
part B's rim (``left-clip``) or the right clip (``right-clip``).
"""

from __future__ import annotations

import numpy as np

from softtip._core.units import MM, UT_PER_T
from softtip.systems.hall_fingertip.engine import HeldPart
from softtip.systems.hall_fingertip.experiments import inverter_contacts, world_up
from softtip.lab.protocols import Protocol
from softtip.systems.hall_fingertip.protocols import fingertip_for
from softtip.systems.hall_fingertip.realism import FabricatedUnit

CASES = {"good": 1, "left-clip": 2, "right-clip": 3}


class SimulatedArm:
    """Moves its pose toward a commanded pose at a set speed, one control period at a time."""

    def __init__(self, pose: float):
        self.pose = np.array([pose])

    def move_toward(self, pose: np.ndarray, speed: float, dt: float) -> None:
        step = np.asarray(pose, float) - self.pose
        distance = float(np.linalg.norm(step))
        self.pose = self.pose + (step if distance <= speed * dt else step / distance * speed * dt)

    def stop(self) -> None:
        """The simulated arm has no momentum: it stands still until told to move."""

    def current_pose(self) -> np.ndarray:
        return self.pose.copy()


class InsertionWorld:
    def __init__(self, protocol: Protocol, case: str, rng: np.random.Generator):
        if case not in CASES:
            raise ValueError(f"case = {case!r}: expected one of {', '.join(CASES)}")
        p = protocol.parameters
        self.state = CASES[case]
        fingertip = fingertip_for(protocol.design, p)
        self.part = HeldPart.grasp(fingertip, p.grip_depth_mm * MM, p.part_thickness_mm * MM)
        self.points, self.seat = inverter_contacts(p)[self.state]
        self.normal = world_up(p.tilt_y_deg, 0.0)
        self.units = (FabricatedUnit(protocol.design, protocol.realism, rng),
                      FabricatedUnit(protocol.design, protocol.realism, rng))
        self.rng = rng
        self.noise = protocol.realism.noise
        self.baseline = np.zeros(12)

    def absolute_uT(self, pose: float) -> np.ndarray:
        """What the four chips read (µT, absolute) with part A at height ``pose`` (m)."""
        travel = np.array([max(0.0, -pose)])
        out = self.part.collide(self.points, self.normal, -self.normal, travel, self.seat)
        readings = []
        for k, unit in enumerate(self.units):
            field = unit.field(out[f"magnets_{k}"])
            readings.append(unit.sensor.acquire(field, self.rng).values
                            if self.noise else field * UT_PER_T)
        self.force = float(out["contact_forces"].sum())
        return np.concatenate(readings, axis=1).ravel()

    def take_baseline(self, pose: float, samples: int = 10) -> None:
        """The initial value, averaged over a few readings in the air after grasping."""
        self.baseline = np.mean([self.absolute_uT(pose) for _ in range(samples)], axis=0)

    def reader(self, arm: SimulatedArm):
        return lambda: self.absolute_uT(float(arm.current_pose()[0])) - self.baseline
