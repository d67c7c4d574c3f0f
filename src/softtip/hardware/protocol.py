"""Binary serial protocol of the softtip fingertip firmware (host side).

Every frame, in both directions::

    offset 0  2 bytes  sync 0xA5 0x5A
           2  1        protocol version (1)
           3  1        frame type (FrameType)
           4  1        payload length L
           5  L        payload
         5+L  2        CRC-16/CCITT-FALSE of bytes 2 .. 4+L, little-endian

Multi-byte fields are little-endian. The payload layouts, the command set and a
frame-period budget are in firmware/PROTOCOL.md; the firmware's encoder
(firmware/softtip_fingertip/protocol.cpp) is checked byte for byte against this
module by the tests.
"""

from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass
from enum import IntEnum, IntFlag

import numpy as np
from numpy.typing import ArrayLike

from softtip.sensors.mlx90393 import MLX90393Settings

SYNC = b"\xa5\x5a"
PROTOCOL_VERSION = 1
HEADER_SIZE = 5
CRC_SIZE = 2
MAX_CHIPS = 8
MAX_NAME_LENGTH = 48
MAX_COMMAND_PAYLOAD = 16  # tag + up to 15 argument bytes
DATA_HEADER_SIZE = 8  # seq, device time, chip count, flags
BOOT_FRAMES = 8  # the first data frames after power-on carry DataFlag.BOOT
MIN_RATE_HZ = 1
MAX_RATE_HZ = 1000
_UINT16_MODULUS = 1 << 16
_UINT32_MODULUS = 1 << 32


class FrameType(IntEnum):
    DATA = 0x01
    IDENTITY = 0x02
    ACK = 0x03
    ERROR = 0x04
    IDENTIFY = 0x10
    CONFIGURE = 0x11
    START = 0x12
    STOP = 0x13
    SET_RATE = 0x14


FIRST_COMMAND = 0x10
LAST_COMMAND = 0x1F


class ErrorCode(IntEnum):
    UNKNOWN_COMMAND = 1
    BAD_LENGTH = 2
    BAD_SETTINGS = 3
    BAD_RATE = 4
    CHIP_FAILURE = 5  # detail: bit i set when chip i refused the settings


class DataFlag(IntFlag):
    TEMPERATURE = 0x01  # every chip block carries a raw temperature word
    BOOT = 0x02  # one of the first BOOT_FRAMES frames since the device powered on


class ChipStatus(IntFlag):
    """Per-chip status byte of a data frame, composed by the firmware."""

    BUS_ERROR = 0x01  # no acknowledge or short read; the words are 0
    CHIP_ERROR = 0x02  # ERROR bit in the chip's SM or RM status byte
    RESET = 0x04  # RS bit: the chip restarted with power-on settings
    COUNT_MISMATCH = 0x08  # RM status D1:D0 disagrees with the words requested
    SED = 0x10  # single-error detection in the chip's memory (informational)


CHIP_FAULTS = int(ChipStatus.BUS_ERROR | ChipStatus.CHIP_ERROR | ChipStatus.RESET | ChipStatus.COUNT_MISMATCH)

_DATA_HEADER = struct.Struct("<HIBB")
_CRC = struct.Struct("<H")
_BLOCK_DTYPES = {
    False: np.dtype([("status", "u1"), ("xyz", "<u2", (3,))]),
    True: np.dtype([("status", "u1"), ("xyz", "<u2", (3,)), ("t", "<u2")]),
}
_SETTINGS_ARGS = 9


def crc16_ccitt_false(data: bytes | bytearray | memoryview) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, unreflected, no final XOR)."""
    # binascii.crc_hqx is this CRC with a caller-chosen initial value.
    return binascii.crc_hqx(data, 0xFFFF)


# --------------------------------------------------------------------------
# Messages
# --------------------------------------------------------------------------


def _check_int(name: str, value: object, low: int, high: int) -> int:
    if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or not low <= value <= high:
        raise ValueError(f"{name} = {value!r}: expected an integer {low}..{high}")
    return int(value)


def _word_array(name: str, values: ArrayLike, shape: tuple[int, ...], high: int, dtype) -> np.ndarray:
    array = np.asarray(values)
    if array.shape != shape:
        raise ValueError(f"{name} has shape {array.shape}: expected {shape}")
    if array.size and (
        not np.issubdtype(array.dtype, np.integer) or array.min() < 0 or array.max() > high
    ):
        raise ValueError(f"{name}: expected integers 0..{high}")
    result = array.astype(dtype)
    result.setflags(write=False)
    return result


@dataclass(frozen=True, eq=False)
class Frame:
    """One synchronous acquisition of n chips (a DATA frame).

    raw holds the chips' x, y, z register words as read (uint16, shape (n, 3));
    status the per-chip ChipStatus bytes (n,); temperature_raw the chips' raw
    temperature words (n,) or None when the frame carries no temperature.
    """

    seq: int
    device_time_us: int
    status: np.ndarray
    raw: np.ndarray
    temperature_raw: np.ndarray | None = None
    boot: bool = False

    def __post_init__(self) -> None:
        _check_int("seq", self.seq, 0, _UINT16_MODULUS - 1)
        _check_int("device_time_us", self.device_time_us, 0, _UINT32_MODULUS - 1)
        raw = np.asarray(self.raw)
        if raw.ndim != 2 or raw.shape[1] != 3 or not 1 <= raw.shape[0] <= MAX_CHIPS:
            raise ValueError(f"raw has shape {raw.shape}: expected (n, 3) with n in 1..{MAX_CHIPS}")
        chips = raw.shape[0]
        object.__setattr__(self, "seq", int(self.seq))
        object.__setattr__(self, "device_time_us", int(self.device_time_us))
        object.__setattr__(self, "raw", _word_array("raw", raw, (chips, 3), 0xFFFF, np.uint16))
        object.__setattr__(self, "status", _word_array("status", self.status, (chips,), 0xFF, np.uint8))
        if self.temperature_raw is not None:
            temperature = _word_array(
                "temperature_raw", self.temperature_raw, (chips,), 0xFFFF, np.uint16
            )
            object.__setattr__(self, "temperature_raw", temperature)
        object.__setattr__(self, "boot", bool(self.boot))

    @classmethod
    def decoded(cls, seq: int, device_time_us: int, status: np.ndarray, raw: np.ndarray,
                temperature_raw: np.ndarray | None, boot: bool) -> Frame:
        """A frame from the decoder, whose fields have their types and ranges by construction (a
        CRC-checked payload of the right length): built without re-checking them, since the
        decoder does this for every frame in real time."""
        frame = object.__new__(cls)
        frame.__dict__.update(seq=seq, device_time_us=device_time_us, status=status, raw=raw,
                              temperature_raw=temperature_raw, boot=boot)
        return frame

    @property
    def chips(self) -> int:
        return self.raw.shape[0]

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Frame):
            return NotImplemented
        same_temperature = (self.temperature_raw is None and other.temperature_raw is None) or (
            self.temperature_raw is not None
            and other.temperature_raw is not None
            and np.array_equal(self.temperature_raw, other.temperature_raw)
        )
        return (
            self.seq == other.seq
            and self.device_time_us == other.device_time_us
            and self.boot == other.boot
            and np.array_equal(self.status, other.status)
            and np.array_equal(self.raw, other.raw)
            and same_temperature
        )

    __hash__ = None  # equality compares arrays, which have no hash


@dataclass(frozen=True)
class Identity:
    """Reply to IDENTIFY: the number of chips and the device name."""

    tag: int
    chips: int
    name: str

    def __post_init__(self) -> None:
        _check_int("tag", self.tag, 0, 255)
        _check_int("chips", self.chips, 0, MAX_CHIPS)
        if not isinstance(self.name, str) or not (self.name.isascii() and self.name.isprintable()):
            raise ValueError(f"name = {self.name!r}: expected printable ASCII")
        if len(self.name) > MAX_NAME_LENGTH:
            raise ValueError(f"name = {self.name!r}: expected at most {MAX_NAME_LENGTH} characters")


@dataclass(frozen=True)
class Ack:
    """A command was carried out."""

    command: int
    tag: int

    def __post_init__(self) -> None:
        _check_int("command", self.command, 0, 255)
        _check_int("tag", self.tag, 0, 255)


@dataclass(frozen=True)
class ErrorReply:
    """A command was refused; code is an ErrorCode, detail depends on it."""

    command: int
    tag: int
    code: int
    detail: int = 0

    def __post_init__(self) -> None:
        for name in ("command", "tag", "code", "detail"):
            _check_int(name, getattr(self, name), 0, 255)


@dataclass(frozen=True)
class Command:
    """A host command: its type (0x10..0x1F), a tag echoed by the reply, its arguments."""

    code: int
    tag: int
    args: bytes = b""

    def __post_init__(self) -> None:
        _check_int("code", self.code, FIRST_COMMAND, LAST_COMMAND)
        _check_int("tag", self.tag, 0, 255)
        if not isinstance(self.args, (bytes, bytearray)) or len(self.args) > MAX_COMMAND_PAYLOAD - 1:
            raise ValueError(f"args = {self.args!r}: expected at most {MAX_COMMAND_PAYLOAD - 1} bytes")
        object.__setattr__(self, "args", bytes(self.args))


Message = Frame | Identity | Ack | ErrorReply | Command


def _is_printable_ascii(data: bytes) -> bool:
    return all(0x20 <= byte < 0x7F for byte in data)


# --------------------------------------------------------------------------
# Commands
# --------------------------------------------------------------------------


class CommandError(ValueError):
    """A command's arguments are invalid; code is the ErrorCode the device replies with."""

    def __init__(self, message: str, code: ErrorCode) -> None:
        super().__init__(message)
        self.code = code


def identify_command(tag: int) -> Command:
    return Command(FrameType.IDENTIFY, tag)


def configure_command(tag: int, settings: MLX90393Settings) -> Command:
    """CONFIGURE every chip with settings (the same registers on all chips)."""
    args = bytes([
        settings.gain_sel,
        *settings.res_xyz,
        settings.osr,
        settings.dig_filt,
        settings.osr2,
        settings.hallconf,
        int(settings.temperature),
    ])
    return Command(FrameType.CONFIGURE, tag, args)


def start_command(tag: int) -> Command:
    return Command(FrameType.START, tag)


def stop_command(tag: int) -> Command:
    return Command(FrameType.STOP, tag)


def checked_rate_hz(rate_hz: object) -> int:
    """rate_hz as an int if the firmware accepts it (1..1000 Hz); ValueError otherwise."""
    return _check_int("rate_hz", rate_hz, MIN_RATE_HZ, MAX_RATE_HZ)


def set_rate_command(tag: int, rate_hz: int) -> Command:
    return Command(FrameType.SET_RATE, tag, struct.pack("<H", checked_rate_hz(rate_hz)))


def decode_configure(command: Command) -> MLX90393Settings:
    """Settings carried by a CONFIGURE command; CommandError if they are invalid."""
    args = command.args
    if len(args) != _SETTINGS_ARGS:
        raise CommandError(
            f"CONFIGURE has {len(args)} argument bytes: expected {_SETTINGS_ARGS}", ErrorCode.BAD_LENGTH
        )
    if args[8] > 1:
        raise CommandError(f"CONFIGURE temperature = {args[8]}: expected 0 or 1", ErrorCode.BAD_SETTINGS)
    try:
        return MLX90393Settings(
            gain_sel=args[0],
            res_xyz=(args[1], args[2], args[3]),
            osr=args[4],
            dig_filt=args[5],
            osr2=args[6],
            hallconf=args[7],
            temperature=bool(args[8]),
        )
    except ValueError as error:
        raise CommandError(f"CONFIGURE: {error}", ErrorCode.BAD_SETTINGS) from None


def decode_set_rate(command: Command) -> int:
    """Frame rate in Hz carried by a SET_RATE command; CommandError if invalid."""
    if len(command.args) != 2:
        raise CommandError(
            f"SET_RATE has {len(command.args)} argument bytes: expected 2", ErrorCode.BAD_LENGTH
        )
    (rate,) = struct.unpack("<H", command.args)
    if not MIN_RATE_HZ <= rate <= MAX_RATE_HZ:
        raise CommandError(
            f"SET_RATE rate = {rate}: expected {MIN_RATE_HZ}..{MAX_RATE_HZ} Hz", ErrorCode.BAD_RATE
        )
    return rate


# --------------------------------------------------------------------------
# Encoding
# --------------------------------------------------------------------------


def _frame_bytes(frame_type: int, payload: bytes) -> bytes:
    body = bytes([PROTOCOL_VERSION, frame_type, len(payload)]) + payload
    return SYNC + body + _CRC.pack(crc16_ccitt_false(body))


def encode_frame(message: Message) -> bytes:
    """The complete wire frame (sync to CRC) of any message."""
    if isinstance(message, Frame):
        with_temperature = message.temperature_raw is not None
        flags = DataFlag(0)
        if with_temperature:
            flags |= DataFlag.TEMPERATURE
        if message.boot:
            flags |= DataFlag.BOOT
        blocks = np.zeros(message.chips, dtype=_BLOCK_DTYPES[with_temperature])
        blocks["status"] = message.status
        blocks["xyz"] = message.raw
        if with_temperature:
            blocks["t"] = message.temperature_raw
        header = _DATA_HEADER.pack(message.seq, message.device_time_us, message.chips, int(flags))
        return _frame_bytes(FrameType.DATA, header + blocks.tobytes())
    if isinstance(message, Identity):
        name = message.name.encode("ascii")
        return _frame_bytes(FrameType.IDENTITY, bytes([message.tag, message.chips]) + name)
    if isinstance(message, Ack):
        return _frame_bytes(FrameType.ACK, bytes([message.command, message.tag]))
    if isinstance(message, ErrorReply):
        payload = bytes([message.command, message.tag, message.code, message.detail])
        return _frame_bytes(FrameType.ERROR, payload)
    if isinstance(message, Command):
        return _frame_bytes(message.code, bytes([message.tag]) + message.args)
    raise ValueError(f"message = {message!r}: expected a Frame, Identity, Ack, ErrorReply or Command")


# --------------------------------------------------------------------------
# Decoding
# --------------------------------------------------------------------------

_DATA_LENGTHS = frozenset(
    DATA_HEADER_SIZE + chips * block.itemsize
    for chips in range(1, MAX_CHIPS + 1)
    for block in _BLOCK_DTYPES.values()
)


def _length_allowed(frame_type: int, length: int) -> bool:
    """Whether a header's type and payload length can belong to a valid frame."""
    if frame_type == _DATA:
        return length in _DATA_LENGTHS
    if frame_type == _IDENTITY:
        return 2 <= length <= 2 + MAX_NAME_LENGTH
    if frame_type == _ACK:
        return length == 2
    if frame_type == _ERROR:
        return length == 4
    if FIRST_COMMAND <= frame_type <= LAST_COMMAND:
        return 1 <= length <= MAX_COMMAND_PAYLOAD
    return False


# plain ints of the enums the decoder compares for every frame: enum operators cost microseconds
_DATA, _IDENTITY, _ACK, _ERROR = (int(FrameType.DATA), int(FrameType.IDENTITY), int(FrameType.ACK),
                                  int(FrameType.ERROR))
_TEMPERATURE_FLAG, _BOOT_FLAG = int(DataFlag.TEMPERATURE), int(DataFlag.BOOT)


def _parse_payload(frame_type: int, payload: bytes) -> Message | None:
    """The message of a CRC-checked payload, or None when its content is inconsistent."""
    if frame_type == _DATA:
        seq, device_time_us, chips, flags = _DATA_HEADER.unpack_from(payload)
        with_temperature = bool(flags & _TEMPERATURE_FLAG)
        block = _BLOCK_DTYPES[with_temperature]
        if not 1 <= chips <= MAX_CHIPS or len(payload) != DATA_HEADER_SIZE + chips * block.itemsize:
            return None
        # read-only views straight into the payload's bytes: no copy
        blocks = np.frombuffer(payload, block, chips, DATA_HEADER_SIZE)
        return Frame.decoded(seq, device_time_us, blocks["status"], blocks["xyz"],
                             blocks["t"] if with_temperature else None, bool(flags & _BOOT_FLAG))
    if frame_type == FrameType.IDENTITY:
        if payload[1] > MAX_CHIPS or not _is_printable_ascii(payload[2:]):
            return None
        return Identity(tag=payload[0], chips=payload[1], name=payload[2:].decode("ascii"))
    if frame_type == FrameType.ACK:
        return Ack(command=payload[0], tag=payload[1])
    if frame_type == FrameType.ERROR:
        return ErrorReply(command=payload[0], tag=payload[1], code=payload[2], detail=payload[3])
    return Command(code=frame_type, tag=payload[0], args=payload[1:])


class LinkEnd:
    """Either end of the serial link (the driver, the emulated board): the sensor settings and the
    frame rate it has agreed on, set by its constructor and by CONFIGURE / SET RATE."""

    _settings: MLX90393Settings
    _rate_hz: int

    @property
    def settings(self) -> MLX90393Settings:
        return self._settings

    @property
    def rate_hz(self) -> int:
        return self._rate_hz


class FrameDecoder:
    """Streaming decoder: bytes in, messages out, whatever the bytes are.

    feed() never raises on byte input and returns only frames whose CRC matches.
    After a failed candidate it steps one byte past that candidate's sync and
    searches again, so a frame that follows garbage or a damaged frame is still
    found; a damaged length can hold it back until the bytes that disprove that
    header have arrived (at most one longest frame, 87 bytes).

    Counters: frames (messages returned), crc_errors (candidates with a valid
    header and a wrong CRC), malformed (right CRC, inconsistent content) and
    bytes_discarded (bytes that are part of no returned frame). Every byte fed
    is in a returned frame, in bytes_discarded or still pending.
    """

    def __init__(self) -> None:
        self._buffer = bytearray()
        self.frames = 0
        self.crc_errors = 0
        self.malformed = 0
        self.bytes_discarded = 0

    @property
    def pending(self) -> int:
        """Bytes held back because they may start a frame not yet complete."""
        return len(self._buffer)

    def clear(self) -> None:
        """Discard the pending bytes (after the byte stream was interrupted)."""
        self.bytes_discarded += len(self._buffer)
        self._buffer.clear()

    def feed(self, data: bytes | bytearray | memoryview) -> list[Message]:
        buffer = self._buffer
        buffer += data
        messages: list[Message] = []
        size = len(buffer)
        position = 0
        while True:
            start = buffer.find(SYNC, position)
            if start < 0:
                # A final first sync byte may pair with the next chunk: keep it.
                keep = 1 if size > position and buffer[-1] == SYNC[0] else 0
                self.bytes_discarded += size - keep - position
                position = size - keep
                break
            self.bytes_discarded += start - position
            position = start
            if size - position < HEADER_SIZE:
                break
            version, frame_type, length = buffer[position + 2 : position + HEADER_SIZE]
            if version != PROTOCOL_VERSION or not _length_allowed(frame_type, length):
                position += 1
                self.bytes_discarded += 1
                continue
            end = position + HEADER_SIZE + length + CRC_SIZE
            if end > size:
                break
            body = bytes(buffer[position + 2 : end - CRC_SIZE])
            message = None
            if crc16_ccitt_false(body) != _CRC.unpack_from(buffer, end - CRC_SIZE)[0]:
                self.crc_errors += 1
            else:
                message = _parse_payload(frame_type, body[3:])
                if message is None:
                    self.malformed += 1
            if message is None:
                position += 1
                self.bytes_discarded += 1
                continue
            messages.append(message)
            self.frames += 1
            position = end
        del buffer[:position]
        return messages
