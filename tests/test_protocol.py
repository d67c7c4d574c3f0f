"""Fingertip serial protocol: CRC against its catalogue check value and a bitwise
reference, frames against a byte layout built by hand, and a fuzzed streaming
decoder that never raises, never returns a damaged frame and loses no intact one."""

import binascii
import itertools
import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from softtip.hardware.protocol import (
    MAX_CHIPS,
    Ack,
    Command,
    CommandError,
    ErrorCode,
    ErrorReply,
    Frame,
    FrameDecoder,
    FrameType,
    Identity,
    configure_command,
    crc16_ccitt_false,
    decode_configure,
    decode_set_rate,
    encode_frame,
    identify_command,
    set_rate_command,
    start_command,
    stop_command,
)
from softtip.sensors import MLX90393Settings


def bitwise_crc16_ccitt_false(data: bytes) -> int:
    """Reference: the MSB-first shift register, one bit at a time."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


# --------------------------------------------------------------------------
# CRC
# --------------------------------------------------------------------------


def test_crc_matches_the_catalogue_check_value():
    # CRC-16/CCITT-FALSE ("CRC-16/IBM-3740"): check = 0x29B1 for ASCII "123456789".
    assert crc16_ccitt_false(b"123456789") == 0x29B1


@settings(deadline=None)  # shared machine: time per example varies
@given(st.binary(max_size=200))
def test_crc_matches_a_bitwise_shift_register(data):
    assert crc16_ccitt_false(data) == bitwise_crc16_ccitt_false(data)


# --------------------------------------------------------------------------
# Encoding against hand-built byte layouts (firmware/PROTOCOL.md)
# --------------------------------------------------------------------------


# A damaged header can announce a long payload; the frames behind it come out once
# enough bytes have arrived to disprove it: at most one longest frame (5 + 80 + 2).
FLUSH = bytes(87)


def with_crc(body: bytes) -> bytes:
    return b"\xa5\x5a" + body + struct.pack("<H", bitwise_crc16_ccitt_false(body))


def test_data_frame_layout_built_by_hand():
    frame = Frame(
        seq=0x1234,
        device_time_us=0x89ABCDEF,
        status=[0x02, 0x00],
        raw=[[0x0001, 0x8000, 0xFFFF], [0x0A0B, 0x0C0D, 0x0E0F]],
        boot=True,
    )
    body = bytes([
        0x01, 0x01, 22,  # version, DATA, payload length 8 + 2 * 7
        0x34, 0x12, 0xEF, 0xCD, 0xAB, 0x89, 2, 0x02,  # seq, time, chips, flags = BOOT
        0x02, 0x01, 0x00, 0x00, 0x80, 0xFF, 0xFF,  # chip 0: status, x, y, z
        0x00, 0x0B, 0x0A, 0x0D, 0x0C, 0x0F, 0x0E,  # chip 1
    ])
    assert encode_frame(frame) == with_crc(body)


def test_data_frame_with_temperature_layout_built_by_hand():
    frame = Frame(seq=65535, device_time_us=0, status=[0x10], raw=[[1, 2, 3]], temperature_raw=[46244])
    body = bytes([0x01, 0x01, 17, 0xFF, 0xFF, 0, 0, 0, 0, 1, 0x01, 0x10, 1, 0, 2, 0, 3, 0, 0xA4, 0xB4])
    assert encode_frame(frame) == with_crc(body)


def test_reply_and_command_layouts_built_by_hand():
    assert encode_frame(Identity(7, 4, "ab")) == with_crc(bytes([1, 0x02, 4, 7, 4, ord("a"), ord("b")]))
    assert encode_frame(Ack(0x11, 9)) == with_crc(bytes([1, 0x03, 2, 0x11, 9]))
    error = ErrorReply(0x14, 3, ErrorCode.BAD_RATE, 0)
    assert encode_frame(error) == with_crc(bytes([1, 0x04, 4, 0x14, 3, 4, 0]))
    assert encode_frame(set_rate_command(5, 1000)) == with_crc(bytes([1, 0x14, 3, 5, 0xE8, 0x03]))
    settings = MLX90393Settings(
        gain_sel=5, res_xyz=(1, 2, 3), osr=2, dig_filt=6, osr2=1, hallconf=0, temperature=True
    )
    configure = bytes([1, 0x11, 10, 1, 5, 1, 2, 3, 2, 6, 1, 0, 1])  # tag, then the 9 settings
    assert encode_frame(configure_command(1, settings)) == with_crc(configure)


# --------------------------------------------------------------------------
# Round trips
# --------------------------------------------------------------------------


@st.composite
def frames(draw):
    chips = draw(st.integers(1, MAX_CHIPS))
    words = st.lists(st.integers(0, 0xFFFF), min_size=chips * 3, max_size=chips * 3)
    temperature = draw(st.none() | st.lists(st.integers(0, 0xFFFF), min_size=chips, max_size=chips))
    return Frame(
        seq=draw(st.integers(0, 0xFFFF)),
        device_time_us=draw(st.integers(0, 2**32 - 1)),
        status=draw(st.lists(st.integers(0, 255), min_size=chips, max_size=chips)),
        raw=np.array(draw(words), dtype=np.int64).reshape(chips, 3),
        temperature_raw=temperature,
        boot=draw(st.booleans()),
    )


printable = st.text(alphabet=st.characters(min_codepoint=0x20, max_codepoint=0x7E), max_size=48)
messages = st.one_of(
    frames(),
    st.builds(Identity, st.integers(0, 255), st.integers(0, MAX_CHIPS), printable),
    st.builds(Ack, st.integers(0, 255), st.integers(0, 255)),
    st.builds(ErrorReply, st.integers(0, 255), st.integers(0, 255), st.integers(0, 255), st.integers(0, 255)),
    st.builds(Command, st.integers(0x10, 0x1F), st.integers(0, 255), st.binary(max_size=15)),
)


@settings(deadline=None)  # shared machine: time per example varies
@given(st.lists(messages, min_size=1, max_size=12))
def test_every_message_round_trips_through_the_decoder(sent):
    decoder = FrameDecoder()
    stream = b"".join(encode_frame(message) for message in sent)
    assert decoder.feed(stream) == sent
    assert decoder.crc_errors == decoder.malformed == decoder.bytes_discarded == decoder.pending == 0


@settings(deadline=None)  # shared machine: time per example varies
@given(st.lists(messages, min_size=1, max_size=6), st.data())
def test_decoding_does_not_depend_on_how_the_stream_is_split(sent, data):
    stream = b"".join(encode_frame(message) for message in sent)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=10)))
    decoder = FrameDecoder()
    received = []
    for start, end in itertools.pairwise([0, *cuts, len(stream)]):
        received += decoder.feed(stream[start:end])
    assert received == sent


# --------------------------------------------------------------------------
# Damaged streams
# --------------------------------------------------------------------------


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=400))
def test_arbitrary_bytes_never_raise_and_only_crc_valid_frames_come_out(garbage):
    decoder = FrameDecoder()
    out = decoder.feed(garbage)
    for message in out:
        # A returned frame is a byte-exact, CRC-valid frame present in the input.
        assert encode_frame(message) in garbage
    frame_bytes = sum(len(encode_frame(message)) for message in out)
    assert frame_bytes + decoder.bytes_discarded + decoder.pending == len(garbage)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(messages, st.binary(max_size=40)), min_size=1, max_size=8), st.data())
def test_every_intact_frame_after_garbage_is_recovered(pieces, data):
    stream = b"".join(garbage + encode_frame(message) for message, garbage in pieces) + FLUSH
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=8)))
    decoder = FrameDecoder()
    received = []
    for start, end in itertools.pairwise([0, *cuts, len(stream)]):
        received += decoder.feed(stream[start:end])
    assert received == [message for message, _ in pieces]
    assert sum(len(garbage) for _, garbage in pieces) + len(FLUSH) == decoder.bytes_discarded
    assert decoder.pending == 0


@settings(deadline=None)  # shared machine: time per example varies
@given(frames(), frames(), st.data())
def test_a_single_damaged_byte_is_always_caught(damaged, following, data):
    # CRC-16 detects every error burst of up to 16 bits: no altered byte gets through.
    stream = bytearray(encode_frame(damaged))
    position = data.draw(st.integers(2, len(stream) - 1))
    stream[position] ^= data.draw(st.integers(1, 255))
    decoder = FrameDecoder()
    assert decoder.feed(bytes(stream) + encode_frame(following) + FLUSH) == [following]


def test_a_bogus_long_length_does_not_swallow_the_next_frame():
    # A header claiming a long payload takes the next frame's bytes as its own;
    # the CRC fails and the decoder searches again from just after that header.
    next_frame = Frame(seq=1, device_time_us=2, status=[0], raw=[[3, 4, 5]])
    bogus = b"\xa5\x5a\x01\x01" + bytes([8 + 8 * 9]) + b"\x00" * 6
    decoder = FrameDecoder()
    assert decoder.feed(bogus + encode_frame(next_frame) + b"\x00" * 80) == [next_frame]
    assert decoder.crc_errors == 1


def test_crc_valid_frames_with_inconsistent_content_are_counted_as_malformed():
    # DATA payload of 15 bytes says 2 chips (needs 22): right CRC, wrong content.
    body = bytes([1, 0x01, 15, 0, 0, 0, 0, 0, 0, 2, 0]) + bytes(7)
    identity_with_control_character = bytes([1, 0x02, 3, 0, 1, 0x07])
    decoder = FrameDecoder()
    assert decoder.feed(with_crc(body) + with_crc(identity_with_control_character)) == []
    assert decoder.malformed == 2


# --------------------------------------------------------------------------
# Commands
# --------------------------------------------------------------------------


def test_configure_round_trips_every_permitted_register_combination():
    for gain, osr, dig_filt, hallconf in itertools.product(range(8), range(4), range(8), (0x0, 0xC)):
        if (osr, dig_filt) in {(0, 0), (0, 1), (1, 0)}:
            continue
        settings = MLX90393Settings(
            gain_sel=gain, res_xyz=(osr, 3 - osr, dig_filt % 4), osr=osr, dig_filt=dig_filt,
            osr2=3 - osr, hallconf=hallconf, temperature=bool(gain % 2),
        )
        assert decode_configure(configure_command(0, settings)) == settings


@pytest.mark.parametrize(
    ("args", "code"),
    [
        (bytes([8, 0, 0, 0, 0, 2, 0, 12, 0]), ErrorCode.BAD_SETTINGS),  # gain_sel 8
        (bytes([7, 4, 0, 0, 0, 2, 0, 12, 0]), ErrorCode.BAD_SETTINGS),  # res_x 4
        (bytes([7, 0, 0, 0, 0, 1, 0, 12, 0]), ErrorCode.BAD_SETTINGS),  # OSR 0 with DIG_FILT 1: forbidden
        (bytes([7, 0, 0, 0, 0, 2, 0, 5, 0]), ErrorCode.BAD_SETTINGS),  # hallconf 5
        (bytes([7, 0, 0, 0, 0, 2, 0, 12, 2]), ErrorCode.BAD_SETTINGS),  # temperature 2
        (bytes([7, 0, 0, 0, 0, 2, 0, 12]), ErrorCode.BAD_LENGTH),
    ],
)
def test_invalid_configure_arguments_are_refused_with_the_device_error_code(args, code):
    with pytest.raises(CommandError) as refused:
        decode_configure(Command(FrameType.CONFIGURE, 0, args))
    assert refused.value.code == code


def test_set_rate_limits():
    assert decode_set_rate(set_rate_command(0, 1)) == 1
    assert decode_set_rate(set_rate_command(0, 1000)) == 1000
    for rate in (0, 1001):
        with pytest.raises(CommandError) as refused:
            decode_set_rate(Command(FrameType.SET_RATE, 0, struct.pack("<H", rate)))
        assert refused.value.code == ErrorCode.BAD_RATE
    with pytest.raises(ValueError, match="rate_hz"):
        set_rate_command(0, 1001)


def test_simple_commands_carry_only_their_tag():
    for make, code in ((identify_command, 0x10), (start_command, 0x12), (stop_command, 0x13)):
        assert make(42) == Command(code, 42, b"")


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"raw": np.zeros((0, 3), np.uint16), "status": []}, "raw has shape"),
        ({"raw": np.zeros((9, 3), np.uint16), "status": [0] * 9}, "raw has shape"),
        ({"raw": [[0, 0, 70000]], "status": [0]}, "raw: expected integers 0..65535"),
        ({"raw": [[0, 0, 1.5]], "status": [0]}, "raw: expected integers"),
        ({"raw": [[0, 0, 0]], "status": [0, 0]}, "status has shape"),
        ({"raw": [[0, 0, 0]], "status": [0], "seq": 65536}, "seq = 65536"),
        ({"raw": [1, 2, 3], "status": [0]}, r"^raw has shape \(3,\): expected \(n, 3\) with n in 1\.\.8$"),
        ({"raw": [[0, 0, 0, 0]], "status": [0]}, r"^raw has shape \(1, 4\): expected \(n, 3\) with n in 1\.\.8$"),
        ({"raw": [[0, 0, 0]], "status": [256]}, r"^status: expected integers 0\.\.255$"),
        ({"raw": [[0, 0, 0]], "status": [0], "temperature_raw": [65536]}, r"^temperature_raw: expected integers 0\.\.65535$"),
        ({"raw": [[0, 0, 0]], "status": [0], "device_time_us": 2**32},
         r"^device_time_us = 4294967296: expected an integer 0\.\.4294967295$"),
    ],
)
def test_frame_validation_names_the_field(kwargs, message):
    fields = {"seq": 0, "device_time_us": 0, **kwargs}
    with pytest.raises(ValueError, match=message):
        Frame(**fields)


def test_a_frame_holds_plain_ints_and_read_only_register_arrays():
    frame = Frame(seq=np.uint16(7), device_time_us=np.uint32(9), status=[1], raw=[[1, 2, 3]],
                  temperature_raw=[4], boot=1)
    assert type(frame.seq) is int and type(frame.device_time_us) is int and frame.boot is True
    assert (frame.raw.dtype, frame.status.dtype, frame.temperature_raw.dtype) == (np.uint16, np.uint8, np.uint16)
    for words in (frame.raw, frame.status, frame.temperature_raw):
        with pytest.raises(ValueError, match="read-only"):
            words[0] = 0


def test_frames_differing_in_any_one_field_are_unequal():
    fields = {"seq": 1, "device_time_us": 2, "status": [0], "raw": [[3, 4, 5]], "temperature_raw": [6], "boot": False}
    frame = Frame(**fields)
    assert frame == Frame(**fields)
    changes = [("seq", 9), ("device_time_us", 9), ("status", [9]), ("raw", [[3, 4, 9]]), ("temperature_raw", [9]),
               ("temperature_raw", None), ("boot", True)]
    for name, value in changes:
        other = Frame(**{**fields, name: value})
        assert frame != other and other != frame, name


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: Identity(256, 1, "a"), r"^tag = 256: expected an integer 0\.\.255$"),
        (lambda: Identity(0, 9, "a"), r"^chips = 9: expected an integer 0\.\.8$"),
        (lambda: Identity(0, 1, "é"), r"^name = 'é': expected printable ASCII$"),
        (lambda: Identity(0, 1, "a\x07"), r"^name = 'a\\x07': expected printable ASCII$"),
        (lambda: Identity(0, 1, "n" * 49), r"^name = 'n{49}': expected at most 48 characters$"),
        (lambda: Ack(256, 0), r"^command = 256: expected an integer 0\.\.255$"),
        (lambda: Ack(0, 256), r"^tag = 256: expected an integer 0\.\.255$"),
        (lambda: Ack(True, 0), r"^command = True: expected an integer 0\.\.255$"),
        (lambda: Ack(1.0, 0), r"^command = 1\.0: expected an integer 0\.\.255$"),
        (lambda: ErrorReply(0, 0, 0, 256), r"^detail = 256: expected an integer 0\.\.255$"),
        (lambda: Command(0x20, 0), r"^code = 32: expected an integer 16\.\.31$"),
        (lambda: Command(0x10, 256), r"^tag = 256: expected an integer 0\.\.255$"),
        (lambda: Command(0x10, 0, bytes(16)), r"^args = b'(\\x00){16}': expected at most 15 bytes$"),
        (lambda: Command(0x10, 0, [1, 2]), r"^args = \[1, 2\]: expected at most 15 bytes$"),
        (lambda: set_rate_command(0, 1001), r"^rate_hz = 1001: expected an integer 1\.\.1000$"),
        (lambda: encode_frame("ab"), r"^message = 'ab': expected a Frame, Identity, Ack, ErrorReply or Command$"),
    ],
)
def test_invalid_messages_are_refused_naming_the_field(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_command_arguments_are_bytes_up_to_fifteen():
    command = Command(0x10, 0, bytearray(range(15)))
    assert type(command.args) is bytes and command.args == bytes(range(15))


@pytest.mark.parametrize(
    ("args", "code", "message"),
    [
        (b"\x01", ErrorCode.BAD_LENGTH, "SET_RATE has 1 argument bytes: expected 2"),
        (b"\x01\x00\x00", ErrorCode.BAD_LENGTH, "SET_RATE has 3 argument bytes: expected 2"),
        (b"\x00\x80", ErrorCode.BAD_RATE, "SET_RATE rate = 32768: expected 1..1000 Hz"),  # 0x8000, unsigned
    ],
)
def test_set_rate_refusals_carry_the_device_error_code_and_say_why(args, code, message):
    with pytest.raises(CommandError) as refused:
        decode_set_rate(Command(FrameType.SET_RATE, 0, args))
    assert (refused.value.code, str(refused.value)) == (code, message)


def test_configure_refusals_say_why():
    for args, message in [(bytes(8), "CONFIGURE has 8 argument bytes: expected 9"),
                          (bytes([7, 0, 0, 0, 0, 2, 0, 12, 2]), "CONFIGURE temperature = 2: expected 0 or 1")]:
        with pytest.raises(CommandError) as refused:
            decode_configure(Command(FrameType.CONFIGURE, 0, args))
        assert str(refused.value) == message
    with pytest.raises(CommandError) as refused:
        decode_configure(Command(FrameType.CONFIGURE, 0, bytes([8, 0, 0, 0, 0, 2, 0, 12, 0])))
    assert str(refused.value).startswith("CONFIGURE: ") and "gain_sel" in str(refused.value)


# --------------------------------------------------------------------------
# Decoder bookkeeping on hand-built streams
# --------------------------------------------------------------------------

# Ack(command=0x11, tag=9); its CRC computed here by binascii, independently of the module
ACK_BODY = bytes([1, 0x03, 2, 0x11, 9])
ACK = b"\xa5\x5a" + ACK_BODY + struct.pack("<H", binascii.crc_hqx(ACK_BODY, 0xFFFF))


def test_decoder_counts_frames_and_discarded_bytes():
    decoder = FrameDecoder()
    assert decoder.feed(b"\x00\x01" + ACK + ACK) == [Ack(0x11, 9)] * 2
    assert (decoder.frames, decoder.bytes_discarded, decoder.pending) == (2, 2, 0)


@pytest.mark.parametrize(
    "header",
    [
        bytes([0xA5, 0x5A, 2, 0x03, 2]),  # protocol version 2
        bytes([0xA5, 0x5A, 1, 0x03, 3]),  # an ACK payload is 2 bytes
        bytes([0xA5, 0x5A, 1, 0x05, 2]),  # no frame type 0x05
        bytes([0xA5, 0x5A, 1, 0x02, 51]),  # an IDENTITY payload is at most 2 + 48 bytes
    ],
)
def test_a_header_no_frame_can_have_is_skipped_without_a_crc_check(header):
    decoder = FrameDecoder()
    assert decoder.feed(b"\x00\x00" + header) == []
    assert (decoder.bytes_discarded, decoder.pending) == (7, 0)  # nothing held back for it
    assert decoder.feed(ACK) == [Ack(0x11, 9)]
    assert (decoder.crc_errors, decoder.malformed, decoder.bytes_discarded, decoder.pending) == (0, 0, 7, 0)


def test_frames_with_a_wrong_crc_are_discarded_whole():
    damaged = ACK[:-1] + bytes([ACK[-1] ^ 0x01])
    decoder = FrameDecoder()
    assert decoder.feed(damaged + damaged + ACK) == [Ack(0x11, 9)]
    assert (decoder.crc_errors, decoder.bytes_discarded, decoder.frames) == (2, 2 * len(ACK), 1)


def test_an_identity_with_the_longest_name_round_trips():
    frame = with_crc(bytes([1, 0x02, 50, 7, 4]) + b"n" * 48)
    assert FrameDecoder().feed(frame) == [Identity(7, 4, "n" * 48)]
    assert encode_frame(Identity(7, 4, "n" * 48)) == frame


def test_an_identity_name_with_the_delete_character_is_malformed():
    decoder = FrameDecoder()
    assert decoder.feed(with_crc(bytes([1, 0x02, 3, 0, 1, 0x7F])) + ACK) == [Ack(0x11, 9)]
    assert decoder.malformed == 1


def test_a_trailing_first_sync_byte_waits_for_the_next_chunk():
    decoder = FrameDecoder()
    assert decoder.feed(b"\x00\x00" + ACK[:1]) == []
    assert (decoder.pending, decoder.bytes_discarded) == (1, 2)
    assert decoder.feed(ACK[1:]) == [Ack(0x11, 9)]


def test_clear_discards_the_pending_bytes():
    decoder = FrameDecoder()
    decoder.feed(b"\x00" + ACK[:4])
    decoder.clear()
    assert (decoder.pending, decoder.bytes_discarded) == (0, 5)
    assert decoder.feed(ACK[4:] + ACK) == [Ack(0x11, 9)]  # the rest of the cut frame is garbage now
    assert decoder.bytes_discarded == 5 + len(ACK) - 4
