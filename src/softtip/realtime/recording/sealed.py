"""An MCAP writer whose file is complete after every flush, so a killed recorder leaves a file
that indexed readers open as it is.

:class:`SealedMcapWriter` keeps the data section's new records (chunks of messages, their message
indexes, metadata and attachments) in memory between flushes. Each :meth:`~SealedMcapWriter.flush`
writes them where the previous data section ended, followed by a new DataEnd record (with the CRC of
the whole data section), the summary (schemas, channels, statistics, chunk, metadata and attachment
indexes, summary offsets), the footer and the closing magic, in one write. The new tail is never
shorter than the one it overwrites, so no stale bytes remain after it.

A process killed between two flushes (SIGKILL, the out-of-memory killer) therefore leaves a file
that ``mcap``'s indexed reader, Foxglove and ``ros2 bag`` open with every message up to the last
flush; the messages since then were only in memory. Only a kill during the write itself (about a
millisecond per flush) can tear the tail, which
:func:`~softtip.realtime.recording.writer.repair_recording` mends. A write the disk refuses or
cuts short (a full disk) puts the previous tail back where it stood, in space the file already
holds, and nothing more is written: the file stays sealed at the last flush. The price is the summary written
again at every flush: it grows by one chunk index per flush (about 150 bytes), and its records are
kept serialised: a flush took 0.7 ms at the start of a recording of two chips at 500 frames/s
flushed twice a second, and 6 ms an hour into it.

It offers the writing half of ``mcap``'s own writer that ``mcap-ros2-support`` uses: ``start``,
``register_schema``, ``register_channel``, ``add_message``, ``add_metadata``, ``add_attachment``,
``flush`` and ``finish``. Schema and channel records go into the data section outside chunks, where
the format allows them and every reader looks for them.
"""

from __future__ import annotations

import errno
import os
import struct
import zlib
from collections import defaultdict
from typing import BinaryIO

import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
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

from softtip.realtime.recording.format import RecordingError

MAGIC = b"\x89MCAP0\r\n"
_FOOTER_HEAD = struct.Struct("<BQQQ")  # the footer's opcode, length and offsets, covered by the summary CRC
_SUMMARY_GROUPS = (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.STATISTICS, Opcode.CHUNK_INDEX, Opcode.ATTACHMENT_INDEX,
                   Opcode.METADATA_INDEX)


def _serialised(record: McapRecord) -> bytes:
    builder = RecordBuilder()
    record.write(builder)
    return builder.end()


# a chunk's compression as the file names it, and the function that does it
COMPRESSIONS = {"zstd": ("zstd", zstandard.ZstdCompressor().compress), "none": ("", bytes)}


class SealedMcapWriter:
    """Writes an MCAP file to ``stream`` (a seekable binary file opened for writing) that is complete
    after every :meth:`flush` (see the module notes). Messages gather in a chunk of up to
    ``chunk_size`` bytes before compression (``compression``: ``"zstd"`` or ``"none"``)."""

    def __init__(self, stream: BinaryIO, *, chunk_size: int = 1024 * 1024, compression: str = "zstd") -> None:
        if compression not in COMPRESSIONS:
            raise RecordingError(f"compression = {compression!r}: expected one of {', '.join(COMPRESSIONS)}")
        self._fd = stream.fileno()
        self._compression, self._compress = COMPRESSIONS[compression]
        self._chunk_size = chunk_size
        self._end = 0  # where the data section's next record goes: the previous DataEnd record
        self._data_crc = 0  # of the data section up to _end
        self._pending = RecordBuilder()  # data section records not yet written
        self._chunk = RecordBuilder()  # the chunk being gathered, uncompressed
        self._chunk_index: defaultdict[int, list[tuple[int, int]]] = defaultdict(list)
        self._chunk_times = [0, 0]
        # the summary's groups but statistics, serialised as their records are made: they never change
        self._summary = {opcode: bytearray() for opcode in _SUMMARY_GROUPS}
        self._statistics = Statistics(attachment_count=0, channel_count=0, channel_message_counts={},
                                      chunk_count=0, message_count=0, message_end_time=0, message_start_time=0,
                                      metadata_count=0, schema_count=0)
        self._finished = False
        self._failed: str | None = None  # why a write failed: nothing more is written
        self._sealed_tail = b""  # the tail the last flush wrote, put back if a later write fails

    # ---------------------------------------------------------------- records

    def _add(self, record: McapRecord) -> tuple[int, bytes]:
        """Queues ``record`` for the data section and returns its offset and its bytes."""
        offset, data = self._end + self._pending.count, _serialised(record)
        self._pending.write(data)
        return offset, data

    def start(self, profile: str = "", library: str = "") -> None:
        """Writes the magic and the header, and seals the file."""
        self._pending.write(MAGIC)
        Header(profile=profile, library=library).write(self._pending)
        self.flush()

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        self._statistics.schema_count += 1
        schema = Schema(id=self._statistics.schema_count, name=name, encoding=encoding, data=data)
        self._summary[Opcode.SCHEMA] += self._add(schema)[1]
        return schema.id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         metadata: dict[str, str] | None = None) -> int:
        if not 0 <= schema_id <= self._statistics.schema_count:  # ids count up from 1; 0: no schema
            raise RecordingError(f"channel {topic!r}: schema {schema_id} was never registered")
        self._statistics.channel_count += 1
        channel = Channel(id=self._statistics.channel_count, topic=topic, message_encoding=message_encoding,
                          schema_id=schema_id, metadata=dict(metadata or {}))
        self._summary[Opcode.CHANNEL] += self._add(channel)[1]
        return channel.id

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int,
                    sequence: int = 0) -> None:
        if not 1 <= channel_id <= self._statistics.channel_count:
            raise RecordingError(f"a message on channel {channel_id}, which was never registered")
        if self._chunk.count == 0:
            self._chunk_times = [log_time, log_time]
        else:
            self._chunk_times = [min(self._chunk_times[0], log_time), max(self._chunk_times[1], log_time)]
        self._chunk_index[channel_id].append((log_time, self._chunk.count))
        Message(channel_id=channel_id, log_time=log_time, data=data, publish_time=publish_time,
                sequence=sequence).write(self._chunk)
        statistics = self._statistics
        statistics.message_start_time = (log_time if statistics.message_count == 0
                                         else min(statistics.message_start_time, log_time))
        statistics.message_end_time = max(statistics.message_end_time, log_time)
        statistics.message_count += 1
        statistics.channel_message_counts[channel_id] = statistics.channel_message_counts.get(channel_id, 0) + 1
        if self._chunk.count >= self._chunk_size:
            self._close_chunk()

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        offset, record = self._add(Metadata(name=name, metadata=dict(data)))
        self._summary[Opcode.METADATA_INDEX] += _serialised(MetadataIndex(offset=offset, length=len(record), name=name))
        self._statistics.metadata_count += 1

    def add_attachment(self, create_time: int, log_time: int, name: str, media_type: str, data: bytes) -> None:
        offset, record = self._add(Attachment(create_time=create_time, log_time=log_time, name=name,
                                              media_type=media_type, data=data))
        self._summary[Opcode.ATTACHMENT_INDEX] += _serialised(AttachmentIndex(
            offset=offset, length=len(record), log_time=log_time, create_time=create_time, data_size=len(data), name=name,
            media_type=media_type))
        self._statistics.attachment_count += 1

    def _close_chunk(self) -> None:
        """Moves the chunk being gathered, compressed, and its message indexes to the pending records."""
        if self._chunk.count == 0:
            return
        content = self._chunk.end()
        compressed = self._compress(content)
        chunk_offset, chunk = self._add(Chunk(
            compression=self._compression, data=compressed, message_start_time=self._chunk_times[0],
            message_end_time=self._chunk_times[1], uncompressed_crc=zlib.crc32(content),
            uncompressed_size=len(content)))
        index_offsets = {}
        index_start = self._end + self._pending.count
        for channel_id, records in self._chunk_index.items():
            index_offsets[channel_id] = self._add(MessageIndex(channel_id=channel_id, records=records))[0]
        self._summary[Opcode.CHUNK_INDEX] += _serialised(ChunkIndex(
            message_start_time=self._chunk_times[0], message_end_time=self._chunk_times[1],
            chunk_start_offset=chunk_offset, chunk_length=len(chunk), message_index_offsets=index_offsets,
            message_index_length=self._end + self._pending.count - index_start, compression=self._compression,
            compressed_size=len(compressed), uncompressed_size=len(content)))
        self._statistics.chunk_count += 1
        self._chunk_index = defaultdict(list)

    # ---------------------------------------------------------------- the tail

    def _tail(self, summary_start: int, data_crc: int) -> bytes:
        """The DataEnd record, summary, footer and magic of a data section that ends at ``summary_start``."""
        self._summary[Opcode.STATISTICS] = _serialised(self._statistics)
        data_end = _serialised(DataEnd(data_section_crc=data_crc))
        summary_start += len(data_end)
        groups = [self._summary[opcode] for opcode in _SUMMARY_GROUPS]
        offsets, start = bytearray(), summary_start
        for opcode, group in zip(_SUMMARY_GROUPS, groups, strict=True):
            if group:
                offsets += _serialised(SummaryOffset(group_opcode=opcode, group_start=start, group_length=len(group)))
                start += len(group)
        offset_start = start
        summary_bytes = b"".join(groups) + offsets
        crc = zlib.crc32(_FOOTER_HEAD.pack(Opcode.FOOTER, 20, summary_start, offset_start),
                         zlib.crc32(summary_bytes))
        footer = _serialised(Footer(summary_start=summary_start, summary_offset_start=offset_start, summary_crc=crc))
        return data_end + summary_bytes + footer + MAGIC

    def flush(self, *, fsync: bool = False) -> None:
        """Closes the chunk being gathered and writes every pending record, then the tail, in one
        write; with ``fsync``, waits until the disk has them."""
        if self._finished:
            raise RecordingError("the recording is finished: nothing more can be written")
        self._close_chunk()
        data = self._pending.end()
        if not data and self._end:
            return  # nothing new: the file is sealed as it is
        if self._failed is not None:
            raise RecordingError(f"the recording stopped at an earlier failed write ({self._failed})")
        end = self._end + len(data)
        data_crc = zlib.crc32(data, self._data_crc)
        tail = self._tail(end, data_crc)
        try:
            written = os.pwrite(self._fd, data + tail, self._end)
            if written != len(data) + len(tail):  # a full disk: the kernel writes what fits, then refuses
                raise OSError(errno.ENOSPC, f"{os.strerror(errno.ENOSPC)}: {written} of {len(data) + len(tail)} bytes "
                              "written")
            if fsync:
                os.fsync(self._fd)
        except OSError as error:
            self._failed = error.strerror or str(error)
            raise RecordingError(f"the recording's write failed ({self._failed}); "
                                 f"{self._seal_again()}") from None
        self._end, self._data_crc, self._sealed_tail = end, data_crc, tail

    def _seal_again(self) -> str:
        """Puts the tail of the last flush back over what a failed write left, where its bytes stood
        (space the file holds already), and cuts the file after it; says what the file holds."""
        try:
            if os.pwrite(self._fd, self._sealed_tail, self._end) != len(self._sealed_tail):
                raise OSError(errno.EIO, "the tail was not written whole")
            os.ftruncate(self._fd, self._end + len(self._sealed_tail))
        except OSError as error:
            return f"its tail could not be put back ({error.strerror or error}): softtip recording repair mends it"
        return ("the file holds every message up to the last flush, sealed" if self._sealed_tail
                else "nothing had been written")

    def finish(self) -> None:
        """Writes what is pending, sealed as after every flush; nothing more can be written. After a
        failed write the file stays as the failure left it (sealed at the last flush)."""
        if not self._finished and self._failed is None:
            self.flush()
        self._finished = True
