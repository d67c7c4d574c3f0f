"""The 3-cable fingertip-mounted device: kinematics, workspace, servos and cable springs.

Frame {0} is the static platform's: origin at its centre, z0 its normal pointing from the mobile
platform up to the static one (on the nail). Cable i leaves the static platform at
a_i = ρ (cos φ_i, sin φ_i, 0) and, as the spec allows, stays parallel to z0, so its end on the mobile
platform is P_i = (ρ cos φ_i, ρ sin φ_i, −l_i). The mobile platform's contact face is the plane
through the three ends: its pose is that plane, given by its centroid p_c (the mean of the P_i) and
its unit normal z1 (pointing up, towards the finger pad).

The chain is servo angles θ (rad) → cable lengths l = l_0 − r θ (winding shortens a cable; l_0 the
released length, r the pulley radius) → platform pose. The inverse takes any point q on a plane and
its normal n: each cable end lies where the plane meets its line, z_i = q_z − (n_x(x_i − q_x) +
n_y(y_i − q_y))/n_z, so l_i = −z_i and θ = (l_0 − l)/r. Both directions are exact, and exact inverses
over the workspace: servo angles within [0, θ_max] and tilts within the device's limit.

The servos take position commands at their frame rate (50 Hz), resolve them to their dead band and
move at a finite slew rate (:func:`servo_angles`). The springs round the cables push the platforms
apart; with the contact wrench on the platform, the cables' tensions follow from the platform's
balance in z and in moment about x and y (:func:`cable_tensions`): a cable whose tension would be
negative is slack.

Each cable, with its knots and the servo horn's give, is a spring in series (``[cables] stiffness``):
under the contact's load it stretches, so a pressing platform sits lower than its kinematics say, and
the spring round it, lengthened as much, pushes less (``[springs] stiffness`` adds to the cable's).
A servo holds at most its stall torque over the pulley's radius (:meth:`DeviceSpec.stall_tension`):
beyond it the servo is driven back, the cable pays out and the platform stops short, so the force
a platform renders is capped. :func:`loaded_pose` solves that balance with the contact;
:func:`forward_kinematics` is the unloaded, rigid-cable pose every method's model uses. A device
whose servos could not even hold their springs (the springs' push at the wound length beyond the
stall tension) is refused when its file is read.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Annotated

import numpy as np

from softtip._core.config import (
    ConfigError,
    PositiveNumber,
    Real,
    Refusal,
    Text,
    expect,
    from_numpy,
    number,
    parse,
    read_toml,
    schema,
)
from softtip._core.errors import NotConverged
from softtip.systems.haptics.limits import LOOP_RATE_HZ

DEVICE_FILE = Path(__file__).with_name("device.toml")
_TOLERANCE = 1e-9  # rad: rounding in the kinematics' inverse, far below a servo's dead band

# a fingertip-mounted device is centimetres across: a length beyond this is a unit slip, refused before
# the kinematics divide by it
LARGEST_LENGTH = 0.1  # m
Length = number(f"a length in m, above 0 and at most {LARGEST_LENGTH:g}", gt=0, le=LARGEST_LENGTH)
Angles3 = Annotated[tuple[Real, Real, Real], from_numpy, expect("3 angles in degrees")]
Point3 = Annotated[tuple[Real, Real, Real], from_numpy, expect("3 coordinates (m)")]


class DeviceError(ConfigError):
    """A device file or setting that cannot describe a working device."""


class UnreachablePose(ValueError):
    """A platform pose outside the device's workspace."""


@schema(section="device", error=DeviceError)
class Geometry:
    """The cables' attachments and winding (m, degrees)."""

    name: Text
    attachment_radius: Length
    attachment_angles_deg: Angles3
    pulley_radius: Length
    released_length: Length
    max_tilt_deg: number("an angle in degrees strictly between 0 and 90", gt=0, lt=90)

    def __post_init__(self) -> None:
        points = np.column_stack([np.cos(np.radians(self.attachment_angles_deg)),
                                  np.sin(np.radians(self.attachment_angles_deg))])
        first, second = points[1] - points[0], points[2] - points[0]
        twice_area = abs(first[0] * second[1] - first[1] * second[0])
        if twice_area < 0.1:  # the three cable ends must span a plane, well conditioned
            raise Refusal("attachment_angles_deg",
                          "expected three angles well apart (the cable ends must span a plane)")


@schema(section="servo", error=DeviceError)
class Servo:
    """A position servo: its range (degrees), command rate (Hz), slew (degrees/s), dead band and stall
    torque (N·m), the most it holds: beyond it the servo is driven back (:func:`loaded_pose`)."""

    angle_max_deg: number("an angle in degrees, 0 < angle <= 360", gt=0, le=360)
    # a servo reads at most one command a tick of the 1 kHz render loop (softtip.systems.haptics.limits)
    command_rate_hz: number(f"a rate in Hz above 0 and at most the render loop's {LOOP_RATE_HZ:g}", gt=0,
                            le=LOOP_RATE_HZ)
    slew_deg_per_s: PositiveNumber
    resolution_deg: PositiveNumber
    stall_torque: PositiveNumber


@schema(section="springs", error=DeviceError)
class Springs:
    """The compression springs round the cables: stiffness (N/m) and free length (m). Their push loads
    the servos (:meth:`DeviceSpec.stall_tension`) and, as a pressed platform moves away, eases: they
    stiffen the cables' give (:func:`loaded_pose`)."""

    stiffness: PositiveNumber
    free_length: Length


@schema(section="cables", error=DeviceError)
class Cables:
    """Each cable's axial stiffness (N/m) in series with its servo: the cable, its knots and the servo
    horn's give, which lengthen a cable by its tension over this stiffness."""

    stiffness: PositiveNumber


@schema(section="finger", error=DeviceError)
class FingerPlacement:
    """The fingertip's centre in the static platform's frame (m)."""

    centre: Point3


@schema(section="fit", error=DeviceError)
class FitRecord:
    """Which of the file's values were fitted (dotted keys, e.g. ``cables.stiffness``), their standard
    errors (each value's unit) and correlations, how they were fitted, the figures fitted to and the
    fit's residuals there (figure − published, in the figures' unit). A file without it states no fit."""

    method: Text
    parameters: list[Text]
    standard_errors: list[PositiveNumber]
    correlation: list[list[Real]]
    figures: list[Text]
    residuals: list[Real]

    def __post_init__(self) -> None:
        count = len(self.parameters)
        if len(self.standard_errors) != count:
            raise Refusal("standard_errors", f"expected one per parameter, {count}")
        matrix = np.array(self.correlation, dtype=float) if all(len(r) == count for r in self.correlation) else None
        if (matrix is None or matrix.shape != (count, count) or not np.allclose(matrix, matrix.T)
                or not np.allclose(np.diag(matrix), 1.0) or np.linalg.eigvalsh(matrix).min() < -1e-9):
            raise Refusal("correlation", f"expected a symmetric {count} x {count} correlation matrix (ones on "
                                         "its diagonal, positive semi-definite)")
        if len(self.residuals) != len(self.figures):
            raise Refusal("residuals", f"expected one per figure, {len(self.figures)}")

    @property
    def covariance(self) -> np.ndarray:
        """The fitted values' covariance, in their units."""
        errors = np.array(self.standard_errors)
        return np.array(self.correlation) * np.outer(errors, errors)


@schema(error=DeviceError)
class DeviceSpec:
    """A whole device file: ``[device]``, ``[servo]``, ``[springs]``, ``[cables]``, ``[finger]`` and, when
    some values were fitted, ``[fit]``."""

    device: Geometry
    servo: Servo
    springs: Springs
    cables: Cables
    finger: FingerPlacement
    fit: FitRecord | None = None

    def __post_init__(self) -> None:
        wound = self.wound_length
        if wound <= 0:
            raise Refusal(("device", "released_length"),
                          f"expected above pulley_radius x angle_max ({self.device.released_length - wound:.4g} m): "
                          "a fully wound cable would pass through the static platform")
        if self.springs.free_length <= self.device.released_length:
            raise Refusal(("springs", "free_length"),
                          f"expected above device.released_length = {self.device.released_length}: "
                          "released cables would go slack")
        spring_push = self.springs.stiffness * (self.springs.free_length - wound)  # the most, at the wound length
        if not spring_push < self.stall_tension:
            held = spring_push * self.device.pulley_radius
            raise Refusal(("servo", "stall_torque"),
                          f"expected above {held:.3g} N m, what the spring's push at the wound cable length "
                          f"({spring_push:.3g} N: springs.stiffness x compression) takes on the pulley: the servo "
                          "could not hold its spring")
        if not -self.device.released_length < self.finger.centre[2] < 0:
            raise Refusal(("finger", "centre"), "expected the centre between the platforms (-released_length < z < 0)")
        if not np.hypot(*self.finger.centre[:2]) <= self.device.attachment_radius:
            raise Refusal(("finger", "centre"), "expected the centre inside the cables' circle (x² + y² <= "
                                                "device.attachment_radius²)")
        for key in self.fit.parameters if self.fit else ():
            section, _, name = key.partition(".")
            if section not in {"device", "servo", "springs", "cables", "finger"} or not isinstance(
                    getattr(getattr(self, section), name, None), float):
                raise Refusal(("fit", "parameters"), f"{key!r}: expected a number of the file as section.key, "
                                                     "e.g. cables.stiffness")

    def value(self, key: str) -> float:
        """The value of a dotted key, e.g. ``cables.stiffness``."""
        section, _, name = key.partition(".")
        return getattr(getattr(self, section), name)

    def with_values(self, keys, values) -> DeviceSpec:
        """This device with the dotted ``keys`` set to ``values``, validated as a device file is."""
        changes: dict[str, dict[str, float]] = {}
        for key, value in zip(keys, values, strict=True):
            section, _, name = key.partition(".")
            changes.setdefault(section, {})[name] = float(value)
        return replace(self, **{section: replace(getattr(self, section), **names)
                                for section, names in changes.items()})

    @property
    def wound_length(self) -> float:
        """The cable length with the servo at its end (m): the mobile platform's highest."""
        return self.device.released_length - self.device.pulley_radius * math.radians(self.servo.angle_max_deg)

    @property
    def stall_tension(self) -> float:
        """The most tension (N) a servo holds on its cable: its stall torque over the pulley's radius."""
        return self.servo.stall_torque / self.device.pulley_radius

    @property
    def angle_max(self) -> float:
        return math.radians(self.servo.angle_max_deg)

    @property
    def anchors(self) -> np.ndarray:
        """The cables' (x, y) in frame {0} (m), (3, 2)."""
        angles = np.radians(self.device.attachment_angles_deg)
        return self.device.attachment_radius * np.column_stack([np.cos(angles), np.sin(angles)])

    @property
    def centre(self) -> np.ndarray:
        return np.array(self.finger.centre)


def load_device(path: str | Path = DEVICE_FILE) -> DeviceSpec:
    """The device described by the TOML file ``path`` (softtip's own device by default)."""
    return parse(DeviceSpec, read_toml(path, "device", DeviceError), str(path), error=DeviceError)


@dataclass(frozen=True)
class PlatformPose:
    """Mobile-platform poses: the contact plane's centroid (..., 3) and unit normal (..., 3), in frame {0}."""

    centroid: np.ndarray
    normal: np.ndarray

    @property
    def tilt(self) -> np.ndarray:
        """The angle between the platform's normal and z0 (rad), (...)."""
        return np.arccos(np.clip(self.normal[..., 2], -1.0, 1.0))

    def moved_along_normal(self, distance) -> PlatformPose:
        """The same orientation, the plane moved by ``distance`` (m, (...)) along its own normal."""
        return PlatformPose(self.centroid + np.asarray(distance, dtype=float)[..., None] * self.normal, self.normal)

    def frame(self) -> np.ndarray:
        """The platform's axes as the columns of rotations (..., 3, 3): x1 is x0 projected on the
        plane, y1 = z1 × x1, z1 the normal."""
        x0 = np.broadcast_to([1.0, 0.0, 0.0], self.normal.shape)
        x1 = x0 - np.sum(x0 * self.normal, axis=-1, keepdims=True) * self.normal
        x1 /= np.linalg.norm(x1, axis=-1, keepdims=True)
        return np.stack([x1, np.cross(self.normal, x1), self.normal], axis=-1)


def _angles(angles) -> np.ndarray:
    angles = np.asarray(angles, dtype=float)
    if angles.shape[-1:] != (3,):
        raise ValueError(f"servo angles have shape {angles.shape}: expected (..., 3)")
    if not np.all(np.isfinite(angles)):
        raise ValueError("servo angles: expected finite numbers (rad)")
    return angles


def cable_lengths(spec: DeviceSpec, angles) -> np.ndarray:
    """Cable lengths (m, (..., 3)) at servo angles (rad, (..., 3))."""
    return spec.device.released_length - spec.device.pulley_radius * _angles(angles)


def servo_angles_of_lengths(spec: DeviceSpec, lengths) -> np.ndarray:
    """Servo angles (rad) that give cable ``lengths`` (m), both (..., 3)."""
    return (spec.device.released_length - np.asarray(lengths, dtype=float)) / spec.device.pulley_radius


def cable_ends(spec: DeviceSpec, lengths) -> np.ndarray:
    """The cables' ends on the mobile platform (..., 3 cables, 3 coordinates)."""
    lengths = np.asarray(lengths, dtype=float)
    anchors = np.broadcast_to(spec.anchors, (*lengths.shape[:-1], 3, 2))
    return np.concatenate([anchors, -lengths[..., None]], axis=-1)


def forward_kinematics(spec: DeviceSpec, angles) -> PlatformPose:
    """The mobile platform's pose at servo angles (rad, (..., 3)), its cables rigid."""
    ends = cable_ends(spec, cable_lengths(spec, angles))
    normal = np.cross(ends[..., 1, :] - ends[..., 0, :], ends[..., 2, :] - ends[..., 0, :])
    normal *= np.sign(normal[..., 2:3])  # up, towards the pad, whatever the order of the cables
    return PlatformPose(ends.mean(axis=-2), normal / np.linalg.norm(normal, axis=-1, keepdims=True))


def inverse_kinematics_unchecked(spec: DeviceSpec, pose: PlatformPose) -> np.ndarray:
    """Servo angles (rad, (..., 3)) that put the contact plane through ``pose``, whether or not the
    servos can reach them: see :func:`reachable` and :func:`inverse_kinematics`."""
    point, normal = np.asarray(pose.centroid, dtype=float), np.asarray(pose.normal, dtype=float)
    if np.any(normal[..., 2] <= 0):
        raise UnreachablePose("pose.normal: expected normals pointing up (z > 0) towards the finger pad")
    offsets = spec.anchors - point[..., None, :2]
    heights = point[..., None, 2] - np.sum(normal[..., None, :2] * offsets, axis=-1) / normal[..., None, 2]
    return servo_angles_of_lengths(spec, -heights)


def reachable(spec: DeviceSpec, angles, tilt=None) -> np.ndarray:
    """Which servo angles (rad, (..., 3)) the device can take: each within [0, θ_max], and the
    platform's tilt (computed when not given) within the device's limit."""
    angles = _angles(angles)
    inside = np.all((angles >= -_TOLERANCE) & (angles <= spec.angle_max + _TOLERANCE), axis=-1)
    tilt = forward_kinematics(spec, np.clip(angles, 0.0, spec.angle_max)).tilt if tilt is None else tilt
    return inside & (tilt <= math.radians(spec.device.max_tilt_deg) + _TOLERANCE)


def inverse_kinematics(spec: DeviceSpec, pose: PlatformPose) -> np.ndarray:
    """Servo angles (rad, (..., 3)) for ``pose``; a pose outside the workspace raises
    :class:`UnreachablePose` naming the first such pose and why."""
    angles = inverse_kinematics_unchecked(spec, pose)
    ok = reachable(spec, angles, pose.tilt)
    if not np.all(ok):
        first = np.unravel_index(np.flatnonzero(~ok.ravel())[0], ok.shape) if ok.ndim else ()
        degrees = np.degrees(angles[first])
        raise UnreachablePose(
            f"pose {tuple(int(i) for i in first)}: servo angles {np.round(degrees, 2).tolist()} deg, tilt "
            f"{math.degrees(float(pose.tilt[first])):.1f} deg: expected angles within 0..{spec.servo.angle_max_deg:g} "
            f"deg and tilt <= {spec.device.max_tilt_deg:g} deg")
    return np.clip(angles, 0.0, spec.angle_max)


# ---------------------------------------------------------------------------------------------- servos


def quantised(spec: DeviceSpec, angles) -> np.ndarray:
    """The angles (rad) a servo resolves from commands (rad): its dead band's steps, within its range."""
    step = math.radians(spec.servo.resolution_deg)
    return np.clip(np.round(_angles(angles) / step) * step, 0.0, spec.angle_max)


def servo_angles(spec: DeviceSpec, start, commands, loop_rate_hz: float) -> np.ndarray:
    """The servos' angles (rad) at each tick of a loop at ``loop_rate_hz`` (ticks, 3), from ``start``
    (3,) under ``commands`` (ticks, 3) given every tick: a servo reads a new command once per frame of
    its command rate, resolves it to its dead band and moves towards it at its slew rate."""
    commands = _angles(commands)
    if commands.ndim != 2:
        raise ValueError(f"commands have shape {commands.shape}: expected (ticks, 3)")
    if not loop_rate_hz >= spec.servo.command_rate_hz:
        raise ValueError(f"loop_rate_hz = {loop_rate_hz!r}: expected at least the servo command rate "
                         f"{spec.servo.command_rate_hz:g} Hz")
    ticks_per_frame = loop_rate_hz / spec.servo.command_rate_hz
    frame_of_tick = np.floor(np.arange(len(commands)) / ticks_per_frame).astype(int)
    first_tick_of_frame = np.ceil(frame_of_tick * ticks_per_frame).astype(int)
    targets = quantised(spec, commands[first_tick_of_frame])  # the command held by the current frame
    step = math.radians(spec.servo.slew_deg_per_s) / loop_rate_hz
    angles = np.empty_like(targets)
    angle = _angles(start).astype(float)
    for tick, target in enumerate(targets):
        angle = angle + np.clip(target - angle, -step, step)
        angles[tick] = angle
    return angles


def move_time(spec: DeviceSpec, start, end) -> np.ndarray:
    """Seconds the servos take from angles ``start`` to ``end`` (rad, (..., 3)): the slowest servo's
    travel at the slew rate, from the next command frame (on average half a frame away)."""
    travel = np.max(np.abs(_angles(end) - _angles(start)), axis=-1)
    return 0.5 / spec.servo.command_rate_hz + travel / math.radians(spec.servo.slew_deg_per_s)


# ---------------------------------------------------------------------------------------------- statics


def spring_forces(spec: DeviceSpec, lengths) -> np.ndarray:
    """Each spring's push (N, (..., 3)) between the platforms at cable ``lengths`` (m)."""
    return spec.springs.stiffness * (spec.springs.free_length - np.asarray(lengths, dtype=float))


def cable_tensions(spec: DeviceSpec, angles, finger_wrench) -> np.ndarray:
    """The cables' tensions (N, (..., 3)) holding the platform at servo ``angles`` (rad) against its
    springs and the contact: ``finger_wrench`` (..., 6) is the wrench the platform applies to the
    finger, about the origin of frame {0}. Balance in z and in moment about x and y (the parallel
    cables cannot hold a lateral force, which the kinematics' assumption neglects)."""
    lengths = cable_lengths(spec, angles)
    ends = cable_ends(spec, lengths)
    wrench = np.asarray(finger_wrench, dtype=float)
    balance = np.stack([np.ones_like(ends[..., 0]), ends[..., 1], -ends[..., 0]], axis=-2)  # (..., 3, 3)
    load = np.stack([wrench[..., 2], wrench[..., 3], wrench[..., 4]], axis=-1)
    return spring_forces(spec, lengths) + np.linalg.solve(balance, load[..., None])[..., 0]


def normal_give(spec: DeviceSpec, normal_force) -> np.ndarray:
    """How far (m) the platform gives way along its normal under a normal force (N, (...)) while the
    servos hold: F / 3(k_c + k_s), :func:`loaded_pose`'s balance below the stall."""
    return np.asarray(normal_force, dtype=float) / (3.0 * (spec.cables.stiffness + spec.springs.stiffness))


_GIVE_TOLERANCE = 1e-15  # m: the cables' give, far below a servo's dead band (microns of cable)
_GIVE_ITERATIONS = 100


def loaded_pose(spec: DeviceSpec, angles, contact) -> tuple[PlatformPose, np.ndarray]:
    """The platform's pose at servo ``angles`` (rad, (..., 3)) pressed on a finger, the cables
    stretched (and past their servos' stall, paid out) by the contact, and the contact wrench there:
    ``contact(pose)`` gives the wrench (..., 6) the platform applies to the finger.

    The platform gives way along its normal by s, keeping its tilt (the contact's moment is left to
    the rigid balance, :func:`cable_tensions`), so the three cables share the normal force F_n(s)
    alike: each holds F_n / 3 beyond its spring's preload, which is part of the released length.
    Moving away, each cable stretches by s (tension k_c s, ``cables.stiffness``) and its spring
    lengthens by s (its push eases by k_s s, ``springs.stiffness``) until a servo stalls: the
    cable's tension can rise by at most H = T_stall − the largest spring push (the first servo to
    stall stops the platform), and past it the servo pays cable out. So s solves
    g(s) = min(k_c s, H) + k_s s − F_n(s) / 3 = 0, g rising with s from g(0) = −F_n(0) / 3; with
    f = F_n(0) / 3 it is bracketed by 0 and max(f / (k_c + k_s), (f − H) / k_s). The Illinois
    false-position method narrows the bracket below 1e-15 m, or raises :class:`NotConverged`."""
    rigid = forward_kinematics(spec, angles)
    cable, spring = spec.cables.stiffness, spec.springs.stiffness
    headroom = spec.stall_tension - spring_forces(spec, cable_lengths(spec, angles)).max(axis=-1)

    def balance(give):
        wrench = contact(rigid.moved_along_normal(-give))
        return np.minimum(cable * give, headroom) + spring * give - np.sum(wrench[..., :3] * rigid.normal, axis=-1) / 3

    low = np.zeros(rigid.normal.shape[:-1])
    low_value = balance(low)
    share = -low_value  # F_n(0) / 3
    high = np.maximum(share / (cable + spring), (share - headroom) / spring)
    high_value = np.where(high > 0, balance(high), 0.0)
    kept = np.zeros(low.shape, dtype=int)  # which end stayed twice: -1 low, +1 high (Illinois' halving)
    for _ in range(_GIVE_ITERATIONS):
        if np.all(high - low <= _GIVE_TOLERANCE):
            pose = rigid.moved_along_normal(-high)
            return pose, contact(pose)
        span = high_value - low_value
        middle = np.where(span > 0, (low * high_value - high * low_value) / np.where(span > 0, span, 1.0), low)
        middle = np.clip(middle, low, high)
        value = balance(middle)
        below = value < 0
        low_value = np.where(below, value, np.where(kept == -1, low_value / 2, low_value))
        high_value = np.where(below, np.where(kept == 1, high_value / 2, high_value), value)
        kept = np.where(below, 1, -1)  # the end that did not move this time
        low, high = np.where(below, middle, low), np.where(below, high, middle)
        exact = value == 0
        low, high = np.where(exact, middle, low), np.where(exact, middle, high)
    raise NotConverged(f"loaded platform: the cables' give still spans {np.max(high - low):.3g} m after "
                       f"{_GIVE_ITERATIONS} steps (cables.stiffness = {cable:g} N/m, springs.stiffness = "
                       f"{spring:g} N/m, servo.stall_torque = {spec.servo.stall_torque:g} N m)")
