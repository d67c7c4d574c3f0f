"""The fingertips the device presses: the fingertip sensor (FS), the six test fingertips, and what
makes a real finger differ, as explicit settings.

A fingertip is an elastomer cap over a rigid core; the 6-axis sensor on the core reads the wrench the
mobile platform applies, about the core's origin (:func:`finger_wrench`). The device-mounted sensor
(DS) on the platform reads the opposite wrench, about the platform's centroid and in the platform's
own axes (:func:`platform_wrench`).

The settings and their values (softtip's, beyond the publication except where said):

- ``radius``: the cap's radius. The publication's six casts: spheres of 6.5 (small), 7.5 (the FS)
  and 8.5 mm (large), and three human fingertips approximated as spheres of 6.5, 8 and 10 mm.
- ``shape``: ``sphere``; ``ellipsoid``, longer along the finger (y) by 1.6, the ratio of the finger
  pad's radii (Serina et al. 1998's ellipsoidal pulp), the shape of the three human casts (a cast of
  a human fingertip is no sphere: the publication approximates each by a sphere of its radius for the
  geometric method only, and softtip keeps that approximation in the method, not in the cast);
  ``pad``, broader than deep (1.3 r across and along, r deep), so flatter under the pad: its radius
  of curvature there is 1.69 r. Every shape keeps its lowest point r below its centre.
- ``contact``: the normal law and material (:class:`~softtip.mechanics.plate_contact.PlateContactLaw`).
  The publication casts every fingertip in one rubber, VytaFlex 30 (Smooth-On: Shore 30A); E = 1.14
  MPa from Gent's Shore-A relation (E = 0.0981(56 + 7.62 S)/(0.1375(254 − 2.54 S)) MPa at S = 30),
  incompressible. Every cast is taken over the FS's rigid core (radius 4.5 mm, softtip's choice), so
  a larger cast has more rubber. The study uses the bonded-layer law with an effective thickness
  calibrated by softtip's finite elements (:mod:`softtip.mechanics.cap_fe`) as a function of the
  radius over 6.5–11 mm (:func:`layer_thickness`; the script ``examples/haptics_contact_calibration.py``
  prints the evidence): at the study's depths (0.1–1 mm) Hertz gives 34–93 % of the FE force (the
  core stiffens the contact), the calibrated law 89–111 % (95–105 % from 7.5 mm up). With one core, equal depth takes about the same force on every cast
  (the √R of Hertz offset by the thicker rubber). The exponential law describes living finger pulp,
  not these casts. A different stiffness per finger is softtip's addition, declared as such.
- ``core_offset``: where the core's sensor origin sits from the cap's centre (m): it moves the
  torques, not the force.
- ``mounting``: ``centre``, the fingertip's centre at the device's finger centre (the geometric
  method's assumption); or ``nail``, the device resting on the nail, so the top of the fingertip
  stays where the FS's top is and a larger finger reaches further down.
"""

from __future__ import annotations

import functools
from typing import Annotated

import numpy as np

from softtip._core.config import PositiveNumber, Real, Text, choice, expect, from_numpy, schema
from softtip.mechanics.plate_contact import PlateContactLaw, plate_wrench
from softtip.sensors.wrench import shift_wrench, wrench_in_frame
from softtip.systems.haptics.device import DeviceSpec, PlatformPose, loaded_pose

FS_RADIUS = 7.5e-3  # m: the fingertip sensor's quarter-sphere tip (the publication)
CORE_RADIUS = 4.5e-3  # m: the rigid core inside every cast, 3 mm of rubber under the FS's pad (softtip's choice)
VYTAFLEX_30_MODULUS = 1.14e6  # Pa: Gent's Shore-A relation at Shore 30A
SHAPE_AXES = {"sphere": (1.0, 1.0, 1.0), "ellipsoid": (1.0, 1.6, 1.0), "pad": (1.3, 1.3, 1.0)}
# 3 mm of rubber over the core under the pad: softtip's choice for a cast over a rigid core (not published)
VYTAFLEX_30 = PlateContactLaw(law="hertz", youngs_modulus=VYTAFLEX_30_MODULUS, poisson_ratio=0.5,
                              layer_thickness=FS_RADIUS - CORE_RADIUS)

Offset3 = Annotated[tuple[Real, Real, Real], from_numpy, expect("3 coordinates (m)")]


@schema(section="fingertip")
class Fingertip:
    """A fingertip in the device: radius (m), shape, contact law, core offset (m), mounting."""

    name: Text
    radius: PositiveNumber
    shape: choice(*SHAPE_AXES) = "sphere"
    contact: PlateContactLaw = VYTAFLEX_30
    core_offset: Offset3 = (0.0, 0.0, 0.0)
    mounting: choice("centre", "nail") = "centre"

    @property
    def semi_axes(self) -> np.ndarray:
        return self.radius * np.array(SHAPE_AXES[self.shape])

    def centre(self, device: DeviceSpec) -> np.ndarray:
        """The cap's centre in the device's frame (m)."""
        if self.mounting == "centre":
            return device.centre
        return device.centre + np.array([0.0, 0.0, FS_RADIUS - self.semi_axes[2]])


# The bonded-layer law's effective thickness (m) for a VytaFlex 30 cast of each radius over the FS's
# core, fitted to softtip's FE over depths 0.1–1 mm (examples/haptics_contact_calibration.py, which
# also checks the interpolation at radii outside this grid; a slow test repeats the FS's and 9 mm's):
# (radius, effective thickness)
CALIBRATED_LAYERS = ((6.5e-3, 3.09e-3), (7.5e-3, 4.75e-3), (8.0e-3, 5.68e-3), (8.5e-3, 6.69e-3), (10.0e-3, 9.95e-3),
                     (11.0e-3, 12.28e-3))
CALIBRATED_RADII = (CALIBRATED_LAYERS[0][0], CALIBRATED_LAYERS[-1][0])  # m: the range layer_thickness covers


@functools.cache
def _layer_interpolant():
    from scipy.interpolate import PchipInterpolator

    return PchipInterpolator(*np.array(CALIBRATED_LAYERS).T)


def layer_thickness(radius: float) -> float:
    """The bonded-layer law's effective thickness (m) for a VytaFlex 30 cast of ``radius`` (m) over the
    FS's core: the FE calibration at the radii of :data:`CALIBRATED_LAYERS`, between them a monotone
    cubic (PCHIP), over :data:`CALIBRATED_RADII` (6.5–11 mm). Checked by FE at radii outside the grid:
    at 9 mm the interpolated thickness is 0.15 % above the FE's own fit and the law's force 1.5–2.6 %
    from the FE's at 0.1–1 mm; at 7 mm 0.03 % and 0.1–6.8 % (the law's own misfit on thin rubber, the
    same with the FE's fit). Below 6.5 mm the law stops describing the FE (at 6 mm, 1.5 mm of rubber:
    81–116 % of the FE's force), so a smaller radius is refused, as is one beyond 11 mm (not calibrated)."""
    low, high = CALIBRATED_RADII
    if not (isinstance(radius, (int, float)) and low <= radius <= high):
        raise ValueError(f"radius = {radius!r}: expected a cast radius from {low * 1e3:g} to {high * 1e3:g} mm (m), "
                         "the range of the FE calibration (softtip.mechanics.cap_fe)")
    return float(_layer_interpolant()(radius))


def cast(name: str, radius: float, shape: str = "sphere") -> Fingertip:
    """A VytaFlex 30 cast of ``radius`` (m) and ``shape`` over the FS's core, with the FE-calibrated
    contact law (:func:`layer_thickness`; a shape keeps the rubber's depth under the pad, r minus the core)."""
    law = PlateContactLaw(law="bonded-layer", youngs_modulus=VYTAFLEX_30_MODULUS,
                          layer_thickness=layer_thickness(radius))
    return Fingertip(name=name, radius=radius, shape=shape, contact=law)


FINGERTIP_SENSOR = cast("FS (7.5 mm)", FS_RADIUS)
# the publication's six test fingertips, all cast in VytaFlex 30 over a rigid core: three spheres and
# three casts of human fingertips, ellipsoidal pulps named by the sphere the geometric method takes for them
HUMAN_SHAPE = "ellipsoid"
TEST_FINGERTIPS = (
    cast("small cast (6.5 mm)", 6.5e-3),
    cast("FS cast (7.5 mm)", 7.5e-3),
    cast("large cast (8.5 mm)", 8.5e-3),
    cast("human 1 (6.5 mm)", 6.5e-3, HUMAN_SHAPE),
    cast("human 2 (8 mm)", 8.0e-3, HUMAN_SHAPE),
    cast("human 3 (10 mm)", 10.0e-3, HUMAN_SHAPE),
)


HUMAN_FINGERTIPS = TEST_FINGERTIPS[3:]  # after the three casts


def finger_wrench(fingertip: Fingertip, device: DeviceSpec, pose: PlatformPose) -> tuple[np.ndarray, np.ndarray]:
    """The wrench (..., 6) the platform applies to the fingertip, about its core's origin, and the
    indentation (m, (...))."""
    centre = fingertip.centre(device)
    return plate_wrench(fingertip.contact, centre, fingertip.semi_axes, pose.centroid, pose.normal,
                        centre + np.array(fingertip.core_offset))


def loaded_contact(fingertip: Fingertip, device: DeviceSpec, angles) -> tuple[PlatformPose, np.ndarray]:
    """The platform's pose at servo ``angles`` (rad, (..., 3)) pressed on ``fingertip``, its cables
    stretched under its load (:func:`~.device.loaded_pose`), and the wrench (..., 6) it applies to
    the fingertip about its core's origin."""
    return loaded_pose(device, angles, lambda pose: finger_wrench(fingertip, device, pose)[0])


def platform_wrench(fingertip: Fingertip, device: DeviceSpec, pose: PlatformPose,
                    on_finger: np.ndarray) -> np.ndarray:
    """What the DS reads: the wrench (..., 6) the fingertip applies to the platform, about the
    platform's centroid and in its axes, from ``on_finger`` (the finger's wrench, about its core)."""
    origin = fingertip.centre(device) + np.array(fingertip.core_offset)
    about_centroid = shift_wrench(-np.asarray(on_finger), origin, pose.centroid)
    return wrench_in_frame(about_centroid, pose.frame())
