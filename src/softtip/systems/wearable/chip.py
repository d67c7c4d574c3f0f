"""The wearable's sensors: the side chip (a 3-axis tactile chip on the side of the nail, its reading
in N, streamed live) and the table's reference force sensor.

:data:`TACTILE_CHIP` is a MEMS 3-axis tactile chip of the ShokacChip class (Touchence): pressure on
its z axis, shear on x and y. No datasheet of the chip was available to us; its figures are
assumptions for a piezoresistive MEMS chip of that class read by a 12-bit converter: pressure 0–5 N
(a compression-only axis: the chip cannot be pulled), shear ±2.5 N, so one step of
5 N / 4096 = 1.22 mN on every axis, and 2 mN RMS noise.

Channel ``side_f{x|y|z}_N`` is its axis (a second chip would be ``side1_f...``); its readings are
recorded and published as ``geometry_msgs/WrenchStamped`` on ``chip{k}/force`` (torque NaN).
"""

from softtip._core.channels import Reading
from softtip._core.units import FORCE_UNITS
from softtip.sensors.force_sensor import NANO17, ForceSensor, ForceSensorSpec

FORCE = Reading("force", "N", "F", "N", prefix="side", infix="f", units=FORCE_UNITS, drift_threshold=0.05,
                baseline_step=1e-4, decimals=3, topic="force", message="geometry_msgs/msg/WrenchStamped",
                first_numbered=False)
TACTILE_CHIP = ForceSensorSpec(
    name="ShokacChip-class MEMS 3-axis tactile chip", lowest=(-2.5, -2.5, 0.0), highest=(2.5, 2.5, 5.0),
    resolution=(5.0 / 4096,) * 3, noise=(2e-3,) * 3,
    source="assumed: no datasheet available; a 12-bit reading of a 5 N span per axis, 2 mN RMS noise")
CHIP = ForceSensor(TACTILE_CHIP, FORCE)

# the table's reference sensor under the object: it labels the calibration and is not streamed
TABLE = Reading("table force", "N", "F", "N", prefix="table", infix="f", units=FORCE_UNITS, drift_threshold=0.05,
                baseline_step=1e-4, decimals=3, topic="force", message="geometry_msgs/msg/WrenchStamped",
                first_numbered=False)
TABLE_SENSOR = ForceSensor(NANO17, TABLE)
