"""Reading a recording back, whole or up to the torn tail a killed writer leaves, and what was lost.

:func:`scan_recording` reads an MCAP file record by record without its index, checking every
chunk's CRC: a file whose writer was killed reads up to its last complete chunk, and a damaged
chunk in the middle is skipped; its :class:`Salvage` says what was read and what was lost (bytes,
and the time range the lost chunks' headers state). :func:`read_recording` gathers the messages by
topic; :meth:`TopicMessages.decoded` decodes a topic's ROS 2 messages with ``mcap-ros2-support``
from the schema embedded in the file.
"""

from __future__ import annotations

import os
import struct
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from types import SimpleNamespace
from typing import BinaryIO

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, Chunk, Header, McapRecord, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk
from mcap_ros2.decoder import DecoderFactory

from softtip.realtime.recording.format import RecordingError

MAGIC = b"\x89MCAP0\r\n"
_RECORD_HEAD = struct.Struct("<BQ")  # opcode, length of the record's body
_CHUNK_TIMES = struct.Struct("<QQ")  # a chunk's body begins with its first and last message's log time
# The records of the data section that hold content; the others are indexes, rebuilt on repair.
_CONTENT = {Opcode.HEADER: Header, Opcode.SCHEMA: Schema, Opcode.CHANNEL: Channel, Opcode.METADATA: Metadata,
            Opcode.ATTACHMENT: Attachment}


@dataclass
class Salvage:
    """What a read of a recording got and what it lost.

    ``messages``: complete messages read, the first at log time ``first_ns``; ``bytes_read`` of the
    file's ``file_bytes`` held them (the rest: ``bytes_lost``); ``truncated``: the file ends before
    its footer (the writer was killed, or the file was cut), ``reason`` says how its tail ends;
    ``damaged_records``: records skipped because they do not parse (a chunk: its CRC, its
    compression); ``lost_from_ns``, ``lost_to_ns``: the log times the lost chunks' headers state
    (None when no lost chunk's header could be read); ``data_crc_ok``: whether the data section
    matches the CRC its DataEnd record states (None: no DataEnd, or one that states none, as some
    writers' do; their chunks carry CRCs of their own), which also covers the records outside chunks. Messages still in the writer's memory when it
    was killed were never in the file: no file says how many.
    """

    file_bytes: int
    bytes_read: int = 0
    messages: int = 0
    truncated: bool = True
    reason: str = ""
    damaged_records: int = 0
    lost_from_ns: int | None = None
    lost_to_ns: int | None = None
    first_ns: int | None = None
    data_crc_ok: bool | None = None
    _damaged_bytes: int = 0

    @property
    def bytes_lost(self) -> int:
        return self.file_bytes - self.bytes_read

    def _lose(self, opcode: int, body: bytes) -> None:
        """A damaged record, skipped."""
        self.damaged_records += 1
        self._damaged_bytes += _RECORD_HEAD.size + len(body)
        if opcode == Opcode.CHUNK:
            self._lose_chunk(body)

    def _lose_chunk(self, body: bytes) -> None:
        if len(body) >= _CHUNK_TIMES.size:
            start, end = _CHUNK_TIMES.unpack_from(body)
            self.lost_from_ns = start if self.lost_from_ns is None else min(start, self.lost_from_ns)
            self.lost_to_ns = end if self.lost_to_ns is None else max(end, self.lost_to_ns)

    def _count(self, message: Message) -> None:
        self.messages += 1
        self.first_ns = message.log_time if self.first_ns is None else min(message.log_time, self.first_ns)

    def report(self) -> dict:
        """The salvage as JSON values; times in s from the first complete message."""
        origin = self.first_ns or 0
        lost = (None if self.lost_from_ns is None else
                [round((self.lost_from_ns - origin) * 1e-9, 6), round((self.lost_to_ns - origin) * 1e-9, 6)])
        return {"messages_read": self.messages, "truncated": self.truncated, "bytes_lost": self.bytes_lost,
                "damaged_records": self.damaged_records, "time_lost_s": lost, "data_crc_ok": self.data_crc_ok,
                **({"tail": self.reason} if self.reason else {})}


def _parsed(opcode: int, body: bytes) -> list[McapRecord]:
    """The records of one record's body: a chunk's, CRC checked, or the record itself."""
    stream = ReadDataStream(BytesIO(body))
    if opcode == Opcode.CHUNK:
        return breakup_chunk(Chunk.read(stream), validate_crc=True)
    if opcode == Opcode.MESSAGE:
        return [Message.read(stream, len(body))]
    return [_CONTENT[opcode].read(stream)]


def scan_recording(stream: BinaryIO, salvage: Salvage, source: str | os.PathLike) -> Iterator[McapRecord]:
    """The content records of the MCAP file ``source`` open as ``stream`` (header, schemas, channels,
    messages, metadata, attachments), in file order, with the messages taken out of their chunks;
    ``salvage`` is filled as the scan goes. Raises RecordingError for a file that does not start as MCAP."""
    if stream.read(len(MAGIC)) != MAGIC:
        raise RecordingError(f"{source} is not an MCAP file")
    salvage.bytes_read = len(MAGIC)
    in_summary = False
    data_crc = zlib.crc32(MAGIC)  # of the data section, up to its DataEnd record
    while True:
        head = stream.read(_RECORD_HEAD.size)
        if len(head) < _RECORD_HEAD.size:
            salvage.reason = "the file ends between records" if not head else "the file ends in a record's head"
            return
        opcode, length = _RECORD_HEAD.unpack(head)
        if length > salvage.file_bytes:
            salvage.reason = f"a record of opcode 0x{opcode:02x} claims {length} bytes, more than the file holds"
            return
        body = stream.read(length)
        if len(body) < length:
            salvage.reason = f"the file ends {length - len(body)} bytes short of a record (opcode 0x{opcode:02x})"
            if opcode == Opcode.CHUNK:
                salvage._lose_chunk(body)
            return
        if opcode == Opcode.FOOTER:
            salvage.truncated = False
            salvage.bytes_read = salvage.file_bytes - salvage._damaged_bytes  # the summary: indexes of the data
            return
        if opcode == Opcode.DATA_END and not in_summary:
            stated = int.from_bytes(body[:4], "little")
            salvage.data_crc_ok = None if stated == 0 else stated == data_crc
            in_summary = True  # the summary repeats schemas and channels and indexes the data: nothing new
        elif not in_summary:
            data_crc = zlib.crc32(body, zlib.crc32(head, data_crc))
        if not in_summary and (opcode in (Opcode.CHUNK, Opcode.MESSAGE) or opcode in _CONTENT):
            try:
                records = _parsed(opcode, body)
            except Exception:  # a CRC mismatch, a compressed stream or a record that does not parse
                salvage._lose(opcode, body)
                continue
            for record in records:
                if isinstance(record, Message):
                    salvage._count(record)
                yield record
        salvage.bytes_read += _RECORD_HEAD.size + length


@dataclass
class TopicMessages:
    """The messages of one topic, in file order; ``decoder`` turns one into a ROS 2 message
    (None when the topic holds no ROS 2 CDR messages with a ``ros2msg`` schema)."""

    topic: str
    schema_name: str
    message_encoding: str
    metadata: dict[str, str]
    decoder: Callable[[bytes], SimpleNamespace] | None
    log_times: list[int] = field(default_factory=list)
    sequences: list[int] = field(default_factory=list)
    data: list[bytes] = field(default_factory=list)

    def decoded(self) -> list[SimpleNamespace]:
        """Every message as a ROS 2 message object (fields as attributes)."""
        if self.decoder is None:
            raise RecordingError(f"topic {self.topic}: {self.message_encoding or 'schemaless'} messages of "
                                 f"{self.schema_name or 'no schema'} are not ROS 2 messages with a ros2msg schema")
        try:
            return [self.decoder(message) for message in self.data]
        except Exception as problem:  # the decoder reports a short or foreign message in its own way
            raise RecordingError(f"topic {self.topic}: a message does not decode as {self.schema_name} "
                                 f"({type(problem).__name__}: {problem})") from None


@dataclass
class Recording:
    """What :func:`read_recording` found: messages per topic, the metadata records, and what was
    salvaged (:class:`Salvage`: whether, and how, the file ended before its footer; what was lost)."""

    path: Path
    topics: dict[str, TopicMessages]
    metadata: dict[str, dict[str, str]]
    schemas: dict[str, str]
    salvage: Salvage

    @property
    def truncated(self) -> bool:
        return self.salvage.truncated

    @property
    def truncation(self) -> str:
        return self.salvage.reason

    @property
    def message_count(self) -> int:
        return sum(len(t.data) for t in self.topics.values())


def _decoder(factory: DecoderFactory, path: Path, channel: Channel, schema: Schema | None):
    try:
        return factory.decoder_for(channel.message_encoding, schema)
    except Exception as problem:  # a ros2msg schema the library cannot parse
        raise RecordingError(f"{path}: topic {channel.topic}: schema {schema.name} does not parse "
                             f"({type(problem).__name__}: {problem})") from None


def read_recording(path: str | os.PathLike) -> Recording:
    """Every message of an MCAP file, read front to back without its index (:func:`scan_recording`),
    so that a file whose writer was killed reads up to its last complete chunk (``truncated`` is then
    set) and a damaged chunk costs only its own messages."""
    path = Path(path)
    if not path.is_file():
        raise RecordingError(f"recording {path} does not exist")
    factory = DecoderFactory()
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    topics: dict[str, TopicMessages] = {}
    metadata: dict[str, dict[str, str]] = {}
    salvage = Salvage(path.stat().st_size)
    with path.open("rb") as stream:
        for record in scan_recording(stream, salvage, path):
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
                if record.topic not in topics:
                    schema = schemas.get(record.schema_id)
                    topics[record.topic] = TopicMessages(
                        record.topic, schema.name if schema else "", record.message_encoding,
                        dict(record.metadata), _decoder(factory, path, record, schema))
            elif isinstance(record, Metadata):
                metadata[record.name] = dict(record.metadata)
    if salvage.truncated and not channels and not metadata:
        raise RecordingError(f"{path}: unreadable MCAP file ({salvage.reason})")
    return Recording(path, topics, metadata, {s.name: s.data.decode("utf-8", errors="replace")
                                             for s in schemas.values()}, salvage)
