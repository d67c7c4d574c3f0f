"""Reading a recording back, whole or up to the torn tail a killed writer leaves.

:func:`read_recording` reads the file record by record without its index, so a file whose
writer was killed reads up to its last complete chunk. Messages are kept as stored;
:meth:`TopicMessages.decoded` decodes a topic's ROS 2 messages with ``mcap-ros2-support``
from the schema embedded in the file.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

from mcap.exceptions import InvalidMagic
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap_ros2.decoder import DecoderFactory

from softtip.realtime.recording.format import RecordingError


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


def _decoder(factory: DecoderFactory, path: Path, channel: Channel, schema: Schema | None):
    try:
        return factory.decoder_for(channel.message_encoding, schema)
    except Exception as problem:  # a ros2msg schema the library cannot parse
        raise RecordingError(f"{path}: topic {channel.topic}: schema {schema.name} does not parse "
                             f"({type(problem).__name__}: {problem})") from None


def read_recording(path: str | os.PathLike) -> Recording:
    """Every message of an MCAP file, read front to back without its index, so that a file
    whose writer was killed reads up to its last complete chunk (``truncated`` is then set)."""
    path = Path(path)
    if not path.is_file():
        raise RecordingError(f"recording {path} does not exist")
    factory = DecoderFactory()
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
                    if record.topic not in topics:
                        schema = schemas.get(record.schema_id)
                        topics[record.topic] = TopicMessages(
                            record.topic, schema.name if schema else "", record.message_encoding,
                            dict(record.metadata), _decoder(factory, path, record, schema))
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

