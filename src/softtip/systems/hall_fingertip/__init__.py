"""The Hall-effect soft fingertips (S1): cylindrical and rectangular elastomer bodies with four
magnets over MLX90393 chips - their shipped designs, the published experiments as protocols on the
twin, the studies that reproduce the publications' figures, the insertion controller, the live
scenarios of the emulated fingertip and the demos.

Importing this package loads only its registration record (:data:`SYSTEM`).
"""

from softtip._core.systems import Study, System

_STUDIES = "softtip.systems.hall_fingertip.studies"

SYSTEM = System(
    name="hall-fingertip",
    title="Hall-effect soft fingertips: one or two MLX90393 chips under four magnets in silicone",
    label="S1",
    package=__name__,
    benches={"fingertip": "softtip.systems.hall_fingertip.protocols:BENCH"},
    protocols=dict.fromkeys(("pushing", "force3", "force-cycles", "hysteresis", "grasp-two", "grasp-positions",
                             "contact-states", "inverter"), "fingertip"),
    studies=(
        Study("pushing", "pushing", f"{_STUDIES}:pushing", "S1 §1: board orientation from one sensor, designs A-D, "
              "polynomial vs network"),
        Study("force3", "force3", f"{_STUDIES}:force3",
              "S1 §1: 3-axis force calibration against a reference force sensor"),
        Study("hysteresis", "hysteresis", f"{_STUDIES}:hysteresis",
              "S1 §2 (the thesis, generation 2): load to 3 mm at 1 mm/s, 3 s rest, unload; hysteresis and sensitivity"),
        Study("grasp-two", "grasp-two", f"{_STUDIES}:grasp_two",
              "S1 §1: board orientation grasped between two fingertips"),
        Study("grasp-positions", "grasp-positions", f"{_STUDIES}:grasp_positions",
              "S1 §2: orientation and grip force at 49 contact positions, trained and untrained"),
        Study("contact-states", "contact-states", f"{_STUDIES}:contact_states",
              "S1 §2: contact states of a grasped thin board"),
        Study("inverter", "inverter", f"{_STUDIES}:inverter",
              "S1 §2: contact states of the inverter assembly, detection force"),
    ),
    scenarios={"push": "softtip.systems.hall_fingertip.live:push_scenario",
               "insertion": "softtip.systems.hall_fingertip.live:insertion_scenario"},
    demos={"insertion": "softtip.systems.hall_fingertip.commands:demo_insertion"},
    commands={"fingertip": "softtip.systems.hall_fingertip.commands:app"},
    sensors={"mlx90393": "softtip.sensors.mlx90393:SENSOR"},
    defaults={"simulate": "cylindrical-A", "bench": "cylindrical-D", "scenario": "push",
              "demo": "softtip.systems.hall_fingertip.commands:demo"},
)
