"""Reading a recording back, whole or up to the torn tail a killed writer leaves, and what was lost.

:func:`scan_recording` reads an MCAP file record by record without its index, checking every
chunk's CRC: a file whose writer was killed reads up to its last complete chunk, a damaged
chunk in the middle is skipped, and a damaged length field is passed by resynchronising on the next
record; its :class:`Salvage` says what was read and what was lost (bytes,
and the time range the lost chunks' headers state). :func:`read_recording` gathers the messages by
topic; :meth:`TopicMessages.decoded` decodes a topic's ROS 2 messages with ``mcap-ros2-support``
from the schema embedded in the file.
"""

from __future__ import annotations

import mmap
import os
import struct
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from types import SimpleNamespace
from typing import BinaryIO

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Header,
    McapRecord,
    Message,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.stream_reader import breakup_chunk
from mcap_ros2.decoder import DecoderFactory
from numpy.lib.stride_tricks import sliding_window_view

from softtip._core.files import not_a_file
from softtip.realtime.recording.format import RecordingError

MAGIC = b"\x89MCAP0\r\n"
_RECORD_HEAD = struct.Struct("<BQ")  # opcode, length of the record's body
_CHUNK_TIMES = struct.Struct("<QQ")  # a chunk's body begins with its first and last message's log time
# The records of the data section that hold content; the others are indexes, rebuilt on repair.
_CONTENT = {Opcode.HEADER: Header, Opcode.SCHEMA: Schema, Opcode.CHANNEL: Channel, Opcode.METADATA: Metadata,
            Opcode.ATTACHMENT: Attachment}
# every record the format defines but the footer, by opcode: what resynchronising accepts as a record
_RECORDS = {**_CONTENT, Opcode.MESSAGE: Message, Opcode.CHUNK: Chunk, Opcode.MESSAGE_INDEX: MessageIndex,
            Opcode.CHUNK_INDEX: ChunkIndex, Opcode.ATTACHMENT_INDEX: AttachmentIndex, Opcode.STATISTICS: Statistics,
            Opcode.METADATA_INDEX: MetadataIndex, Opcode.SUMMARY_OFFSET: SummaryOffset, Opcode.DATA_END: DataEnd}
_OPCODE_SET = frozenset([*_RECORDS, Opcode.FOOTER])
_OPCODES = np.array(sorted(_OPCODE_SET), dtype=np.uint8)


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
    writers' do; their chunks carry CRCs of their own), which also covers the records outside chunks;
    ``resynchronised``: records whose length field was damaged, past which the scan found the next
    record (see :func:`scan_recording`). Messages still in the writer's memory when it
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
    resynchronised: int = 0
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

    def refuse_unexplained_damage(self, source: str | os.PathLike) -> None:
        """Raises RecordingError when the data section fails its CRC and no damaged or resynchronised
        record explains it: then a record without a CRC of its own (a schema, a channel, the metadata)
        was altered, and a topic or label read from it may be misnamed with nothing to show it."""
        if self.data_crc_ok is False and not (self.damaged_records or self.resynchronised):
            raise RecordingError(f"{source}: the data section fails its CRC though every record in it parses: a "
                                 "schema, channel or metadata record (topic names, units, labels) was altered")

    def report(self) -> dict:
        """The salvage as JSON values; times in s from the first complete message."""
        origin = self.first_ns or 0
        lost = (None if self.lost_from_ns is None else
                [round((self.lost_from_ns - origin) * 1e-9, 6), round((self.lost_to_ns - origin) * 1e-9, 6)])
        return {"messages_read": self.messages, "truncated": self.truncated, "bytes_lost": self.bytes_lost,
                "damaged_records": self.damaged_records, "time_lost_s": lost, "data_crc_ok": self.data_crc_ok,
                "resynchronised": self.resynchronised,
                **({"tail": self.reason} if self.reason else {})}


class _WholeReads(ReadDataStream):
    """mcap's record stream, refusing a read that comes back short (mcap's returns what is left)."""

    def read(self, length: int) -> bytes:
        data = super().read(length)
        if len(data) != length:
            raise EndOfFile()
        return data


def _records(opcode: int, body: bytes) -> list[McapRecord] | None:
    """The content records of one record's body: a chunk's messages, CRC checked, the record itself,
    or none (an index; a record of an opcode the format does not define, which readers skip); None
    if the body does not parse as a record of ``opcode`` that ends where the body ends."""
    record = _RECORDS.get(opcode)
    if record is None:
        return []
    stream = _WholeReads(BytesIO(body))
    try:
        if opcode == Opcode.CHUNK:
            records = breakup_chunk(Chunk.read(stream), validate_crc=True)
        elif opcode == Opcode.MESSAGE:
            records = [Message.read(stream, len(body))]
        else:
            parsed = record.read(stream)
            records = [parsed] if opcode in _CONTENT else []  # an index: rebuilt on repair
    except Exception:  # a CRC mismatch, a compressed stream or a record that does not parse
        return None
    return records if stream.count == len(body) else None


def _heads_plausible(content: np.ndarray, at: np.ndarray, *, whole: bool) -> np.ndarray:
    """Whether a record could begin at each offset of ``at`` into ``content`` (the file's bytes): a
    defined opcode, and with ``whole`` a length that fits in the file. At the file's end, or too close
    to it for a record's head (a torn tail), true unless ``whole``."""
    size = len(content)
    room = at + _RECORD_HEAD.size <= size
    plausible = ~room & (at <= size) & (not whole)
    head = at[room]
    plausible[room] = np.isin(content[head], _OPCODES)
    if whole and len(head):
        lengths = sliding_window_view(content, 8)[head + 1].copy().view("<u8").ravel()
        plausible[room] &= lengths <= (size - head - _RECORD_HEAD.size).astype(np.uint64)
    return plausible


def _next_record(content: bytes | mmap.mmap, start: int) -> int | None:
    """The first offset at or after ``start`` into the file's bytes ``content`` where a whole record
    begins that parses (see :func:`_records`) and is followed by a plausible record's head, or None."""
    array = np.frombuffer(content, dtype=np.uint8)
    size = len(array)
    candidates = start + np.flatnonzero(np.isin(array[start:size - _RECORD_HEAD.size + 1], _OPCODES))
    candidates = candidates[_heads_plausible(array, candidates, whole=True)]
    if not len(candidates):
        return None
    lengths = sliding_window_view(array, 8)[candidates + 1].copy().view("<u8").ravel().astype(np.int64)
    ends = candidates + _RECORD_HEAD.size + lengths
    chained = _heads_plausible(array, ends, whole=False)
    for offset, end in zip(candidates[chained].tolist(), ends[chained].tolist(), strict=True):
        if _records(content[offset], content[offset + _RECORD_HEAD.size:end]) is not None:
            return offset
    return None


def scan_recording(stream: BinaryIO, salvage: Salvage, source: str | os.PathLike) -> Iterator[McapRecord]:
    """The content records of the MCAP file ``source`` open as ``stream`` (header, schemas, channels,
    messages, metadata, attachments), in file order, with the messages taken out of their chunks;
    ``salvage`` is filled as the scan goes. Raises RecordingError for a file that does not start as MCAP.

    A record whose length field is damaged (it runs past the file's end, or the bytes after it do
    not begin a record) does not end the scan: it resynchronises on the next place where a record
    begins that parses whole and is followed by another record's head, as a file system checker
    walks past a damaged entry. The damaged record is then read again with the length that place
    implies; a chunk so read whose CRC holds is salvaged whole (``resynchronised`` counts both).
    """
    if stream.read(len(MAGIC)) != MAGIC:
        raise RecordingError(f"{source} is not an MCAP file")
    # closed when the scan lets go of it (a close here would fail while an array of it is alive)
    yield from _scan(mmap.mmap(stream.fileno(), 0, access=mmap.ACCESS_READ), salvage)


def _crc_of(content: mmap.mmap, stop: int) -> int:
    """The CRC32 of the file's first ``stop`` bytes, read in place."""
    with memoryview(content) as view, view[:stop] as head:
        return zlib.crc32(head)


def _scan(content: mmap.mmap, salvage: Salvage) -> Iterator[McapRecord]:
    size = len(content)
    salvage.bytes_read = position = len(MAGIC)
    in_summary = False
    while True:
        if size - position < _RECORD_HEAD.size:
            salvage.reason = "the file ends between records" if position == size else "the file ends in a record's head"
            return
        opcode, length = _RECORD_HEAD.unpack(content[position:position + _RECORD_HEAD.size])
        end = position + _RECORD_HEAD.size + length
        if opcode == Opcode.FOOTER and end <= size:
            salvage.truncated = False
            salvage.bytes_read = size - salvage._damaged_bytes  # the summary: indexes of the data
            return
        # whether the record ends where another begins (or the file does, or too close for a head)
        fits = end <= size and (end + _RECORD_HEAD.size > size or content[end] in _OPCODE_SET)
        records = (_records(opcode, content[position + _RECORD_HEAD.size:end]) if fits and not in_summary
                   else [] if fits else None)
        if records is None:  # a damaged record, or a damaged length: find where the next record begins
            found = _next_record(content, position + 1)
            if found is None and not fits:
                if opcode == Opcode.CHUNK:
                    salvage._lose_chunk(content[position + _RECORD_HEAD.size:size])
                if length > size:
                    salvage.reason = (f"a record of opcode 0x{opcode:02x} claims {length} bytes, "
                                      "more than the file holds")
                elif end > size:
                    salvage.reason = f"the file ends {end - size} bytes short of a record (opcode 0x{opcode:02x})"
                else:
                    salvage.reason = f"no record follows the record of opcode 0x{opcode:02x} at byte {position}"
                return
            if found is not None:
                implied = [] if in_summary else _records(opcode, content[position + _RECORD_HEAD.size:found])
                if implied is not None:  # whole with the length the next record implies
                    salvage.resynchronised += 1
                    records, end = implied, found
                elif not fits:
                    end = found  # lost up to the next record
            if records is None:
                salvage._lose(opcode, content[position + _RECORD_HEAD.size:end])
                position = end
                continue
        if opcode == Opcode.DATA_END and not in_summary:
            stated = int.from_bytes(content[position + _RECORD_HEAD.size:end][:4], "little")
            salvage.data_crc_ok = None if stated == 0 else stated == _crc_of(content, position)
            in_summary = True  # the summary repeats schemas and channels and indexes the data: nothing new
        for record in records:
            if isinstance(record, Message):
                salvage._count(record)
            yield record
        salvage.bytes_read += end - position
        position = end


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
    problem = not_a_file(path)
    if problem:
        raise RecordingError(f"recording {path} {problem}")
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
