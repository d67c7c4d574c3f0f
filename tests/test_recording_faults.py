"""Recordings that survive faults: a live session stopped by SIGTERM or SIGHUP finishes its file as on
Ctrl-C; a file whose writer was killed (SIGKILL) opens in ``mcap``'s indexed reader as it is, with
every message up to the last flush; a file torn during a write is repaired into one that opens with
every complete message; a torn or damaged file converts with a report of what was lost."""

from __future__ import annotations

import collections
import errno
import io
import json
import os
import re
import signal
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.reader import NonSeekingReader, make_reader
from mcap.writer import Writer
from mcap.records import Chunk, ChunkIndex, Message, MessageIndex, Statistics
from typer.testing import CliRunner

from softtip.cli.main import app
from softtip.realtime.recording import convert
from softtip.realtime.recording.format import RecordingError
from softtip.realtime.recording.reader import (
    MAGIC,
    Salvage,
    TopicMessages,
    _heads_plausible,
    _next_record,
    _records,
    read_recording,
    scan_recording,
)
from softtip.realtime.recording.sealed import SealedMcapWriter
from softtip.realtime.recording.writer import McapRecorder, repair_recording

HANG_GUARD_S = 60.0

# A live session of a paced Hall chip (200 frames/s) recorded with a flush every 50 ms in chunks of
# 1 kB, run by ``run_live`` as ``softtip live`` runs it; it prints the frames it wrote when it ends.
LIVE_RECORDING = """
import json, sys
import numpy as np
from softtip._core.channels import MAGNETIC
from softtip.hardware import PacedSource
from softtip.realtime.session import run_live
from softtip.realtime.sinks.recorder import RecorderSink

t = np.arange(400) / 200.0
source = PacedSource(np.stack([np.sin(t), np.cos(t), t], axis=1)[:, None, :], 200.0, reading=MAGNETIC, name="paced")
sink = RecorderSink(sys.argv[1], flush_interval_s=0.05, chunk_size=1024)
run_live(source, [], [sink], None, baseline_frames=1)
print(json.dumps({"frames": sink.recorder.frames_written}), flush=True)
"""


def record_until(path: Path, signal_number: int) -> subprocess.CompletedProcess:
    """Runs the live recording until its file holds a few flushed chunks, then sends ``signal_number``."""
    child = subprocess.Popen([sys.executable, "-c", LIVE_RECORDING, str(path)], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + HANG_GUARD_S
        while (not path.exists() or path.stat().st_size < 8000) and time.monotonic() < deadline:
            assert child.poll() is None, child.stderr.read()
            time.sleep(0.05)
        assert path.stat().st_size >= 8000, "the recording did not grow in time"
        child.send_signal(signal_number)
        stdout, stderr = child.communicate(timeout=HANG_GUARD_S)
    finally:
        if child.poll() is None:
            child.kill()
            child.communicate()
    return subprocess.CompletedProcess(child.args, child.returncode, stdout, stderr)


def indexed_messages(path: Path) -> tuple[object, list[tuple]]:
    """The summary and the messages of ``path`` as mcap's seeking reader gives them through the index."""
    with path.open("rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None and summary.chunk_indexes, f"{path} has no summary or index"
        messages = [(channel.topic, message.log_time, message.sequence, message.data)
                    for _, channel, message in reader.iter_messages(log_time_order=False)]
    return summary, messages


def streamed_messages(path: Path) -> tuple[list[tuple], Exception | None]:
    """The messages mcap's stream reader reads front to back, and the error it ends on (a torn tail)."""
    messages, tail = [], None
    with path.open("rb") as stream:
        try:
            for _, channel, message in NonSeekingReader(stream).iter_messages(log_time_order=False):
                messages.append((channel.topic, message.log_time, message.sequence, message.data))
        except Exception as error:
            tail = error
    return messages, tail


def chip_sequences(messages: list[tuple]) -> list[int]:
    return [sequence for topic, _, sequence, _ in messages if topic == "/fingertip/chip0/field"]


@pytest.mark.parametrize("stop", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_a_live_recording_stopped_by_a_signal_is_finished_as_on_ctrl_c(tmp_path, stop):
    path = tmp_path / "stopped.mcap"
    ended = record_until(path, stop)
    assert ended.returncode == 0, ended.stderr
    frames = json.loads(ended.stdout.strip().splitlines()[-1])["frames"]
    summary, messages = indexed_messages(path)
    # every frame the session took is in the file, in order, and the summary counts each message once
    assert chip_sequences(messages) == list(range(frames))
    assert summary.statistics.message_count == len(messages) == frames + 1  # and the one baseline
    assert streamed_messages(path) == (messages, None)
    assert check_as_the_specification_defines(path) == len(messages)


def test_a_killed_recording_opens_in_the_indexed_reader_as_it_is(tmp_path):
    path = tmp_path / "killed.mcap"
    ended = record_until(path, signal.SIGKILL)
    assert ended.returncode == -signal.SIGKILL
    summary, messages = indexed_messages(path)
    # the reference: mcap's own stream reader, front to back, reads the same and finds no torn tail
    assert streamed_messages(path) == (messages, None)
    assert len(messages) > 20 and summary.statistics.message_count == len(messages)
    assert chip_sequences(messages) == list(range(len(messages) - 1))  # frames 0.. with none missing
    assert check_as_the_specification_defines(path) == len(messages)
    salvage = convert(path).salvage
    assert not salvage.truncated and salvage.data_crc_ok is True and salvage.bytes_lost == 0


# --------------------------------------------------------------------------
# Torn and damaged files: what convert says it lost
# --------------------------------------------------------------------------


def hall_frame(k: int) -> SimpleNamespace:
    """Frame ``k`` of one Hall chip at 100 frames/s, with a baseline."""
    return SimpleNamespace(seq=k, stamp_ns=1_700_000_000_000_000_000 + k * 10_000_000,
                           reading=np.full((1, 3), 1e-6 * k), baseline=np.zeros((1, 3)), baseline_version=0,
                           estimates=None, state=None)


def recorded(path: Path, frames: int = 600, per_flush: int = 25) -> Path:
    """A complete recording of one Hall chip, a chunk closed every ``per_flush`` frames."""
    recorder = McapRecorder(path, 1, chunk_size=1024)
    for start in range(0, frames, per_flush):
        recorder.write_frames([hall_frame(k) for k in range(start, min(start + per_flush, frames))])
        recorder.flush()
    recorder.close()
    return path


def recorded_with_a_force(path: Path) -> Path:
    """200 frames of one Hall chip, each with an estimated Fz in N: the labels the wrench topic carries."""
    recorder = McapRecorder(path, 1, target_names=["Fz"], target_units=["N"], chunk_size=1024)
    recorder.write_frames([SimpleNamespace(**{**vars(hall_frame(k)), "estimates": np.array([0.01 * k])})
                           for k in range(200)])
    recorder.close()
    return path


def chunks_of(path: Path) -> list:
    with path.open("rb") as stream:
        return sorted(make_reader(stream).get_summary().chunk_indexes, key=lambda index: index.chunk_start_offset)


def test_convert_reports_the_tail_it_lost_when_a_file_is_cut(tmp_path):
    whole = recorded(tmp_path / "whole.mcap")
    chunks = chunks_of(whole)
    cut_chunk = chunks[len(chunks) // 2]
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(whole.read_bytes()[:cut_chunk.chunk_start_offset + cut_chunk.chunk_length // 2])
    conversion = convert(cut)
    salvage = conversion.salvage
    assert conversion.truncated and salvage.truncated
    assert salvage.bytes_lost == cut.stat().st_size - cut_chunk.chunk_start_offset
    assert (salvage.lost_from_ns, salvage.lost_to_ns) == (cut_chunk.message_start_time, cut_chunk.message_end_time)
    # the frames read are those of the whole chunks, each one message (plus the baseline)
    streamed, _ = streamed_messages(cut)
    assert salvage.messages == len(streamed) and conversion.frames == len(streamed) - 1
    report = salvage.report()
    first = chunks[0].message_start_time
    assert report["time_lost_s"] == [round((cut_chunk.message_start_time - first) * 1e-9, 6),
                                     round((cut_chunk.message_end_time - first) * 1e-9, 6)]


def test_convert_skips_a_damaged_chunk_and_says_so(tmp_path):
    whole = recorded(tmp_path / "whole.mcap")
    chunks = chunks_of(whole)
    damaged = chunks[3]
    content = bytearray(whole.read_bytes())
    content[damaged.chunk_start_offset + damaged.chunk_length - 5] ^= 0x20  # inside its compressed records
    broken = tmp_path / "damaged.mcap"
    broken.write_bytes(bytes(content))
    conversion = convert(broken, salvage=True)
    salvage = conversion.salvage
    _, every = indexed_messages(whole)
    in_damaged = [m for m in every if damaged.message_start_time <= m[1] <= damaged.message_end_time]
    assert not salvage.truncated and salvage.damaged_records == 1
    assert salvage.messages == len(every) - len(in_damaged) and conversion.frames == 600 - len(in_damaged)
    assert salvage.bytes_lost == damaged.chunk_length
    assert (salvage.lost_from_ns, salvage.lost_to_ns) == (damaged.message_start_time, damaged.message_end_time)


def torn_between(before: bytes, after: bytes, cut: int) -> bytes:
    """The file a write of ``after`` over ``before`` leaves when it stops ``cut`` bytes in (a kill
    during the write: the kernel stops a write at a page boundary)."""
    return after[:cut] + before[cut:]


def test_a_recording_torn_during_a_flush_is_repaired_with_every_complete_message(tmp_path):
    path = tmp_path / "torn.mcap"
    recorder = McapRecorder(path, 1, chunk_size=100_000)
    recorder.write_frames([hall_frame(k) for k in range(300)])
    recorder.flush()
    before = path.read_bytes()
    recorder.write_frames([hall_frame(k) for k in range(300, 900)])
    recorder.flush()
    after = path.read_bytes()
    recorder.close()
    flushed, _ = streamed_messages(path)
    first_flush = [m for m in flushed if m[2] < 300]
    # the second flush's write began where the first's summary began, and was stopped one page in
    start = next(k for k, (a, b) in enumerate(zip(before, after)) if a != b)
    torn = tmp_path / "torn-write.mcap"
    torn.write_bytes(torn_between(before, after, (start // 4096 + 1) * 4096))
    with torn.open("rb") as stream, pytest.raises(Exception):
        make_reader(stream).get_summary()
    # the reference: what mcap's own stream reader reads of the torn file before its tail
    complete, tail = streamed_messages(torn)
    assert tail is not None and complete == first_flush
    repaired = tmp_path / "repaired.mcap"
    salvage = repair_recording(torn, repaired)
    summary, messages = indexed_messages(repaired)
    assert messages == complete and check_as_the_specification_defines(repaired) == len(complete)
    assert summary.statistics.message_count == salvage.messages == len(complete)
    assert salvage.truncated and salvage.damaged_records + salvage.bytes_lost > 0
    np.testing.assert_array_equal(convert(repaired).dataset.X(), convert(torn).dataset.X())
    # the command line does the same, beside the recording by default, and names what it did
    result = CliRunner().invoke(app, ["recording", "repair", str(torn)])
    assert result.exit_code == 0, result.output
    assert indexed_messages(tmp_path / "torn-write.repaired.mcap")[1] == complete
    assert f"messages_read: {len(complete)}" in result.output and "truncated: True" in result.output
    refused = CliRunner().invoke(app, ["recording", "repair", str(torn), "-o", str(torn)])
    assert refused.exit_code == 2 and "is the input" in refused.output


def test_a_recording_carries_a_crc_of_its_data_section(tmp_path):
    whole = recorded(tmp_path / "whole.mcap")
    assert convert(whole).salvage.data_crc_ok is True
    repaired = tmp_path / "repaired.mcap"
    assert repair_recording(whole, repaired).messages == len(indexed_messages(whole)[1])
    assert convert(repaired).salvage.data_crc_ok is True
    # the softtip metadata record lies outside the chunks: only the data section's CRC covers it
    content = bytearray(repaired.read_bytes())
    with repaired.open("rb") as stream:
        index = make_reader(stream).get_summary().metadata_indexes[0]
    content[index.offset + index.length - 3] ^= 0x04
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(content))
    with pytest.raises(RecordingError, match="damaged.mcap: the data section fails its CRC though every record"):
        convert(damaged)


def test_a_flipped_byte_in_a_topic_name_is_refused_not_converted_without_its_labels(tmp_path):
    whole = recorded_with_a_force(tmp_path / "whole.mcap")
    assert convert(whole).dataset.labels == {"Fz": "N"}  # from the wrench topic
    content = bytearray(whole.read_bytes())
    topic = content.index(b"/fingertip/wrench")  # the channel record in the data section (before the summary's)
    content[topic + len(b"/fingertip/wrenc")] ^= 0x01  # "wrenci": the force labels' topic misnamed
    damaged = tmp_path / "topic.mcap"
    damaged.write_bytes(bytes(content))
    # mcap's own reader reads the misnamed topic as it stands: nothing in it says the labels are gone
    with damaged.open("rb") as stream:
        assert "/fingertip/wrenci" in {channel.topic for _, channel, _ in NonSeekingReader(stream).iter_messages()}
    converted = CliRunner().invoke(app, ["convert", str(damaged), str(tmp_path / "topic.parquet")])
    assert converted.exit_code == 2 and not (tmp_path / "topic.parquet").exists()
    assert converted.output.strip().splitlines() == [
        f"error: {damaged}: the data section fails its CRC though every record in it parses: a schema, channel or "
        "metadata record (topic names, units, labels) was altered"]
    repaired = CliRunner().invoke(app, ["recording", "repair", str(damaged)])
    assert repaired.exit_code == 2 and not damaged.with_suffix(".repaired.mcap").exists()
    assert "fails its CRC though every record in it parses" in repaired.output


def test_a_topic_name_flipped_beside_a_damaged_chunk_is_refused_unless_salvaged(tmp_path):
    whole = recorded_with_a_force(tmp_path / "whole.mcap")
    damaged_chunk = chunks_of(whole)[3]
    content = bytearray(whole.read_bytes())
    content[damaged_chunk.chunk_start_offset + damaged_chunk.chunk_length - 5] ^= 0x20
    content[content.index(b"/fingertip/wrench") + len(b"/fingertip/wrenc")] ^= 0x01  # "wrenci"
    damaged = tmp_path / "both.mcap"
    damaged.write_bytes(bytes(content))
    # the damaged chunk explains the failed CRC as well as the topic name would: nothing tells them apart
    salvage = convert(damaged, salvage=True).salvage
    assert salvage.damaged_records == 1 and salvage.data_crc_ok is False
    refused = CliRunner().invoke(app, ["convert", str(damaged), str(tmp_path / "both.parquet")])
    assert refused.exit_code == 2 and not (tmp_path / "both.parquet").exists()
    assert refused.output.strip().splitlines() == [
        f"error: {damaged}: the data section fails its CRC beside 1 damaged and 0 resynchronised records, and a "
        "topic name, unit or label outside them may be altered too: refused unless salvaged (--salvage)"]
    salvaged = CliRunner().invoke(app, ["convert", str(damaged), str(tmp_path / "both.parquet"), "--salvage", "--json"])
    assert salvaged.exit_code == 0 and salvaged.stderr.startswith(f"warning: {damaged} is damaged")
    assert json.loads(salvaged.stdout)["damaged_records"] == 1
    # the chunk alone (the topic name intact) is refused all the same: the CRC cannot say which it is
    content[content.index(b"/fingertip/wrenci") + len(b"/fingertip/wrenc")] ^= 0x01
    damaged.write_bytes(bytes(content))
    with pytest.raises(RecordingError, match="fails its CRC beside 1 damaged"):
        convert(damaged)
    assert convert(damaged, salvage=True).dataset.labels == {"Fz": "N"}


def test_convert_says_on_stderr_that_it_converted_a_damaged_recording(tmp_path):
    whole = recorded(tmp_path / "whole.mcap")
    damaged_chunk = chunks_of(whole)[3]
    content = bytearray(whole.read_bytes())
    content[damaged_chunk.chunk_start_offset + damaged_chunk.chunk_length - 5] ^= 0x20
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(content))
    result = CliRunner().invoke(app, ["convert", str(damaged), str(tmp_path / "d.parquet"), "--json", "--salvage"])
    assert result.exit_code == 0, result.output
    salvage = convert(damaged, salvage=True).salvage
    assert result.stderr.strip() == (
        f"warning: {damaged} is damaged: converted the {salvage.messages} messages salvaged "
        f"({damaged_chunk.chunk_length} bytes lost, 1 damaged records skipped, 0 resynchronised; the summary says "
        "which times)")
    assert json.loads(result.stdout)["damaged_records"] == 1
    clean = CliRunner().invoke(app, ["convert", str(whole), str(tmp_path / "w.parquet")])
    assert clean.exit_code == 0 and clean.stderr == ""


# --------------------------------------------------------------------------
# Damaged length fields: the scan resynchronises on the next record
# --------------------------------------------------------------------------


def data_section_heads(content: bytes) -> list[tuple[int, int]]:
    """(offset, opcode) of every record of an intact file's data section, walked by the length fields."""
    heads, offset = [], 8
    while content[offset] != 0x0F:  # DataEnd
        heads.append((offset, content[offset]))
        offset += 9 + int.from_bytes(content[offset + 1:offset + 9], "little")
    return heads


@pytest.mark.parametrize(("byte", "mask"), [(1, 0x01), (2, 0x40), (8, 0x80)],
                         ids=["one-byte-longer-or-shorter", "inside-the-file", "past-the-file"])
def test_a_damaged_record_length_is_repaired_with_every_message(tmp_path, byte, mask):
    whole = recorded(tmp_path / "whole.mcap")
    _, intact = indexed_messages(whole)
    damaged_chunk = chunks_of(whole)[len(chunks_of(whole)) // 2]
    content = bytearray(whole.read_bytes())
    content[damaged_chunk.chunk_start_offset + byte] ^= mask  # a byte of the chunk's length field
    damaged = tmp_path / "damaged-length.mcap"
    damaged.write_bytes(bytes(content))
    # the reference: mcap's own stream reader stops at the damaged record (reading a chunk by its own
    # fields, it passes over a length one byte off)
    streamed, tail = streamed_messages(damaged)
    assert (tail is None) == (byte == 1) and (len(streamed) < len(intact)) == (byte != 1)
    result = CliRunner().invoke(app, ["recording", "repair", str(damaged), "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    repaired = Path(report["output"])
    # the chunk is read with the length the next record implies, and its own CRC holds: nothing is lost
    assert indexed_messages(repaired)[1] == intact and report["messages_read"] == len(intact) == 601
    assert report["resynchronised"] == 1 and report["damaged_records"] == 0 and report["bytes_lost"] == 0
    assert report["data_crc_ok"] is False  # the damaged byte is still damaged, and said so


def test_a_damaged_message_and_a_damaged_length_cost_only_their_own_chunk(tmp_path):
    whole = recorded(tmp_path / "whole.mcap")
    _, intact = indexed_messages(whole)
    chunks = chunks_of(whole)
    content = bytearray(whole.read_bytes())
    content[chunks[2].chunk_start_offset + chunks[2].chunk_length - 5] ^= 0x20  # its compressed messages
    content[chunks[2].chunk_start_offset + 3] ^= 0x10  # and its length
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(content))
    salvage = repair_recording(damaged, tmp_path / "repaired.mcap")
    in_chunk = [m for m in intact if chunks[2].message_start_time <= m[1] <= chunks[2].message_end_time]
    assert indexed_messages(tmp_path / "repaired.mcap")[1] == [m for m in intact if m not in in_chunk]
    assert salvage.damaged_records == 1 and salvage.messages == len(intact) - len(in_chunk)
    assert (salvage.lost_from_ns, salvage.lost_to_ns) == (chunks[2].message_start_time, chunks[2].message_end_time)


@pytest.mark.slow
def test_every_damaged_length_byte_of_every_record_is_repaired_whole(tmp_path):
    whole = recorded(tmp_path / "whole.mcap", frames=100)
    summary, intact = indexed_messages(whole)
    content = whole.read_bytes()
    heads = data_section_heads(content)
    assert {opcode for _, opcode in heads} == {0x01, 0x03, 0x04, 0x06, 0x07, 0x0C}  # header .. metadata
    not_whole = []
    for offset, opcode in heads:
        for byte in range(1, 9):
            for mask in (0x01, 0x80, 0xFF):
                damaged = bytearray(content)
                damaged[offset + byte] ^= mask
                (tmp_path / "damaged.mcap").write_bytes(bytes(damaged))
                salvage = repair_recording(tmp_path / "damaged.mcap", tmp_path / "repaired.mcap")
                repaired, messages = indexed_messages(tmp_path / "repaired.mcap")
                if (messages != intact or salvage.resynchronised != 1 or repaired.schemas != summary.schemas
                        or repaired.channels != summary.channels):
                    not_whole.append((offset, opcode, byte, mask))
    assert not_whole == []


# --------------------------------------------------------------------------
# The file as the MCAP specification defines it, checked where mcap's reader does not look
# --------------------------------------------------------------------------

FOOTER_BYTES = 9 + 20  # opcode, length, summary_start, summary_offset_start, summary_crc


def records_between(content: bytes, start: int, stop: int) -> list[tuple[int, int, bytes]]:
    """(offset, opcode, body) of the records from ``start`` to ``stop``, which must hold whole records."""
    found, offset = [], start
    while offset < stop:
        opcode, length = struct.unpack_from("<BQ", content, offset)
        found.append((offset, opcode, content[offset + 9:offset + 9 + length]))
        offset += 9 + length
    assert offset == stop, f"the records from {start} run past {stop} to {offset}"
    return found


def check_as_the_specification_defines(path: Path) -> int:
    """Checks ``path`` against the MCAP specification and returns the messages its index reaches:
    the footer's summary CRC is the CRC32 of every byte from the summary's start up to the end of the
    footer's summary_offset_start; every chunk index's chunk_length is the chunk record's (opcode and
    length included), its message_index_length that of the message index records after the chunk,
    its message_index_offsets each at a message index record of that channel, and every entry of
    those at a message record of that channel and log time in the decompressed chunk, every message
    indexed once, each chunk's times those of its messages; the statistics count the messages, chunks,
    schemas, channels, metadata and attachments it holds; the DataEnd CRC is the CRC32 of the data
    section before it."""
    content = path.read_bytes()
    footer = len(content) - 8 - FOOTER_BYTES
    assert content[-8:] == MAGIC and content[footer] == 0x02
    summary_start, offset_start, summary_crc = struct.unpack_from("<QQI", content, footer + 9)
    summary = records_between(content, summary_start, footer)
    chunk_indexes = [ChunkIndex.read(ReadDataStream(io.BytesIO(body))) for _, opcode, body in summary if opcode == 0x08]
    assert chunk_indexes, f"{path}: no chunk index"
    (statistics,) = [Statistics.read(ReadDataStream(io.BytesIO(body))) for _, opcode, body in summary if opcode == 0x0B]
    counted = collections.Counter(opcode for _, opcode, _ in summary)
    every: list[Message] = []
    indexed = 0
    for index in chunk_indexes:
        opcode, length = struct.unpack_from("<BQ", content, index.chunk_start_offset)
        assert opcode == 0x06 and index.chunk_length == 9 + length, f"chunk index length {index.chunk_length}"
        chunk = Chunk.read(ReadDataStream(io.BytesIO(content[index.chunk_start_offset + 9:
                                                                index.chunk_start_offset + 9 + length])))
        records = zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=chunk.uncompressed_size) \
            if chunk.compression == "zstd" else chunk.data
        assert zlib.crc32(records) == chunk.uncompressed_crc and len(records) == index.uncompressed_size
        messages = {offset: Message.read(ReadDataStream(io.BytesIO(body)), len(body))
                    for offset, opcode, body in records_between(records, 0, len(records)) if opcode == 0x05}
        index_start = index.chunk_start_offset + index.chunk_length
        message_indexes = records_between(content, index_start, index_start + index.message_index_length)
        assert sorted(index.message_index_offsets.values()) == [offset for offset, _, _ in message_indexes], \
            "message index offsets"
        reached = []
        for channel, offset in index.message_index_offsets.items():
            (_, opcode, body), = [record for record in message_indexes if record[0] == offset]
            message_index = MessageIndex.read(ReadDataStream(io.BytesIO(body)))
            assert opcode == 0x07 and message_index.channel_id == channel, "message index channel"
            for log_time, message_offset in message_index.records:
                message = messages.get(message_offset)
                assert message is not None and (message.channel_id, message.log_time) == (channel, log_time), \
                    f"a message index entry at {message_offset} reaches no message of channel {channel}"
                reached.append(message_offset)
        assert sorted(reached) == sorted(messages), "messages not indexed once each"
        assert (index.message_start_time, index.message_end_time) == (
            min(m.log_time for m in messages.values()), max(m.log_time for m in messages.values())), "chunk times"
        indexed += len(reached)
        every += messages.values()
    # the statistics count what the file holds
    assert (statistics.message_count, statistics.chunk_count) == (len(every), len(chunk_indexes)), "statistics"
    assert statistics.channel_message_counts == collections.Counter(m.channel_id for m in every), "statistics"
    assert (statistics.message_start_time, statistics.message_end_time) == (
        min(m.log_time for m in every), max(m.log_time for m in every)), "statistics"
    assert (statistics.schema_count, statistics.channel_count, statistics.metadata_count,
            statistics.attachment_count) == (counted[0x03], counted[0x04], counted[0x0D], counted[0x0A]), "statistics"
    assert summary_crc == zlib.crc32(content[summary_start:footer + 9 + 16]), "summary CRC"
    # the summary offsets: one per group of records of one opcode, framing exactly that group, in order
    # (mcap's own writer also writes one of length 0 for a group it has nothing for)
    groups, start = [], summary_start
    for offset, opcode, body in summary:
        if opcode == 0x0E:
            group_opcode, group_start, group_length = struct.unpack_from("<BQQ", body)
            framed = {op for _, op, _ in records_between(content, group_start, group_start + group_length)}
            assert group_start == start and framed == ({group_opcode} if group_length else set()), "summary offsets"
            groups += [group_opcode] if group_length else []
            start = group_start + group_length
    assert start == offset_start and groups == list(dict.fromkeys(
        opcode for _, opcode, _ in summary if opcode != 0x0E)), "summary offsets"
    data_end = summary_start - 9 - 4
    assert content[data_end] == 0x0F
    assert struct.unpack_from("<I", content, data_end + 9)[0] == zlib.crc32(content[:data_end]), "data section CRC"
    return indexed


def test_recordings_are_written_as_the_mcap_specification_defines(tmp_path):
    whole = recorded(tmp_path / "whole.mcap")
    _, messages = indexed_messages(whole)
    assert check_as_the_specification_defines(whole) == len(messages) == 601
    repaired = tmp_path / "repaired.mcap"  # written by mcap's own writer on repair
    repair_recording(whole, repaired)
    assert check_as_the_specification_defines(repaired) == len(messages)


def test_an_attachment_is_sealed_and_indexed_as_mcaps_reader_reads_it(tmp_path):
    path = tmp_path / "attached.mcap"
    with path.open("wb") as stream:
        writer = SealedMcapWriter(stream, chunk_size=1024, compression="none")
        writer.start(profile="ros2", library="test")
        channel = writer.register_channel("/notes", "json", writer.register_schema("note", "jsonschema", b"{}"))
        writer.add_message(channel, 5, b'{"n": 1}', 5)
        writer.add_attachment(3, 4, "calibration.toml", "application/toml", b"gain = 2.5\n")
        writer.flush()  # sealed as it stands: what a killed recorder leaves
        assert check_as_the_specification_defines(path) == 1
        writer.finish()
    assert check_as_the_specification_defines(path) == 1
    with path.open("rb") as stream:
        reader = make_reader(stream)
        (attachment,) = list(reader.iter_attachments())
        (index,) = reader.get_summary().attachment_indexes
    assert (attachment.create_time, attachment.log_time, attachment.name, attachment.media_type, attachment.data) == (
        3, 4, "calibration.toml", "application/toml", b"gain = 2.5\n")
    assert (index.create_time, index.log_time, index.data_size, index.name, index.media_type) == (
        3, 4, 11, "calibration.toml", "application/toml")
    # the index's offset and length frame the attachment record itself
    content = path.read_bytes()
    assert content[index.offset] == 0x09 and int.from_bytes(content[index.offset + 1:index.offset + 9],
                                                            "little") + 9 == index.length
    with pytest.raises(RecordingError, match="finished"):
        writer.flush()


def rewritten_record(content: bytes, offset: int, body: bytes) -> bytes:
    """``content`` with the record at ``offset`` given ``body`` (its length field made to match)."""
    opcode, length = struct.unpack_from("<BQ", content, offset)
    return content[:offset] + struct.pack("<BQ", opcode, len(body)) + body + content[offset + 9 + length:]


@pytest.mark.parametrize("fault", ["summary CRC over the summary without its offsets",
                                   "message index offsets one record late",
                                   "chunk index lengths that include the message indexes"])
def test_the_specification_check_finds_what_mcaps_reader_passes(tmp_path, fault):
    whole = recorded(tmp_path / "whole.mcap", frames=100)
    content = whole.read_bytes()
    footer = len(content) - 8 - FOOTER_BYTES
    summary_start, offset_start, _ = struct.unpack_from("<QQI", content, footer + 9)
    if fault.startswith("summary CRC"):
        wrong = zlib.crc32(content[summary_start:offset_start])
        content = content[:footer + 25] + struct.pack("<I", wrong) + content[footer + 29:]
        expected = "summary CRC"
    elif fault.startswith("message index"):
        offset, _, body = next(record for record in records_between(content, 8, summary_start - 13)
                               if record[1] == 0x07)
        message_index = MessageIndex.read(ReadDataStream(io.BytesIO(body)))
        late = b"".join(struct.pack("<QQ", log_time, message_offset + 31)
                        for log_time, message_offset in message_index.records)  # 31: a message past
        content = rewritten_record(content, offset, body[:2] + struct.pack("<I", len(late)) + late)
        expected = "reaches no message"
    else:
        offset, _, body = next(record for record in records_between(content, summary_start, footer)
                               if record[1] == 0x08)
        chunk_index = ChunkIndex.read(ReadDataStream(io.BytesIO(body)))
        body = body[:24] + struct.pack("<Q", chunk_index.chunk_length + chunk_index.message_index_length) + body[32:]
        content = content[:offset + 9] + body + content[offset + 9 + len(body):]
        expected = "chunk index length"
    damaged = tmp_path / "fault.mcap"
    damaged.write_bytes(content)
    with damaged.open("rb") as stream:
        assert len(list(make_reader(stream).iter_messages())) == 101  # mcap's reader passes it
    with pytest.raises(AssertionError, match=expected):
        check_as_the_specification_defines(damaged)


# --------------------------------------------------------------------------
# Children and signals
# --------------------------------------------------------------------------

# An emulated fingertip in its child process, as ``softtip live --emulate`` runs it; Ctrl-C stops it
# as the session does, by the pipe, and prints how many frames the child's log holds.
EMULATED = """
import time
from softtip.hardware import EmulatorProcess, PressCycle
emulator = EmulatorProcess(PressCycle(2), rate_hz=50, chips=2).start()
print(emulator._process.pid, flush=True)
try:
    time.sleep(HANG_GUARD_S)
except KeyboardInterrupt:
    print(len(emulator.close().seq), flush=True)
""".replace("HANG_GUARD_S", str(HANG_GUARD_S))


def running(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie, not yet reaped by whoever adopted it, does not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def emulated_until(stop) -> tuple[int, str, str]:
    """Runs the emulator's host in a session of its own, calls ``stop(host)`` once the child is up,
    and returns the child's pid and what the host and child printed by the time both ended."""
    host = subprocess.Popen([sys.executable, "-c", EMULATED], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    try:
        child = int(host.stdout.readline())
        stop(host)
        stdout, stderr = host.communicate(timeout=HANG_GUARD_S)  # until the child, sharing the pipes, ends too
    finally:
        if host.poll() is None:
            host.kill()
            host.communicate()
    return child, stdout, stderr


def test_the_emulator_child_of_a_killed_session_ends_quietly():
    child, _, stderr = emulated_until(lambda host: host.send_signal(signal.SIGKILL))
    assert stderr == ""  # no EOFError traceback from the child
    assert not running(child)


def test_ctrl_c_reaches_the_emulator_child_and_the_session_still_stops_it_by_the_pipe():
    child, stdout, stderr = emulated_until(lambda host: (time.sleep(0.5), os.killpg(host.pid, signal.SIGINT)))
    # the child's log came back (no client read a frame: an empty one): it left the terminal's Ctrl-C to
    # its host, which stopped it by the pipe
    assert stderr == "" and stdout.strip() == "0"
    assert not running(child)


def test_a_disk_that_fills_mid_recording_ends_in_one_line_with_the_sealed_tail_intact(tmp_path, monkeypatch, capfd):
    from softtip._core.channels import MAGNETIC
    from softtip.hardware import PacedSource
    from softtip.realtime.session import run_live
    from softtip.realtime.sinks.recorder import RecorderSink

    path = tmp_path / "full.mcap"
    capacity = 12_000  # bytes the disk has for the file
    written_whole = os.pwrite
    refused = []

    def full_disk(fd: int, data: bytes, offset: int) -> int:
        """As the kernel writes to a full disk: what fits, then ENOSPC."""
        room = capacity - offset
        if len(data) <= room:
            return written_whole(fd, data, offset)
        refused.append(offset)
        if room > 0:
            return written_whole(fd, data[:room], offset)  # the old tail is overwritten in part: torn
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "pwrite", full_disk)
    t = np.arange(400) / 200.0
    source = PacedSource(np.stack([np.sin(t), np.cos(t), t], axis=1)[:, None, :], 200.0, reading=MAGNETIC,
                         name="paced")
    sink = RecorderSink(path, flush_interval_s=0.05, chunk_size=1024)
    with pytest.raises(RecordingError) as stopped:
        run_live(source, [], [sink], 3.0, baseline_frames=1)
    assert str(stopped.value) == (f"recording {path} stopped early: the recording's write failed (No space left on "
                                  f"device: {capacity - refused[0]} of ") + str(stopped.value).split(" of ")[1]
    assert str(stopped.value).endswith("bytes written); the file holds every message up to the last flush, sealed")
    assert len(refused) == 1 and capfd.readouterr().err == ""  # no traceback: the one line is the caller's to print
    monkeypatch.undo()
    # the tail of the last flush is back in place: the file opens in the indexed reader as it stands
    summary, messages = indexed_messages(path)
    assert streamed_messages(path) == (messages, None) and path.stat().st_size <= capacity
    assert check_as_the_specification_defines(path) == len(messages) > 20
    assert chip_sequences(messages) == list(range(len(messages) - 1))  # frames 0.. with none missing


def test_a_tail_that_cannot_be_put_back_is_said_so_and_repair_mends_it(tmp_path, monkeypatch):
    path = tmp_path / "gone.mcap"
    recorder = McapRecorder(path, 1, chunk_size=1024)
    recorder.write_frames([hall_frame(k) for k in range(100)])
    recorder.flush()
    _, flushed = indexed_messages(path)
    written_whole = os.pwrite

    def failing_disk(fd: int, data: bytes, offset: int) -> int:
        """A disk that takes a part of the next write and then nothing (an I/O error)."""
        monkeypatch.setattr(os, "pwrite", lambda *_: (_ for _ in ()).throw(OSError(errno.EIO, "Input/output error")))
        return written_whole(fd, data[:len(data) // 2], offset)

    monkeypatch.setattr(os, "pwrite", failing_disk)
    recorder.write_frames([hall_frame(k) for k in range(100, 200)])
    with pytest.raises(RecordingError, match=r"^the recording's write failed \(No space left on device: \d+ of \d+ "
                                             r"bytes written\); its tail could not be put back \(Input/output error\): "
                                             r"softtip recording repair mends it$"):
        recorder.flush()
    recorder.write_frames([hall_frame(200)])
    with pytest.raises(RecordingError, match="stopped at an earlier failed write"):
        recorder.flush()
    recorder.close()  # writes nothing more
    monkeypatch.undo()
    salvage = repair_recording(path, tmp_path / "mended.mcap")
    # every message of the last flush is still there, before the torn tail
    assert indexed_messages(tmp_path / "mended.mcap")[1][:len(flushed)] == flushed and salvage.truncated


# --------------------------------------------------------------------------
# What a scan says it lost, and what the sealed writer says when a write fails, on small files
# --------------------------------------------------------------------------


def chunked(path: Path, chunk_times: list[range]) -> list:
    """A recording of one channel, one chunk of uncompressed messages per range of log times (ns), in
    that order; returns the chunk indexes in file order."""
    with path.open("wb") as stream:
        writer = SealedMcapWriter(stream, compression="none")
        writer.start()
        channel = writer.register_channel("/notes", "json", writer.register_schema("note", "jsonschema", b"{}"))
        for times in chunk_times:
            for log_time in times:
                writer.add_message(channel, log_time, b'{"n": %d}' % log_time, log_time)
            writer.flush()  # closes the chunk
        writer.finish()
    return chunks_of(path)


def with_damaged_chunks(path: Path, chunks: list) -> Path:
    """``path`` with a byte of the last message of each of ``chunks`` flipped (its CRC then fails)."""
    content = bytearray(path.read_bytes())
    for chunk in chunks:
        content[chunk.chunk_start_offset + chunk.chunk_length - 3] ^= 0x01
    damaged = path.with_name("damaged.mcap")
    damaged.write_bytes(bytes(content))
    return damaged


def test_two_damaged_chunks_are_both_counted_with_the_times_their_headers_state(tmp_path):
    times = [range(100, 200, 10), range(500, 600, 10), range(1000, 1100, 10)]
    chunks = chunked(tmp_path / "ordered.mcap", times)
    salvage = read_recording(with_damaged_chunks(tmp_path / "ordered.mcap", [chunks[0], chunks[2]])).salvage
    assert salvage.damaged_records == 2 and salvage.messages == 10
    assert salvage.bytes_lost == chunks[0].chunk_length + chunks[2].chunk_length
    assert (salvage.lost_from_ns, salvage.lost_to_ns) == (100, 1090)
    # time going backwards (a restarted device): the range still spans both lost chunks
    chunks = chunked(tmp_path / "backwards.mcap", times[::-1])
    salvage = read_recording(with_damaged_chunks(tmp_path / "backwards.mcap", [chunks[0], chunks[2]])).salvage
    assert (salvage.lost_from_ns, salvage.lost_to_ns) == (100, 1090) and salvage.damaged_records == 2


@pytest.mark.parametrize(("kept", "lost_times"), [(16, (500, 590)), (15, (None, None))],
                         ids=["both-times-kept", "one-byte-short"])
def test_a_file_cut_inside_a_chunk_header_states_the_lost_times_only_when_both_are_there(tmp_path, kept, lost_times):
    chunks = chunked(tmp_path / "whole.mcap", [range(100, 200, 10), range(500, 600, 10)])
    cut = tmp_path / "cut.mcap"
    cut.write_bytes((tmp_path / "whole.mcap").read_bytes()[:chunks[1].chunk_start_offset + 9 + kept])
    salvage = read_recording(cut).salvage
    assert salvage.truncated and salvage.messages == 10
    assert (salvage.lost_from_ns, salvage.lost_to_ns) == lost_times


def test_the_salvage_report_gives_the_lost_times_in_microseconds_from_the_first_message():
    # by hand: (lost - first) ns, in s rounded to 6 decimals; from 0 when no message was read (500 ns
    # times 1e-9 is a hair above half a microsecond in binary: 1 µs, where 499 ns is 0)
    assert Salvage(100, first_ns=None, lost_from_ns=500, lost_to_ns=1_234_567).report()["time_lost_s"] == [
        0.000001, 0.001235]
    assert Salvage(100, lost_from_ns=499, lost_to_ns=499).report()["time_lost_s"] == [0.0, 0.0]
    assert Salvage(100, first_ns=1_000, lost_from_ns=1_501, lost_to_ns=1_235_567).report()["time_lost_s"] == [
        0.000001, 0.001235]
    assert Salvage(100).report()["time_lost_s"] is None
    # every field, under its name; the tail's reason only when there is one
    salvage = Salvage(1000, bytes_read=900, messages=7, reason="the file ends in a record's head", damaged_records=1,
                      lost_from_ns=1_501, lost_to_ns=1_235_567, first_ns=1_000, data_crc_ok=False, resynchronised=2)
    assert salvage.report() == {"messages_read": 7, "truncated": True, "bytes_lost": 100, "damaged_records": 1,
                                "time_lost_s": [0.000001, 0.001235], "data_crc_ok": False, "resynchronised": 2,
                                "tail": "the file ends in a record's head"}
    assert "tail" not in Salvage(1000, truncated=False).report()


def test_every_attachment_and_metadata_record_is_indexed_and_counted(tmp_path):
    path = tmp_path / "two.mcap"
    with path.open("wb") as stream:
        writer = SealedMcapWriter(stream, compression="none")
        writer.start(profile="ros2", library="test")
        channel = writer.register_channel("/notes", "json", writer.register_schema("note", "jsonschema", b"{}"))
        writer.add_message(channel, 5, b'{"n": 1}', 5)
        for k in range(2):
            writer.add_attachment(3 + k, 4 + k, f"a{k}.toml", "application/toml", b"gain = %d\n" % k)
            writer.add_metadata(f"m{k}", {"k": str(k)})
        writer.finish()
    assert check_as_the_specification_defines(path) == 1
    with path.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert [index.name for index in summary.attachment_indexes] == ["a0.toml", "a1.toml"]
    assert [index.name for index in summary.metadata_indexes] == ["m0", "m1"]
    assert (summary.statistics.attachment_count, summary.statistics.metadata_count) == (2, 2)


def test_a_failed_first_write_says_that_nothing_had_been_written(tmp_path, monkeypatch):
    written_whole = os.pwrite

    def full_disk(fd: int, data: bytes, offset: int) -> int:
        if data:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return written_whole(fd, data, offset)

    monkeypatch.setattr(os, "pwrite", full_disk)
    path = tmp_path / "first.mcap"
    with path.open("wb") as stream, pytest.raises(RecordingError) as failed:
        SealedMcapWriter(stream).start()
    assert str(failed.value) == "the recording's write failed (No space left on device); nothing had been written"
    assert path.stat().st_size == 0
    # an error of the system's that carries words but no error number: said in its words
    monkeypatch.setattr(os, "pwrite", lambda fd, data, offset: (_ for _ in ()).throw(OSError("disk gone")) if data
                        else written_whole(fd, data, offset))
    with path.open("wb") as stream, pytest.raises(RecordingError) as failed:
        SealedMcapWriter(stream).start()
    assert str(failed.value) == "the recording's write failed (disk gone); nothing had been written"


def test_a_tail_put_back_short_is_said_so(tmp_path, monkeypatch):
    path = tmp_path / "short.mcap"
    written_whole = os.pwrite
    with path.open("wb") as stream:
        writer = SealedMcapWriter(stream, compression="none")
        writer.start()
        channel = writer.register_channel("/notes", "json", writer.register_schema("note", "jsonschema", b"{}"))
        writer.add_message(channel, 5, b'{"n": 1}', 5)
        writer.flush()
        # from now on the disk takes half of every write
        monkeypatch.setattr(os, "pwrite", lambda fd, data, offset: written_whole(fd, data[:len(data) // 2], offset))
        writer.add_message(channel, 6, b'{"n": 2}', 6)
        with pytest.raises(RecordingError, match=r"; its tail could not be put back \(the tail was not written "
                                                 r"whole\): softtip recording repair mends it$") as failed:
            writer.flush()
        # the disk took half of the write: the message counts what it took of the whole
        written, whole = map(int, re.search(r"device: (\d+) of (\d+) bytes written", str(failed.value)).groups())
        assert written == whole // 2 and whole > 100


def test_finish_after_a_failed_write_writes_nothing_more(tmp_path, monkeypatch):
    path = tmp_path / "failed.mcap"
    written_whole = os.pwrite
    with path.open("wb") as stream:
        writer = SealedMcapWriter(stream, compression="none")
        writer.start()
        channel = writer.register_channel("/notes", "json", writer.register_schema("note", "jsonschema", b"{}"))
        writer.add_message(channel, 5, b'{"n": 1}', 5)
        monkeypatch.setattr(os, "pwrite", lambda fd, data, offset: (_ for _ in ()).throw(OSError(
            errno.ENOSPC, os.strerror(errno.ENOSPC))) if data else written_whole(fd, data, offset))
        with pytest.raises(RecordingError, match="the recording.s write failed"):
            writer.flush()
        left = path.read_bytes()
        writer.add_message(channel, 7, b'{"n": 3}', 7)
        writer.finish()  # nothing more is written, and no second error
    assert path.read_bytes() == left


def test_where_a_record_head_is_plausible_by_hand():
    # 21 bytes: a message record (opcode 0x05) of 3 body bytes, then one of none that ends the file exactly
    content = np.frombuffer(struct.pack("<BQ3sBQ", 0x05, 3, b"abc", 0x05, 0), dtype=np.uint8)
    at = np.array([0, 2, 12, 13, 21, 22])
    # 0, 12: heads of records that fit; 2: byte 0x00, no opcode; 13, 21: too close to the end for a head
    # (a torn tail: plausible unless whole records are asked for); 22: past the end
    np.testing.assert_array_equal(_heads_plausible(content, at, whole=False), [1, 0, 1, 1, 1, 0])
    np.testing.assert_array_equal(_heads_plausible(content, at, whole=True), [1, 0, 1, 0, 0, 0])
    # lengths that run one byte past the end: heads, but not of whole records
    longer = np.frombuffer(struct.pack("<BQ3sBQ", 0x05, 13, b"abc", 0x05, 1), dtype=np.uint8)
    np.testing.assert_array_equal(_heads_plausible(longer, np.array([0, 2, 12]), whole=False), [1, 0, 1])
    np.testing.assert_array_equal(_heads_plausible(longer, np.array([0, 2, 12]), whole=True), [0, 0, 0])
    exact = np.frombuffer(struct.pack("<BQ3sBQ", 0x05, 12, b"abc", 0x05, 0), dtype=np.uint8)
    np.testing.assert_array_equal(_heads_plausible(exact, np.array([0]), whole=True), [1])
    # no opcode, though the 8 bytes after it would make a length that fits
    padded = np.concatenate([content, np.zeros(9, np.uint8)])
    np.testing.assert_array_equal(_heads_plausible(padded, np.array([12, 13]), whole=True), [1, 0])


def test_resynchronising_finds_a_record_whose_head_ends_the_file():
    # by hand: five bytes of no record, then a head of opcode 0x02 (the footer's, whose body a scan does
    # not read) and length 0 that ends the file exactly
    content = b"\x00" * 5 + struct.pack("<BQ", 0x02, 0)
    assert _next_record(content, 0) == 5
    assert _next_record(content, 6) is None
    assert _next_record(content[:-1], 0) is None  # one byte short of a head
    # followed by a torn head rather than a whole record: found all the same (a torn tail)
    assert _next_record(content + b"\x05\x01", 0) == 5
    # a message head of length 2 chained to the next head, whose body does not parse as a message: passed over
    content = b"\x00" * 3 + struct.pack("<BQ2sBQ", 0x05, 2, b"zz", 0x02, 0)
    assert _next_record(content, 0) == 14


def test_how_a_cut_or_damaged_tail_ends_is_said_word_for_word(tmp_path):
    whole = recorded(tmp_path / "whole.mcap", frames=100)
    content = whole.read_bytes()
    chunk = chunks_of(whole)[1]
    start, end = chunk.chunk_start_offset, chunk.chunk_start_offset + chunk.chunk_length

    def tail(data: bytes) -> str:
        (tmp_path / "tail.mcap").write_bytes(data)
        return read_recording(tmp_path / "tail.mcap").salvage.reason

    assert tail(content[:start]) == "the file ends between records"
    assert tail(content[:start + 4]) == "the file ends in a record's head"
    assert tail(content[:start + 100]) == f"the file ends {chunk.chunk_length - 100} bytes short of a record (opcode 0x06)"
    claimed = bytearray(content[:start + 100])
    claimed[start + 6] = 0x01  # the length's sixth byte: 2**40 more
    assert tail(bytes(claimed)) == (f"a record of opcode 0x06 claims {chunk.chunk_length - 9 + 2**40} bytes, more "
                                    "than the file holds")
    claimed[start + 1:start + 9] = struct.pack("<Q", len(claimed))  # as long as the whole file: no more than it
    assert tail(bytes(claimed)) == f"the file ends {start + 9} bytes short of a record (opcode 0x06)"
    assert tail(content[:end] + bytes(20)) == f"no record follows the record of opcode 0x06 at byte {start}"


def test_a_file_that_is_no_recording_is_refused_in_one_line(tmp_path):
    missing = tmp_path / "missing.mcap"
    with pytest.raises(RecordingError) as refused:
        read_recording(missing)
    assert str(refused.value) == f"recording {missing} does not exist"
    for content, why in [(b"hello, world", None), (MAGIC, "the file ends between records"),
                         (MAGIC + b"\x01\x02", "the file ends in a record's head")]:
        path = tmp_path / "short.mcap"
        path.write_bytes(content)
        with pytest.raises(RecordingError) as refused:
            read_recording(path)
        assert str(refused.value) == (f"{path} is not an MCAP file" if why is None else
                                      f"{path}: unreadable MCAP file ({why})")


def test_a_topic_that_does_not_decode_says_why_word_for_word():
    with pytest.raises(RecordingError) as refused:
        TopicMessages("/t", "", "", {}, None, data=[b"x"]).decoded()
    assert str(refused.value) == "topic /t: schemaless messages of no schema are not ROS 2 messages with a ros2msg schema"
    with pytest.raises(RecordingError) as refused:
        TopicMessages("/t", "note", "json", {}, None, data=[b"x"]).decoded()
    assert str(refused.value) == "topic /t: json messages of note are not ROS 2 messages with a ros2msg schema"
    with pytest.raises(RecordingError) as refused:
        TopicMessages("/t", "note", "cdr", {}, lambda message: message[9], data=[b"x"]).decoded()
    assert str(refused.value) == "topic /t: a message does not decode as note (IndexError: index out of range)"


def test_a_ros2_schema_that_does_not_parse_is_refused_naming_the_topic(tmp_path):
    path = tmp_path / "bad-schema.mcap"
    with path.open("wb") as stream:
        writer = SealedMcapWriter(stream)
        writer.start()
        schema = writer.register_schema("pkg/msg/Bad", "ros2msg", b"this is not ! a message definition")
        writer.add_message(writer.register_channel("/bad", "cdr", schema), 1, b"\x00\x01\x00\x00", 1)
        writer.finish()
    with pytest.raises(RecordingError) as refused:
        read_recording(path)
    # the parser's own words: "this" is read as a type name, which must begin with a capital
    assert str(refused.value).startswith(f"{path}: topic /bad: schema pkg/msg/Bad does not parse (InvalidResourceName: "
                                         "'this' is an invalid message name.")


def test_the_sealed_writer_refuses_what_the_format_cannot_hold_word_for_word(tmp_path):
    with (tmp_path / "refusals.mcap").open("wb") as stream:
        with pytest.raises(RecordingError) as refused:
            SealedMcapWriter(stream, compression="lz4")
        assert str(refused.value) == "compression = 'lz4': expected one of zstd, none"
        writer = SealedMcapWriter(stream)
        writer.start()
        for schema_id in (-1, 1):  # ids count up from 1 as schemas are registered; 0 is no schema
            with pytest.raises(RecordingError) as refused:
                writer.register_channel("/t", "json", schema_id)
            assert str(refused.value) == f"channel '/t': schema {schema_id} was never registered"
        assert writer.register_channel("/plain", "json", 0) == 1
        schema = writer.register_schema("note", "jsonschema", b"{}")
        assert (schema, writer.register_channel("/t", "json", schema)) == (1, 2)
        for channel in (0, 3):
            with pytest.raises(RecordingError) as refused:
                writer.add_message(channel, 1, b"{}", 1)
            assert str(refused.value) == f"a message on channel {channel}, which was never registered"
        writer.add_message(2, 1, b"{}", 1)
        writer.finish()
        with pytest.raises(RecordingError) as refused:
            writer.flush()
        assert str(refused.value) == "the recording is finished: nothing more can be written"
    assert check_as_the_specification_defines(tmp_path / "refusals.mcap") == 1
    # a message given no sequence number has 0, as mcap's own writer gives it; a channel of no schema has
    # no schema name; the schemas by name, as text
    recording = read_recording(tmp_path / "refusals.mcap")
    assert recording.topics["/t"].sequences == [0] and recording.topics["/plain"].schema_name == ""
    assert recording.schemas == {"note": "{}"}


def test_the_sealed_writer_closes_a_chunk_once_it_holds_chunk_size_bytes(tmp_path):
    path = tmp_path / "chunks.mcap"
    with path.open("wb") as stream:
        # a message record of 2 data bytes: opcode 1, length 8, channel 2, sequence 4, two times 8 each: 33
        writer = SealedMcapWriter(stream, chunk_size=33, compression="none")
        writer.start()
        channel = writer.register_channel("/t", "json", writer.register_schema("note", "jsonschema", b"\xff{}"))
        for log_time in (1, 2, 3):
            writer.add_message(channel, log_time, b"{}", log_time)
        writer.finish()
    assert [chunk.uncompressed_size for chunk in chunks_of(path)] == [33, 33, 33]
    assert read_recording(path).schemas == {"note": "\ufffd{}"}  # a byte that is no UTF-8, replaced


def test_a_recording_of_no_message_states_what_mcaps_own_writer_states(tmp_path):
    path = tmp_path / "empty.mcap"
    with path.open("wb") as stream:
        writer = SealedMcapWriter(stream)
        writer.start()
        writer.finish()
    reference = tmp_path / "reference.mcap"
    with reference.open("wb") as stream:
        mcap_writer = Writer(stream)
        mcap_writer.start()
        mcap_writer.finish()
    with path.open("rb") as stream, reference.open("rb") as other:
        ours, theirs = make_reader(stream), make_reader(other)
        assert set(vars(ours.get_header()).values()) == {""}  # its profile and the writer it names: both empty
        statistics, expected = ours.get_summary().statistics, theirs.get_summary().statistics
    assert (statistics.message_count, statistics.message_start_time, statistics.message_end_time) == (
        expected.message_count, expected.message_start_time, expected.message_end_time) == (0, 0, 0)


def test_messages_are_read_by_topic_with_their_sequences_and_a_message_on_no_channel_is_refused(tmp_path):
    whole = recorded(tmp_path / "whole.mcap", frames=50)
    streamed, _ = streamed_messages(whole)  # the reference: mcap's own stream reader
    recording = read_recording(whole)
    for name, topic in recording.topics.items():
        assert topic.topic == name
        assert topic.sequences == [sequence for t, _, sequence, _ in streamed if t == name]
        assert topic.log_times == [log_time for t, log_time, _, _ in streamed if t == name]
    content = bytearray(whole.read_bytes())
    # the chip's channel record (id u16, schema id u16, then the topic's length u32 and its text) given id 9
    content[content.index(b"/fingertip/chip0/field") - 8] = 9
    renumbered = tmp_path / "renumbered.mcap"
    renumbered.write_bytes(bytes(content))
    with pytest.raises(RecordingError) as refused:
        read_recording(renumbered)
    assert str(refused.value) == f"{renumbered}: a message on unknown channel 1"


def test_messages_outside_chunks_are_read_as_mcaps_own_reader_reads_them(tmp_path):
    path = tmp_path / "unchunked.mcap"
    with path.open("wb") as stream:  # the reference writer, as some writers do: no chunks
        writer = Writer(stream, use_chunking=False)
        writer.start()
        channel = writer.register_channel("/t", "json", writer.register_schema("note", "jsonschema", b"{}"))
        for log_time in (5, 6, 7):
            writer.add_message(channel, log_time, b'{"n": %d}' % log_time, log_time, sequence=log_time - 4)
        writer.finish()
    streamed, tail = streamed_messages(path)
    recording = read_recording(path)
    assert tail is None and recording.salvage.messages == 3 and recording.salvage.damaged_records == 0
    topic = recording.topics["/t"]
    assert [("/t", t, s, d) for t, s, d in zip(topic.log_times, topic.sequences, topic.data, strict=True)] == streamed


def test_a_flush_waits_for_the_disk_only_when_asked(tmp_path, monkeypatch):
    synced = []
    monkeypatch.setattr(os, "fsync", synced.append)
    with (tmp_path / "synced.mcap").open("wb") as stream:
        writer = SealedMcapWriter(stream)
        writer.start()
        assert synced == []
        writer.register_schema("note", "jsonschema", b"{}")
        writer.flush(fsync=True)
        assert synced == [stream.fileno()]


def test_a_scan_yields_the_content_records_and_parses_each_body_whole(tmp_path):
    whole = recorded(tmp_path / "whole.mcap", frames=50)
    with whole.open("rb") as stream:
        kinds = collections.Counter(type(record).__name__
                                    for record in scan_recording(stream, Salvage(whole.stat().st_size), whole))
    summary, messages = indexed_messages(whole)  # the reference: mcap's indexed reader
    # each once (the summary's copies of schemas and channels are not read again); no index, statistics or DataEnd
    assert kinds == {"Header": 1, "Schema": len(summary.schemas), "Channel": len(summary.channels),
                     "Metadata": len(summary.metadata_indexes), "Message": len(messages)}
    # a header record's body (two empty strings) parses; with a byte more it is not a header
    assert [type(record).__name__ for record in _records(0x01, bytes(8))] == ["Header"]
    assert _records(0x01, bytes(9)) is None


def test_a_record_head_that_ends_the_file_is_read(tmp_path):
    # by hand: the magic, a header record (two empty strings), and a footer's head of length 0 that ends the file
    path = tmp_path / "tiny.mcap"
    path.write_bytes(MAGIC + struct.pack("<BQ", 0x01, 8) + bytes(8) + struct.pack("<BQ", 0x02, 0))
    recording = read_recording(path)
    assert recording.truncated is False and recording.truncation == "" and recording.topics == {}
    # the header followed by nine bytes that begin no record: nothing follows it
    path.write_bytes(MAGIC + struct.pack("<BQ", 0x01, 8) + bytes(8) + bytes(9))
    with pytest.raises(RecordingError) as refused:
        read_recording(path)
    assert str(refused.value) == f"{path}: unreadable MCAP file (no record follows the record of opcode 0x01 at byte 8)"


def test_a_data_end_record_states_its_crc_and_0_for_none(tmp_path):
    whole = recorded(tmp_path / "whole.mcap", frames=50)
    content = whole.read_bytes()
    data_end = content.rindex(b"\x0f\x04\x00\x00\x00\x00\x00\x00\x00", 0, len(content) - 8 - FOOTER_BYTES)
    crc = content[data_end + 9:data_end + 13]
    assert read_recording(whole).salvage.data_crc_ok is True

    def scanned(body: bytes):
        (tmp_path / "data-end.mcap").write_bytes(rewritten_record(content, data_end, body))
        return read_recording(tmp_path / "data-end.mcap").salvage

    assert scanned(crc).data_crc_ok is True
    assert scanned(bytes(4)).data_crc_ok is None  # 0: the writer states none
    assert scanned(b"\x01\x00\x00\x00").data_crc_ok is False


def test_each_damaged_length_is_counted_in_the_data_and_in_the_summary(tmp_path):
    whole = recorded(tmp_path / "whole.mcap")
    _, intact = indexed_messages(whole)
    chunks = chunks_of(whole)
    content = bytearray(whole.read_bytes())
    for chunk in (chunks[1], chunks[3]):
        content[chunk.chunk_start_offset + 1] ^= 0x01  # one byte longer or shorter
    footer = len(content) - 8 - FOOTER_BYTES
    summary_start = struct.unpack_from("<Q", content, footer + 9)[0]
    index = next(offset for offset, opcode, _ in records_between(bytes(content), summary_start, footer) if opcode == 0x08)
    content[index + 1] ^= 0x01  # a chunk index's length, in the summary
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(content))
    salvage = read_recording(damaged).salvage
    assert (salvage.resynchronised, salvage.damaged_records, salvage.messages) == (3, 0, len(intact))


def test_a_stray_byte_after_the_magic_costs_its_own_head(tmp_path):
    whole = recorded(tmp_path / "whole.mcap", frames=50)
    _, intact = indexed_messages(whole)
    stray = tmp_path / "stray.mcap"
    stray.write_bytes(MAGIC + b"\x05" + whole.read_bytes()[len(MAGIC):])  # a message's opcode, then the file
    salvage = read_recording(stray).salvage
    # the stray head (its length read from the header's first bytes) is skipped; the header and all after it read
    assert (salvage.damaged_records, salvage.messages, salvage.bytes_lost) == (1, len(intact), 9)


def test_a_summary_record_with_a_damaged_length_is_passed_whatever_its_body(tmp_path):
    whole = recorded(tmp_path / "whole.mcap", frames=50)
    content = bytearray(whole.read_bytes())
    footer = len(content) - 8 - FOOTER_BYTES
    summary_start = struct.unpack_from("<Q", content, footer + 9)[0]
    index = next(offset for offset, opcode, _ in records_between(bytes(content), summary_start, footer) if opcode == 0x08)
    content[index + 1] ^= 0x01  # its length
    content[index + 9 + 32 + 3] ^= 0x80  # and its message index offsets' byte count: the body parses no more
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(content))
    salvage = read_recording(damaged).salvage
    # the summary only indexes the data: passed over to the next record, nothing of the data lost
    assert (salvage.resynchronised, salvage.damaged_records, salvage.messages) == (1, 0, 51)


def test_resynchronising_looks_only_past_the_damaged_record(tmp_path):
    # by hand: a header whose last byte (its library's one character) is 0x02, the footer's opcode; then at
    # byte 26 a schema record of 3 bytes that does not parse, zeros, and a footer's head 779 bytes on.
    # Read from the byte before the damaged record, that 0x02 and the damaged record's first 8 bytes would
    # make a "record" reaching that footer exactly: only the bytes after the damaged record's start count.
    start = len(MAGIC) + 9 + 9
    content = (MAGIC + struct.pack("<BQII1s", 0x01, 9, 0, 1, b"\x02") + struct.pack("<BQ", 0x03, 3) + bytes(770)
               + struct.pack("<BQ", 0x02, 0))
    assert content[start - 1] == 0x02 and len(content) == start + 779 + 9
    path = tmp_path / "edge.mcap"
    path.write_bytes(content)
    salvage = read_recording(path).salvage
    assert (salvage.truncated, salvage.damaged_records, salvage.bytes_lost) == (False, 1, 779)
