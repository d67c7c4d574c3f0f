"""What the wearable's sensors read, in N: the side chip's reading (streamed) and the table sensor's
(labels only), kept apart from the sensor models so that the registration record
(:data:`softtip.systems.wearable.SYSTEM`) imports nothing heavier.

Channel ``side_f{x|y|z}_N`` is its axis (a second chip would be ``side1_f...``); its readings are
recorded and published as ``geometry_msgs/WrenchStamped`` on ``chip{k}/force`` (torque NaN).
"""

from softtip._core.channels import Reading
from softtip._core.units import FORCE_UNITS


def _force_reading(quantity: str, prefix: str) -> Reading:
    return Reading(quantity, "N", "F", "N", prefix=prefix, infix="f", units=FORCE_UNITS, drift_threshold=0.05,
                   baseline_step=1e-4, decimals=3, topic="force", message="geometry_msgs/msg/WrenchStamped",
                   first_numbered=False)


FORCE = _force_reading("force", "side")
TABLE = _force_reading("table force", "table")
