"""The firmware executed: its own AVR build runs in simavr (firmware/sim/fingertip_sim.c) with an
emulated TCA9548A and MLX90393s, and streams to the host driver over a pseudo-terminal.

The fields fed to the emulated chips are read back through the firmware, the frames and the driver,
and compared with a hand computation from the datasheet's sensitivity (Table 17, HALLCONF 0xC): 0.150
µT per count on X and Y and 0.242 on Z at GAIN_SEL 7, RES 0 (the power-on gain); 3.004 and 4.840 at
GAIN_SEL 0, RES 2; the temperature word 46244 + 45.2 per kelvin above 25 °C (the datasheet's
typical reference, the driver's too). A chip that does not acknowledge must be reported as the
protocol says (status bit 0, BUS_ERROR; the host reads NaN) while the other chips carry on. CI
installs simavr with .ci/run.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from softtip.bench.firmware import (SimulatedBoard, build, command_answers, read_fields, simulated_board,
                                    toolchain_missing, write_fields)
from softtip.hardware.driver import FingertipDriver
from softtip.sensors import MLX90393Settings

MISSING = toolchain_missing()
pytestmark = [pytest.mark.skipif(MISSING is not None, reason=str(MISSING)), pytest.mark.slow]
CHIPS = 2
FIRMWARE = Path(__file__).resolve().parents[1] / "firmware"  # the checkout's: a wheel holds no sketch


@pytest.fixture(scope="module")
def simulator():
    return build([CHIPS], FIRMWARE)


@pytest.fixture(scope="module")
def fields_uT():
    rng = np.random.default_rng(7)
    return np.stack([rng.uniform(-800, 800, (500, CHIPS)), rng.uniform(-800, 800, (500, CHIPS)),
                     rng.uniform(1500, 3000, (500, CHIPS))], axis=-1)


def by_hand(field_uT: np.ndarray, xy_uT_per_count: float, z_uT_per_count: float) -> np.ndarray:
    sensitivity = np.array([xy_uT_per_count, xy_uT_per_count, z_uT_per_count])
    return np.round(field_uT / sensitivity) * sensitivity


def streamed(simulator, fields_uT, settings: MLX90393Settings, seconds: float, rate_hz: int):
    with simulated_board(simulator, fields_uT, temperature_c=31.5) as board:
        with FingertipDriver(board.port, settings=settings, rate_hz=rate_hz, reply_timeout_s=3.0,
                             boot_timeout_s=12.0) as driver:
            driver.start()
            board.wait_simulated(seconds)
            driver.stop()
            board.wait_simulated(0.01)
            samples, stats = driver.drain(), driver.stats
        return samples, stats, list(board.log.frames), list(board.log.conversions)


@pytest.mark.parametrize("settings, xy, z", [(MLX90393Settings(), 0.150, 0.242),
                                             (MLX90393Settings(gain_sel=0, res_xyz=(2, 2, 2), temperature=True),
                                              3.004, 4.840)])
def test_frames_decode_and_read_back_the_fields_fed(simulator, fields_uT, settings, xy, z):
    samples, stats, sent, conversions = streamed(simulator, fields_uT, settings, 0.25, 200)
    seqs = [s.seq for s in samples]
    # every frame the firmware sent while streaming arrived intact, in order, without gaps
    assert len(samples) >= 45 and seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    assert [f.seq for f in sent if seqs[0] <= f.seq <= seqs[-1]] == seqs
    assert (stats.crc_errors, stats.malformed, stats.dropped) == (0, 0, 0)
    # a fault-free stream triggers every chip once per frame from power-on: frame k holds conversion k
    for chip in range(CHIPS):
        assert {c.index for c in conversions if c.chip == chip} >= set(seqs)
    for sample in samples:
        assert not sample.status.any()
        np.testing.assert_allclose(sample.reading, by_hand(fields_uT[sample.seq % len(fields_uT)], xy, z),
                                   rtol=0, atol=1e-9)
        if settings.temperature:  # the chip sends T first: 46244 + 6.5 K x 45.2 = 46537.8 -> 46538 counts
            assert sample.temperature_C == pytest.approx([25 + (46538 - 46244) / 45.2] * CHIPS, abs=1e-9)
        else:
            assert sample.temperature_C is None
    period = np.median(np.diff([s.device_time_s for s in samples]))
    assert period == pytest.approx(1 / 200, abs=2e-6)  # micros() ticks in 4 us steps


def test_a_chip_that_does_not_acknowledge_is_reported_and_recovers(simulator, fields_uT):
    settings = MLX90393Settings()
    with simulated_board(simulator, fields_uT) as board:
        with FingertipDriver(board.port, settings=settings, rate_hz=200, reply_timeout_s=3.0,
                             boot_timeout_s=12.0) as driver:
            driver.start()
            board.wait_simulated(0.03)
            board.control("nak 1 1")
            board.wait_simulated(0.1)
            board.control("nak 1 0")
            board.wait_simulated(0.1)
            driver.stop()
            samples = driver.drain()
    status = np.array([s.status for s in samples])
    refused = np.flatnonzero(status[:, 1])
    # at least the 0.1 s held at 200 frames/s; the protocol's BUS_ERROR bit alone, and NaN on the host
    assert len(refused) >= 19 and np.all(status[refused, 1] == 0x01)
    assert np.array_equal(refused, np.arange(refused[0], refused[-1] + 1))
    assert all(np.isnan(samples[i].reading[1]).all() for i in refused)
    assert not status[:, 0].any()  # chip 0 is read all along, with its own fields
    for sample in samples:
        np.testing.assert_allclose(sample.reading[0], by_hand(fields_uT[sample.seq % len(fields_uT), 0], 0.150, 0.242),
                                   rtol=0, atol=1e-9)
    # re-initialised after the frame that found it again: later frames read it without fault
    assert refused[-1] < len(samples) - 15 and not status[refused[-1] + 1:].any()


def test_a_chip_that_refuses_commands_is_reset_after_one_frame(simulator, fields_uT):
    with simulated_board(simulator, fields_uT) as board:
        with FingertipDriver(board.port, rate_hz=200, reply_timeout_s=3.0, boot_timeout_s=12.0) as driver:
            driver.start()
            board.wait_simulated(0.03)
            board.control("burst 1")  # left in burst mode: SM is refused with ERROR until EX
            board.wait_simulated(0.1)
            samples = driver.drain()
    status = np.array([s.status for s in samples])
    # one frame reports CHIP_ERROR (bit 1, NaN on the host); EX, RT and the settings follow it
    assert np.flatnonzero(status[:, 1]).size == 1 and status[:, 1].max() == 0x02 and not status[:, 0].any()
    after = samples[int(np.flatnonzero(status[:, 1])[0]) + 1:]
    assert len(after) >= 15
    for sample in after:  # the refused SM started no conversion: the chip is one behind the frames
        row = fields_uT[(sample.seq - 1) % len(fields_uT), 1]
        np.testing.assert_allclose(sample.reading[1], by_hand(row, 0.150, 0.242), rtol=0, atol=1e-9)


def test_a_stuck_bus_costs_one_timeout_per_frame_and_the_rate_holds(simulator, fields_uT):
    with simulated_board(simulator, fields_uT) as board:
        with FingertipDriver(board.port, rate_hz=100, reply_timeout_s=3.0, boot_timeout_s=12.0) as driver:
            driver.start()
            board.wait_simulated(0.03)
            driver.drain()
            board.control("stuck 1")
            board.wait_simulated(0.2)
            during = driver.drain()
            identity = driver.identify()  # commands are still answered
            board.control("stuck 0")
            board.wait_simulated(0.1)
            after = driver.drain()
    stuck = [s for s in during if (s.status == 0x01).all()]
    assert len(stuck) >= 17 and identity.chips == CHIPS
    # a 3 ms timeout per frame, not per transfer: the 10 ms period holds
    assert np.median(np.diff([s.device_time_s for s in stuck])) == pytest.approx(0.010, abs=1e-4)
    # the frames still stuck (sent before the release reached the bus) come first; then every one is clean
    faulty = np.flatnonzero(np.array([s.status for s in after]).any(axis=1))
    assert np.array_equal(faulty, np.arange(len(faulty))) and len(after) - len(faulty) >= 8


def test_commands_and_bad_input_are_answered_as_the_protocol_says(simulator, fields_uT):
    answers = command_answers(simulator, CHIPS, fields_uT)
    assert [a["case"] for a in answers if not a["ok"]] == []
    by_case = {a["case"]: a["answer"] for a in answers}
    assert by_case["IDENTIFY with a bad CRC"] == "no reply"
    assert by_case["reserved command 0x15"] == "ERROR UNKNOWN_COMMAND (detail 0x00)"
    # CHIP_FAILURE's detail has bit i set for each chip i that refused the settings
    assert by_case[f"CONFIGURE while chip {CHIPS - 1} does not acknowledge"] == "ERROR CHIP_FAILURE (detail 0x02)"
    # GAIN_SEL 5 at [6:4], HALLCONF 0xC; OSR 1, DIG_FILT 3 at [4:2], RES 1, 1, 2 at [6:5], [8:7], [10:9]
    words = (0x5C, 0x1 | 3 << 2 | 1 << 5 | 1 << 7 | 2 << 9)
    assert by_case["registers 0x00, 0x02 after CONFIGURE"] == str([words] * CHIPS)


def test_fields_from_a_pipe(simulator, fields_uT, tmp_path):
    pipe = tmp_path / "fields"
    os.mkfifo(pipe)
    # held open for writing by this process (Linux allows it without a reader), filled before the start
    writer = os.open(pipe, os.O_RDWR | os.O_NONBLOCK)
    rows = fields_uT[:40].round(3)
    os.write(writer, ("\n".join(" ".join(f"{v:.3f}" for v in row.ravel()) for row in rows) + "\n").encode())
    board = SimulatedBoard(simulator, CHIPS, pipe)
    try:
        with FingertipDriver(board.port, rate_hz=200, reply_timeout_s=3.0, boot_timeout_s=12.0) as driver:
            driver.start()
            board.wait_simulated(0.3)
            samples = driver.drain()
    finally:
        board.close()
        os.close(writer)
    # a pipe's rows are taken in turn; once they run out the last one holds
    assert samples[-1].seq > 45
    for sample in samples:
        np.testing.assert_allclose(sample.reading, by_hand(rows[min(sample.seq, 39)], 0.150, 0.242),
                                   rtol=0, atol=1e-9)


def softtip(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    return subprocess.run([sys.executable, "-m", "softtip", *args], capture_output=True, text=True, env=env,
                          timeout=1800)


def test_bench_command_reports_every_chip_count(fields_uT, tmp_path):
    write_fields(tmp_path / "fields.txt", fields_uT)
    result = softtip("bench", "firmware", "--chips", str(CHIPS), "--seconds", "0.2", "--firmware", str(FIRMWARE),
                     "--fields", str(tmp_path / "fields.txt"), "--json")
    assert result.returncode == 0, result.stderr[-2000:]
    report = json.loads(result.stdout)
    assert [s["chips"] for s in report["streams"]] == [1, 2]
    assert report["fields"] == {"source": f"the field file {tmp_path / 'fields.txt'}", "rows": 500, "chips": CHIPS}
    # No frame is shorter than the firmware's wait for chip 0's conversion (Table 8 at the default
    # settings, 2169 us, plus its 10 % margin: 2385.9 us) and the bus time at 400 kHz (PROTOCOL.md's
    # timeline): select + SM of chip 0 (147.5 us; 97.5 us without the select of a lone chip, whose
    # channel stays), then its RM (232.5 us) and select + RM of each other chip (282.5 us). The Wire
    # library's software time between bytes, which that count leaves out, is under a third of a frame.
    for s, shortest_us in zip(report["streams"], (97.5 + 2385.9 + 232.5, 147.5 + 2385.9 + 232.5 + 282.5)):
        assert s["frames_lost"] == 0 and s["frames_not_as_fed"] == 0 and s["frames_received"] == s["frames_sent"]
        assert s["frames_per_s_bus_and_conversion_bound"] == pytest.approx(1e6 / shortest_us)
        assert 2 / 3 * 1e6 / shortest_us < s["frames_per_s"] < 1e6 / shortest_us
    assert all(a["ok"] for a in report["commands"])


def test_the_twins_push_fields_are_fed_by_default_and_read_back_as_the_datasheet_quantises_them(simulator, tmp_path):
    """The default fields are the fingertip twin's push scenario, as the live path caches it, sampled at
    its own 200 Hz; streamed, each frame carries them quantised at 0.150 µT (X, Y) and 0.242 µT (Z) a count."""
    from softtip.lab import load_protocol
    from softtip.systems.hall_fingertip.live import live_pushes

    exported = tmp_path / "twin.txt"
    result = softtip("bench", "firmware", "--chips", str(CHIPS), "--export-fields", str(exported), "--json")
    assert result.returncode == 0, result.stderr[-2000:]
    report = json.loads(result.stdout)
    assert report["source"].startswith("the twin's push scenario (") and "chip k reads its chip k mod 1" in report["source"]
    twin = live_pushes(load_protocol("force3"))  # the cache entry the command computed (design D: one chip)
    fields = read_fields(exported, CHIPS)
    # its three motions at 200 Hz (17 s), then its loop again: the scenario's time runs modulo its last
    # sample's, so that sample reads as the first and the rows compared stop before it
    loop = len(twin.times_s) - 1
    assert len(fields) == 4000 and loop < 4000 and np.allclose(np.diff(twin.times_s), 1 / 200)
    assert np.allclose(fields[:loop], np.repeat(twin.field_uT[:loop], CHIPS, axis=1), rtol=0, atol=1e-6)  # 6 decimals
    moving = int(np.argmax(np.any(fields[:, 0] != fields[0, 0], axis=1)))  # the first row after the rest
    with simulated_board(simulator, fields[moving - 20:]) as board:
        with FingertipDriver(board.port, rate_hz=200, reply_timeout_s=3.0, boot_timeout_s=12.0) as driver:
            driver.start()
            board.wait_simulated(0.3)
            samples = driver.drain()
    assert len(samples) >= 45
    for sample in samples:
        np.testing.assert_allclose(sample.reading, by_hand(fields[moving - 20 + sample.seq], 0.150, 0.242),
                                   rtol=0, atol=1e-9)
    # by hand for the first frame: each word the field over the step, rounded, times the step (measured: the
    # rest field -30.736492, 10.842272, 3726.321472 µT, words -205, 72, 15398, read -30.750, 10.800, 3726.316 µT)
    first = fields[moving - 20 + samples[0].seq, 0]
    words = [round(first[0] / 0.150), round(first[1] / 0.150), round(first[2] / 0.242)]
    assert np.allclose(samples[0].reading[0], [words[0] * 0.150, words[1] * 0.150, words[2] * 0.242], atol=1e-9)
    assert 1000 < abs(words[2]) < 32767  # the chip's axis field: thousands of counts, within the 16-bit word
