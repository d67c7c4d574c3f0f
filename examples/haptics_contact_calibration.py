"""Calibrates the bonded-layer contact law of S3's test fingertips by finite elements, and prints the
evidence for the law the study uses: for each cast radius (rubber over the FS's rigid core), the FE
plate force at the study's depths beside Hertz and the calibrated law, and the calibrated effective
thickness that ``softtip.systems.haptics.fingertips`` holds.

    python examples/haptics_contact_calibration.py
"""

from __future__ import annotations

import numpy as np

from softtip.mechanics.cap_fe import plate_on_cap_fe
from softtip.systems.haptics.fingertips import CORE_RADIUS, VYTAFLEX_30_MODULUS

DEPTHS = np.array([0.1e-3, 0.25e-3, 0.5e-3, 0.75e-3, 1.0e-3])


def main() -> None:
    for radius in (6.5e-3, 7.5e-3, 8.0e-3, 8.5e-3, 10.0e-3):
        curve = plate_on_cap_fe(radius, radius - CORE_RADIUS, VYTAFLEX_30_MODULUS, DEPTHS, tip_size=0.5e-3)
        print(f"R = {radius * 1e3:.1f} mm, rubber {curve.thickness * 1e3:.1f} mm: converged {curve.converged}; "
              f"FE {np.round(curve.fe_forces, 3).tolist()} N; "
              f"Hertz/FE {np.round(curve.hertz_forces / curve.fe_forces, 3).tolist()}; "
              f"effective thickness {curve.calibrated_thickness * 1e3:.2f} mm, law/FE "
              f"{np.round(curve.calibrated_forces / curve.fe_forces, 3).tolist()}")


if __name__ == "__main__":
    main()
