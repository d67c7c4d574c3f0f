"""A magnetic whisker over an Infineon TLV493D 3-D Hall sensor: softtip's example of a system of a lab's
own, installed as a package of its own (docs: the package's README).

Importing this package loads only its registration record (:data:`SYSTEM`).
"""

from softtip.plugin import Study, System

SYSTEM = System(
    name="whisker",
    title="A steel whisker rocking a magnet on silicone over a TLV493D: the tip's sideways force",
    label="W1",
    package=__name__,
    benches={"whisker": "softtip_whisker.bench:BENCH"},
    protocols={"whisker-sweep": "whisker"},
    studies=(Study("whisker", "whisker-sweep", "softtip_whisker.study:whisker",
                   "W1: the tip's force from the TLV493D's field; the chip's output step and noise beside its "
                   "data sheet",
                   # three directions are the fewest that span the plane the force map is fitted in
                   quick={"calibration_trials": 3}),),
    scenarios={"whisker": "softtip_whisker.live:whisker_scenario"},
    sensors={"tlv493d": "softtip_whisker.tlv493d:SENSOR"},
)
