"""Writing the live stream to an MCAP file in ROS 2 message types (:mod:`~softtip.realtime.recording.format`),
and repairing a recording whose writer was killed.

Messages are serialised by ``mcap-ros2-support`` from the embedded message definitions and
written by :class:`~softtip.realtime.recording.sealed.SealedMcapWriter`, so the file is complete,
summary and index included, after every :meth:`McapRecorder.flush`: a process that is killed
leaves a file that indexed readers (``mcap``'s seeking reader, Foxglove, ``ros2 bag``) open as it
is, with every message up to its last flush. A file whose tail was torn all the same (a kill
during a flush's write, a copy cut short, another writer's killed file) is mended by
:func:`repair_recording`, which rewrites it with every complete message and the summary and index
it lacks.
"""

from __future__ import annotations

import json
from dataclasses import astuple
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from mcap_ros2.writer import Writer
from mcap.well_known import Profile

from softtip import __version__
from softtip._core.channels import MAGNETIC, Reading
from softtip._core.config import PositiveInteger, checked, integer
from softtip._core.files import atomic_write, not_a_file
from softtip.realtime.recording.format import (
    DEFAULT_PREFIX,
    FLOAT64_MULTI_ARRAY,
    MESSAGE_ENCODING,
    METADATA_NAME,
    RECORDING_FORMAT,
    STRING,
    WRENCH_STAMPED,
    RecordingError,
    frame_id,
    reading_fields,
    reading_topic,
    schema_text,
    wrench_mapping,
    wrench_values,
)
from softtip.realtime.recording.reader import Salvage, scan_recording
from softtip.realtime.recording.sealed import COMPRESSIONS, SealedMcapWriter

CHUNK_SIZE = integer(1024, expected="an integer >= 1024 bytes")  # the smallest MCAP chunk the recorder accepts


class _Ros2Writer(Writer):
    """mcap-ros2-support's writer, serialising ROS 2 messages, over a
    :class:`~softtip.realtime.recording.sealed.SealedMcapWriter` instead of ``mcap``'s writer, with
    channel metadata, which it does not offer. Both go to the MCAP writer it wraps (``_writer``),
    channels under the topic map it keeps (``_channel_ids``)."""

    def __init__(self, writer: SealedMcapWriter) -> None:
        self._writer = writer
        self._encoders = {}
        self._channel_ids = {}
        self._finished = False
        writer.start(profile=Profile.ROS2, library=f"softtip {__version__}")

    def register_channel(self, topic: str, schema: Schema, metadata: Mapping[str, str]) -> None:
        self._channel_ids[topic] = self._writer.register_channel(topic, MESSAGE_ENCODING, schema.id, dict(metadata))


def _vector(values: np.ndarray) -> dict:
    x, y, z = values.tolist()
    return {"x": x, "y": y, "z": z}


def _header(stamp_ns: int, frame: str) -> dict:
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    return {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": frame}


class McapRecorder:
    """Writes frames of the live stream to an MCAP file (see the module notes).

    ``chips``: sensors per frame, reading ``reading`` (flux density or force);
    ``target_names``/``target_units``: the regression
    estimates in order; ``classes``: the contact states (None without a classifier);
    ``covariance_T2``: the MagneticField covariance (9 values; Hall chips); ``metadata``: JSON values
    stored in the file's ``softtip`` metadata record. ``chunk_size`` bytes per chunk
    before compression (``compression``: zstd or none); :meth:`flush` closes the
    chunk in progress and hands the bytes to the operating system (and, with ``fsync``,
    to the disk).
    """

    def __init__(self, path: str | os.PathLike, chips: int, *, target_names: Sequence[str] = (),
                 target_units: Sequence[str] = (), classes: Sequence[str] | None = None,
                 covariance_T2: np.ndarray | None = None, metadata: Mapping | None = None,
                 prefix: str = DEFAULT_PREFIX, chunk_size: int = 256 * 1024, compression: str = "zstd",
                 fsync: bool = False, reading: Reading = MAGNETIC) -> None:
        checked(PositiveInteger, "chips", chips, RecordingError)
        self.reading = reading
        leaf, reading_schema = reading_topic(reading)
        if len(target_names) != len(target_units):
            raise RecordingError(f"target_units: expected {len(target_names)} units, got {len(target_units)}")
        if compression not in COMPRESSIONS:
            raise RecordingError(f"compression = {compression!r}: expected one of {', '.join(COMPRESSIONS)}")
        checked(CHUNK_SIZE, "chunk_size", chunk_size, RecordingError)
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
        covariance = np.zeros(9) if covariance_T2 is None else np.asarray(covariance_T2, dtype=np.float64)
        if covariance.shape != (9,):
            raise RecordingError(f"covariance_T2: expected 9 values, got shape {covariance.shape}")
        self._covariance = covariance.tolist()
        self._fsync = bool(fsync)
        self._frame_ids = [frame_id(prefix, k) for k in range(chips)]
        self._wrench_frame_id = frame_id(prefix)
        self._baseline_version: int | None = None
        self.frames_written = 0

        self._stream = open(path, "wb")
        self._sealed = SealedMcapWriter(self._stream, chunk_size=chunk_size, compression=compression)
        self._writer = _Ros2Writer(self._sealed)
        self._writer.add_metadata(METADATA_NAME, {
            "format": RECORDING_FORMAT,
            "chips": str(chips),
            "reading": json.dumps({"quantity": reading.quantity, "unit": reading.unit}),
            "target_names": json.dumps(self.target_names),
            "target_units": json.dumps(self.target_units),
            "classes": json.dumps(self.classes),
            "extra": json.dumps(dict(metadata or {}), allow_nan=False),
            "softtip_version": __version__,
        })
        schemas = {name: self._writer.register_msgdef(name, schema_text(name))
                   for name in dict.fromkeys((reading_schema, WRENCH_STAMPED, STRING, FLOAT64_MULTI_ARRAY))}

        def channel(topic: str, schema: str, metadata: dict | None = None) -> tuple[str, Schema]:
            self._writer.register_channel(topic, schemas[schema], metadata or {})
            return topic, schemas[schema]

        self._reading_channels = [channel(f"{prefix}/chip{k}/{leaf}", reading_schema) for k in range(chips)]
        self._baseline_channels = [channel(f"{prefix}/chip{k}/baseline", reading_schema) for k in range(chips)]
        self._wrench_channel = channel(f"{prefix}/wrench", WRENCH_STAMPED) if self._wrench else None
        self._estimates_channel = (channel(f"{prefix}/estimates", FLOAT64_MULTI_ARRAY,
                                           {"names": json.dumps(self.target_names),
                                            "units": json.dumps(self.target_units)})
                                   if self.target_names else None)
        self._estimates_label = ",".join(self.target_names)
        self._state_channel = (channel(f"{prefix}/contact_state", STRING, {"classes": json.dumps(self.classes)})
                               if self.classes is not None else None)

    def _reading(self, stamp_ns: int, chip: int, values: np.ndarray, covariance: list[float] | None) -> dict:
        return {"header": _header(stamp_ns, self._frame_ids[chip]),
                **reading_fields(self.reading, values, _vector, covariance)}

    def write_frames(self, frames: Sequence) -> None:
        """Adds frames (objects with seq, stamp_ns, reading, baseline, baseline_version,
        estimates, state)."""
        if not frames:
            return
        readings = np.stack([f.reading for f in frames])
        if readings.shape[1:] != (self.chips, len(self.reading.axes)):
            raise RecordingError(f"frames hold readings of shape {readings.shape[1:]}, the recording "
                                 f"{(self.chips, len(self.reading.axes))}")
        write = self._writer.write_message
        for frame, reading in zip(frames, readings, strict=True):
            stamp, seq = frame.stamp_ns, frame.seq
            if frame.baseline is not None and frame.baseline_version != self._baseline_version:
                self._baseline_version = frame.baseline_version
                for k, (topic, schema) in enumerate(self._baseline_channels):
                    # a baseline has no covariance of its own
                    write(topic, schema, self._reading(stamp, k, frame.baseline[k], None), stamp, stamp, seq)
            for k, (topic, schema) in enumerate(self._reading_channels):
                write(topic, schema, self._reading(stamp, k, reading[k], self._covariance), stamp, stamp, seq)
            if frame.estimates is not None and self._estimates_channel is not None:
                if self._wrench_channel is not None:
                    wrench = wrench_values(frame.estimates, self._wrench)
                    write(*self._wrench_channel, {"header": _header(stamp, self._wrench_frame_id),
                                                  "wrench": {"force": _vector(wrench[:3]),
                                                             "torque": _vector(wrench[3:])}}, stamp, stamp, seq)
                count = len(frame.estimates)
                write(*self._estimates_channel, {
                    "layout": {"dim": [{"label": self._estimates_label, "size": count, "stride": count}],
                               "data_offset": 0},
                    "data": np.asarray(frame.estimates, dtype=np.float64).tolist()}, stamp, stamp, seq)
            if self._state_channel is not None and frame.state is not None:
                write(*self._state_channel, {"data": frame.state}, stamp, stamp, seq)
        self.frames_written += len(frames)

    def flush(self) -> None:
        """Closes the chunk in progress and writes it out with the summary: a killed process keeps a
        complete file."""
        self._sealed.flush(fsync=self._fsync)

    def close(self) -> None:
        """Writes the summary and footer and closes the file."""
        if self._stream.closed:
            return
        self._writer.finish()
        self._stream.close()


def repair_recording(path: str | os.PathLike, output: str | os.PathLike) -> Salvage:
    """Writes to ``output`` every complete message, schema, channel, metadata record and attachment of
    the recording ``path`` (:func:`~softtip.realtime.recording.reader.scan_recording`: up to a torn
    tail, past a damaged chunk, resynchronising past a damaged length field), in chunks with the
    summary and index an indexed reader needs and a CRC of the whole data section, and returns what
    was salvaged. ``output`` is replaced only once it is complete.
    A recording whose data section fails its CRC with no damaged record to explain it is refused
    (:meth:`~softtip.realtime.recording.reader.Salvage.refuse_unexplained_damage`)."""
    path, output = Path(path), Path(output)
    problem = not_a_file(path)
    if problem:
        raise RecordingError(f"recording {path} {problem}")
    salvage = Salvage(path.stat().st_size)

    def rewrite(handle) -> None:
        writer = McapWriter(handle, compression=CompressionType.ZSTD, enable_data_crcs=True)
        schema_ids, channel_ids = {0: 0}, {}
        started = False
        with path.open("rb") as stream:
            for record in scan_recording(stream, salvage, path):
                if not started:
                    # the killed file's own header (profile, writer's name), or an empty one if it lost it
                    header = record if isinstance(record, Header) else Header("", "")
                    writer.start(*astuple(header))
                    started = True
                if isinstance(record, Message):
                    if record.channel_id not in channel_ids:
                        raise RecordingError(f"{path}: a message on channel {record.channel_id}, whose record "
                                             "was lost")
                    writer.add_message(channel_ids[record.channel_id], record.log_time, record.data,
                                       record.publish_time, record.sequence)
                elif isinstance(record, Schema):
                    schema_ids[record.id] = writer.register_schema(record.name, record.encoding, record.data)
                elif isinstance(record, Channel):
                    channel_ids[record.id] = writer.register_channel(
                        record.topic, record.message_encoding, schema_ids.get(record.schema_id, 0), record.metadata)
                elif isinstance(record, Metadata):
                    writer.add_metadata(record.name, record.metadata)
                elif isinstance(record, Attachment):
                    writer.add_attachment(record.create_time, record.log_time, record.name, record.media_type,
                                          record.data)
        if not started:
            raise RecordingError(f"{path}: nothing to salvage ({salvage.reason})")
        salvage.refuse_unexplained_damage(path)  # a new CRC would vouch for the altered record
        writer.finish()

    atomic_write(output, rewrite)
    return salvage
