"""Firmware protocol unit against the Python protocol, and the AVR build.

firmware/test/frame_test.cpp is compiled with the host's g++ together with the
firmware's own protocol.cpp; its frames must equal the Python encoder's byte for
byte and decode back to what was encoded, its command parser must recover the
same commands from a damaged stream, and its settings validation and conversion
time must agree with the MLX90393 model. The AVR build runs where Debian's
arduino-mk toolchain is installed (CI installs it with .ci/firmware).
"""

import itertools
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from softtip.hardware.protocol import (
    Ack,
    Command,
    CommandError,
    ErrorReply,
    Frame,
    FrameDecoder,
    FrameType,
    Identity,
    configure_command,
    decode_configure,
    decode_set_rate,
    encode_frame,
    identify_command,
    set_rate_command,
    start_command,
)
from softtip.sensors import MLX90393Settings, conversion_time_s

FIRMWARE = Path(__file__).resolve().parents[1] / "firmware"
SKETCH = FIRMWARE / "softtip_fingertip"
ARDUINO_MK = Path("/usr/share/arduino/Arduino.mk")


@pytest.fixture(scope="module")
def frame_test(tmp_path_factory):
    compiler = shutil.which("g++")
    if compiler is None:
        pytest.skip("g++ is not installed: cannot build firmware/test/frame_test.cpp")
    binary = tmp_path_factory.mktemp("frame_test") / "frame_test"
    subprocess.run(
        [compiler, "-std=c++11", "-O1", "-Wall", "-Wextra", "-Werror", "-pedantic", f"-I{SKETCH}",
         str(FIRMWARE / "test" / "frame_test.cpp"), str(SKETCH / "protocol.cpp"), "-o", str(binary)],
        check=True, capture_output=True, text=True,
    )

    def run(requests: list[str]) -> list[str]:
        result = subprocess.run([str(binary)], input="\n".join(requests) + "\n",
                                capture_output=True, text=True, check=True, timeout=30)
        return result.stdout.splitlines()

    return run


def frame_request(frame: Frame) -> str:
    flags = (1 if frame.temperature_raw is not None else 0) | (2 if frame.boot else 0)
    words = []
    for chip in range(frame.chips):
        words += [frame.status[chip], *frame.raw[chip]]
        if frame.temperature_raw is not None:
            words.append(frame.temperature_raw[chip])
    fields = [frame.seq, frame.device_time_us, flags, frame.chips, *words]
    return "data " + " ".join(str(int(value)) for value in fields)


def random_frames(rng: np.random.Generator, count: int) -> list[Frame]:
    frames = []
    for index in range(count):
        chips = int(rng.integers(1, 9))
        frames.append(Frame(
            seq=int(rng.integers(0, 2**16)),
            device_time_us=int(rng.integers(0, 2**32)),
            status=rng.integers(0, 256, chips),
            raw=rng.integers(0, 2**16, (chips, 3)),
            temperature_raw=rng.integers(0, 2**16, chips) if index % 2 else None,
            boot=bool(index % 3 == 0),
        ))
    # Extremes: every field at its limits.
    frames.append(Frame(seq=65535, device_time_us=2**32 - 1, status=[255] * 8,
                        raw=np.full((8, 3), 65535), temperature_raw=[65535] * 8, boot=True))
    frames.append(Frame(seq=0, device_time_us=0, status=[0], raw=[[0, 0, 0]]))
    return frames


def test_firmware_crc_matches_the_check_value(frame_test):
    assert frame_test(["crc " + b"123456789".hex()]) == [f"crc {0x29B1}"]


def test_firmware_data_frames_equal_the_python_encoder_byte_for_byte(frame_test):
    frames = random_frames(np.random.default_rng(20240611), 300)
    replies = frame_test([frame_request(frame) for frame in frames])
    encoded = [bytes.fromhex(reply.removeprefix("frame ")) for reply in replies]
    assert encoded == [encode_frame(frame) for frame in frames]
    decoder = FrameDecoder()
    assert decoder.feed(b"".join(encoded)) == frames
    assert decoder.crc_errors == decoder.bytes_discarded == 0


def test_firmware_replies_and_commands_equal_the_python_encoder(frame_test):
    name = "softtip-fingertip/1 mux uart"
    expected = [
        Identity(9, 4, name),
        Ack(FrameType.CONFIGURE, 200),
        ErrorReply(FrameType.CONFIGURE, 3, 5, 0b1010),
        configure_command(17, MLX90393Settings(gain_sel=3, res_xyz=(0, 1, 2), osr=3, dig_filt=7, osr2=2)),
        set_rate_command(255, 733),
        identify_command(0),
    ]
    requests = [
        f"identity 9 4 {name.encode().hex()}",
        "ack 17 200",
        "error 17 3 5 10",
        *(f"command {c.code} {(bytes([c.tag]) + c.args).hex()}" for c in expected[3:]),
    ]
    replies = frame_test(requests)
    encoded = [bytes.fromhex(reply.removeprefix("frame ")) for reply in replies]
    assert encoded == [encode_frame(message) for message in expected]


def test_firmware_command_parser_recovers_intact_commands_from_a_damaged_stream(frame_test):
    rng = np.random.default_rng(7)
    commands = [
        identify_command(1),
        configure_command(2, MLX90393Settings(gain_sel=5, dig_filt=4)),
        start_command(3),
        Command(0x1E, 4, b"unknown"),
        set_rate_command(5, 100),
    ]
    stream, intact, damaged_after_header = bytearray(), [], 0
    for round_index, command in enumerate(commands * 6):
        stream += rng.integers(0, 256, int(rng.integers(0, 30)), dtype=np.uint8).tobytes()
        frame = bytearray(encode_frame(command))
        if round_index % 4 == 3:
            position = int(rng.integers(2, len(frame)))
            frame[position] ^= int(rng.integers(1, 256))
            damaged_after_header += position >= 5
        else:
            intact.append(command)
        stream += frame
    stream += encode_frame(Ack(0x11, 1))  # a device frame: not a command, ignored
    *lines, summary = frame_test(["parse " + bytes(stream).hex()])
    parsed = []
    for line in lines:
        _, code, tag, args = (line.split(" ") + [""])[:4]
        parsed.append(Command(int(code), int(tag), bytes.fromhex(args)))
    assert parsed == intact
    assert FrameDecoder().feed(bytes(stream))[:-1] == intact  # the Python decoder agrees
    # A frame damaged after its header is read to its end and fails the CRC.
    assert damaged_after_header > 0 and int(summary.split()[1]) >= damaged_after_header


def test_firmware_settings_validation_and_conversion_time_agree_with_the_model(frame_test):
    cases = [bytes([gain, res, (res + 2) % 5, res, osr, dig_filt, osr2, hallconf, temperature])
             for gain, res, osr, dig_filt, osr2, hallconf, temperature in itertools.product(
                 (0, 7, 8), (0, 3, 4), range(4), range(8), (0, 3), (0, 12, 5), (0, 1, 2))]
    cases.append(bytes(8))  # short
    replies = frame_test(["settings " + args.hex() for args in cases])
    for args, reply in zip(cases, replies, strict=True):
        _, code, conversion_us = reply.split()
        try:
            settings = decode_configure(Command(FrameType.CONFIGURE, 0, args))
        except CommandError as refused:
            assert int(code) == refused.code, args.hex()
            continue
        assert int(code) == 0, args.hex()
        # Table 8 timings are whole microseconds: the sums agree exactly.
        assert int(conversion_us) == round(conversion_time_s(settings) * 1e6), args.hex()


def test_firmware_rate_validation_agrees(frame_test):
    rates = [0, 1, 2, 50, 999, 1000, 1001, 65535]
    replies = frame_test([f"rate {rate.to_bytes(2, 'little').hex()}" for rate in rates] + ["rate 01"])
    for rate, reply in zip(rates, replies[:-1], strict=True):
        _, code, accepted = reply.split()
        try:
            expected = decode_set_rate(Command(FrameType.SET_RATE, 0, rate.to_bytes(2, "little")))
            assert (int(code), int(accepted)) == (0, expected)
        except CommandError as refused:
            assert int(code) == refused.code
    assert replies[-1] == "rate 2 0"  # one argument byte: BAD_LENGTH


def avr_toolchain_missing() -> str | None:
    for tool in ("make", "avr-gcc", "avr-g++"):
        if shutil.which(tool) is None:
            return f"{tool} is not installed"
    if not ARDUINO_MK.exists():
        return f"{ARDUINO_MK} (Debian arduino-mk) is not installed"
    return None


@pytest.mark.skipif(avr_toolchain_missing() is not None, reason=str(avr_toolchain_missing()))
def test_sketch_builds_for_the_uno_and_fits(tmp_path):
    result = subprocess.run(
        ["make", "-C", str(FIRMWARE), f"OBJDIR={tmp_path}"],
        capture_output=True, text=True, timeout=300, env={**os.environ, "MAKEFLAGS": ""},
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert (tmp_path / "softtip_fingertip.hex").stat().st_size > 0
    # ATmega328P: 32256 bytes of flash below the bootloader, 2048 bytes of RAM.
    program = int(re.search(r"Program:\s+(\d+) bytes", result.stdout).group(1))
    data = int(re.search(r"Data:\s+(\d+) bytes", result.stdout).group(1))
    assert program < 32256 and data < 2048 - 512  # leave room for the stack
    warnings = [
        line for line in result.stderr.splitlines() if "softtip_fingertip/" in line and "warning" in line
    ]
    assert warnings == []
