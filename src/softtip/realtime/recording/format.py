"""The recording format: ROS 2 message types, topics, units, and the stream's mapping onto them.

A recording is an MCAP file with the ``ros2`` profile: every channel has a ``ros2msg``
schema (the message definition with its dependencies, as ``ros2 bag`` writes it) and
``cdr`` messages (ROS 2's wire format). Only standard message packages are used, so
``ros2 bag play`` needs nothing installed and Foxglove decodes the file from its embedded
schemas.

Topics (``prefix`` is ``/fingertip`` by default):

==============================  ===========================  =======================================
``{prefix}/chip{k}/field``      sensor_msgs/msg/MagneticField  the reading of Hall chip k, in tesla
                                                               (NaN when the chip reported a fault);
                                                               covariance: the sensor model's noise
                                                               plus quantisation, at start-up settings
``{prefix}/chip{k}/force``      geometry_msgs/msg/WrenchStamped  instead, the reading of force chip k
                                                               in N; torque NaN
``{prefix}/chip{k}/baseline``   the chip's message type        the baseline subtracted from chip k,
                                                               written whenever it changes
``{prefix}/wrench``             geometry_msgs/msg/WrenchStamped  estimated force (N) and torque (N m);
                                                               components no model estimates are NaN
``{prefix}/estimates``          std_msgs/msg/Float64MultiArray  every regression estimate; the
                                                               dimension label lists the names,
                                                               channel metadata ``units`` the units
``{prefix}/contact_state``      std_msgs/msg/String            the estimated contact state
==============================  ===========================  =======================================

All messages of one frame share one log time: the frame's acquisition time in ns since the
Unix epoch, also the ``header.stamp`` of the stamped ones; the MCAP ``sequence`` is the
frame's sequence number.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence

import numpy as np

from softtip._core.channels import Reading
from softtip._core.units import FORCE_UNITS
from softtip.sensors.registry import ChipSettings

PROFILE = "ros2"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"
METADATA_NAME = "softtip"
RECORDING_FORMAT = "softtip-recording"
DEFAULT_PREFIX = "/fingertip"

_SEPARATOR = "=" * 80
_NO_TORQUE = np.full(3, np.nan)  # a force chip measures no torque

# Message definitions as the ROS 2 packages state them (comments left out).
DEFINITIONS = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/Wrench": "geometry_msgs/Vector3 force\ngeometry_msgs/Vector3 torque",
    "sensor_msgs/MagneticField": (
        "std_msgs/Header header\ngeometry_msgs/Vector3 magnetic_field\nfloat64[9] magnetic_field_covariance"
    ),
    "geometry_msgs/WrenchStamped": "std_msgs/Header header\ngeometry_msgs/Wrench wrench",
    "geometry_msgs/Vector3Stamped": "std_msgs/Header header\ngeometry_msgs/Vector3 vector",
    "std_msgs/String": "string data",
    "std_msgs/MultiArrayDimension": "string label\nuint32 size\nuint32 stride",
    "std_msgs/MultiArrayLayout": "std_msgs/MultiArrayDimension[] dim\nuint32 data_offset",
    "std_msgs/Float64MultiArray": "std_msgs/MultiArrayLayout layout\nfloat64[] data",
}
MAGNETIC_FIELD = "sensor_msgs/msg/MagneticField"
WRENCH_STAMPED = "geometry_msgs/msg/WrenchStamped"
VECTOR3_STAMPED = "geometry_msgs/msg/Vector3Stamped"
STRING = "std_msgs/msg/String"
FLOAT64_MULTI_ARRAY = "std_msgs/msg/Float64MultiArray"

# the unit a chip's reading message carries, by message type (a Vector3Stamped: the reading's own)
READING_MESSAGES = {MAGNETIC_FIELD: "T", WRENCH_STAMPED: "N", VECTOR3_STAMPED: None}
# where the reading's vector sits in each of those messages
READING_VECTORS = {MAGNETIC_FIELD: "magnetic_field", WRENCH_STAMPED: "wrench.force", VECTOR3_STAMPED: "vector"}

WRENCH_FLOATS = 6  # force (3) + torque (3)

# Estimated targets that fill a WrenchStamped, by name: (index in force+torque, SI unit).
WRENCH_COMPONENTS = {
    "fx": 0, "fy": 1, "fz": 2, "force_x": 0, "force_y": 1, "force_z": 2, "normal_force": 2, "fn": 2,
    "tx": 3, "ty": 4, "tz": 5, "mx": 3, "my": 4, "mz": 5, "torque_x": 3, "torque_y": 4, "torque_z": 5,
}
WRENCH_LABELS = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")
WRENCH_UNITS = ("N", "N", "N", "N m", "N m", "N m")
TORQUE_UNITS_IN_NM = {"N m": 1.0, "N*m": 1.0, "Nm": 1.0, "N.m": 1.0, "mN m": 1e-3, "N mm": 1e-3}


class RecordingError(ValueError):
    """A recording that cannot be written or read as asked."""


def _dependencies(name: str) -> list[str]:
    """Every message type ``name`` uses, depth first, each once."""
    found: list[str] = []

    def visit(type_name: str) -> None:
        for line in DEFINITIONS[type_name].splitlines():
            field_type = re.sub(r"\[\d*\]$", "", line.split()[0])
            if "/" in field_type and field_type not in found:
                found.append(field_type)
                visit(field_type)

    visit(name)
    return found


def schema_text(schema_name: str) -> str:
    """The ``ros2msg`` schema of ``pkg/msg/Name``: its definition, then each dependency's."""
    name = schema_name.replace("/msg/", "/")
    if name not in DEFINITIONS:
        raise RecordingError(f"schema {schema_name!r}: no definition (known: {', '.join(sorted(DEFINITIONS))})")
    parts = [DEFINITIONS[name]]
    parts += [f"{_SEPARATOR}\nMSG: {dependency}\n{DEFINITIONS[dependency]}" for dependency in _dependencies(name)]
    return "\n".join(parts) + "\n"


def reading_topic(reading: Reading) -> tuple[str, str]:
    """(topic leaf, message type) of a chip's reading, e.g. ``field`` MagneticField, ``force`` WrenchStamped."""
    if reading.message not in READING_MESSAGES or READING_MESSAGES[reading.message] not in (None, *reading.units):
        raise RecordingError(f"reading {reading.quantity!r}: not recordable as {reading.message} (known: "
                             f"{', '.join(f'{m} in {u}' for m, u in READING_MESSAGES.items())})")
    return reading.topic, reading.message


def reading_fields(reading: Reading, values: np.ndarray, vector: Callable[[np.ndarray], dict],
                   covariance: list | None = None) -> dict:
    """The fields of a chip's reading message after its header: ``values`` (its axes, in the reading's
    unit) in SI, each vector encoded by ``vector`` (an axis the reading does not have is NaN: the
    message's x, y, z are fixed, the chip's axes are not); a MagneticField carries ``covariance``
    (9 values, T², default unknown: zeros), a force chip's WrenchStamped a NaN torque."""
    carried = in_xyz(reading, np.asarray(values) / per_message_unit(reading))
    if reading.message == MAGNETIC_FIELD:
        return {"magnetic_field": vector(carried), "magnetic_field_covariance": covariance or [0.0] * 9}
    if reading.message == VECTOR3_STAMPED:
        return {"vector": vector(carried)}
    return {"wrench": {"force": vector(carried), "torque": vector(_NO_TORQUE)}}


def in_xyz(reading: Reading, values: np.ndarray, missing: float = np.nan) -> np.ndarray:
    """Values on a reading's axes (..., axes) placed in a message's x, y, z (..., 3): the axes it does
    not read are ``missing``."""
    values = np.asarray(values, dtype=np.float64)
    placed = np.full((*values.shape[:-1], 3), missing)
    placed[..., list(reading.positions)] = values
    return placed


def per_message_unit(reading: Reading) -> float:
    """How many of the reading's unit one unit of its message is (1 T = 1e6 µT)."""
    unit = READING_MESSAGES[reading.message]
    return 1.0 if unit is None else reading.units[unit]


def frame_id(prefix: str, chip: int | None = None) -> str:
    """The header frame id under ``prefix``: ``fingertip_chip{k}`` for a chip, ``fingertip`` for the wrench."""
    base = prefix.strip("/").replace("/", "_")
    return base if chip is None else f"{base}_chip{chip}"


def wrench_mapping(target_names: Sequence[str], target_units: Sequence[str]) -> list[tuple[int, int, float]]:
    """(target index, wrench component 0..5, factor to N or N m) for every target that is a
    force or torque component (Fx, force_x, normal_force, Tz, ..., also with its unit after an
    underscore: fx_N)."""
    mapping = []
    for index, (name, unit) in enumerate(zip(target_names, target_units, strict=True)):
        component = WRENCH_COMPONENTS.get(name.lower().removesuffix(f"_{unit}".lower()))
        if component is None:
            continue
        units = FORCE_UNITS if component < 3 else TORQUE_UNITS_IN_NM
        if unit not in units:
            raise RecordingError(f"target {name}: unit {unit!r} is not a {'force' if component < 3 else 'torque'} "
                                 f"unit ({', '.join(units)})")
        mapping.append((index, component, units[unit]))
    components = [component for _, component, _ in mapping]
    if len(set(components)) != len(components):
        raise RecordingError(f"targets {list(target_names)} name one wrench component twice")
    return mapping


def wrench_values(estimates: np.ndarray, mapping: Sequence[tuple[int, int, float]]) -> np.ndarray:
    """Force and torque (..., 6) in N and N m from estimates (..., targets) by :func:`wrench_mapping`;
    components no target estimates are NaN."""
    estimates = np.asarray(estimates, dtype=np.float64)
    wrench = np.full(estimates.shape[:-1] + (WRENCH_FLOATS,), np.nan)
    for target, component, factor in mapping:
        wrench[..., component] = estimates[..., target] * factor
    return wrench


def magnetic_covariance_T2(settings: ChipSettings | None) -> np.ndarray:
    """Row-major 3x3 covariance, in its message's unit squared (T^2 for a magnetic field), of a chip
    read at ``settings``: the registered sensor's noise plus uniform quantisation per axis; zeros (ROS:
    unknown) when the settings are not known or the sensor declares no noise."""
    variance = None if settings is None else settings.variance()
    if variance is None:
        return np.zeros(9)
    reading = settings.kind.reading  # an axis the chip does not read: unknown, 0
    return np.diag(in_xyz(reading, variance / per_message_unit(reading) ** 2, missing=0.0)).ravel()
