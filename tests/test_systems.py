"""A system of a lab's own, in a package of its own: registered through an entry point, without any
edit to softtip, it appears in every command that loops over the registered systems.

The package (written here, "installed" on the path with its dist-info) is a linear spring pressed by
a rigid plate, read by a linear 1-axis displacement sensor (a reading of one axis, z: one channel);
its study fits the stiffness by least squares and prints it beside its "published" figure. Its gauge
on a serial port sends one displacement per text line: a wire format of its own, a registered driver.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import tty
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from softtip._core.systems import System, names, register, systems, unregister
from softtip.data import Dataset
from softtip.realtime.recording.reader import read_recording

STIFFNESS_N_PER_MM = 2.5  # the spring's; the "publication" printed 2.4

PACKAGE = {
    "__init__.py": '''
        from softtip.plugin import Reading, Study, System

        DISPLACEMENT = Reading("displacement", "mm", "x", "mm", prefix="d", infix="x", units={"mm": 1.0, "m": 1e3},
                               drift_threshold=0.01, baseline_step=1e-4, decimals=3, topic="displacement",
                               message="geometry_msgs/msg/Vector3Stamped", axes=("z",))
        SYSTEM = System(
            name="springtip", title="A spring under a plate, read by a 1-axis displacement sensor", label="T1",
            package=__name__, readings=(DISPLACEMENT,), benches={"spring": "springtip.bench:BENCH"},
            protocols={"spring-push": "spring"},
            studies=(Study("spring-push", "spring-push", "springtip.bench:analyse", "T1: the spring's stiffness"),),
            scenarios={"spring": "springtip.bench:scenario"}, drivers={"spring-gauge": "springtip.gauge:DRIVER"},
            sensors={"spring-gauge": "springtip.gauge:SENSOR"})
    ''',
    "gauge.py": '''
        import dataclasses
        import threading
        import time

        import numpy as np
        import serial

        from softtip.plugin import Driver, Sample, SensorKind
        from springtip import DISPLACEMENT

        @dataclasses.dataclass(frozen=True)
        class GaugeSettings:
            range_mm: float = 5.0

            @classmethod
            def from_dict(cls, table):
                if set(table) - {"range_mm"}:
                    raise ValueError(f"expected range_mm, got {sorted(table)}")
                return cls(**table)

            def to_dict(self):
                return dataclasses.asdict(self)

        # a 16-bit converter over its range: the step is the range over 2^15
        SENSOR = SensorKind("spring-gauge", DISPLACEMENT, 1, GaugeSettings, widest=GaugeSettings(10.0),
                            full_scale=lambda s: np.array([s.range_mm]), step=lambda s: np.array([s.range_mm / 2**15]),
                            title="spring gauge")

        class GaugeStream:
            """The spring's gauge on a serial port: one displacement in mm per text line, at its own rate."""

            reading, settings, rate_hz, finished, chips = DISPLACEMENT, None, None, False, 1

            def __init__(self, request):
                if request.settings is not None or request.chips not in (None, 1):
                    raise ValueError("the spring's gauge is one sensor with no settings")
                self.name, self.port, self.delivered = f"spring gauge on {request.port}", request.port, 0
                self._stop, self._thread, self._serial = threading.Event(), None, None

            def open(self):
                self._serial = serial.serial_for_url(self.port, timeout=0.05)
                return self

            def start(self, deliver):
                self._thread = threading.Thread(target=self._run, args=(deliver,), daemon=True)
                self._thread.start()
                return self

            def _run(self, deliver):
                ok, status, clear = np.ones(1, bool), np.zeros(1, np.uint8), np.zeros((1, 1), bool)
                while not self._stop.is_set():
                    line = self._serial.readline()
                    if line.endswith(b"\\n"):
                        reading = np.array([[float(line)]])
                        deliver(Sample(seq=self.delivered % 65536, device_time_s=None, host_time_s=time.perf_counter(),
                                       reading=reading, status=status, chip_ok=ok, saturated=clear))
                        self.delivered += 1

            def counters(self):
                return {"delivered": self.delivered}

            def close(self):
                self._stop.set()
                if self._thread is not None:
                    self._thread.join()
                if self._serial is not None:
                    self._serial.close()

        DRIVER = Driver("spring-gauge", "the spring's gauge: a displacement in mm per text line", GaugeStream,
                        own_rate=True)
    ''',
    "bench.py": '''
        import dataclasses
        from dataclasses import asdict

        import numpy as np

        from softtip._core.config import NonNegativeNumber, PositiveNumber, integer, schema
        from softtip.data import DatasetMetadata, TrialWriter
        from softtip.hardware import PacedSource
        from softtip.lab import BenchKind
        from softtip.lab.bench import SeededBench
        from softtip.lab.protocols import protocol_file_schema
        from softtip.mechanics.viscoelastic import PronySeries
        from softtip.published import published_table
        from softtip.realtime.scenario import LiveScenario
        from softtip.report.tables import Table
        from softtip.studies.outcome import Headline, StudyOutcome
        from springtip import DISPLACEMENT

        @schema(section="parameters")
        class Parameters:
            stiffness_N_per_mm: PositiveNumber = 2.5
            depth_mm: PositiveNumber = 2.0
            trials: integer(1) = 3
            rate_hz: PositiveNumber = 20.0

        @schema(section="realism")
        class Realism:
            noise_mm: NonNegativeNumber = 0.0
            def to_dict(self):
                return asdict(self)

        @schema(section="viscoelastic")
        class Relaxation:
            pass

        ProtocolFile = protocol_file_schema(Realism, Relaxation)

        @dataclasses.dataclass(frozen=True)
        class Spring:
            name: str = "spring"
            spec: dict = dataclasses.field(default_factory=dict)

        def push(bench, p, seed, record):
            writer = TrialWriter(dict.fromkeys(DISPLACEMENT.channel_names(1), "mm"), {"fz_N": "N"}, {"role": "1"},
                                 DatasetMetadata(description="spring pushes", design={}, sensor_settings={},
                                                 protocol=record, seed=seed))
            for trial in range(p.trials):
                depth = np.linspace(0, p.depth_mm, 1 + round(p.rate_hz))
                read = (depth + bench.scatter(bench.realism.noise_mm, len(depth)))[:, None, None]
                writer.add({"time_s": np.arange(len(depth)) / p.rate_hz, **DISPLACEMENT.columns(read),
                            "fz_N": p.stiffness_N_per_mm * depth},
                           {"role": "calibration" if trial else "validation"})
            return writer.to_dataset()

        def setup(protocol, progress, timings):
            bench = SeededBench(prony=PronySeries((), ()), realism=protocol.realism,
                                rng=np.random.default_rng(protocol.seed), rate_hz=protocol.parameters.rate_hz)
            return bench, {}, "spring pushes"

        BENCH = BenchKind(protocol_file=ProtocolFile, parameters={"spring-push": Parameters},
                          runners={"spring-push": push}, device=lambda *_: Spring(), setup=setup,
                          realism_sources={"noise_mm": "none"}, viscoelastic_sources={})

        def analyse(protocol, seed, progress):
            from softtip.lab import run_protocol
            dataset, _ = run_protocol(protocol, progress)
            x, f = dataset.column("d0_xz_mm"), dataset.column("fz_N")
            stiffness = float(np.linalg.lstsq(x[:, None], f, rcond=None)[0][0])
            published = published_table("spring-stiffness")
            table = Table("Stiffness", "item", ["spring"], ["stiffness"], {("spring", "stiffness"): stiffness},
                          unit="N/mm", published=published)
            return StudyOutcome({"stiffness_N_per_mm": stiffness}, [table], [],
                                Headline.of(table, "spring", "stiffness", "stiffness"))

        def scenario(progress, check):
            check(1, 20.0)
            readings = np.linspace(0, 1, 20)[:, None, None]
            return LiveScenario("a spring pressed once", PacedSource(readings, 20.0, reading=DISPLACEMENT),
                                (), chips=1, rate_hz=20.0, baseline_frames=1)
    ''',
    "protocols/spring-push.toml": '''
        protocol = "spring-push"
        seed = 3

        [parameters]
        trials = 3
    ''',
    "published.toml": '''
        [spring-stiffness]
        study = "spring-push"
        title = "The spring's stiffness"
        source = "a made-up note"
        unit = "N/mm"
        digits = 2
        row_label = "item"
        rows = ["spring"]
        columns = ["stiffness"]
        values = [[2.4]]
        close = { ratio = 1.1, why = "a spring's rating" }
    ''',
}


@pytest.fixture(scope="module")
def springtip(tmp_path_factory, install_package) -> dict:
    """The package and its dist-info on a folder; the environment a command needs to find it."""
    root = tmp_path_factory.mktemp("site")
    install_package(root, "springtip", PACKAGE, "springtip = springtip:SYSTEM")
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}


def softtip(env: dict, cwd: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "softtip", *args], env=env, cwd=cwd, capture_output=True, text=True,
                          timeout=120)


@pytest.mark.slow  # nine commands in child processes: 30 to 100 s, by the machine's load
def test_a_system_of_its_own_appears_in_every_command_that_loops_over_the_systems(springtip, tmp_path):
    help_text = softtip(springtip, tmp_path, "--help").stdout
    assert "springtip" in help_text and "hall-fingertip" in help_text
    assert "spring-push" in softtip(springtip, tmp_path, "lab", "run", "--help").stdout

    ran = softtip(springtip, tmp_path, "lab", "run", "spring-push", "-o", "spring.parquet", "--json")
    assert ran.returncode == 0, ran.stderr
    summary = json.loads(ran.stdout)
    assert summary["trials"] == 3 and summary["channels"] == ["d0_xz_mm"]  # its one axis: no padding
    calibrated = softtip(springtip, tmp_path, "calibrate", "spring.parquet", "-t", "fz_N", "--model", "polynomial",
                         "-o", "spring.npz", "--json")
    assert calibrated.returncode == 0, calibrated.stderr
    # pressed 25 mm deep: beyond twice the gauge's widest range (10 mm), not a reading it can give
    (tmp_path / "deep.toml").write_text('protocol = "spring-push"\nseed = 3\n\n[parameters]\ndepth_mm = 25.0\n')
    assert softtip(springtip, tmp_path, "lab", "run", "deep.toml", "-o", "deep.parquet").returncode == 0
    refused = softtip(springtip, tmp_path, "calibrate", "deep.parquet", "-t", "fz_N", "--model", "polynomial",
                      "-o", "deep.npz")
    assert refused.returncode == 2 and refused.stderr.strip() == (
        "error: deep.parquet: channel d0_xz_mm reaches 25 mm, beyond twice the spring gauge's 10 mm range at its "
        "widest setting")

    reproduced = softtip(springtip, tmp_path, "reproduce", "spring-push", "-o", "reports", "--json")
    assert reproduced.returncode == 0, reproduced.stderr
    study = json.loads(reproduced.stdout)["studies"]["spring-push"]
    assert study["results"]["stiffness_N_per_mm"] == pytest.approx(STIFFNESS_N_PER_MM, rel=1e-9)
    assert study["comparisons"][0]["published"] == "2.40"  # beside its publication's figure
    assert "spring-push.html" in (tmp_path / "reports" / "index.html").read_text()

    streamed = softtip(springtip, tmp_path, "live", "--emulate", "--scenario", "spring", "--model", "spring.npz",
                       "--duration", "1.5", "--record", "spring.mcap", "--json")
    assert streamed.returncode == 0, streamed.stderr
    with open(tmp_path / "spring.mcap", "rb") as handle:
        topics = {channel.topic for channel in make_reader(handle).get_summary().channels.values()}
    assert "/fingertip/chip0/displacement" in topics
    vectors = [message.vector for message in
               read_recording(tmp_path / "spring.mcap").topics["/fingertip/chip0/displacement"].decoded()]
    # a Vector3's x, y, z are fixed: the axes the gauge does not read are NaN, its own the depth (mm, as read)
    assert np.isnan([(v.x, v.y) for v in vectors]).all() and max(v.z for v in vectors) == pytest.approx(1.0)
    converted = softtip(springtip, tmp_path, "convert", "spring.mcap", "spring-live.parquet", "--json")
    assert converted.returncode == 0, converted.stderr
    assert json.loads(converted.stdout)["channels"] == ["d0_xz_mm"]
    live = Dataset.read(tmp_path / "spring-live.parquet")
    change, force = live.column("d0_xz_mm"), live.column("fz_N")
    estimated = np.isfinite(force)
    assert estimated.sum() >= 20 and change[estimated].max() > 0.9  # every frame after the baseline's, pressed 1 mm
    np.testing.assert_allclose(force[estimated], STIFFNESS_N_PER_MM * change[estimated], atol=1e-6)  # Hooke's law


@pytest.mark.slow  # three commands in child processes: 7 to 24 s, by the machine's load
def test_a_driver_of_its_own_streams_its_board_on_a_port(springtip, tmp_path):
    """The gauge (a pseudo-terminal fed 0.00, 0.01, 0.02 ... mm, a line every 10 ms) read through the
    spring's registered driver, recorded and converted: the changes from the first line are the lines'."""
    controller, device = os.openpty()
    tty.setraw(device)
    stop = threading.Event()

    def gauge() -> None:
        for k in range(100_000):
            if stop.wait(0.01):
                return
            os.write(controller, f"{0.01 * k:.2f}\n".encode())

    port = os.ttyname(device)
    feeding = threading.Thread(target=gauge, daemon=True)
    feeding.start()
    try:
        streamed = softtip(springtip, tmp_path, "live", "--port", port, "--driver", "spring-gauge",
                           "--baseline-frames", "1", "--duration", "1.5", "--record", "gauge.mcap", "--json")
        refused = softtip(springtip, tmp_path, "live", "--port", port, "--driver", "spring-gauge", "--rate", "100")
    finally:
        stop.set()
        feeding.join()
        os.close(controller)
        os.close(device)
    assert streamed.returncode == 0, streamed.stderr
    summary = json.loads(streamed.stdout)
    assert summary["source"] == f"spring gauge on {port}" and summary["chips"] == 1
    assert summary["frames"] == summary["delivered"] > 50
    assert refused.returncode == 2 and refused.stderr.strip() == (
        "error: --rate = 100: a spring-gauge board streams at its own rate; leave --rate out")
    converted = softtip(springtip, tmp_path, "convert", "gauge.mcap", "gauge.parquet", "--json")
    assert converted.returncode == 0, converted.stderr
    change = Dataset.read(tmp_path / "gauge.parquet").column("d0_xz_mm")
    np.testing.assert_allclose(change, 0.01 * np.arange(len(change)), atol=1e-9)  # every line, in order


def test_a_name_two_systems_claim_is_refused_and_the_toolkit_systems_are_registered():
    assert {"hall-fingertip", "wearable", "haptics", "cilia"} <= set(systems())
    clash = System(name="copycat", title="", label="X", package="softtip", protocols={"pushing": "fingertip"})
    with pytest.raises(ValueError, match="protocol 'pushing' is also system 'hall-fingertip'"):
        register(clash)
    assert "copycat" not in systems() and names("protocol").count("pushing") == 1
    unregister("copycat")


def test_the_toolkit_names_no_system():
    """Only a system's own folder (and the list of entry points) names it."""
    root = Path(__file__).parents[1] / "src" / "softtip"
    own = {"wearable": ("wearable",), "hall_fingertip": ("hall_fingertip", "force3", "cylindrical-", "inverter"),
           "haptics": ("haptic",), "cilia": ("cilia",)}
    for folder, words in own.items():
        for path in root.rglob("*"):
            if path.is_file() and path.suffix in (".py", ".toml") and "systems" not in path.relative_to(root).parts:
                text = path.read_text(encoding="utf-8").lower()
                assert not [w for w in words if w in text], (path, words)
