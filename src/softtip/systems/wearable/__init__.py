"""The wearable fingertip-force sensor (S2): a 3-axis tactile chip on the side of the nail, held by a
ring - the finger pad's mechanics and a person's force, the calibration protocol on its twin, the
study of identified transfer-function and state-space models, the emulated chip live and its demo.

Importing this package loads only its registration record (:data:`SYSTEM`).
"""

from softtip._core.systems import Study, System
from softtip.systems.wearable.reading import FORCE

SYSTEM = System(
    name="wearable",
    title="A 3-axis force chip on the side of the nail: fingertip force without covering the pad",
    label="S2",
    package=__name__,
    readings=(FORCE,),
    benches={"wearable": "softtip.systems.wearable.bench:BENCH"},
    protocols={"wearable": "wearable"},
    studies=(
        Study("wearable", "wearable", "softtip.systems.wearable.study:wearable",
              "S2: fingertip force from the side of the nail, transfer-function and state-space models per "
              "participant", sets={"contacts": ["flat", "curved", "edge", "point"]},
              because="the authors' extension: calibrate on flat contact, test on curved, edge and point contacts"),
    ),
    scenarios={"wearable": "softtip.systems.wearable.live:wearable_scenario"},
    demos={"wearable": "softtip.systems.wearable.commands:demo_wearable"},
    defaults={"scenario": "wearable"},
)
