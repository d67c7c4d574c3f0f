"""Table collection, simulated as the real procedure runs: each configuration driven, held, and read
by the 6-axis sensors averaged over the end of the hold, with their noise at their sampling rate.

The servos travel between configurations at their slew rate from their next command frame
(:func:`~.device.move_time`); each configuration is then held ``hold_s`` (published: 1 s) and the
last ``window_s`` (0.2 s) of readings at 1 kHz are averaged. The time a real collection takes is the
sum of the travels and holds, in the order the configurations are driven.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from softtip._core.config import PositiveNumber, Refusal, checked, instance, integer, schema
from softtip.sensors.wrench import NANO17_WRENCH, WrenchSensorSpec, held_wrench
from softtip.systems.haptics.device import DeviceSpec, move_time, quantised
from softtip.systems.haptics.fingertips import Fingertip, loaded_contact, platform_wrench


@schema(section="collection")
class CollectionSettings:
    """How each configuration is held and read (s), and the sensor (FS, DS and test sensors alike)."""

    hold_s: PositiveNumber = 1.0
    window_s: PositiveNumber = 0.2
    sensor: instance(WrenchSensorSpec) = NANO17_WRENCH

    def __post_init__(self) -> None:
        if self.window_s > self.hold_s:
            raise Refusal("window_s", f"expected at most hold_s = {self.hold_s} s")


def motor_grid(device: DeviceSpec, levels: int) -> np.ndarray:
    """``levels``³ motor inputs (rad, (levels³, 3)) evenly over every servo's range, in the order
    driven: the last servo fastest, each sweep reversing (a boustrophedon, so no long return)."""
    levels = checked(integer(2), "levels", levels)
    steps = np.linspace(0.0, device.angle_max, levels)
    rows = []
    for i in range(levels):
        for j_index in range(levels):
            j = j_index if i % 2 == 0 else levels - 1 - j_index
            sweep = steps if (i * levels + j_index) % 2 == 0 else steps[::-1]
            rows.append(np.column_stack([np.full(levels, steps[i]), np.full(levels, steps[j]), sweep]))
    return np.vstack(rows)


@dataclass(frozen=True)
class Collection:
    """A collected table: motor inputs (entries, 3, rad), the fingertip's sensor's readings and the
    DS's (entries, 6), where either saturated (entries,), and how long a real collection takes (s)."""

    motor_inputs: np.ndarray
    finger_wrenches: np.ndarray
    platform_wrenches: np.ndarray
    saturated: np.ndarray
    duration_s: float

    def unsaturated(self) -> Collection:
        """The entries no sensor saturated on: a saturated reading is the range's end, not the force,
        so it has no place in a table. The collection's time is still the whole procedure's."""
        keep = ~self.saturated
        return replace(self, motor_inputs=self.motor_inputs[keep], finger_wrenches=self.finger_wrenches[keep],
                       platform_wrenches=self.platform_wrenches[keep], saturated=self.saturated[keep])


def collection_duration(device: DeviceSpec, motor_inputs, hold_s: float) -> float:
    """Seconds a real collection of ``motor_inputs`` (in order, from the released configuration) takes."""
    motor_inputs = np.asarray(motor_inputs, dtype=float)
    path = np.vstack([np.zeros((1, 3)), quantised(device, motor_inputs)])
    return float(move_time(device, path[:-1], path[1:]).sum() + hold_s * len(motor_inputs))


def _driven(device: DeviceSpec, fingertip: Fingertip, motor_inputs: np.ndarray):
    """The platform's pose with ``motor_inputs`` commanded (the servos reach their quantised angles,
    the cables stretch under their load) and the wrench it applies to the fingertip."""
    return loaded_contact(fingertip, device, quantised(device, motor_inputs))


def sensed_contact(device: DeviceSpec, fingertip: Fingertip, motor_inputs, settings: CollectionSettings,
                   rng: np.random.Generator | None) -> Collection:
    """Drive ``motor_inputs`` (entries, 3) on ``fingertip`` and read its sensor and the DS as the
    procedure does (``rng`` None: exact readings)."""
    motor_inputs = np.asarray(motor_inputs, dtype=float)
    pose, on_finger = _driven(device, fingertip, motor_inputs)
    on_platform = platform_wrench(fingertip, device, pose, on_finger)
    finger_reading, finger_saturated = held_wrench(on_finger, settings.sensor, settings.window_s, rng)
    platform_reading, platform_saturated = held_wrench(on_platform, settings.sensor, settings.window_s, rng)
    return Collection(motor_inputs, finger_reading, platform_reading,
                      finger_saturated.any(axis=-1) | platform_saturated.any(axis=-1),
                      collection_duration(device, motor_inputs, settings.hold_s))


def sensed_by_fingertip(device: DeviceSpec, fingertip: Fingertip, motor_inputs, settings: CollectionSettings,
                        rng: np.random.Generator | None) -> tuple[np.ndarray, np.ndarray]:
    """What the sensor under ``fingertip`` alone reads (entries, 6) with ``motor_inputs`` held, and
    where it saturated (entries,): a rendering's result, which no DS reads."""
    _, on_finger = _driven(device, fingertip, np.asarray(motor_inputs, dtype=float))
    reading, saturated = held_wrench(on_finger, settings.sensor, settings.window_s, rng)
    return reading, saturated.any(axis=-1)
