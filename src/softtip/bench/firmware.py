"""The fingertip firmware executed: its own AVR build (ATmega328P, 16 MHz) run in simavr by
``firmware/sim/fingertip_sim.c``, with a TCA9548A and N MLX90393s emulated on the I2C bus and the
UART on a pseudo-terminal that the host driver opens like the board's serial port at 1,000,000 baud.

The simulator reports every conversion (simulated time of its end, and the wall clock when the
simulation reached it) and every DATA frame whose last bit left the UART (simulated time, and the
wall clock when its bytes were written to the pseudo-terminal). The host driver stamps each decoded
frame with the same monotonic clock. The latency from a chip's conversion to the host's decoded frame
is then the sum of a simulated part (conversion end to the frame's last bit, as on the board) and a
host part (bytes written to decoded), which holds whether or not the simulation keeps up with the
wall clock (the simulation is paced never to run ahead of it; on a loaded machine it runs slower).
Rates are in simulated time: what the firmware does on a real board.

The chips are fed the twin's fields by default: the default live scenario's (``softtip live --emulate``'s,
the fingertip twin's pushes and shears), computed once and cached as the live path caches them,
sampled at :data:`FIELD_RATE_HZ` from its start, one row per conversion; a build with more chips than
the scenario streams feeds chip k the scenario's chip k mod its count. ``--fields FILE`` feeds a
file's rows instead, and ``--export-fields FILE`` writes the rows the bench would feed, in the
simulator's format (:func:`write_fields`).
"""

from __future__ import annotations

import hashlib
import itertools
import os
import queue
import shutil
import subprocess
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from softtip._core.cache import cache_dir
from softtip._core.files import atomic_write
from softtip._core.progress import SILENT, Progress
from softtip._core.systems import default, load, owner
from softtip.hardware.driver import FingertipDriver, Sample, open_serial
from softtip.hardware.protocol import (CHIP_FAULTS, Ack, ChipStatus, Command, ErrorCode, ErrorReply, FrameDecoder,
                                       FrameType, Identity, configure_command, encode_frame, identify_command,
                                       set_rate_command, start_command, stop_command)
from softtip.realtime.scenario import LiveScenario
from softtip.sensors.mlx90393 import MLX90393, MLX90393Settings, conversion_time_s

FIRMWARE_DIR = Path(__file__).resolve().parents[3] / "firmware"
ARDUINO_MK = Path("/usr/share/arduino/Arduino.mk")
SIMAVR_HEADER = Path("/usr/include/simavr/avr_twi.h")
SOURCES = ("Makefile", "softtip_fingertip/softtip_fingertip.ino", "softtip_fingertip/mlx90393.cpp",
           "softtip_fingertip/mlx90393.h", "softtip_fingertip/protocol.cpp", "softtip_fingertip/protocol.h",
           "sim/fingertip_sim.c")
MAX_CHIPS = 8  # the sketch's SOFTTIP_CHIP_COUNT: 1 to 8
MAX_RATE_HZ = 1000  # the firmware's highest rate: frames then follow back to back
FIELD_ROWS = 4000  # rows of the field file, used in turn by the conversions (cycling)
FIELD_RATE_HZ = 200.0  # a scenario's time between rows: the push scenario's own sampling, so rows are its samples
REPLY_WAIT_S = 3.0  # wall time for a reply: the simulation may run several times slower than real time
SIMULATED_WAIT_S = 0.05  # simulated time a dropped command is given to prove it has no reply
# PROTOCOL.md's frame-period budget: bit periods at 400 kHz of a mux select, an SM and an XYZ RM
I2C_BIT_US = 2.5
SELECT_BITS, SM_BITS, RM_BITS = 20, 39, 93


class SimulatorUnavailable(RuntimeError):
    """A tool the simulated board needs is missing or its build failed."""


def toolchain_missing() -> str | None:
    """Why the simulated board cannot be built here, or None."""
    for tool in ("make", "avr-gcc", "avr-g++", "cc"):
        if shutil.which(tool) is None:
            return f"{tool} is not installed (Debian: apt-get install arduino-mk gcc-avr avr-libc build-essential)"
    if not ARDUINO_MK.exists():
        return f"{ARDUINO_MK} is missing (Debian: apt-get install arduino-mk arduino-core-avr)"
    if not SIMAVR_HEADER.exists():
        return f"{SIMAVR_HEADER} is missing (Debian: apt-get install simavr libsimavr-dev)"
    return None


@dataclass(frozen=True)
class SimulatorBuild:
    harness: Path
    firmware: dict[int, Path]  # chip count -> ELF


def _run_make(firmware_dir: Path, *arguments: str) -> None:
    result = subprocess.run(["make", "-C", str(firmware_dir), *arguments], capture_output=True, text=True,
                            env={**os.environ, "MAKEFLAGS": ""}, timeout=600)
    if result.returncode != 0:
        tail = "\n".join((result.stdout + result.stderr).splitlines()[-15:])
        raise SimulatorUnavailable(f"make {' '.join(arguments)} failed:\n{tail}")


def build(chip_counts: list[int], firmware_dir: Path = FIRMWARE_DIR, progress: Progress = SILENT) -> SimulatorBuild:
    """The simulator and one firmware build per chip count (the sketch's SOFTTIP_CHIP_COUNT), built with
    the sketch's own Makefile into the cache, under a hash of the sources."""
    missing = toolchain_missing()
    if missing is not None:
        raise SimulatorUnavailable(missing)
    digest = hashlib.sha256()
    for name in SOURCES:
        digest.update(name.encode() + b"\0" + (firmware_dir / name).read_bytes())
    folder = cache_dir() / "firmware-sim" / digest.hexdigest()[:16]
    harness = folder / "fingertip_sim"
    elves = {n: folder / f"uno-{n}" / "softtip_fingertip.elf" for n in chip_counts}
    todo = [n for n, elf in elves.items() if not elf.exists()]
    with progress.task("building the firmware and the simulator", total=len(todo) + 1) as task:
        if not harness.exists():
            _run_make(firmware_dir, "sim", f"SIM={harness}")
        task.advance(note="simulator")
        for n in todo:
            _run_make(firmware_dir, f"OBJDIR={elves[n].parent}", f"EXTRA_FLAGS=-DSOFTTIP_CHIP_COUNT={n}")
            task.advance(note=f"{n} chip{'s' * (n > 1)}")
    return SimulatorBuild(harness, elves)


@dataclass(frozen=True)
class FedFields:
    """What the emulated chips read, one row per conversion ((rows, chips, 3) µT), the chips' settings
    (the source's, else the power-on ones) and what the rows come from, in words for the report."""

    fields_uT: np.ndarray
    settings: MLX90393Settings
    source: str


def scenario_fields(scenario: LiveScenario, chips: int, rows: int = FIELD_ROWS,
                    rate_hz: float = FIELD_RATE_HZ) -> np.ndarray:
    """(rows, chips, 3) µT: ``scenario``'s emulated fields at ``rate_hz`` from its start, chip k the
    scenario's chip k mod its chips; a scenario that emulates no chips of its own is refused."""
    if scenario.emulator_source is None:
        raise ValueError(f"scenario {scenario.description!r}: streams from a source of its own, not emulated chips' "
                         "fields, expected a scenario of the fingertip's emulator")
    sampled = np.stack([np.asarray(scenario.emulator_source(k / rate_hz), dtype=float) for k in range(rows)])
    return sampled[:, np.arange(chips) % scenario.chips]


def twin_fields(chips: int, progress: Progress = SILENT, name: str | None = None) -> FedFields:
    """The default live scenario's fields (``name``: another registered scenario), computed or read
    from the cache as ``softtip live --emulate`` does, for a build of ``chips`` chips."""
    name = default("scenario") if name is None else name
    if name is None:
        raise ValueError("bench firmware: no registered system offers a live scenario to take the fields from; "
                         "give --fields FILE")
    scenario = load(owner("scenario", name).scenarios[name])(progress)
    if scenario.settings is None or not isinstance(scenario.settings.values, MLX90393Settings):
        raise ValueError(f"scenario {name!r}: its chips are no MLX90393s, which the simulated board emulates; "
                         "give --fields FILE")
    fed = "" if chips <= scenario.chips else f"; chip k reads its chip k mod {scenario.chips}"
    return FedFields(scenario_fields(scenario, chips), scenario.settings.values,
                     f"the twin's {name} scenario ({scenario.description}: {scenario.chips} chip"
                     f"{'s' * (scenario.chips > 1)}, sampled at {FIELD_RATE_HZ:g} Hz from its start{fed})")


def file_fields(path: Path, chips: int) -> FedFields:
    """A field file's rows (:func:`read_fields`), read by chips at their power-on settings."""
    return FedFields(read_fields(path, chips), MLX90393Settings(), f"the field file {path}")


def read_fields(path: Path, chips: int) -> np.ndarray:
    """(rows, chips, 3) µT from a field file (the format of write_fields); ValueError naming the file."""
    try:
        values = np.loadtxt(path, ndmin=2)
    except ValueError as error:
        raise ValueError(f"--fields {path}: expected rows of numbers: {error}") from None
    if values.shape[1] != 3 * chips or len(values) == 0 or not np.isfinite(values).all():
        raise ValueError(f"--fields {path}: expected rows of {3 * chips} finite numbers "
                         f"(x y z in µT of {chips} chips)")
    return values.reshape(len(values), chips, 3)


def write_fields(path: Path, fields_uT: np.ndarray) -> None:
    """The simulator's field file: one row per conversion, x y z of chip 0, then chip 1, ..."""
    def write(stream) -> None:
        np.savetxt(stream, fields_uT.reshape(len(fields_uT), -1), fmt="%.6f",
                   header="x y z (uT) of each chip, one row per conversion")
    atomic_write(path, write)


@dataclass(frozen=True)
class Conversion:
    chip: int
    index: int  # the chip's k-th conversion since power-on
    sim_ns: int
    wall_ns: int


@dataclass(frozen=True)
class SentFrame:
    seq: int
    sim_ns: int  # the frame's last bit left the UART
    wall_ns: int  # its bytes were written to the pseudo-terminal


@dataclass
class BoardLog:
    conversions: list[Conversion] = field(default_factory=list)
    frames: list[SentFrame] = field(default_factory=list)
    early_reads: int = 0
    sim_ns: int = 0  # the latest simulated time reported
    reported_wall_ns: int = 0  # the wall clock of the latest "time" report


class SimulatedBoard:
    """The firmware running in the simulator: ``port`` for the host, ``control`` for bus faults."""

    def __init__(self, build: SimulatorBuild, chips: int, fields_path: Path, temperature_c: float = 25.0) -> None:
        self.chips = chips
        self.log = BoardLog()
        self._registers: queue.Queue[tuple[int, int, int]] = queue.Queue()
        self._process = subprocess.Popen(
            [str(build.harness), str(build.firmware[chips]), "--chips", str(chips), "--fields", str(fields_path),
             "--temperature-c", repr(float(temperature_c))],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1)
        line = self._process.stdout.readline()
        while line and not line.startswith("pty "):
            line = self._process.stdout.readline()
        if not line:
            raise SimulatorUnavailable(f"the simulator did not start: {self._process.stderr.read().strip()}")
        self.port = line.split()[1]
        self._reader = threading.Thread(target=self._read_events, name="fingertip-sim-events", daemon=True)
        self._reader.start()

    def _read_events(self) -> None:
        log = self.log
        for line in self._process.stdout:
            kind, *values = line.split()
            if kind == "conv":
                chip, index, sim_ns, wall_ns = map(int, values[:4])
                log.conversions.append(Conversion(chip, index, sim_ns, wall_ns))
                log.sim_ns = max(log.sim_ns, sim_ns)
            elif kind == "frame":
                seq, sim_ns, wall_ns = map(int, values)
                log.frames.append(SentFrame(seq, sim_ns, wall_ns))
                log.sim_ns = max(log.sim_ns, sim_ns)
            elif kind == "early":
                log.early_reads += 1
            elif kind == "regs":
                chip, reg0, reg2 = int(values[0]), int(values[1], 16), int(values[2], 16)
                self._registers.put((chip, reg0, reg2))
            elif kind == "time":
                log.sim_ns = max(log.sim_ns, int(values[0]))
                log.reported_wall_ns = int(values[1])

    def control(self, line: str) -> None:
        self._process.stdin.write(line + "\n")
        self._process.stdin.flush()

    def registers(self) -> list[tuple[int, int]]:
        """Registers 0x00 and 0x02 of every chip, as the firmware left them."""
        self.control("regs")
        found = {}
        while len(found) < self.chips:
            chip, reg0, reg2 = self._registers.get(timeout=REPLY_WAIT_S)
            found[chip] = (reg0, reg2)
        return [found[chip] for chip in range(self.chips)]

    def wait_simulated(self, seconds: float) -> None:
        """Until the simulation has advanced by ``seconds`` of simulated time."""
        asked_ns = time.monotonic_ns()  # the simulator's wall clock is CLOCK_MONOTONIC too
        self.control("time")
        self._until(lambda: self.log.reported_wall_ns >= asked_ns)
        target = self.log.sim_ns + round(seconds * 1e9)
        self._until(lambda: self.log.sim_ns >= target)

    def _until(self, condition) -> None:
        while not condition():
            if self._process.poll() is not None:
                raise SimulatorUnavailable(f"the simulator stopped: {self._process.stderr.read().strip()}")
            time.sleep(0.002)

    def close(self) -> None:
        if self._process.poll() is None:
            self.control("quit")
            try:
                self._process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self._process.kill()
                self._process.wait()
        self._reader.join(timeout=5)


@contextmanager
def simulated_board(build: SimulatorBuild, fields_uT: np.ndarray, temperature_c: float = 25.0
                    ) -> Iterator[SimulatedBoard]:
    with tempfile.TemporaryDirectory(prefix="softtip-firmware-") as folder:
        path = Path(folder) / "fields.txt"
        write_fields(path, fields_uT)
        board = SimulatedBoard(build, fields_uT.shape[1], path, temperature_c)
        try:
            yield board
        finally:
            board.close()


def bus_and_conversion_us(chips: int, settings: MLX90393Settings = MLX90393Settings()) -> float:
    """The shortest frame the firmware's sequence allows, counting only the bus and the conversion
    (PROTOCOL.md's budget; XYZ): select + SM of chip 0 (no select with one chip: its channel stays),
    the wait for its conversion (+10 %) while the others are triggered, its RM, then select + RM of
    each other chip."""
    select = SELECT_BITS if chips > 1 else 0
    wait_us = conversion_time_s(settings) * 1e6 * 1.1
    bits = select + SM_BITS + RM_BITS + (chips - 1) * (SELECT_BITS + RM_BITS)
    return bits * I2C_BIT_US + wait_us


def as_fed(board: SimulatedBoard, samples: list[Sample], fields_uT: np.ndarray,
           settings: MLX90393Settings) -> np.ndarray:
    """(frames, chips) whether each chip's reading is the field it was fed, as the host decodes it.

    A chip's k-th conversion takes row k mod rows of the fields; a frame carries, for each chip, the
    last conversion that chip finished before the frame left (a chip skipped while faulty lags)."""
    expected = MLX90393(settings).read_uT(fields_uT * 1e-6, noise=False)
    frame_end = {frame.seq: frame.sim_ns for frame in board.log.frames}
    ends = np.array([frame_end.get(sample.seq, -1) for sample in samples])
    matches = np.zeros((len(samples), board.chips), dtype=bool)
    conversions = list(board.log.conversions)
    for chip in range(board.chips):
        own = sorted((c.sim_ns, c.index) for c in conversions if c.chip == chip)
        times = np.array([t for t, _ in own])
        latest = np.searchsorted(times, ends, side="right") - 1
        for i, (sample, position) in enumerate(zip(samples, latest)):
            if ends[i] >= 0 and position >= 0:
                row = own[position][1] % len(fields_uT)
                matches[i, chip] = np.array_equal(sample.reading[chip], expected[row, chip])
    return matches


def _percentiles_ms(values_s: np.ndarray) -> dict[str, float]:
    if len(values_s) == 0:
        return {"p50_ms": float("nan"), "p99_ms": float("nan"), "max_ms": float("nan")}
    return {"p50_ms": float(np.percentile(values_s, 50) * 1e3), "p99_ms": float(np.percentile(values_s, 99) * 1e3),
            "max_ms": float(np.max(values_s) * 1e3)}


def stream_figures(board: SimulatedBoard, samples: list[Sample], fields_uT: np.ndarray,
                   settings: MLX90393Settings) -> dict:
    """Frames per second (simulated), frames lost and damaged, latency, and the fields read back, of a
    fault-free stream: frame k carries every chip's k-th conversion."""
    if not samples:
        raise SimulatorUnavailable("no frame reached the host: the simulation may be far slower than real time")
    received = {sample.seq: sample for sample in samples}
    sent = {frame.seq: frame for frame in board.log.frames}
    first, last = min(received), max(received)
    sent_while_listening = [seq for seq in sent if first <= seq <= last]
    conversion_end = {(c.chip, c.index): c.sim_ns for c in board.log.conversions}
    oldest, newest, host = [], [], []
    for seq, sample in received.items():
        frame = sent.get(seq)
        if frame is None or (0, seq) not in conversion_end:
            continue
        oldest.append((frame.sim_ns - conversion_end[0, seq]) * 1e-9)
        newest.append((frame.sim_ns - conversion_end[board.chips - 1, seq]) * 1e-9)
        host.append(sample.host_time_s - frame.wall_ns * 1e-9)
    oldest, newest, host = np.array(oldest), np.array(newest), np.array(host)
    mismatched = int(np.sum(~as_fed(board, samples, fields_uT, settings).all(axis=1)))
    device_times = [s.device_time_s for s in samples]
    span_s = max(device_times) - min(device_times)
    return {
        "frames_received": len(received),
        "frames_sent": len(sent_while_listening),
        "frames_lost": len(set(sent_while_listening) - set(received)),
        "frames_per_s": (len(received) - 1) / span_s if span_s > 0 else float("nan"),
        "frames_not_as_fed": mismatched,
        "early_reads": board.log.early_reads,
        "latency_oldest_chip": _percentiles_ms(oldest + host),
        "latency_newest_chip": _percentiles_ms(newest + host),
        "latency_simulated_part": _percentiles_ms(oldest),
        "latency_host_part": _percentiles_ms(host),
    }


def stream(build: SimulatorBuild, chips: int, seconds: float, fields_uT: np.ndarray,
           settings: MLX90393Settings = MLX90393Settings(), rate_hz: int = MAX_RATE_HZ) -> dict:
    """The firmware streaming to the host driver for ``seconds`` of simulated time."""
    with simulated_board(build, fields_uT) as board:
        wall_start = time.perf_counter()
        with FingertipDriver(board.port, settings=settings, rate_hz=rate_hz, reply_timeout_s=REPLY_WAIT_S,
                             boot_timeout_s=4 * REPLY_WAIT_S) as driver:
            driver.start()
            board.wait_simulated(seconds)
            driver.stop()
            board.wait_simulated(0.01)  # frames in flight arrive
            samples = driver.drain()
            stats = driver.stats
        simulated_s = board.log.sim_ns * 1e-9
        figures = stream_figures(board, samples, fields_uT, settings)
    figures.update(chips=chips, rate_hz=rate_hz, simulated_s=simulated_s,
                   frames_per_s_bus_and_conversion_bound=1e6 / bus_and_conversion_us(chips, settings),
                   realtime_factor=simulated_s / (time.perf_counter() - wall_start),
                   crc_errors=stats.crc_errors, malformed=stats.malformed, gaps=stats.dropped,
                   queue_overflows=stats.queue_overflows)
    return figures


# ------------------------------------------------------------------------------------------- commands


class RawLink:
    """The serial port read as bytes and decoded, for commands the driver would never send."""

    def __init__(self, port: str) -> None:
        self._serial = open_serial(port, 1_000_000)
        self._decoder = FrameDecoder()

    def close(self) -> None:
        self._serial.close()

    def send(self, data: bytes) -> None:
        self._serial.write(data)

    def wait_for_boot(self) -> None:
        """IDENTIFY until the firmware answers: bytes sent before it opens its UART are lost, as on a
        board that is booting (the driver does the same)."""
        deadline = time.monotonic() + 4 * REPLY_WAIT_S
        for tag in itertools.cycle(range(100, 200)):  # tags the checks do not use: late replies are skipped
            self.send(encode_frame(identify_command(tag)))
            if self.reply(tag, 0.3) is not None:
                return
            if time.monotonic() > deadline:
                raise SimulatorUnavailable("the simulated firmware did not answer IDENTIFY")

    def reply(self, tag: int, wait_s: float = REPLY_WAIT_S) -> Identity | Ack | ErrorReply | None:
        """The reply with ``tag`` (DATA frames and other replies are skipped), or None after wait_s."""
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline:
            for message in self._decoder.feed(self._serial.read(max(1, self._serial.in_waiting))):
                if isinstance(message, (Identity, Ack, ErrorReply)) and message.tag == tag:
                    return message
        return None


def _describe(reply: Identity | Ack | ErrorReply | None) -> str:
    if reply is None:
        return "no reply"
    if isinstance(reply, Identity):
        return f"IDENTITY {reply.name!r}, {reply.chips} chips"
    if isinstance(reply, Ack):
        return f"ACK {FrameType(reply.command).name}"
    code = ErrorCode(reply.code).name if reply.code in ErrorCode._value2member_map_ else f"code {reply.code}"
    return f"ERROR {code} (detail {reply.detail:#04x})"


def register_words(settings: MLX90393Settings, reg0: int, reg2: int) -> tuple[int, int]:
    """Registers 0x00 and 0x02 after writing settings over (reg0, reg2): datasheet bit positions."""
    res_x, res_y, res_z = settings.res_xyz
    reg0 = (reg0 & ~0x7F) | settings.gain_sel << 4 | settings.hallconf
    reg2 = (reg2 & ~0x1FFF) | settings.osr | settings.dig_filt << 2 | res_x << 5 | res_y << 7 | res_z << 9 \
        | settings.osr2 << 11
    return reg0, reg2


def command_answers(build: SimulatorBuild, chips: int, fields_uT: np.ndarray) -> list[dict]:
    """Each host command and each bad input, what the firmware answered and what the protocol says."""
    answers = []
    configured = MLX90393Settings(gain_sel=5, res_xyz=(1, 1, 2), osr=1, dig_filt=3)
    with simulated_board(build, fields_uT) as board:
        link = RawLink(board.port)
        try:
            def ask(case: str, data: bytes, expected: str, tag: int | None = None) -> None:
                link.send(data)
                answer = _describe(link.reply(data[5] if tag is None else tag))  # the tag follows the header
                answers.append({"case": case, "answer": answer, "expected": expected, "ok": answer == expected})

            link.wait_for_boot()
            name = f"IDENTITY 'softtip-fingertip/1 mux uart', {chips} chips"
            ask("IDENTIFY", encode_frame(identify_command(1)), name)
            power_on = board.registers()
            ask("CONFIGURE (GAIN_SEL 5, RES 1/1/2, OSR 1, DIG_FILT 3)", encode_frame(configure_command(2, configured)),
                "ACK CONFIGURE")
            words = board.registers()
            wanted = [register_words(configured, *registers) for registers in power_on]
            answers.append({"case": "registers 0x00, 0x02 after CONFIGURE", "answer": str(words),
                            "expected": str(wanted), "ok": words == wanted})
            board.control(f"nak {chips - 1} 1")
            ask(f"CONFIGURE while chip {chips - 1} does not acknowledge", encode_frame(configure_command(12, configured)),
                f"ERROR CHIP_FAILURE (detail {1 << (chips - 1):#04x})")
            board.control(f"nak {chips - 1} 0")
            forbidden = bytes([7, 0, 0, 0, 0, 0, 0, 0xC, 0])  # OSR 0 with DIG_FILT 0
            ask("CONFIGURE with OSR 0, DIG_FILT 0", encode_frame(Command(FrameType.CONFIGURE, 3, forbidden)),
                "ERROR BAD_SETTINGS (detail 0x00)")
            ask("SET_RATE 0 Hz", encode_frame(Command(FrameType.SET_RATE, 4, bytes(2))), "ERROR BAD_RATE (detail 0x00)")
            ask("SET_RATE 100 Hz", encode_frame(set_rate_command(5, 100)), "ACK SET_RATE")
            ask("reserved command 0x15", encode_frame(Command(0x15, 6)), "ERROR UNKNOWN_COMMAND (detail 0x00)")
            ask("IDENTIFY with an argument byte", encode_frame(Command(FrameType.IDENTIFY, 7, b"\x00")),
                "ERROR BAD_LENGTH (detail 0x00)")
            garbled = bytearray(encode_frame(identify_command(8)))
            garbled[-1] ^= 0x40  # the CRC no longer matches
            link.send(bytes(garbled))
            board.wait_simulated(SIMULATED_WAIT_S)
            answer = _describe(link.reply(8, 0.0))
            answers.append({"case": "IDENTIFY with a bad CRC", "answer": answer, "expected": "no reply",
                            "ok": answer == "no reply"})
            noise = np.random.default_rng(0).integers(0, 256, 64, dtype=np.uint8).tobytes() + b"\xa5\x5a\x01\x10"
            ask("64 random bytes and a cut header, then IDENTIFY", noise + encode_frame(identify_command(9)), name,
                tag=9)
            ask("START", encode_frame(start_command(10)), "ACK START")
            frames_before = len(board.log.frames)
            board.wait_simulated(0.1)
            streamed = len(board.log.frames) - frames_before
            answers.append({"case": "DATA frames sent in 0.1 s at 100 Hz after START", "answer": str(streamed),
                            "expected": "9 to 11", "ok": 9 <= streamed <= 11})
            ask("STOP", encode_frame(stop_command(11)), "ACK STOP")
            frames_before = len(board.log.frames)
            board.wait_simulated(0.1)
            after = len(board.log.frames) - frames_before
            answers.append({"case": "DATA frames sent in 0.1 s after STOP's ACK", "answer": str(after),
                            "expected": "0", "ok": after == 0})
        finally:
            link.close()
    return answers


# --------------------------------------------------------------------------------------------- faults


def _recovered_from(status: np.ndarray, chip: int) -> int:
    """Index of the first frame after the chip's last faulty one (0: never faulty; len: still faulty)."""
    faulty = np.flatnonzero(status[:, chip] & CHIP_FAULTS)
    return int(faulty[-1]) + 1 if len(faulty) else 0


def fault_answers(build: SimulatorBuild, chips: int, fields_uT: np.ndarray, hold_s: float = 0.2) -> list[dict]:
    """The stream while one chip does not acknowledge, while SDA is held low, after a chip restarts
    (supply dip) and after one is left in burst mode: what the frames report, and whether the stream
    recovers with the fields as fed."""
    answers = []
    faulty = chips - 1
    others = [c for c in range(chips) if c != faulty]
    settings = MLX90393Settings()
    with simulated_board(build, fields_uT) as board, FingertipDriver(
            board.port, settings=settings, rate_hz=100, reply_timeout_s=REPLY_WAIT_S,
            boot_timeout_s=4 * REPLY_WAIT_S) as driver:
        driver.start()
        board.wait_simulated(0.05)

        def phase(on: str, off: str | None) -> tuple[list[Sample], np.ndarray, list[Sample], np.ndarray]:
            driver.drain()
            board.control(on)
            board.wait_simulated(hold_s)
            during = driver.drain()
            if off is not None:
                board.control(off)
                board.wait_simulated(hold_s)
            after = driver.drain()
            return during, np.array([s.status for s in during]), after, np.array([s.status for s in after])

        def recovery(samples: list[Sample], status: np.ndarray, chips_checked: list[int]) -> dict:
            fed = as_fed(board, samples, fields_uT, settings)
            frames = max(_recovered_from(status, c) for c in chips_checked)
            return {"frames_until_recovered": frames if frames < len(samples) else "not recovered",
                    "as_fed_after_recovery": bool(frames < len(samples) and fed[frames:, chips_checked].all())}

        during, status, after, after_status = phase(f"nak {faulty} 1", f"nak {faulty} 0")
        bus_error = status[:, faulty] & ChipStatus.BUS_ERROR != 0
        answers.append({
            "case": f"chip {faulty} does not acknowledge for {hold_s:g} s",
            "frames": len(during),
            "frames_with_its_bus_error": int(bus_error.sum()),
            "its_reading_nan_then": bool(all(np.isnan(s.reading[faulty]).all()
                                             for s, error in zip(during, bus_error) if error)),
            "other_chips_as_fed": bool(as_fed(board, during, fields_uT, settings)[:, others].all()),
            "frames_after_release": len(after),
            **recovery(after, after_status, [faulty]),
        })
        during, status, after, after_status = phase("stuck 1", "stuck 0")
        times = np.array([s.device_time_s for s in during])
        answers.append({
            "case": f"SDA held low for {hold_s:g} s",
            "frames": len(during),
            "frames_all_chips_bus_error": int(np.all(status & ChipStatus.BUS_ERROR != 0, axis=1).sum()),
            "frame_period_ms": float(np.median(np.diff(times)) * 1e3) if len(times) > 1 else float("nan"),
            "frames_after_release": len(after),
            **recovery(after, after_status, list(range(chips))),
        })
        during, status, _, _ = phase(f"reset {faulty}", None)
        answers.append({
            "case": f"chip {faulty} restarts with power-on registers",
            "frames": len(during),
            "frames_with_its_reset": int(np.sum(status[:, faulty] & ChipStatus.RESET != 0)),
            **recovery(during, status, [faulty]),
        })
        during, status, _, _ = phase(f"burst {faulty}", None)
        answers.append({
            "case": f"chip {faulty} left in burst mode (refuses SM until EX)",
            "frames": len(during),
            "frames_with_its_chip_error": int(np.sum(status[:, faulty] & ChipStatus.CHIP_ERROR != 0)),
            **recovery(during, status, [faulty]),
        })
        answers.append({"case": "frames lost in transit during the faults (sequence gaps)",
                        "frames": driver.stats.dropped, "crc_errors": driver.stats.crc_errors})
    return answers


# ------------------------------------------------------------------------------------------ the bench


def bench_firmware(chips: int = 4, seconds: float = 2.0, progress: Progress = SILENT,
                   fields: FedFields | None = None, firmware_dir: Path = FIRMWARE_DIR) -> dict:
    """Frames per second, losses and latency for 1..chips chips at the firmware's highest rate, the
    answers to each host command and bad input, and the stream under bus faults (``chips`` chips),
    the chips fed ``fields`` (default the twin's, :func:`twin_fields`)."""
    counts = list(range(1, chips + 1))
    simulator = build(counts, firmware_dir, progress=progress)
    fields = twin_fields(chips, progress) if fields is None else fields
    load_before = os.getloadavg()
    streams = []
    with progress.task(f"streaming {seconds:g} s (simulated) per chip count", total=len(counts)) as task:
        for n in counts:
            streams.append(stream(simulator, n, seconds, fields.fields_uT[:, :n], fields.settings))
            task.advance(note=f"{n} chip{'s' * (n > 1)}: {streams[-1]['frames_per_s']:.0f} frames/s")
    with progress.task("host commands and bad input"):
        commands = command_answers(simulator, chips, fields.fields_uT)
    with progress.task("bus faults"):
        faults = fault_answers(simulator, chips, fields.fields_uT)
    return {"fields": {"source": fields.source, "rows": len(fields.fields_uT), "chips": chips},
            "streams": streams, "commands": commands, "faults": faults,
            "load_average_before": list(load_before), "load_average_after": list(os.getloadavg()),
            "cpus": os.cpu_count()}
