"""The checker of a registered system (softtip check-system): the spring of a lab's own holds every
rule; each rule it is made to break is found and said in one line naming the file or the record's key."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from softtip._core import systems as registry
from softtip.plugin import check_system
from test_systems import PACKAGE


@pytest.fixture
def install_spring(tmp_path, monkeypatch, install_package, request):
    """Installs the spring with its files edited (``{path: [(old, new), ...]}``), on a registry read anew."""
    monkeypatch.setattr(registry, "_REGISTERED", {})
    monkeypatch.setattr(registry, "_INSTALLED_BY", {})
    monkeypatch.setattr(registry, "_entry_points", "unread")
    monkeypatch.syspath_prepend(str(tmp_path))
    modules = ("springtip", "springtip.bench", "springtip.gauge")
    request.addfinalizer(lambda: [sys.modules.pop(name, None) for name in modules])

    def install(edits: dict[str, list[tuple[str, str]]]) -> None:
        files = dict(PACKAGE)
        for path, changes in edits.items():
            for old, new in changes:
                assert old in files[path], old
                files[path] = files[path].replace(old, new)
        install_package(tmp_path, "springtip", files, "springtip = springtip:SYSTEM")

    return install


def test_the_spring_holds_every_rule(install_spring):
    install_spring({})
    assert check_system("springtip") == []


@pytest.mark.parametrize(("edits", "expected"), [
    ({"__init__.py": [('"springtip.bench:scenario"', '"springtip.bench:scenari"')]},
     ["springtip (System 'springtip'): scenarios.spring = 'springtip.bench:scenari': cannot be loaded "
      "(AttributeError: module 'springtip.bench' has no attribute 'scenari')"]),
    ({"bench.py": [('realism_sources={"noise_mm": "none"}', "realism_sources={}")]},
     ["springtip (System 'springtip'): bench 'spring': realism_sources names no source for 'noise_mm'"]),
    ({"bench.py": [('"calibration" if trial else "validation"', '"train" if trial else "validation"'),
                   ("check(1, 20.0)", "readings = None")]},
     ["{protocol}: its dataset's role 'train': expected calibration or validation",
      "springtip (System 'springtip'): scenarios.spring: never called check(chips, rate_hz) before its work"]),
    ({"bench.py": [("stiffness = float(", "stiffness = flat(")]},
     ["springtip (System 'springtip'): study 'spring-push': its quick reproduction failed (NameError: name 'flat' "
      "is not defined)"]),
    ({"__init__.py": [('drivers={"spring-gauge": ', 'drivers={"softtip": ')]},
     ["springtip (System 'springtip'): drivers.softtip = 'springtip.gauge:DRIVER': the Driver is named "
      "'spring-gauge', expected 'softtip'",
      "springtip (System 'springtip'): drivers.softtip: softtip's own is named so: expected another name"]),
    ({"gauge.py": [('title="spring gauge")', 'title="spring gauge", model=lambda settings: settings)')]},
     ["springtip (System 'springtip'): sensors.spring-gauge: its model failed to read zeros at its widest settings "
      "(AttributeError: 'GaugeSettings' object has no attribute 'acquire')"]),
    ({"gauge.py": [('title="spring gauge")', 'title="spring gauge", model=lambda settings: type("Model", (), '
                                             '{"acquire": lambda self, true, rng=None: true})())')]},
     ["springtip (System 'springtip'): sensors.spring-gauge: its model read ndarray: expected an Acquisition of 1 "
      "values"]),
], ids=["a typo in a reference", "a realism key without its source", "a role of its own, a scenario unchecked",
        "an analysis that fails", "a driver named as softtip's own", "a sensor model that does not read",
        "a sensor model that returns its input"])
def test_each_broken_rule_is_one_line_naming_where(install_spring, tmp_path, edits, expected):
    install_spring(edits)
    protocol = tmp_path / "springtip" / "protocols" / "spring-push.toml"
    assert check_system("springtip") == [line.format(protocol=protocol) for line in expected]


def test_the_command_checks_a_system_and_refuses_a_name_no_system_has(tmp_path, install_package):
    install_package(tmp_path, "springtip", PACKAGE, "springtip = springtip:SYSTEM")
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), *sys.path])}

    def softtip(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "softtip", "check-system", *args], env=environment, cwd=tmp_path,
                              capture_output=True, text=True, timeout=120)

    held = softtip("springtip", "--json")
    assert held.returncode == 0 and json.loads(held.stdout) == {"system": "springtip", "broken": []}, held.stderr
    unknown = softtip("sprngtip")
    start = "error: NAME = 'sprngtip': expected one of "
    assert unknown.returncode == 2 and unknown.stderr.startswith(start) and len(unknown.stderr.splitlines()) == 1
    listed = unknown.stderr.strip().removeprefix(start).split(", ")  # softtip's own, then every installed one
    assert listed[:4] == ["hall-fingertip", "wearable", "haptics", "cilia"] and "springtip" in listed[4:]


def test_the_contract_is_light_to_import_for_a_record_and_whole_when_used():
    # a system's __init__ imports its record from softtip.plugin: that must not load the toolkit's stages
    # (listing the systems stays light); each other name of the contract loads on first use
    probe = ("import sys\n"
             "from softtip.plugin import MAGNETIC, Reading, Study, System\n"
             "light = sorted(m for m in ('numpy', 'pydantic', 'softtip.lab', 'softtip.design') if m in sys.modules)\n"
             "import softtip.plugin as plugin\n"
             "unresolved = [name for name in plugin.__all__ if getattr(plugin, name, None) is None]\n"
             "print(light, unresolved, plugin.SensorModel.__module__, plugin.BenchKind.__module__)\n")
    ran = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert ran.returncode == 0, ran.stderr
    assert ran.stdout.split() == ["[]", "[]", "softtip.sensors.contract", "softtip.lab.protocols"]
    import softtip.plugin as plugin

    with pytest.raises(AttributeError, match="module 'softtip.plugin' has no attribute 'Sensorkind'"):
        plugin.Sensorkind
