"""Calibrates the bonded-layer contact law of S3's test fingertips by finite elements, and prints the
evidence for the law the study uses and for its interpolation over radii.

For each radius of the calibration grid (a cast of rubber over the FS's rigid core) it prints the FE
plate force at the study's depths beside Hertz and the calibrated law, and the calibrated effective
thickness that ``softtip.systems.haptics.fingertips.CALIBRATED_LAYERS`` holds. Then, at radii outside
the grid, the FE's own calibrated thickness beside ``layer_thickness`` (the grid interpolated) and the
law's force with the interpolated thickness over the FE's; and at 6 mm, below the range, how far the
law is from the FE when it is fitted there.

    python examples/haptics_contact_calibration.py
"""

from __future__ import annotations

import numpy as np

from softtip.mechanics.cap_fe import FE_POISSON_RATIO, plate_on_cap_fe
from softtip.mechanics.plate_contact import bonded_layer_force
from softtip.systems.haptics.fingertips import CALIBRATED_LAYERS, CORE_RADIUS, VYTAFLEX_30_MODULUS, layer_thickness

DEPTHS = np.array([0.1e-3, 0.25e-3, 0.5e-3, 0.75e-3, 1.0e-3])
HELD_OUT = (7.0e-3, 9.0e-3)  # radii not in the grid
BELOW_RANGE = 6.0e-3


def curve(radius: float):
    return plate_on_cap_fe(radius, radius - CORE_RADIUS, VYTAFLEX_30_MODULUS, DEPTHS, tip_size=0.5e-3)


def main() -> None:
    for radius, _ in CALIBRATED_LAYERS:
        fe = curve(radius)
        print(f"R = {radius * 1e3:.1f} mm, rubber {fe.thickness * 1e3:.1f} mm: converged {fe.converged}; "
              f"FE {np.round(fe.fe_forces, 3).tolist()} N; "
              f"Hertz/FE {np.round(fe.hertz_forces / fe.fe_forces, 3).tolist()}; "
              f"effective thickness {fe.calibrated_thickness * 1e3:.2f} mm, law/FE "
              f"{np.round(fe.calibrated_forces / fe.fe_forces, 3).tolist()}")
    modulus = VYTAFLEX_30_MODULUS / (1 - FE_POISSON_RATIO**2) * 0.75  # as cap_fe compares the laws
    for radius in HELD_OUT:
        fe = curve(radius)
        interpolated = layer_thickness(radius)
        law = bonded_layer_force(DEPTHS, radius, modulus, interpolated)
        gap = (interpolated / fe.calibrated_thickness - 1) * 100
        print(f"held out R = {radius * 1e3:.1f} mm: FE's own thickness {fe.calibrated_thickness * 1e3:.3f} mm, "
              f"interpolated {interpolated * 1e3:.3f} mm ({gap:+.2f} %); "
              f"law/FE with it {np.round(law / fe.fe_forces, 3).tolist()}")
    fe = curve(BELOW_RANGE)
    print(f"below the range, R = {BELOW_RANGE * 1e3:.1f} mm: the law at its best fit is "
          f"{np.round(fe.calibrated_forces / fe.fe_forces, 3).tolist()} of the FE")


if __name__ == "__main__":
    main()
