"""S3: personalised data-driven haptic rendering at the fingertip.

A 3-cable fingertip-mounted device (:mod:`.device`), the fingertips it presses (:mod:`.fingertips`), lookup
tables and the k-nearest-neighbour renderer (:mod:`.rendering`), the two personalisations
(:mod:`.personalisation`), the simulated table collection (:mod:`.collection`) and the published
study with its statistics (:mod:`.study`, :mod:`.statistics`); the study as a lab protocol
(:mod:`.bench`) and its report (:mod:`.report`); the commands (:mod:`.commands`) and the real-time
rendering loop (:mod:`.live`).

Importing this package loads only its registration record (:data:`SYSTEM`).
"""

from softtip._core.channels import Reading
from softtip._core.systems import Study, System
from softtip._core.units import FORCE_UNITS

# the force a sensation asks the device to render, streamed by `softtip haptics render` as the live
# pipeline's reading (recorded as geometry_msgs/WrenchStamped, torque NaN)
WANTED = Reading("wanted force", "N", "F", "N", prefix="wanted", infix="f", units=FORCE_UNITS, drift_threshold=0.05,
                 baseline_step=1e-4, decimals=3, topic="wanted_force", message="geometry_msgs/msg/WrenchStamped",
                 first_numbered=False)

SYSTEM = System(
    name="haptics",
    title="Personalised data-driven haptic rendering with a 3-cable fingertip device",
    label="S3",
    package=__name__,
    readings=(WANTED,),
    benches={"haptics": "softtip.systems.haptics.bench:BENCH"},
    protocols={"haptics": "haptics"},
    studies=(
        Study("haptics", "haptics", "softtip.systems.haptics.report:haptics",
              "S3: standard and personalised (data-driven A, geometric B) rendering errors on six test fingertips",
              quick={"curve_n_neighbours": [1, 8], "curve_weighting_powers": [1.0], "curve_fs_levels": [7, 13],
                     "curve_user_levels": [7], "variations": ["as published", "human pads half as stiff"],
                     "robustness_seeds": [2], "robustness_sigmas": 0.0, "ablations": False}),
    ),
    bench_commands={"haptics": "softtip.systems.haptics.commands:bench_haptics",
                    "haptics-loop": "softtip.systems.haptics.commands:bench_haptics_loop"},
    commands={"haptics": "softtip.systems.haptics.commands:app"},
)
