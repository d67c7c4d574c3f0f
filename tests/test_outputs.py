"""The output layer: every file softtip writes is replaced in one step (a full disk leaves the old file and
names it), claimed exclusively where two processes could write it in place, never one of the run's
inputs (files a protocol names included), never two outputs of one command on one path, and replaced
only with --force, folders of outputs included."""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from softtip._core.files import OutputClaimed, atomic_write, claim
from test_cli_checks import digest, recording_csv, refused, run  # noqa: F401 (a fixture)

FIT = ("sysid", "fit", "-u", "u", "-y", "y", "--kind", "ss", "--order", "2")


# --------------------------------------------------------------------------
# A full disk
# --------------------------------------------------------------------------


def full_disk(*args, **kwargs):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def test_a_full_disk_leaves_the_old_plot_and_names_it_in_one_line(recording_csv, tmp_path, monkeypatch):
    import softtip._core.files as files

    bode = tmp_path / "bode.png"
    bode.write_bytes(b"yesterday's plot")
    monkeypatch.setattr(files.os, "fsync", full_disk)  # the disk fills as the new plot reaches it
    line = refused(run(*FIT, "--data", recording_csv, "--bode", bode, "--force"), str(bode), "no space left")
    assert line == f"error: {bode}: no space left on the device"
    assert bode.read_bytes() == b"yesterday's plot"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bode.png", "r.csv"]  # no temporary file left


@pytest.fixture
def tiny_disk(tmp_path):
    """A 64 KiB tmpfs (needs the right to mount: the superuser outside a container that forbids it)."""
    folder = tmp_path / "tiny"
    folder.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(folder)], capture_output=True)
    if mounted.returncode != 0:
        pytest.skip("cannot mount a tmpfs here: " + mounted.stderr.decode(errors="replace").strip())
    yield folder
    subprocess.run(["umount", str(folder)], check=True)


def test_a_really_full_disk_leaves_the_old_file_and_names_it(tiny_disk):
    old = tiny_disk / "results.json"
    old.write_bytes(b"{}" * 8192)  # 16 KiB of the 64
    with pytest.raises(OSError) as raised:
        atomic_write(old, b"x" * 60_000)  # fits beside nothing but an empty disk
    assert raised.value.errno == errno.ENOSPC and raised.value.filename == str(old)
    assert old.read_bytes() == b"{}" * 8192
    assert [p.name for p in tiny_disk.iterdir()] == ["results.json"]


def test_a_really_full_disk_under_a_plot_is_one_line_naming_it(recording_csv, tiny_disk):
    bode = tiny_disk / "bode.png"
    bode.write_bytes(b"\x89PNG old" * 6000)  # 48 of the 64 KiB: the new Bode plot (some 30 KiB) cannot fit beside it
    line = refused(run(*FIT, "--data", recording_csv, "--bode", bode, "--force"), str(bode), "no space left")
    assert line == f"error: {bode}: no space left on the device"
    assert bode.read_bytes() == b"\x89PNG old" * 6000


# --------------------------------------------------------------------------
# Exclusive claims
# --------------------------------------------------------------------------

HOLD = """
import sys, time
from softtip._core.files import claim
with claim(sys.argv[1]):
    print("held", flush=True)
    time.sleep(float(sys.argv[2]))
"""


def holder(path: Path, seconds: float = 60.0) -> subprocess.Popen:
    """Another process holding ``path``'s claim, once it says so."""
    process = subprocess.Popen([sys.executable, "-c", HOLD, str(path), str(seconds)], stdout=subprocess.PIPE,
                               env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert process.stdout.readline() == b"held\n"
    return process


def test_a_claim_is_exclusive_across_processes_and_dies_with_its_holder(tmp_path):
    path = tmp_path / "s.mcap"
    process = holder(path)
    try:
        with pytest.raises(OutputClaimed) as raised:
            with claim(path):
                pass
        assert raised.value.filename == str(path)
    finally:
        process.kill()  # SIGKILL: no clean-up of its own runs
        process.wait()
    with claim(path):  # the kernel dropped the killed holder's lock
        path.write_bytes(b"mine")
    assert path.read_bytes() == b"mine"


RACE = """
import sys, time
from softtip._core.files import OutputClaimed, claim
while time.time() < float(sys.argv[2]):  # every racer starts at one moment
    pass
try:
    with claim(sys.argv[1]) as path:
        path.write_bytes(sys.argv[3].encode())
        time.sleep(1.0)
    print("wrote")
except OutputClaimed:
    print("refused")
"""


def test_of_writers_racing_for_one_file_exactly_one_writes(tmp_path):
    path = tmp_path / "s.mcap"
    start = time.time() + 2.0  # after the interpreters have started
    racers = [subprocess.Popen([sys.executable, "-c", RACE, str(path), str(start), f"racer {k}"],
                               stdout=subprocess.PIPE, env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
              for k in range(4)]
    said = sorted(racer.communicate(timeout=60)[0].decode().strip() for racer in racers)
    assert said == ["refused", "refused", "refused", "wrote"]
    assert path.read_text() in {f"racer {k}" for k in range(4)}


def test_a_claim_is_exclusive_within_a_process_and_removes_only_what_it_made_and_nothing_wrote(tmp_path):
    path = tmp_path / "s.mcap"
    with claim(path):
        assert path.is_file()
        with pytest.raises(OutputClaimed):
            with claim(path):
                pass
    assert not path.exists()  # made by the claim, never written: not left behind
    path.write_bytes(b"")
    with claim(path):
        pass
    assert path.exists()  # an empty file that was there before stays


def test_a_second_live_recording_to_one_file_is_refused_before_the_scenario(tmp_path, monkeypatch):
    import softtip.systems.hall_fingertip.live as fingertip_live

    def computed(*args, **kwargs):
        raise AssertionError("the scenario was computed before the recording was claimed")

    monkeypatch.setattr(fingertip_live, "cached_scenario", computed)
    record = tmp_path / "s.mcap"
    process = holder(record)
    try:
        for args in (("live", "--emulate", "--scenario", "push"), ("demo",)):
            started = time.perf_counter()
            refused(run(*args, "--record", record, "--force"), f"--record = {record}",
                    "another process is writing this file")
            assert time.perf_counter() - started < 3.0
    finally:
        process.kill()
        process.wait()
    assert record.read_bytes() == b""  # the holder's file, untouched


# --------------------------------------------------------------------------
# Inputs, two outputs on one path, folders
# --------------------------------------------------------------------------


def test_two_outputs_of_one_command_on_one_path_are_refused(recording_csv, tmp_path):
    same = tmp_path / "plot.png"
    refused(run(*FIT, "--data", recording_csv, "--bode", same, "--residuals", same),
            f"--residuals = {same}", "also --bode's output")
    linked = tmp_path / "link.png"
    linked.symlink_to(same)  # one file however named
    refused(run(*FIT, "--data", recording_csv, "--bode", same, "--residuals", linked), "--residuals",
            "also --bode's output")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.png", "r.csv"]


def test_a_protocol_s_design_file_is_an_input_even_with_force(tmp_path):
    from softtip.design.model import shipped_design_path
    from softtip.lab.protocols import shipped_protocol_path

    design = tmp_path / "mine.toml"
    shutil.copy(shipped_design_path("cylindrical-A"), design)
    protocol = tmp_path / "p.toml"
    text = shipped_protocol_path("pushing").read_text()
    assert 'design = "cylindrical-A"' in text
    protocol.write_text(text.replace('design = "cylindrical-A"', 'design = "mine.toml"'))
    before = digest(design)
    refused(run("lab", "run", protocol, "-o", design, "--force"), f"--output = {design}", "is the input")
    assert digest(design) == before


def test_a_haptics_protocol_s_device_file_is_an_input_even_with_force(tmp_path):
    from softtip.lab.protocols import shipped_protocol_path
    from softtip.systems.haptics.bench import DEVICE_FILE

    device = tmp_path / "my-device.toml"
    shutil.copy(DEVICE_FILE, device)
    text = shipped_protocol_path("haptics").read_text()
    assert 'device = "shipped"' in text
    protocol = tmp_path / "p.toml"
    protocol.write_text(text.replace('device = "shipped"', 'device = "my-device.toml"'))
    before = digest(device)
    refused(run("lab", "run", protocol, "-o", device, "--force"), f"--output = {device}", "is the input")
    assert digest(device) == before


def test_simulate_never_writes_over_its_design_file_even_with_force(tmp_path):
    from softtip.design.model import shipped_design_path

    design = tmp_path / "mine.npz"  # a design file with a name an output could have
    shutil.copy(shipped_design_path("cylindrical-A"), design)
    before = digest(design)
    refused(run("simulate", "--design", design, "--deformed-mesh", design, "--force"), "--deformed-mesh",
            "is the input")
    assert digest(design) == before


def test_a_reduced_twin_is_saved_only_to_an_npz_file_that_is_not_an_input(tmp_path):
    from softtip.design.model import shipped_design_path

    saved = tmp_path / "rom.npz"
    saved.write_bytes(b"an earlier reduced twin")
    refused(run("bench", "rom", "--save", tmp_path / "rom"), "--save", "expected a file name ending in .npz")
    refused(run("bench", "rom", "--save", saved), f"--save = {saved}", "--force")
    design = tmp_path / "mine.npz"
    shutil.copy(shipped_design_path("cylindrical-A"), design)
    before = digest(design)
    refused(run("bench", "rom", "--design", design, "--save", design, "--force"), "--save", "is the input")
    assert saved.read_bytes() == b"an earlier reduced twin" and digest(design) == before


def test_reports_in_an_output_folder_are_replaced_only_with_force(tmp_path, monkeypatch):
    import softtip.studies.reproduce as reproduce

    def studied(*args, **kwargs):
        raise AssertionError("the study ran before its output folder was checked")

    monkeypatch.setattr(reproduce, "reproduce_study", studied)
    reports = tmp_path / "reports"
    reports.mkdir()
    for name in ("index.html", "pushing.json"):
        (reports / name).write_text("an earlier run's")
        refused(run("reproduce", "pushing", "-o", reports), f"--output = {reports}", name, "--force")
        (reports / name).unlink()
    (reports / "index.html").write_text("an earlier run's")
    forced = run("reproduce", "pushing", "-o", reports, "--force")  # let through to the work
    assert isinstance(forced.exception, AssertionError) and "the study ran" in str(forced.exception)


def test_a_study_s_results_are_replaced_only_with_force(tmp_path):
    config = Path(__file__).parents[1] / "examples" / "estimation-grid.toml"
    out = tmp_path / "out"
    out.mkdir()
    (out / "results.csv").write_text("an earlier study's")
    refused(run("optimize", "--config", config, "--output", out), f"--output = {out}", "results.csv", "--force")
    assert (out / "results.csv").read_text() == "an earlier study's"
