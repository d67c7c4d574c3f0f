"""What makes the wearable bench's experiments look like real ones, with the source of every number.

On by default; each effect can be switched off (set to 0) in the protocol's ``[realism]`` table.
The bench: a person's fingertip on a table force sensor, a tactile chip held against the side of the
nail by a ring (:mod:`softtip.systems.wearable.fingerpad`, :mod:`softtip.systems.wearable.human_force`).
Nothing here is tuned to make a result look better.
"""

from __future__ import annotations

from softtip._core.config import Flag, NonNegativeNumber, schema
from softtip.lab.bench import RealismTable

REALISM_SOURCES = {
    "noise": "each sensor's noise and output step (softtip.sensors.force_sensor: the Nano17's datasheet; the "
             "chip's class figures, assumed)",
    "finger_width_sd_mm": "per participant, around the protocol's breadth; every length of the pad scales with it: "
                          "adult distal index breadths spread by about 1 mm (hand anthropometry)",
    "pad_stiffness_sd": "per participant, log-normal factor on b: in-vivo fingerpad responses vary widely between "
                        "people (Gulati & Srinivasan, MIT RLE TR 605, 1997: five subjects)",
    "friction_sd": "per participant, added to the protocol's coefficient (kept >= 0.3): skin friction varies with "
                   "moisture and person (Dzidek et al., J. R. Soc. Interface 14, 2017)",
    "ring_preload_sd": "per run (the ring is re-seated), on the clamping force: a ring closed by hand",
    "sensor_position_sd_mm": "per run, the chip's place along the nail: re-seating",
    "placement_sd_mm": "per trial, where the pad first meets the object (x, y)",
    "finger_yaw_sd_deg": "per trial, the finger's axis against the table sensor's axes, aligned by eye",
    "force_tremor": "coefficient of variation of the held force, 1-12 Hz (Galganski et al., J. Neurophysiol. 69, "
                    "1993)",
    "cross_talk": "per press, the direction error on each other axis: a person aiming a force along one axis errs "
                  "by several degrees",
    "stream_skew_ms": "per run, at most, between the chip's and the table's samples: two 10 Hz streams aligned to "
                      "the nearest sample are off by up to half a period",
}


@schema(section="realism")
class WearableRealism(RealismTable):
    """The ``[realism]`` table of the wearable protocol."""

    noise: Flag = True
    finger_width_sd_mm: NonNegativeNumber = 1.0
    pad_stiffness_sd: NonNegativeNumber = 0.3
    friction_sd: NonNegativeNumber = 0.2
    ring_preload_sd: NonNegativeNumber = 0.3
    sensor_position_sd_mm: NonNegativeNumber = 1.0
    placement_sd_mm: NonNegativeNumber = 1.0
    finger_yaw_sd_deg: NonNegativeNumber = 5.0
    force_tremor: NonNegativeNumber = 0.02
    cross_talk: NonNegativeNumber = 0.1
    stream_skew_ms: NonNegativeNumber = 50.0
