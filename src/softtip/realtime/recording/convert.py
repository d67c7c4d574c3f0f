"""MCAP recordings to the Parquet trial dataset (:mod:`softtip.data.dataset`).

A frame is a header stamp at which every chip's ``{prefix}/chip{k}/field`` message (a Hall
chip; ``.../force`` for a force chip) is present. Its channels are the change from the baseline
(in µT; in N, channels ``side_f{x|y|z}_N``, for a force chip): the recorded
``{prefix}/chip{k}/baseline`` in use at that stamp (frames before the first baseline use
the first one: it was taken from them), or, in recordings without baselines, the mean of
the first ``baseline_frames`` frames of each trial (initial-value subtraction). Frames in
which a chip reported a fault (NaN) are left out. A new trial starts wherever the time
between frames exceeds ``gap_s`` or goes backwards (a restarted device); ``gap_s=None``
keeps one trial per recording (unless time goes backwards).

Labels, when their topics are present: ``Fx, Fy, Fz`` (N) and ``Tx, Ty, Tz`` (N m) from
``{prefix}/wrench`` (the components that hold a value somewhere), each estimate of
``{prefix}/estimates`` under its own name and unit (unless a wrench label has it already),
and ``contact_state`` from ``{prefix}/contact_state``. Stamped labels are matched to frames
by header stamp, the others by log time; a frame without a label value gets NaN (or an
empty state). A recording cut short by a killed process converts up to its last chunk, one with
a damaged chunk without that chunk's messages; the conversion's ``salvage`` says what was read and
what was lost. A recording whose data section fails its CRC with no damaged record to explain it
(a flipped byte in a topic name, a unit, a label) is refused: what it would misname cannot be told.
One whose CRC fails beside a damaged chunk or length is refused too unless ``salvage`` is asked: the
CRC cannot tell whether the damage stops there or also reached a record outside the chunks, which
no CRC of its own covers (a topic name flipped beside a damaged chunk would convert without its
labels); salvaged, what parses converts and ``salvage`` says what was lost.
"""

from __future__ import annotations

import json
import operator
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from softtip._core.channels import Reading
from softtip._core.config import PositiveNumber, checked
from softtip._core.systems import known_readings
from softtip.data.dataset import (
    DIMENSIONLESS,
    TIME,
    TRIAL,
    Dataset,
    DatasetMetadata,
    subtract_trial_baseline,
)
from softtip.realtime.recording.format import (
    FLOAT64_MULTI_ARRAY,
    MESSAGE_ENCODING,
    METADATA_NAME,
    READING_VECTORS,
    STRING,
    WRENCH_LABELS,
    WRENCH_STAMPED,
    WRENCH_UNITS,
    RecordingError,
    per_message_unit,
    reading_topic,
)
from softtip.realtime.recording.reader import Recording, Salvage, TopicMessages, read_recording

CONTACT_STATE = "contact_state"
_READING_TOPIC = re.compile(r"(?P<prefix>.*)/chip(?P<chip>0|[1-9][0-9]*)/(?P<leaf>[A-Za-z0-9_]+)")


@dataclass(frozen=True)
class Conversion:
    """The dataset written and what was left out on the way."""

    dataset: Dataset
    frames: int
    incomplete_frames: int  # stamps at which some chip's message is missing
    fault_frames: int  # frames with a faulty chip (NaN)
    truncated: bool  # the recording ended before its footer
    salvage: Salvage  # messages read, bytes and time range lost


def _topic(recording: Recording, name: str, schema: str) -> TopicMessages | None:
    topic = recording.topics.get(name)
    if topic is None or not topic.data:
        return None
    if topic.schema_name != schema or topic.message_encoding != MESSAGE_ENCODING:
        raise RecordingError(f"{recording.path}: topic {name} holds {topic.schema_name or 'schemaless'} "
                             f"{topic.message_encoding} messages, expected {schema} in {MESSAGE_ENCODING}")
    return topic


def _stamp_ns(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def _vectors(vectors) -> np.ndarray:
    return np.array([(v.x, v.y, v.z) for v in vectors], dtype=np.float64).reshape(-1, 3)


def _readings(topic: TopicMessages, reading: Reading) -> tuple[np.ndarray, np.ndarray]:
    """(header stamps in ns, readings (n, axes) in the reading's unit) of a topic of a chip's messages:
    the reading's own axes of each message's vector."""
    messages = topic.decoded()
    stamps = np.array([_stamp_ns(m.header) for m in messages], dtype=np.int64)
    vector = operator.attrgetter(READING_VECTORS[reading.message])
    return stamps, _vectors(vector(m) for m in messages)[:, list(reading.positions)] * per_message_unit(reading)


def _reading_topics(recording: Recording, prefix: str | None) -> tuple[str, list[str], Reading]:
    found: dict[str, dict[int, str]] = {}
    readings: dict[str, set[Reading]] = {}
    known = {(reading.topic, reading.message): reading for reading in known_readings()}
    for name, topic in recording.topics.items():
        match = _READING_TOPIC.fullmatch(name)
        reading = known.get((match["leaf"], topic.schema_name)) if match else None
        if reading is not None and topic.data:
            found.setdefault(match["prefix"], {})[int(match["chip"])] = name
            readings.setdefault(match["prefix"], set()).add(reading)
    if prefix is None:
        if len(found) != 1:
            raise RecordingError(f"{recording.path}: " + (
                "no chip readings: expected topics " + " or ".join(
                    f"<prefix>/chip<k>/{r.topic} of {r.message}" for r in known.values()) if not found else
                f"fingertips under several prefixes ({', '.join(sorted(found))}): pass prefix"))
        prefix = next(iter(found))
    chips = found.get(prefix, {})
    if not chips:
        raise RecordingError(f"{recording.path}: no {prefix}/chip<k>/field topics")
    if len(readings[prefix]) > 1:
        raise RecordingError(f"{recording.path}: {prefix} holds chips of different readings "
                              f"({', '.join(sorted(r.quantity for r in readings[prefix]))})")
    if sorted(chips) != list(range(len(chips))):
        raise RecordingError(f"{recording.path}: chips {sorted(chips)} recorded; expected chips 0..{len(chips) - 1}")
    return prefix, [chips[k] for k in range(len(chips))], next(iter(readings[prefix]))


def _frames(recording: Recording, topics: list[str],
            reading: Reading) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(stamps in ns, log times of chip 0, readings (n, chips, axes), stamps left out as incomplete)."""
    decoded = []
    for name in topics:
        topic = recording.topics[name]
        stamps, values = _readings(topic, reading)
        decoded.append((stamps, np.asarray(topic.log_times, dtype=np.int64), values))
    every = np.unique(np.concatenate([stamps for stamps, _, _ in decoded]))
    common = every
    for stamps, _, _ in decoded:
        common = np.intersect1d(common, stamps)
    rows = [_matched(stamps, common) for stamps, _, _ in decoded]
    fields = np.stack([values[r] for (_, _, values), r in zip(decoded, rows, strict=True)], axis=1)
    return common, decoded[0][1][rows[0]], fields, len(every) - len(common)


def _held(stamps: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Index of the last of ``stamps`` (sorted) at or before each of ``at``; the first before any."""
    return np.maximum(np.searchsorted(stamps, at, side="right") - 1, 0)


def _matched(stamps: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Index into ``stamps`` of each of ``at``, -1 where absent."""
    order = np.argsort(stamps, kind="stable")
    position = np.minimum(np.searchsorted(stamps[order], at), len(stamps) - 1)
    found = stamps[order][position] == at
    return np.where(found, order[position], -1)


def _trials(stamps: np.ndarray, gap_s: float | None) -> np.ndarray:
    step = np.diff(stamps)
    breaks = step <= 0
    if gap_s is not None:
        breaks |= step > gap_s * 1e9
    return np.concatenate([[0], np.cumsum(breaks)]).astype(np.int64)


def _labels(recording: Recording, prefix: str, stamps: np.ndarray,
            log_times: np.ndarray) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    columns: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    wrench = _topic(recording, f"{prefix}/wrench", WRENCH_STAMPED)
    if wrench is not None:
        messages = wrench.decoded()
        wrench_stamps = np.array([_stamp_ns(m.header) for m in messages], dtype=np.int64)
        values = np.hstack([_vectors(m.wrench.force for m in messages), _vectors(m.wrench.torque for m in messages)])
        rows = _matched(wrench_stamps, stamps)
        matched = np.where(rows[:, None] >= 0, values[rows], np.nan)
        for component, (name, unit) in enumerate(zip(WRENCH_LABELS, WRENCH_UNITS, strict=True)):
            if np.isfinite(matched[:, component]).any():
                columns[name], units[name] = matched[:, component], unit
    estimates = _topic(recording, f"{prefix}/estimates", FLOAT64_MULTI_ARRAY)
    if estimates is not None:
        decoded = estimates.decoded()
        names = decoded[0].layout.dim[0].label.split(",") if decoded[0].layout.dim else []
        declared_units = json.loads(estimates.metadata.get("units", "null")) or [DIMENSIONLESS] * len(names)
        if len(declared_units) != len(names) or any(len(m.data) != len(names) for m in decoded):
            raise RecordingError(f"{recording.path}: {prefix}/estimates messages do not match their names {names}")
        values = np.array([m.data for m in decoded], dtype=np.float64).reshape(len(decoded), len(names))
        rows = _matched(np.asarray(estimates.log_times, dtype=np.int64), log_times)
        for i, (name, unit) in enumerate(zip(names, declared_units, strict=True)):
            if name not in columns:
                columns[name] = np.where(rows >= 0, values[rows, i], np.nan)
                units[name] = unit
    states = _topic(recording, f"{prefix}/contact_state", STRING)
    if states is not None:
        texts = np.array([m.data for m in states.decoded()] + [""])
        rows = _matched(np.asarray(states.log_times, dtype=np.int64), log_times)
        columns[CONTACT_STATE], units[CONTACT_STATE] = texts[rows], DIMENSIONLESS  # -1: the empty entry
    return columns, units


def convert(mcap_path: str | os.PathLike, parquet_path: str | os.PathLike | None = None, *,
            gap_s: float | None = 1.0, baseline_frames: int = 50, prefix: str | None = None,
            description: str | None = None, salvage: bool = False) -> Conversion:
    """Convert an MCAP recording to a dataset (module notes); written to ``parquet_path`` if given.
    With ``salvage``, a recording whose data section fails its CRC beside damaged records converts."""
    if gap_s is not None:
        checked(PositiveNumber, "gap_s", gap_s)
    recording = read_recording(mcap_path)
    recording.salvage.refuse_unexplained_damage(recording.path)
    if recording.salvage.data_crc_ok is False and not salvage:
        raise RecordingError(f"{recording.path}: the data section fails its CRC beside "
                             f"{recording.salvage.damaged_records} damaged and {recording.salvage.resynchronised} "
                             "resynchronised records, and a topic name, unit or label outside them may be altered "
                             "too: refused unless salvaged (--salvage)")
    prefix, reading_topics, reading = _reading_topics(recording, prefix)
    stamps, log_times, fields, incomplete = _frames(recording, reading_topics, reading)
    chips = len(reading_topics)

    _, schema = reading_topic(reading)
    baselines = [_topic(recording, f"{prefix}/chip{k}/baseline", schema) for k in range(chips)]
    recorded_baseline = all(topic is not None for topic in baselines)
    if recorded_baseline:
        for k, topic in enumerate(baselines):
            baseline_stamps, values = _readings(topic, reading)
            order = np.argsort(baseline_stamps, kind="stable")
            fields[:, k] -= values[order][_held(baseline_stamps[order], stamps)]

    sound = np.isfinite(fields).all(axis=(1, 2))
    labels, units = _labels(recording, prefix, stamps, log_times)
    stamps, fields = stamps[sound], fields[sound]
    labels = {name: values[sound] for name, values in labels.items()}
    if not len(stamps):
        raise RecordingError(f"{recording.path}: no frame in which every chip was read")
    trial = _trials(stamps, gap_s)
    if not recorded_baseline:
        fields = subtract_trial_baseline(fields, trial, baseline_frames)
    starts = np.flatnonzero(np.r_[True, trial[1:] != trial[:-1]])
    first_stamp = np.repeat(stamps[starts], np.diff(np.r_[starts, len(stamps)]))
    channels = reading.columns(fields)
    columns = {TRIAL: trial, TIME: (stamps - first_stamp) * 1e-9, **channels, **labels}

    recorded = recording.metadata.get(METADATA_NAME, {})
    extra = json.loads(recorded.get("extra", "{}"))
    metadata = DatasetMetadata(
        description=description if description is not None else f"converted from {Path(mcap_path).name}",
        sensor_settings=extra.get("sensor_settings"),
        protocol={"source": "mcap recording", "file": Path(mcap_path).name, "truncated": recording.truncated,
                  "gap_s": gap_s, "baseline": "recorded" if recorded_baseline else
                  f"initial value: mean of the first {baseline_frames} frames of each trial",
                  "rate_hz": extra.get("rate_hz"), "models": extra.get("models"), "device": extra.get("device")})
    dataset = Dataset(columns, units, {}, metadata, dict.fromkeys(channels, reading.unit))
    if parquet_path is not None:
        dataset.write(parquet_path)
    return Conversion(dataset, len(stamps), incomplete, int(np.count_nonzero(~sound)), recording.truncated,
                      recording.salvage)
