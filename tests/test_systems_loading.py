"""Installed systems that fail: a plug-in that does not import, is not a record, or claims a name
softtip's own systems have is skipped with one warning naming its package; everything else works,
and the toolkit's four systems never vanish."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from softtip._core import systems as registry

BUILT_IN = ["hall-fingertip", "wearable", "haptics", "cilia"]  # as the specification numbers them, S1-S4

BROKEN = {"__init__.py": "raise ImportError('needs a driver this machine lacks')\n"}
NOT_A_RECORD = {"__init__.py": "SYSTEM = {'name': 'dictionary'}\n"}
# labelled to sort before every built-in one, and claiming the fingertip's study
COPYCAT = {"__init__.py": '''
    from softtip._core.systems import Study, System

    SYSTEM = System(name="copycat", title="A copy", label="A0", package=__name__,
                    studies=(Study("pushing", "pushing", "copycat:nothing", "a copy"),))
'''}
FINE = {"__init__.py": '''
    from softtip._core.systems import System

    SYSTEM = System(name="fine", title="A plug-in that loads", label="T9", package=__name__)
'''}


@pytest.fixture
def unread_registry(monkeypatch):
    """The registry as a new process finds it: nothing registered, the entry points not yet read."""
    monkeypatch.setattr(registry, "_REGISTERED", {})
    monkeypatch.setattr(registry, "_entry_points", "unread")


@pytest.fixture
def site(tmp_path, monkeypatch, install_package):
    """Four plug-ins installed on the path: broken, not a record, a clash, and one that works."""
    for name, files in {"brokentip": BROKEN, "recordless": NOT_A_RECORD, "copycat": COPYCAT, "fine": FINE}.items():
        install_package(tmp_path, name, files, f"{name} = {name}:SYSTEM")
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    for name in ("brokentip", "recordless", "copycat", "fine"):
        sys.modules.pop(name, None)


def test_a_failing_or_clashing_plug_in_is_skipped_with_a_warning_naming_its_package(unread_registry, site):
    with pytest.warns(registry.SystemSkipped) as caught:
        first = registry.systems()
    assert sorted(str(warning.message) for warning in caught) == [
        "softtip system 'brokentip' of package 'brokentip' skipped: ImportError: needs a driver this machine lacks",
        "softtip system 'copycat' of package 'copycat' skipped: ValueError: system 'copycat': study 'pushing' is "
        "also system 'hall-fingertip''s",
        "softtip system 'recordless' of package 'recordless' skipped: TypeError: a softtip system must be a System "
        "record, got dict"]
    assert list(first) == [*BUILT_IN, "fine"]  # softtip's own first, whatever a plug-in's label
    assert registry.owner("study", "pushing").name == "hall-fingertip"
    assert list(registry.systems()) == list(first)  # read once: the second call neither warns nor loses any


def test_the_command_line_runs_beside_a_broken_plug_in_and_says_so_in_one_line(site, tmp_path):
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), *sys.path])}
    ran = subprocess.run([sys.executable, "-m", "softtip", "lab", "run", "--help"], env=environment,
                         capture_output=True, text=True, timeout=120)
    assert ran.returncode == 0, ran.stderr
    assert "pushing" in ran.stdout
    lines = ran.stderr.splitlines()
    assert len(lines) == 3 and all(line.startswith("warning: softtip system ") for line in lines), ran.stderr
    assert "'brokentip' of package 'brokentip' skipped: ImportError: needs a driver this machine lacks" in lines[0]
