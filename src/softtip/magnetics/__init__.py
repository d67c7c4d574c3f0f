"""Exact field of the fingertip's axially magnetised cylindrical magnets.

``cylinder`` holds the closed-form kernel in the magnet's own frame;
``field`` poses many magnets (rotation vectors), sums them at the sensors.
"""

from softtip.magnetics.cylinder import axial_cylinder_field, axial_cylinder_field_rz
from softtip.magnetics.field import (
    magnet_axes,
    magnet_field_at_sensors,
)

__all__ = [
    "axial_cylinder_field",
    "axial_cylinder_field_rz",
    "magnet_axes",
    "magnet_field_at_sensors",
]
