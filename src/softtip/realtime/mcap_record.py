"""MCAP recordings of the live stream in ROS 2 message types, and reading them back.

A recording is an MCAP file with the ``ros2`` profile: every channel has a ``ros2msg``
schema (the message definition with its dependencies, as ``ros2 bag`` writes it) and
``cdr`` messages (the 4-byte encapsulation header ``00 01 00 00``, then little-endian
plain CDR with each primitive aligned to its size, counted from the end of that header).
Only standard message packages are used, so ``ros2 bag play`` needs nothing installed and
Foxglove decodes the file from its embedded schemas.

Topics (``prefix`` is ``/fingertip`` by default):

==============================  ===========================  =======================================
``{prefix}/chip{k}/field``      sensor_msgs/msg/MagneticField  the reading of chip k, in tesla (NaN
                                                               when the chip reported a fault);
                                                               covariance: the sensor model's noise
                                                               plus quantisation, at start-up settings
``{prefix}/chip{k}/baseline``   sensor_msgs/msg/MagneticField  the baseline subtracted from chip k,
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
frame's sequence number. The file is written in chunks that are closed and flushed to the
operating system every flush, so a process that is killed leaves a file readable up to its
last flush: :func:`read_recording` reads such a file record by record and stops at the
damaged tail.
"""

from __future__ import annotations

import json
import os
import re
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mcap.exceptions import InvalidMagic
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from softtip import __version__

PROFILE = "ros2"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"
METADATA_NAME = "softtip"
RECORDING_FORMAT = "softtip-recording"
DEFAULT_PREFIX = "/fingertip"
UT_PER_T = 1e6

ENCAPSULATION_CDR_LE = b"\x00\x01\x00\x00"
_SEPARATOR = "=" * 80

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
    "std_msgs/String": "string data",
    "std_msgs/MultiArrayDimension": "string label\nuint32 size\nuint32 stride",
    "std_msgs/MultiArrayLayout": "std_msgs/MultiArrayDimension[] dim\nuint32 data_offset",
    "std_msgs/Float64MultiArray": "std_msgs/MultiArrayLayout layout\nfloat64[] data",
}
MAGNETIC_FIELD = "sensor_msgs/msg/MagneticField"
WRENCH_STAMPED = "geometry_msgs/msg/WrenchStamped"
STRING = "std_msgs/msg/String"
FLOAT64_MULTI_ARRAY = "std_msgs/msg/Float64MultiArray"

# Float64 values at the end of the fixed-layout stamped messages.
MAGNETIC_FIELD_FLOATS = 12  # field (3) + covariance (9)
WRENCH_FLOATS = 6  # force (3) + torque (3)

# Estimated targets that fill a WrenchStamped, by name: (index in force+torque, SI unit).
WRENCH_COMPONENTS = {
    "fx": 0, "fy": 1, "fz": 2, "force_x": 0, "force_y": 1, "force_z": 2, "normal_force": 2, "fn": 2,
    "tx": 3, "ty": 4, "tz": 5, "mx": 3, "my": 4, "mz": 5, "torque_x": 3, "torque_y": 4, "torque_z": 5,
}
WRENCH_LABELS = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")
WRENCH_UNITS = ("N", "N", "N", "N m", "N m", "N m")
FORCE_UNITS_IN_N = {"N": 1.0, "mN": 1e-3}
TORQUE_UNITS_IN_NM = {"N m": 1.0, "N*m": 1.0, "Nm": 1.0, "N.m": 1.0, "mN m": 1e-3, "N mm": 1e-3}

COMPRESSIONS = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}


class RecordingError(ValueError):
    """A recording that cannot be written or read as asked."""


# --------------------------------------------------------------------------
# Schemas
# --------------------------------------------------------------------------


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


# --------------------------------------------------------------------------
# CDR: fixed-layout stamped messages, vectorised
# --------------------------------------------------------------------------


def _aligned(offset: int, size: int) -> int:
    return -(-offset // size) * size


def stamped_layout(frame_id: str, n_float64: int) -> np.dtype:
    """The CDR byte layout of a message made of a std_msgs/Header with this frame id
    followed by ``n_float64`` float64 values (MagneticField, WrenchStamped), as a numpy
    structured dtype, encapsulation header included."""
    encoded = frame_id.encode("utf-8") + b"\x00"
    # Offsets in the CDR body, i.e. after the 4-byte encapsulation header.
    text_end = 12 + len(encoded)
    values_at = _aligned(text_end, 8)
    return np.dtype({
        "names": ["encapsulation", "sec", "nanosec", "frame_id_length", "frame_id", "values"],
        "formats": ["V4", "<i4", "<u4", "<u4", f"S{len(encoded)}", ("<f8", (n_float64,))],
        "offsets": [0, 4, 8, 12, 16, 4 + values_at],
        "itemsize": 4 + values_at + 8 * n_float64,
    })


def _split_stamp(stamps_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
    return stamps_ns // 1_000_000_000, stamps_ns % 1_000_000_000


def encode_stamped(stamps_ns: np.ndarray, frame_id: str, values: np.ndarray) -> list[bytes]:
    """CDR messages, one per row: Header(stamp, frame_id) followed by the row's float64 values."""
    values = np.asarray(values, dtype=np.float64)
    layout = stamped_layout(frame_id, values.shape[1])
    records = np.zeros(len(values), dtype=layout)
    records["encapsulation"] = np.void(ENCAPSULATION_CDR_LE)
    records["sec"], records["nanosec"] = _split_stamp(stamps_ns)
    records["frame_id_length"] = len(frame_id.encode("utf-8")) + 1
    records["frame_id"] = frame_id.encode("utf-8")
    records["values"] = values
    data, size = records.tobytes(), layout.itemsize
    return [data[i * size:(i + 1) * size] for i in range(len(values))]


def decode_stamped(messages: Sequence[bytes], n_float64: int) -> tuple[np.ndarray, list[str], np.ndarray]:
    """(stamps in ns, frame ids, values (n, n_float64)) of messages made of a Header and
    ``n_float64`` trailing float64 values; RecordingError on anything else."""
    count = len(messages)
    stamps = np.zeros(count, dtype=np.int64)
    values = np.zeros((count, n_float64))
    frame_ids = [""] * count
    lengths = np.fromiter((len(m) for m in messages), dtype=np.int64, count=count)
    # The layout only depends on the frame id's length, so messages of one length share it.
    for length in np.unique(lengths):
        rows = np.flatnonzero(lengths == length)
        text_room = int(length) - 16 - 8 * n_float64
        if text_room < 1:
            raise RecordingError(f"a {length}-byte message is too short for a Header and {n_float64} float64 values")
        layout = np.dtype({"names": ["encapsulation", "sec", "nanosec", "frame_id_length", "text", "values"],
                           "formats": ["V4", "<i4", "<u4", "<u4", f"S{text_room}", ("<f8", (n_float64,))],
                           "offsets": [0, 4, 8, 12, 16, 16 + text_room], "itemsize": int(length)})
        records = np.frombuffer(b"".join(messages[i] for i in rows), dtype=layout)
        if np.any(records["encapsulation"] != np.void(ENCAPSULATION_CDR_LE)):
            raise RecordingError("a message is not little-endian plain CDR (encapsulation header 00 01 00 00)")
        text_lengths = records["frame_id_length"].astype(np.int64)
        if np.any((text_lengths < 1) | (_aligned_array(12 + text_lengths, 8) != 12 + text_room)):
            raise RecordingError(f"a {length}-byte message does not hold a Header and {n_float64} float64 values")
        stamps[rows] = records["sec"].astype(np.int64) * 1_000_000_000 + records["nanosec"]
        values[rows] = records["values"]
        for row, text, text_length in zip(rows, records["text"], text_lengths, strict=True):
            frame_ids[row] = text[:text_length - 1].decode("utf-8", errors="replace")
    return stamps, frame_ids, values


def _aligned_array(offsets: np.ndarray, size: int) -> np.ndarray:
    return -(-offsets // size) * size


# --------------------------------------------------------------------------
# CDR: variable-length messages
# --------------------------------------------------------------------------


class CdrReader:
    """Reads little-endian plain CDR field by field; RecordingError on a short or foreign message."""

    def __init__(self, message: bytes) -> None:
        if message[:4] != ENCAPSULATION_CDR_LE:
            raise RecordingError("a message is not little-endian plain CDR (encapsulation header 00 01 00 00)")
        self._body = memoryview(message)[4:]
        self._at = 0

    def _take(self, size: int, align: int) -> memoryview:
        self._at = _aligned(self._at, align)
        if self._at + size > len(self._body):
            raise RecordingError("a CDR message ends before its last field")
        chunk = self._body[self._at:self._at + size]
        self._at += size
        return chunk

    def uint32(self) -> int:
        return struct.unpack("<I", self._take(4, 4))[0]

    def string(self) -> str:
        length = self.uint32()
        if length < 1:
            raise RecordingError("a CDR string has no terminating NUL")
        return bytes(self._take(length, 1)[:-1]).decode("utf-8", errors="replace")

    def float64_sequence(self) -> np.ndarray:
        count = self.uint32()
        if count == 0:
            return np.zeros(0)
        return np.frombuffer(self._take(8 * count, 8), dtype="<f8").astype(np.float64)


def encode_string(text: str) -> bytes:
    """A std_msgs/msg/String."""
    encoded = text.encode("utf-8") + b"\x00"
    return ENCAPSULATION_CDR_LE + struct.pack("<I", len(encoded)) + encoded


def decode_string(message: bytes) -> str:
    return CdrReader(message).string()


def encode_float64_arrays(values: np.ndarray, label: str) -> list[bytes]:
    """std_msgs/msg/Float64MultiArray messages, one per row of ``values``, each with one
    dimension named ``label`` (rows of one length and one label share a layout: vectorised)."""
    values = np.asarray(values, dtype=np.float64)
    count = values.shape[1]
    encoded = label.encode("utf-8") + b"\x00"
    # Offsets in the CDR body: dim count, label, size, stride, data_offset, data count, data.
    sizes_at = _aligned(8 + len(encoded), 4)
    data_at = _aligned(sizes_at + 16, 8)
    layout = np.dtype({
        "names": ["encapsulation", "dimensions", "label_length", "label", "size", "stride", "data_offset",
                  "data_count", "data"],
        "formats": ["V4", "<u4", "<u4", f"S{len(encoded)}", "<u4", "<u4", "<u4", "<u4", ("<f8", (count,))],
        "offsets": [0, 4, 8, 12, 4 + sizes_at, 8 + sizes_at, 12 + sizes_at, 16 + sizes_at, 4 + data_at],
        "itemsize": 4 + data_at + 8 * count,
    })
    records = np.zeros(len(values), dtype=layout)
    records["encapsulation"] = np.void(ENCAPSULATION_CDR_LE)
    records["dimensions"] = 1
    records["label_length"] = len(encoded)
    records["label"] = label.encode("utf-8")
    records["size"] = records["stride"] = records["data_count"] = count
    records["data"] = values
    data, size = records.tobytes(), layout.itemsize
    return [data[i * size:(i + 1) * size] for i in range(len(values))]


def decode_float64_array(message: bytes) -> tuple[list[str], np.ndarray]:
    """(dimension labels, data) of a std_msgs/msg/Float64MultiArray."""
    reader = CdrReader(message)
    labels = []
    for _ in range(reader.uint32()):
        labels.append(reader.string())
        reader.uint32()
        reader.uint32()
    reader.uint32()
    return labels, reader.float64_sequence()


# --------------------------------------------------------------------------
# What the recorder is told about the stream
# --------------------------------------------------------------------------


def wrench_mapping(target_names: Sequence[str], target_units: Sequence[str]) -> list[tuple[int, int, float]]:
    """(target index, wrench component 0..5, factor to N or N m) for every target that is a
    force or torque component (Fx, force_x, normal_force, Tz, ...)."""
    mapping = []
    for index, (name, unit) in enumerate(zip(target_names, target_units, strict=True)):
        component = WRENCH_COMPONENTS.get(name.lower())
        if component is None:
            continue
        units = FORCE_UNITS_IN_N if component < 3 else TORQUE_UNITS_IN_NM
        if unit not in units:
            raise RecordingError(f"target {name}: unit {unit!r} is not a {'force' if component < 3 else 'torque'} "
                                 f"unit ({', '.join(units)})")
        mapping.append((index, component, units[unit]))
    components = [component for _, component, _ in mapping]
    if len(set(components)) != len(components):
        raise RecordingError(f"targets {list(target_names)} name one wrench component twice")
    return mapping


def magnetic_covariance_T2(noise_rms_uT: np.ndarray | None, lsb_uT: np.ndarray | None) -> np.ndarray:
    """Row-major 3x3 covariance in T^2: sensor noise plus uniform quantisation (LSB^2/12)
    per axis; zeros (ROS: unknown) when the settings are not known."""
    if noise_rms_uT is None or lsb_uT is None:
        return np.zeros(9)
    variance_uT2 = np.asarray(noise_rms_uT) ** 2 + np.asarray(lsb_uT) ** 2 / 12.0
    return np.diag(variance_uT2 / UT_PER_T**2).ravel()


# --------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------


class McapRecorder:
    """Writes frames of the live stream to an MCAP file (see the module notes).

    ``chips``: sensors per frame; ``target_names``/``target_units``: the regression
    estimates in order; ``classes``: the contact states (None without a classifier);
    ``covariance_T2``: the MagneticField covariance (9 values); ``metadata``: JSON values
    stored in the file's ``softtip`` metadata record. ``chunk_size`` bytes per chunk
    before compression (``compression``: zstd, lz4 or none); :meth:`flush` closes the
    chunk in progress and hands the bytes to the operating system (and, with ``fsync``,
    to the disk).
    """

    def __init__(self, path: str | os.PathLike, chips: int, *, target_names: Sequence[str] = (),
                 target_units: Sequence[str] = (), classes: Sequence[str] | None = None,
                 covariance_T2: np.ndarray | None = None, metadata: Mapping | None = None,
                 prefix: str = DEFAULT_PREFIX, chunk_size: int = 256 * 1024, compression: str = "zstd",
                 fsync: bool = False) -> None:
        if isinstance(chips, bool) or not isinstance(chips, int) or chips < 1:
            raise RecordingError(f"chips = {chips!r}: expected an integer >= 1")
        if len(target_names) != len(target_units):
            raise RecordingError(f"target_units: expected {len(target_names)} units, got {len(target_units)}")
        if compression not in COMPRESSIONS:
            raise RecordingError(f"compression = {compression!r}: expected one of {', '.join(COMPRESSIONS)}")
        if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1024:
            raise RecordingError(f"chunk_size = {chunk_size!r}: expected an integer >= 1024 bytes")
        if not re.fullmatch(r"(/[A-Za-z_][A-Za-z0-9_]*)+", prefix):
            raise RecordingError(f"prefix = {prefix!r}: expected a ROS topic namespace such as /fingertip")
        path = Path(path)
        if not path.parent.is_dir():
            raise RecordingError(f"recording {path}: directory {path.parent} does not exist")
        self.path = path
        self.chips = chips
        self.target_names = tuple(target_names)
        self.target_units = tuple(target_units)
        self.classes = None if classes is None else tuple(str(c) for c in classes)
        self._wrench = wrench_mapping(self.target_names, self.target_units)
        self._covariance = np.zeros(9) if covariance_T2 is None else np.asarray(covariance_T2, dtype=np.float64)
        if self._covariance.shape != (9,):
            raise RecordingError(f"covariance_T2: expected 9 values, got shape {self._covariance.shape}")
        self._fsync = bool(fsync)
        self._frame_ids = [f"{prefix.strip('/').replace('/', '_')}_chip{k}" for k in range(chips)]
        self._wrench_frame_id = prefix.strip("/").replace("/", "_")
        self._baseline_version: int | None = None
        self._state_messages: dict[str, bytes] = {}
        self.frames_written = 0

        self._stream = open(path, "wb")
        self._writer = Writer(self._stream, chunk_size=chunk_size, compression=COMPRESSIONS[compression])
        self._writer.start(profile=PROFILE, library=f"softtip/{__version__}")
        self._writer.add_metadata(METADATA_NAME, {
            "format": RECORDING_FORMAT,
            "chips": str(chips),
            "target_names": json.dumps(self.target_names),
            "target_units": json.dumps(self.target_units),
            "classes": json.dumps(self.classes),
            "extra": json.dumps(dict(metadata or {}), allow_nan=False),
            "softtip_version": __version__,
        })
        schemas = {name: self._writer.register_schema(name, SCHEMA_ENCODING, schema_text(name).encode())
                   for name in (MAGNETIC_FIELD, WRENCH_STAMPED, STRING, FLOAT64_MULTI_ARRAY)}

        def channel(topic: str, schema: str, metadata: dict | None = None) -> int:
            return self._writer.register_channel(topic, MESSAGE_ENCODING, schemas[schema], metadata or {})

        self._field_channels = [channel(f"{prefix}/chip{k}/field", MAGNETIC_FIELD) for k in range(chips)]
        self._baseline_channels = [channel(f"{prefix}/chip{k}/baseline", MAGNETIC_FIELD) for k in range(chips)]
        self._wrench_channel = channel(f"{prefix}/wrench", WRENCH_STAMPED) if self._wrench else None
        self._estimates_channel = (channel(f"{prefix}/estimates", FLOAT64_MULTI_ARRAY,
                                           {"names": json.dumps(self.target_names),
                                            "units": json.dumps(self.target_units)})
                                   if self.target_names else None)
        self._estimates_label = ",".join(self.target_names)
        self._state_channel = (channel(f"{prefix}/contact_state", STRING, {"classes": json.dumps(self.classes)})
                               if self.classes is not None else None)

    def write_frames(self, frames: Sequence) -> None:
        """Adds frames (objects with seq, stamp_ns, field_uT, baseline_uT, baseline_version,
        estimates, state), encoding each message type for the whole batch at once."""
        if not frames:
            return
        stamps = np.fromiter((f.stamp_ns for f in frames), dtype=np.int64, count=len(frames))
        fields_T = np.stack([f.field_uT for f in frames]) / UT_PER_T
        if fields_T.shape[1:] != (self.chips, 3):
            raise RecordingError(f"frames hold fields of shape {fields_T.shape[1:]}, the recording {(self.chips, 3)}")
        covariance = np.broadcast_to(self._covariance, (len(frames), 9))
        field_messages = [encode_stamped(stamps, self._frame_ids[k], np.hstack([fields_T[:, k], covariance]))
                          for k in range(self.chips)]

        baseline_rows = []
        for i, frame in enumerate(frames):
            if frame.baseline_uT is not None and frame.baseline_version != self._baseline_version:
                baseline_rows.append(i)
                self._baseline_version = frame.baseline_version
        baseline_messages = {}
        if baseline_rows:
            baselines_T = np.stack([frames[i].baseline_uT for i in baseline_rows]) / UT_PER_T
            zeros = np.zeros((len(baseline_rows), 9))
            encoded = [encode_stamped(stamps[baseline_rows], self._frame_ids[k],
                                      np.hstack([baselines_T[:, k], zeros])) for k in range(self.chips)]
            baseline_messages = {row: [encoded[k][j] for k in range(self.chips)] for j, row in enumerate(baseline_rows)}

        estimated = [i for i, f in enumerate(frames) if f.estimates is not None]
        wrench_messages = estimate_messages = {}
        if estimated and self.target_names:
            estimates = np.stack([frames[i].estimates for i in estimated])
            estimate_messages = dict(zip(estimated, encode_float64_arrays(estimates, self._estimates_label),
                                         strict=True))
            if self._wrench_channel is not None:
                wrenches = np.full((len(estimated), WRENCH_FLOATS), np.nan)
                for target, component, factor in self._wrench:
                    wrenches[:, component] = estimates[:, target] * factor
                wrench_messages = dict(zip(estimated, encode_stamped(stamps[estimated], self._wrench_frame_id,
                                                                     wrenches), strict=True))

        add = self._writer.add_message
        for i, frame in enumerate(frames):
            stamp, seq = int(stamps[i]), frame.seq
            for k, message in enumerate(baseline_messages.get(i, ())):
                add(self._baseline_channels[k], stamp, message, stamp, seq)
            for k in range(self.chips):
                add(self._field_channels[k], stamp, field_messages[k][i], stamp, seq)
            if i in wrench_messages:
                add(self._wrench_channel, stamp, wrench_messages[i], stamp, seq)
            if i in estimate_messages:
                add(self._estimates_channel, stamp, estimate_messages[i], stamp, seq)
            if self._state_channel is not None and frame.state is not None:
                message = self._state_messages.get(frame.state)
                if message is None:  # a handful of states: each encoded once
                    message = self._state_messages[frame.state] = encode_string(frame.state)
                add(self._state_channel, stamp, message, stamp, seq)
        self.frames_written += len(frames)

    def flush(self) -> None:
        """Closes the chunk in progress and writes it out: a killed process keeps it."""
        self._writer.flush()
        if self._fsync:
            os.fsync(self._stream.fileno())

    def close(self) -> None:
        """Writes the summary and footer and closes the file."""
        if self._stream.closed:
            return
        self._writer.finish()
        self._stream.close()


# --------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------


@dataclass
class TopicMessages:
    """The messages of one topic, in file order."""

    schema_name: str
    message_encoding: str
    metadata: dict[str, str]
    log_times: list[int] = field(default_factory=list)
    sequences: list[int] = field(default_factory=list)
    data: list[bytes] = field(default_factory=list)


@dataclass
class Recording:
    """What :func:`read_recording` found: messages per topic, the metadata records, and
    whether (and why) the file ended before its footer."""

    path: Path
    topics: dict[str, TopicMessages]
    metadata: dict[str, dict[str, str]]
    schemas: dict[str, str]
    truncated: bool
    truncation: str = ""

    @property
    def message_count(self) -> int:
        return sum(len(t.data) for t in self.topics.values())


def read_recording(path: str | os.PathLike) -> Recording:
    """Every message of an MCAP file, read front to back without its index, so that a file
    whose writer was killed reads up to its last complete chunk (``truncated`` is then set)."""
    path = Path(path)
    if not path.is_file():
        raise RecordingError(f"recording {path} does not exist")
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    topics: dict[str, TopicMessages] = {}
    metadata: dict[str, dict[str, str]] = {}
    truncation = ""
    footer_seen = False
    with path.open("rb") as stream:
        records = StreamReader(stream, validate_crcs=True).records
        try:
            for record in records:
                if isinstance(record, Message):
                    channel = channels.get(record.channel_id)
                    if channel is None:
                        raise RecordingError(f"{path}: a message on unknown channel {record.channel_id}")
                    topic = topics[channel.topic]
                    topic.log_times.append(record.log_time)
                    topic.sequences.append(record.sequence)
                    topic.data.append(record.data)
                elif isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                    schema = schemas.get(record.schema_id)
                    topics.setdefault(record.topic, TopicMessages(
                        schema.name if schema else "", record.message_encoding, dict(record.metadata)))
                elif isinstance(record, Metadata):
                    metadata[record.name] = dict(record.metadata)
            footer_seen = True
        except InvalidMagic:
            raise RecordingError(f"{path} is not an MCAP file") from None
        except RecordingError:
            raise
        except Exception as problem:  # the torn tail of a killed writer can fail in any way
            if not channels and not metadata:
                raise RecordingError(f"{path}: unreadable MCAP file ({type(problem).__name__}: {problem})") from None
            truncation = f"{type(problem).__name__}: {problem}".strip().rstrip(":")
    return Recording(path, topics, metadata, {s.name: s.data.decode("utf-8", errors="replace")
                                             for s in schemas.values()},
                     truncated=not footer_seen, truncation=truncation)
