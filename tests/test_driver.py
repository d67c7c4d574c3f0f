"""Host driver, pty emulator and ReSkin reader.

The driver runs against the emulator over a real pseudo-terminal. References:
the analytic field the emulator is fed (recovered within half an LSB, the LSB
checked against the datasheet's sensitivity table typed in here), the
datasheet's temperature reference and slope, and the emulator's exact log of
which frames it sent intact, damaged or not at all (delivered + counted as lost
must match it frame for frame). Tests that stream in real time are marked
``realtime``: they wait for what they need, however long the machine takes."""

import logging
import os
import struct
import time
import tty

import numpy as np
import pytest

from softtip.hardware import (
    ChipStatus,
    DeviceTimeout,
    Emulator,
    FaultPlan,
    FingertipDriver,
    Frame,
    FrameDecoder,
    FrameFate,
    PortError,
    ReSkinDecoder,
    ReSkinReader,
    StreamTracker,
    encode_frame,
    temperature_C,
    temperature_to_raw,
)
from softtip.hardware.protocol import (
    BOOT_FRAMES,
    Ack,
    Command,
    ErrorCode,
    ErrorReply,
    FrameType,
    Identity,
    configure_command,
    identify_command,
    set_rate_command,
    start_command,
)
from softtip.sensors import MLX90393Settings, lsb_uT

CHIPS = 4
SLOPES_UT_PER_S = np.array([40.0, -25.0, 60.0])
# How long a test waits for what it waits for: reaching it means a hang, never the expected way out.
HANG_GUARD_S = 60.0

# MLX90393 datasheet values, typed here rather than taken from the code. Temperature: the
# word is TREF = 46244 (0xB4A4) at 25 degC and changes by 45.2 LSB per degC. Sensitivity
# (HALLCONF 0xC, Table 17) in uT/LSB at RES 0 for GAIN_SEL 0..7, (XY, Z); each RES step
# doubles it, the printed entries rounded to 0.001 uT.
TREF_LSB = 0xB4A4
TREF_C = 25.0
TEMPERATURE_LSB_PER_C = 45.2
SENSITIVITY_RES0_UT = {
    0: (0.751, 1.210), 1: (0.601, 0.968), 2: (0.451, 0.726), 3: (0.376, 0.605),
    4: (0.300, 0.484), 5: (0.250, 0.403), 6: (0.200, 0.323), 7: (0.150, 0.242),
}


def linear_field(t_s: float) -> np.ndarray:
    """Field in uT at device time t_s: distinct per chip and axis, linear in time."""
    offsets = np.array(
        [[100.0, -200.0, 300.0], [-1500.0, 800.0, 50.0], [0.0, 0.0, -900.0], [2500.0, -40.0, 10.0]]
    )
    return offsets + SLOPES_UT_PER_S * t_s


def wait_until(condition, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.01)
    return condition()


def datasheet_lsb_uT(settings):
    """The settings' LSB per axis (uT) from the datasheet's table, after checking that the
    sensor model uses it (within the rounding of the RES 0 entry, doubled per RES step,
    and of the printed entry)."""
    xy, z = SENSITIVITY_RES0_UT[settings.gain_sel]
    res = np.array(settings.res_xyz)
    expected = np.array([xy, xy, z]) * 2.0**res
    used = lsb_uT(settings)
    assert (np.abs(used - expected) <= 0.0005 * (2.0**res + 1)).all(), (settings, used, expected)
    return used


def assert_fields_match_source(samples, settings):
    """Each sample's field is the source at its device time, within half an LSB."""
    tolerance = datasheet_lsb_uT(settings) / 2 + 1e-9 + np.abs(SLOPES_UT_PER_S) * 1e-6  # device clock in whole us
    for sample in samples:
        ok = sample.chip_ok
        error = np.abs(sample.reading[ok] - linear_field(sample.device_time_s)[ok])
        assert (error <= tolerance).all(), (sample.seq, error.max())


def delivered_frames(samples):
    """(device session, seq) of each sample: a BOOT-numbered restart begins a new session."""
    session, previous, delivered = 0, None, []
    for sample in samples:
        if previous is not None and sample.seq < previous and sample.seq < BOOT_FRAMES:
            session += 1
        delivered.append((session, sample.seq))
        previous = sample.seq
    return delivered


def assert_exact_accounting(log, delivered, dropped):
    """Delivered frames are exactly the intact ones, and the lost ones are exactly counted.

    Frames after the last delivered frame of a device session cannot be known to
    the host, so the comparison covers each session up to its last delivered frame.
    """
    last_seq = dict(delivered)  # session -> seq of its last delivered frame
    cut = {
        entry.session: position
        for position, entry in enumerate(log)
        if last_seq.get(entry.session) == entry.seq
    }
    countable = [entry for position, entry in enumerate(log) if position <= cut.get(entry.session, -1)]
    assert [(entry.session, entry.seq) for entry in countable if entry.fate is FrameFate.SENT] == delivered
    assert dropped == sum(entry.fate is not FrameFate.SENT for entry in countable)


# --------------------------------------------------------------------------
# Streaming over a pty
# --------------------------------------------------------------------------


def test_temperature_words_follow_the_datasheet():
    np.testing.assert_allclose(temperature_C([TREF_LSB, TREF_LSB + 452, TREF_LSB - 904]), [25.0, 35.0, 5.0],
                               rtol=1e-12)
    assert temperature_to_raw([TREF_C, 31.5, 35.0]).tolist() == [46244, 46538, 46696]  # 46537.8 rounds up


def test_the_sensitivities_of_the_settings_streamed_here_are_the_datasheets():
    np.testing.assert_allclose(datasheet_lsb_uT(MLX90393Settings()), [0.150, 0.150, 0.242], rtol=0, atol=1e-12)
    np.testing.assert_allclose(datasheet_lsb_uT(MLX90393Settings(gain_sel=4, res_xyz=(1, 2, 3))),
                               [0.601, 1.202, 3.872], rtol=0, atol=1e-12)  # Table 17's printed entries


@pytest.mark.realtime
def test_stream_recovers_the_source_field_with_the_configured_settings():
    # Settings unlike the power-on ones, with the RES 2/3 offset formats and the temperature.
    settings = MLX90393Settings(gain_sel=4, res_xyz=(1, 2, 3), osr=1, dig_filt=2, temperature=True)
    with Emulator(linear_field, rate_hz=200, chips=CHIPS, noise=False, temperature_C=31.5) as emulator:
        with FingertipDriver(emulator.port, settings=settings, rate_hz=200, reply_timeout_s=HANG_GUARD_S) as driver:
            assert driver.identity == Identity(0, CHIPS, "softtip-emulator/1")
            driver.start()
            assert wait_until(lambda: driver.stats.frames >= 60, HANG_GUARD_S)
            driver.stop()
            samples = driver.drain()
        assert emulator.settings == settings
    assert len(samples) >= 60
    assert_fields_match_source(samples, settings)
    for sample in samples:
        assert sample.chip_ok.all() and not sample.saturated.any()
        # 31.5 degC is TREF + 6.5 degC x 45.2 = 46537.8 -> word 46538 -> 25 + 294 / 45.2 = 31.5044 degC.
        np.testing.assert_allclose(sample.temperature_C, TREF_C + (46538 - TREF_LSB) / TEMPERATURE_LSB_PER_C,
                                   rtol=1e-12)
    device_times = np.array([sample.device_time_s for sample in samples])
    host_times = np.array([sample.host_time_s for sample in samples])
    assert (np.diff(device_times) > 0).all() and (np.diff(host_times) >= 0).all()
    assert np.median(np.diff(device_times)) == pytest.approx(1 / 200, rel=0.2)


@pytest.mark.realtime
def test_every_fault_is_accounted_for_frame_by_frame(caplog):
    faults = FaultPlan(
        corrupt_every=7, drop_byte_every=11, stall_every=13, stall_ms=25,
        chip_error_every=5, disconnect_every=90, disconnect_ms=120, seed=3,
    )
    caplog.set_level(logging.WARNING, logger="softtip.hardware")
    with Emulator(linear_field, rate_hz=250, chips=CHIPS, noise=False, faults=faults) as emulator:
        with FingertipDriver(emulator.port, rate_hz=250, reconnect_interval_s=0.05,
                             reply_timeout_s=HANG_GUARD_S) as driver:
            driver.start()
            assert wait_until(lambda: driver.stats.reconnects >= 2 and driver.stats.frames >= 250, HANG_GUARD_S)
            driver.stop()
            samples = driver.drain()
            stats = driver.stats
        log, received = emulator.log, emulator.received
    fates = {fate: sum(entry.fate is fate for entry in log) for fate in FrameFate}
    assert min(fates.values()) > 0, fates  # every kind of damage happened
    assert_exact_accounting(log, delivered_frames(samples), stats.dropped)
    assert stats.crc_errors >= fates[FrameFate.CORRUPTED]
    assert sum(command.code == FrameType.IDENTIFY for _, command in received) == 1 + stats.reconnects
    messages = [record.getMessage() for record in caplog.records]
    assert any(message.startswith("disconnected from") for message in messages)
    assert any(message.startswith("reconnected to") for message in messages)
    # The chip-error frames arrive flagged, with that chip's field withheld.
    failed = [sample for sample in samples if not sample.chip_ok.all()]
    assert failed
    for sample in failed:
        (chip,) = np.flatnonzero(~sample.chip_ok)
        assert sample.status[chip] == ChipStatus.CHIP_ERROR and np.isnan(sample.reading[chip]).all()
    assert_fields_match_source(samples, MLX90393Settings())


@pytest.mark.realtime
def test_after_a_reboot_the_driver_restores_settings_rate_and_stream():
    settings = MLX90393Settings(gain_sel=2, res_xyz=(2, 2, 2), osr=1, dig_filt=3)
    faults = FaultPlan(corrupt_every=9, disconnect_every=100, disconnect_ms=100, reboot_on_disconnect=True)
    with Emulator(linear_field, rate_hz=50, chips=CHIPS, noise=False, faults=faults) as emulator:
        with FingertipDriver(
            emulator.port, settings=settings, rate_hz=300, reconnect_interval_s=0.05, reply_timeout_s=HANG_GUARD_S
        ) as driver:
            driver.start()
            assert wait_until(lambda: emulator.session >= 1 and driver.stats.frames >= 150, HANG_GUARD_S)
            driver.stop()
            samples = driver.drain()
            stats = driver.stats
        log = emulator.log
        # The board came back with its power-on settings and 50 Hz; the driver re-sent its own.
        assert emulator.settings == settings and emulator.rate_hz == 300
    delivered = delivered_frames(samples)
    assert {session for session, _ in delivered} >= {0, 1}
    assert_exact_accounting(log, delivered, stats.dropped)
    assert_fields_match_source(samples, settings)


@pytest.mark.realtime
def test_samples_after_a_configure_reply_use_the_new_settings():
    # At 500 Hz frames are in flight while CONFIGURE is answered: the conversion must
    # switch exactly at the reply, or fields are off by the gain ratio.
    first = MLX90393Settings(gain_sel=7)
    second = MLX90393Settings(gain_sel=1, res_xyz=(3, 3, 3))
    with Emulator(linear_field, rate_hz=500, chips=CHIPS, noise=False) as emulator:
        with FingertipDriver(emulator.port, settings=first, rate_hz=500, reply_timeout_s=HANG_GUARD_S) as driver:
            driver.start()
            assert wait_until(lambda: driver.stats.frames >= 40, HANG_GUARD_S)
            driver.configure(second)
            before = driver.stats.frames
            assert wait_until(lambda: driver.stats.frames >= before + 40, HANG_GUARD_S)
            driver.stop()
            samples = driver.drain()
    datasheet_lsb_uT(first)
    step = datasheet_lsb_uT(second) / 2 + 1e-9
    for sample in samples:
        error = np.abs(sample.reading - linear_field(sample.device_time_s))
        assert (error <= step + np.abs(SLOPES_UT_PER_S) * 1e-6).all()


@pytest.mark.realtime
def test_a_full_queue_keeps_the_newest_samples_and_the_callback_sees_all():
    seen = []
    with Emulator(linear_field, rate_hz=500, chips=CHIPS, noise=False) as emulator:
        with FingertipDriver(emulator.port, rate_hz=500, queue_size=5, callback=seen.append,
                             reply_timeout_s=HANG_GUARD_S) as driver:
            driver.start()
            assert wait_until(lambda: driver.stats.frames >= 30, HANG_GUARD_S)
            driver.stop()  # returns with the STOP reply, which follows the last frame on the link
            queued = driver.drain()
            stats = driver.stats
    assert len(seen) == stats.frames
    assert [sample.seq for sample in queued] == [sample.seq for sample in seen[-5:]]
    assert stats.queue_overflows == stats.frames - 5


@pytest.mark.realtime
def test_saturated_axes_are_flagged():
    def strong_field(t_s):
        field = np.zeros((2, 3))
        field[1, 2] = 1e5  # 100 mT on z of chip 1: beyond every range of GAIN_SEL 7
        return field

    with Emulator(strong_field, rate_hz=200, chips=2, noise=False) as emulator:
        with FingertipDriver(emulator.port, rate_hz=200, reply_timeout_s=HANG_GUARD_S) as driver:
            driver.start()
            sample = driver.read(timeout=HANG_GUARD_S)
    assert sample is not None
    np.testing.assert_array_equal(sample.saturated, [[False] * 3, [False, False, True]])
    # RES 0 z saturates at the signed 16-bit limit: 32767 counts x 0.242 uT.
    assert sample.reading[1, 2] == pytest.approx(32767 * 0.242)


# --------------------------------------------------------------------------
# The emulator answers commands like the firmware
# --------------------------------------------------------------------------


def exchange(port_fd, decoder, command):
    os.write(port_fd, encode_frame(command))
    deadline = time.monotonic() + HANG_GUARD_S
    while time.monotonic() < deadline:
        try:
            replies = [m for m in decoder.feed(os.read(port_fd, 4096)) if not isinstance(m, Frame)]
        except BlockingIOError:
            time.sleep(0.005)
            continue
        if replies:
            return replies
    raise AssertionError(f"no reply to {command}")


def test_emulator_replies_match_the_firmware_command_table():
    with Emulator(lambda t_s: linear_field(t_s)[:2], chips=2) as emulator:
        port_fd = os.open(emulator.port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        tty.setraw(port_fd)
        decoder = FrameDecoder()
        try:
            assert exchange(port_fd, decoder, identify_command(1)) == [Identity(1, 2, "softtip-emulator/1")]
            forbidden_filter = bytes([7, 0, 0, 0, 0, 1, 0, 12, 0])  # OSR 0 with DIG_FILT 1
            bad_args = [
                (Command(0x1F, 2), ErrorCode.UNKNOWN_COMMAND),
                (Command(FrameType.START, 3, b"\x00"), ErrorCode.BAD_LENGTH),
                (Command(FrameType.CONFIGURE, 4, forbidden_filter), ErrorCode.BAD_SETTINGS),
                (Command(FrameType.SET_RATE, 5, struct.pack("<H", 0)), ErrorCode.BAD_RATE),
            ]
            for command, code in bad_args:
                assert exchange(port_fd, decoder, command) == [ErrorReply(command.code, command.tag, code, 0)]
            settings = MLX90393Settings(gain_sel=3)
            assert exchange(port_fd, decoder, configure_command(6, settings)) == [Ack(FrameType.CONFIGURE, 6)]
            assert exchange(port_fd, decoder, set_rate_command(7, 20)) == [Ack(FrameType.SET_RATE, 7)]
            assert exchange(port_fd, decoder, start_command(8)) == [Ack(FrameType.START, 8)]
            assert emulator.settings == settings and emulator.rate_hz == 20 and emulator.streaming
        finally:
            os.close(port_fd)


def test_emulator_reports_a_source_of_the_wrong_shape():
    emulator = Emulator(lambda t_s: np.zeros((3, 3)), chips=2).start()
    port_fd = os.open(emulator.port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        tty.setraw(port_fd)
        # The emulator acquires its first frame right after answering START, before it looks
        # for the next command: the failure is recorded once the reply is in.
        exchange(port_fd, FrameDecoder(), start_command(0))
    finally:
        os.close(port_fd)
    with pytest.raises(RuntimeError, match=r"source returned shape \(3, 3\): expected \(2, 3\)"):
        emulator.close()


# --------------------------------------------------------------------------
# Errors
# --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("port", "message"),
    [
        ("/nonexistent/ttyACM9", r"^port = '/nonexistent/ttyACM9': cannot open: No such file or directory$"),
        ("nosuchscheme://device", r"^port = 'nosuchscheme://device': cannot open: .*nosuchscheme"),
        ("  ", r"^port = '  ': expected a serial device path or a pyserial URL$"),
    ],
)
def test_a_bad_port_gives_a_one_line_error(port, message):
    with pytest.raises(PortError, match=message) as error:
        FingertipDriver(port).open()
    assert "\n" not in str(error.value) and isinstance(error.value, ValueError)


def test_a_silent_device_times_out_on_identify():
    master_fd, slave_fd = os.openpty()
    try:
        driver = FingertipDriver(os.ttyname(slave_fd), reply_timeout_s=0.1, boot_timeout_s=0.3)
        with pytest.raises(DeviceTimeout, match="no reply to IDENTIFY within 0.3 s"):
            driver.open()
        assert not driver.connected
    finally:
        os.close(master_fd)
        os.close(slave_fd)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"rate_hz": 0}, "rate_hz = 0"),
        ({"baudrate": -1}, "^baudrate = -1: expected a positive integer$"),
        ({"queue_size": 1.5}, r"^queue_size = 1\.5: expected an integer$"),
        ({"settings": {"gain_sel": 7}}, r"^settings = \{'gain_sel': 7\}: expected MLX90393Settings$"),
        ({"boot_timeout_s": float("inf")}, "^boot_timeout_s = inf: expected a number$"),
        ({"queue_size": 0}, "queue_size = 0 without a callback"),
        ({"reply_timeout_s": 0}, "reply_timeout_s = 0"),
    ],
)
def test_driver_arguments_are_validated(kwargs, message):
    with pytest.raises(ValueError, match=message):
        FingertipDriver("/dev/null", **kwargs)


def test_fault_plan_is_validated():
    with pytest.raises(ValueError, match=r"faults.corrupt_every = -1"):
        FaultPlan(corrupt_every=-1)
    with pytest.raises(ValueError, match=r"^faults.stall_ms = -5: expected a duration >= 0 in ms$"):
        FaultPlan(stall_ms=-5)
    with pytest.raises(ValueError, match=r"^faults.reboot_on_disconnect = 1: expected true or false$"):
        FaultPlan(reboot_on_disconnect=1)
    with pytest.raises(ValueError, match=r"^faults = 'none': expected a FaultPlan$"):
        Emulator(lambda t: np.zeros((4, 3)), faults="none")
    with pytest.raises(ValueError, match=r"^chips = 0: expected an integer 1\.\.\d+$"):
        Emulator(lambda t: np.zeros((4, 3)), chips=0)
    with pytest.raises(ValueError, match=r"^confirm_records = 0: expected a positive integer$"):
        ReSkinDecoder(confirm_records=0)


# --------------------------------------------------------------------------
# Sequence and clock tracking
# --------------------------------------------------------------------------


def frame(seq, time_us=0, boot=False):
    return Frame(seq=seq, device_time_us=time_us, status=[0], raw=[[0, 0, 0]], boot=boot)


def test_tracker_counts_gaps_across_the_sequence_wrap():
    tracker = StreamTracker()
    lost = [tracker.update(frame(seq))[0] for seq in (65533, 65535, 0, 3, 4)]
    assert lost == [0, 1, 0, 2, 0]


def test_tracker_unwraps_the_device_clock():
    tracker = StreamTracker()
    assert tracker.update(frame(1, 2**32 - 1000))[1] == pytest.approx((2**32 - 1000) * 1e-6)
    assert tracker.update(frame(2, 500))[1] == pytest.approx((2**32 + 500) * 1e-6)


def test_tracker_starts_a_new_session_on_a_boot_frame():
    tracker = StreamTracker()
    assert [tracker.update(frame(seq, 10 * seq, boot=True))[0] for seq in (0, 1, 3)] == [0, 0, 1]
    assert tracker.update(frame(900, 9000))[0] == 896
    # The board restarted: frames 0 and 1 of the new session were lost, the clock restarts.
    lost, device_time_s = tracker.update(frame(2, 20, boot=True))
    assert lost == 2 and device_time_s == pytest.approx(20e-6)


# --------------------------------------------------------------------------
# ReSkin / AnySkin
# --------------------------------------------------------------------------

# 144.0392608642578 and 138.05078125 are float32 values whose bytes hold CR LF.
CRLF_FLOAT_A = struct.unpack("<f", b"\x0d\x0a\x10\x43")[0]
CRLF_FLOAT_B = struct.unpack("<f", b"\x00\x0d\x0a\x43")[0]


def reskin_record(index: int) -> np.ndarray:
    values = np.empty((5, 4), dtype=np.float32)
    values[:, 0] = 28.0 + 0.25 * index + np.arange(5)  # temperature, degC
    values[:, 1:] = np.arange(15).reshape(5, 3) * 10.0 - 70.0 + index
    values[1, 2] = CRLF_FLOAT_A
    values[3, 1] = CRLF_FLOAT_B
    return values


def reskin_bytes(values: np.ndarray) -> bytes:
    return values.astype("<f4").tobytes() + b"\r\n"


def test_reskin_decoder_finds_record_boundaries_despite_crlf_inside_the_data():
    records = [reskin_record(i) for i in range(8)]
    # The stream starts in the middle of a record, just before a CR LF inside its data.
    stream = reskin_bytes(reskin_record(-1))[25:] + b"".join(reskin_bytes(r) for r in records)
    decoder = ReSkinDecoder()
    samples = []
    for start in range(0, len(stream), 13):
        samples += decoder.feed(stream[start : start + 13], host_time_s=float(start))
    assert len(samples) == len(records)
    for sample, values in zip(samples, records, strict=True):
        np.testing.assert_array_equal(sample.reading, values[:, 1:].astype(np.float64))
        np.testing.assert_array_equal(sample.temperature_C, values[:, 0].astype(np.float64))
        assert sample.device_time_s is None and sample.chip_ok.all()
    assert [sample.seq for sample in samples] == list(range(8))
    assert decoder.bytes_discarded == len(reskin_bytes(records[0])) - 25
    assert decoder.record_size == 82


def test_reskin_decoder_resynchronises_after_a_lost_byte():
    records = [reskin_record(i) for i in range(10)]
    chunks = [reskin_bytes(r) for r in records]
    chunks[4] = chunks[4][:30] + chunks[4][31:]  # a byte lost in record 4
    decoder = ReSkinDecoder()
    samples = decoder.feed(b"".join(chunks), host_time_s=0.0)
    expected = records[:4] + records[5:]
    assert len(samples) == len(expected) and decoder.resyncs == 1
    for sample, values in zip(samples, expected, strict=True):
        np.testing.assert_array_equal(sample.reading, values[:, 1:].astype(np.float64))


def test_reskin_reader_on_a_pty():
    master_fd, slave_fd = os.openpty()
    tty.setraw(slave_fd)
    try:
        with ReSkinReader(os.ttyname(slave_fd)) as reader:
            os.write(master_fd, b"".join(reskin_bytes(reskin_record(i)) for i in range(4)))
            samples = []
            deadline = time.monotonic() + HANG_GUARD_S
            while len(samples) < 4 and time.monotonic() < deadline:
                samples += reader.read(timeout=0.2)
    finally:
        os.close(master_fd)
        os.close(slave_fd)
    assert len(samples) == 4
    np.testing.assert_array_equal(samples[3].reading, reskin_record(3)[:, 1:].astype(np.float64))
