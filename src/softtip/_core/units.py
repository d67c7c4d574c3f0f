"""Unit constants. softtip computes in SI; a value in another unit is converted where it enters or
leaves: ``depth_mm * MM`` is metres, ``depth_m / MM`` millimetres, ``field_T * UT_PER_T`` microtesla."""

MM = 1e-3  # metres per millimetre
UM = 1e-6  # metres per micrometre
MN = 1e-3  # newtons per millinewton
UN = 1e-6  # newtons per micronewton
UT_PER_T = 1e6  # microtesla per tesla
FORCE_UNITS = {"N": 1.0, "mN": 1e-3}  # newtons per unit
