"""The command line's one error path: user errors as one escaped line and exit code 2, bugs with their
traceback; output paths checked before the work."""

from __future__ import annotations

import errno
import os
import subprocess
from pathlib import Path

import pytest
import typer
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from softtip.cli.common import OutputPathError, check_output, fail, user_errors
from softtip.hardware.driver import DeviceError
from softtip.mechanics.linsolve import NotPositiveDefinite

runner = CliRunner()


def _wrapped(raiser):
    """A one-command application whose command calls ``raiser()``, wrapped as softtip's commands are."""
    app = typer.Typer()
    app.command()(user_errors(lambda: raiser()))
    return app


def one_line(result) -> str:
    lines = result.output.strip().splitlines()
    assert result.exit_code == 2, result.output
    assert len(lines) == 1 and "Traceback" not in result.output, result.output
    return lines[0]


def raise_(error: BaseException):
    def raiser():
        raise error
    return raiser


def test_markup_and_control_characters_are_shown_as_text():
    value = "[bold]x[/bold] nan \x1b[2J\x00 :smile: \udcff µ"
    line = one_line(runner.invoke(_wrapped(raise_(ValueError(f"--label = {value}: expected a name"))), []))
    # the markup tag, the word nan and the emoji code are there as typed; the escape sequence, the NUL and
    # the undecodable byte are written as their escapes, and the line is the error's own words otherwise
    assert line == r"error: --label = [bold]x[/bold] nan \x1b[2J\x00 :smile: \udcff µ: expected a name"
    assert "\x1b" not in line and "\x00" not in line


def test_a_message_of_several_lines_stays_on_one():
    line = one_line(runner.invoke(_wrapped(raise_(ValueError("first\nsecond"))), []))
    assert line == r"error: first\nsecond"


def test_fail_prints_its_message_as_text():
    app = typer.Typer()
    app.command()(lambda: fail("--name = [red]x[/red]: expected letters"))
    line = one_line(runner.invoke(app, []))
    assert line == "error: --name = [red]x[/red]: expected letters"


@pytest.fixture
def folder(tmp_path) -> Path:
    (tmp_path / "data.csv").write_text("a\n")
    (tmp_path / "sub").mkdir()
    return tmp_path


@pytest.mark.parametrize("action, expected", [
    (lambda d: open(d / "missing.csv"), "{d}/missing.csv: does not exist"),
    (lambda d: open(d / "sub"), "{d}/sub: is a directory, expected a file"),
    (lambda d: open(d / "data.csv", "x"), "{d}/data.csv: already exists"),
    (lambda d: open(d / "data.csv" / "x"), "{d}/data.csv/x: a folder on its path is a file"),
    (lambda d: os.rename(d / "nothing", d / "else"), "{d}/nothing -> {d}/else: does not exist"),
])
def test_file_errors_name_the_file_and_the_problem(folder, action, expected):
    line = one_line(runner.invoke(_wrapped(lambda: action(folder)), []))
    assert line == "error: " + expected.format(d=folder)


def test_a_permission_error_names_the_file():
    # raised as the system raises it (the tests may run as root, who is never refused)
    error = PermissionError(errno.EACCES, os.strerror(errno.EACCES), "/etc/shadow")
    assert one_line(runner.invoke(_wrapped(raise_(error)), [])) == "error: /etc/shadow: permission denied"


def test_errors_softtip_defines_are_user_errors_too():
    assert one_line(runner.invoke(_wrapped(raise_(DeviceError("the device refused SET_RATE", 3, 0))), [])) == (
        "error: the device refused SET_RATE")
    assert one_line(runner.invoke(_wrapped(raise_(NotPositiveDefinite("stiffness matrix"))), [])) == (
        "error: stiffness matrix")
    assert one_line(runner.invoke(_wrapped(raise_(TimeoutError("no answer from /dev/ttyACM0 in 2 s"))), [])) == (
        "error: no answer from /dev/ttyACM0 in 2 s")


@pytest.mark.parametrize("bug", [KeyError("weights"), ZeroDivisionError("division by zero"), TypeError("x")])
def test_a_bug_keeps_its_traceback(bug):
    result = runner.invoke(_wrapped(raise_(bug)), [])
    assert result.exit_code == 1 and result.exception is bug


# --------------------------------------------------------------------------
# Output paths
# --------------------------------------------------------------------------


def refusal(path, inputs=(), force=False) -> str:
    with pytest.raises(OutputPathError) as refused:
        check_output(path, "--output", inputs, force=force)
    assert "\n" not in str(refused.value)
    return str(refused.value)


def test_output_paths_that_cannot_be_written_are_refused(folder):
    assert refusal(folder / "sub") == f"--output = {folder}/sub: is a directory, expected a file to write"
    assert refusal(folder / "none" / "out.parquet") == (
        f"--output = {folder}/none/out.parquet: folder {folder}/none does not exist")
    assert refusal(folder / "data.csv" / "out.parquet") == (
        f"--output = {folder}/data.csv/out.parquet: {folder}/data.csv is not a folder")


def test_an_output_that_is_an_input_is_refused_however_named(folder):
    source = folder / "data.csv"
    expected = "is the input {}; the output must be another file".format(source)
    assert refusal(folder / "sub" / ".." / "data.csv", [source], force=True).endswith(expected)
    (folder / "link.csv").symlink_to(source)
    assert refusal(folder / "link.csv", [source], force=True).endswith(expected)
    os.link(source, folder / "hard.csv")
    assert refusal(folder / "hard.csv", [source], force=True).endswith(expected)
    # a file of the same content is another file
    (folder / "copy.csv").write_text("a\n")
    assert check_output(folder / "copy.csv", "--output", [source], force=True) == folder / "copy.csv"


def test_an_existing_output_needs_force(folder):
    assert refusal(folder / "data.csv") == f"--output = {folder}/data.csv: the file exists (pass --force to replace it)"
    assert check_output(folder / "data.csv", "--output", force=True) == folder / "data.csv"
    assert check_output(folder / "new.csv", "-o") == folder / "new.csv"


def test_a_read_only_folder_is_refused(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    # root may write in any folder whatever its mode, but not in an immutable one
    lock = (["chattr", "+i", str(locked)], ["chattr", "-i", str(locked)]) if os.geteuid() == 0 else None
    if lock is None:
        locked.chmod(0o555)
    elif subprocess.run(lock[0], capture_output=True).returncode != 0:
        pytest.skip("this file system cannot make a folder immutable")
    try:
        with pytest.raises(OSError):  # the folder really is read-only
            (locked / "probe").write_text("")
        assert refusal(locked / "out.parquet") == (f"--output = {locked}/out.parquet: folder {locked} is read-only "
                                                   "(files cannot be created there)")
    finally:
        if lock is None:
            locked.chmod(0o755)
        else:
            subprocess.run(lock[1], check=True)


@settings(max_examples=200, deadline=None)
@given(st.text(alphabet=st.characters(codec=None, exclude_categories=())))
def test_any_message_is_one_line_without_control_characters(message):
    result = runner.invoke(_wrapped(raise_(ValueError(message))), [])
    assert result.exit_code == 2
    line = result.stderr.removesuffix("\n")
    assert "\n" not in line and all(character.isprintable() for character in line)
    # and nothing printable is lost or reordered: no markup, emoji code or highlighting took any
    assert line.startswith("error: ")
    shown = iter(line.removeprefix("error: "))
    assert all(character in shown for character in message if character.isprintable())
