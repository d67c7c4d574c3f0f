"""The wearable's sensors: the side chip (a 3-axis tactile chip on the side of the nail, its reading
in N, streamed live) and the table's reference force sensor.

:data:`TACTILE_CHIP` is a MEMS 3-axis tactile chip of the ShokacChip class (Touchence): pressure on
its z axis, shear on x and y. No datasheet of the chip was available to us; its figures are
assumptions for a piezoresistive MEMS chip of that class read by a 12-bit converter: pressure 0–5 N
(a compression-only axis: the chip cannot be pulled), shear ±2.5 N, so one step of
5 N / 4096 = 1.22 mN on every axis, and 2 mN RMS noise.

Its reading, :data:`~softtip.systems.wearable.reading.FORCE`, and the table sensor's are declared in
:mod:`softtip.systems.wearable.reading`.
"""

from softtip.sensors.force_sensor import NANO17, ForceSensor, ForceSensorSpec
from softtip.systems.wearable.reading import FORCE, TABLE

TACTILE_CHIP = ForceSensorSpec(
    name="ShokacChip-class MEMS 3-axis tactile chip", lowest=(-2.5, -2.5, 0.0), highest=(2.5, 2.5, 5.0),
    resolution=(5.0 / 4096,) * 3, noise=(2e-3,) * 3,
    source="assumed: no datasheet available; a 12-bit reading of a 5 N span per axis, 2 mN RMS noise")
CHIP = ForceSensor(TACTILE_CHIP, FORCE)

# the table's reference sensor under the object: it labels the calibration and is not streamed
TABLE_SENSOR = ForceSensor(NANO17, TABLE)
