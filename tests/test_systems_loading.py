"""Installed systems beside softtip's own: a plug-in that does not import, is not a record, or claims a
name softtip's own systems have is skipped with one warning naming its package, everything else works
and the toolkit's four systems never vanish; a plug-in's offered defaults are taken only when the
user's settings choose it, whatever its label."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from softtip._core import systems as registry
from softtip._core.config import ConfigError

BUILT_IN = ["hall-fingertip", "wearable", "haptics", "cilia"]  # as the specification numbers them, S1-S4

BROKEN = {"__init__.py": "raise ImportError('needs a driver this machine lacks')\n"}
NOT_A_RECORD = {"__init__.py": "SYSTEM = {'name': 'dictionary'}\n"}
# labelled to sort before every built-in one, and claiming the fingertip's study
COPYCAT = {"__init__.py": '''
    from softtip._core.systems import Study, System

    SYSTEM = System(name="copycat", title="A copy", label="A0", package=__name__,
                    studies=(Study("pushing", "pushing", "copycat:nothing", "a copy"),))
'''}
# labelled to sort first, offering every default there is
FIRST = {"__init__.py": '''
    from softtip._core.systems import System

    SYSTEM = System(name="first", title="A plug-in labelled first", label="A1", package=__name__,
                    scenarios={"its-own": "first:scenario"},
                    defaults={"simulate": "its-design", "scenario": "its-own", "demo": "first:demo"})

    def demo():
        """Its own demo."""
'''}
OFFERING_A_STRANGER = {"__init__.py": '''
    from softtip._core.systems import System

    SYSTEM = System(name="stranger", title="A default of no use", label="T8", package=__name__,
                    defaults={"colour": "red"})
'''}
FINE = {"__init__.py": '''
    from softtip._core.systems import System

    SYSTEM = System(name="fine", title="A plug-in that loads", label="T9", package=__name__)
'''}

PLUG_INS = {"brokentip": BROKEN, "recordless": NOT_A_RECORD, "copycat": COPYCAT, "first": FIRST,
            "stranger": OFFERING_A_STRANGER, "fine": FINE}


@pytest.fixture
def unread_registry(monkeypatch):
    """The registry as a new process finds it: nothing registered, the entry points not yet read."""
    monkeypatch.setattr(registry, "_REGISTERED", {})
    monkeypatch.setattr(registry, "_INSTALLED_BY", {})
    monkeypatch.setattr(registry, "_entry_points", "unread")


@pytest.fixture
def site(tmp_path, monkeypatch, install_package):
    """The plug-ins installed on the path."""
    for name, files in PLUG_INS.items():
        install_package(tmp_path, name, files, f"{name} = {name}:SYSTEM")
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    for name in PLUG_INS:
        sys.modules.pop(name, None)


def test_a_failing_or_clashing_plug_in_is_skipped_with_a_warning_naming_its_package(unread_registry, site):
    with pytest.warns(registry.SystemSkipped) as caught:
        first = registry.systems()
    assert sorted(str(warning.message) for warning in caught) == [
        "softtip system 'brokentip' of package 'brokentip' skipped: ImportError: needs a driver this machine lacks",
        "softtip system 'copycat' of package 'copycat' skipped: ValueError: system 'copycat': study 'pushing' is "
        "also system 'hall-fingertip''s",
        "softtip system 'recordless' of package 'recordless' skipped: TypeError: a softtip system must be a System "
        "record, got dict",
        "softtip system 'stranger' of package 'stranger' skipped: ValueError: system 'stranger': defaults.colour: "
        "expected one of simulate, bench, scenario, demo"]
    assert list(first)[:4] == BUILT_IN  # softtip's own first, then by package, whatever the label (another
    # plug-in installed beside softtip has its place among them)
    installed = [registry.provenance(first[name])["installed"] for name in list(first)[4:]]
    assert installed == sorted(installed) and {"fine 0.1", "first 0.1"} <= set(installed)
    assert registry.owner("study", "pushing").name == "hall-fingertip"
    assert list(registry.systems()) == list(first)  # read once: the second call neither warns nor loses any


def test_the_command_line_runs_beside_a_broken_plug_in_and_says_so_in_one_line(site, tmp_path):
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), *sys.path])}
    ran = subprocess.run([sys.executable, "-m", "softtip", "lab", "run", "--help"], env=environment,
                         capture_output=True, text=True, timeout=120)
    assert ran.returncode == 0, ran.stderr
    assert "pushing" in ran.stdout
    lines = ran.stderr.splitlines()
    assert len(lines) == 4 and all(line.startswith("warning: softtip system ") for line in lines), ran.stderr
    assert "'brokentip' of package 'brokentip' skipped: ImportError: needs a driver this machine lacks" in lines[0]


def test_a_plug_in_labelled_first_changes_no_default_until_the_user_chooses_it(unread_registry, site, tmp_path,
                                                                                monkeypatch):
    settings = tmp_path / "config.toml"
    monkeypatch.setenv("SOFTTIP_CONFIG", str(settings))
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "nothing here"))
    with pytest.warns(registry.SystemSkipped):
        registry.systems()
    with pytest.raises(ConfigError, match="softtip settings file .*config.toml does not exist"):
        registry.default("simulate")  # named by SOFTTIP_CONFIG: missing is a mistake, not silence
    monkeypatch.delenv("SOFTTIP_CONFIG")
    softtip_own = {"simulate": "cylindrical-A", "bench": "cylindrical-D", "scenario": "push",
                   "demo": "softtip.systems.hall_fingertip.commands:demo"}
    assert {use: registry.default(use) for use in registry.DEFAULT_USES} == softtip_own

    (tmp_path / "nothing here" / "softtip").mkdir(parents=True)
    (tmp_path / "nothing here" / "softtip" / "config.toml").write_text('[defaults]\nsystem = "first"\n')
    assert {use: registry.default(use) for use in registry.DEFAULT_USES} == {
        "simulate": "its-design", "bench": "cylindrical-D", "scenario": "its-own", "demo": "first:demo"}

    (tmp_path / "nothing here" / "softtip" / "config.toml").write_text('[defaults]\nsystem = "gone"\n')
    with pytest.raises(ConfigError, match=r"config.toml: defaults.system = 'gone': expected a registered system: "
                                          r"hall-fingertip, wearable, haptics, cilia, ") as refused:
        registry.default("scenario")
    assert {"fine", "first"} <= set(str(refused.value).rpartition(": ")[2].split(", "))


def test_the_command_line_takes_softtip_s_defaults_beside_a_plug_in_and_refuses_bad_settings(site, tmp_path):
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), *sys.path]),
                   "XDG_CONFIG_HOME": str(tmp_path / "no settings")}
    help_text = subprocess.run([sys.executable, "-m", "softtip", "live", "--help"], env=environment,
                               capture_output=True, text=True, timeout=120).stdout
    assert "[default: push]" in help_text and "its-own (first)" in help_text
    settings = tmp_path / "settings.toml"
    settings.write_text('[defaults]\nsystem = "first"\n')
    chosen = subprocess.run([sys.executable, "-m", "softtip", "live", "--help"], capture_output=True, text=True,
                            env={**environment, "SOFTTIP_CONFIG": str(settings)}, timeout=120)
    assert "[default: its-own]" in chosen.stdout, chosen.stderr
    settings.write_text('[defaults]\nsystems = "first"\n')
    refused = subprocess.run([sys.executable, "-m", "softtip", "designs"], capture_output=True, text=True,
                             env={**environment, "SOFTTIP_CONFIG": str(settings)}, timeout=120)
    assert refused.returncode == 2 and refused.stdout == ""
    assert refused.stderr.splitlines()[-1] == (f"error: {settings}: defaults.systems: unknown key (expected one of "
                                               "system)")


SLOW_TO_IMPORT = {
    "__init__.py": '''
        from softtip._core.systems import Study, System

        SYSTEM = System(name="slowtip", title="A plug-in whose every module takes 3 s to import", label="T7",
                        package=__name__, scenarios={"slow": "slowtip.heavy:scenario"},
                        studies=(Study("slow", "slow", "slowtip.heavy:analysis", "T7: nothing"),),
                        demos={"slow": "slowtip.heavy:demo"}, bench_commands={"slow": "slowtip.heavy:bench"},
                        commands={"slowtip": "slowtip.heavy:app"})
    ''',
    "heavy.py": '''
        import time

        import typer

        time.sleep(3.0)  # a model loaded on import
        app = typer.Typer(help="Its commands.", no_args_is_help=True)

        @app.command("hello")
        def hello() -> None:
            """Say hello."""

        def demo() -> None:
            """Its demo."""

        def bench() -> None:
            """Its benchmark."""
    ''',
}


# softtip --help in a fresh interpreter, then the modules it imported (entry points and "module:attribute"
# references are imported by importlib, which -X importtime does not list)
HELP_THEN_MODULES = """
import sys
from softtip.cli.main import app
try:
    app(["--help"], prog_name="softtip")
except SystemExit:
    pass
sys.stderr.write("\\n".join(sys.modules))
"""


def _help_and_its_modules(environment: dict) -> tuple[float, set[str]]:
    """Seconds ``softtip --help`` takes in a fresh interpreter, and the modules it imports."""
    started = time.perf_counter()
    ran = subprocess.run([sys.executable, "-c", HELP_THEN_MODULES], env=environment, capture_output=True, text=True,
                         timeout=120)
    seconds = time.perf_counter() - started
    assert "Usage: softtip" in ran.stdout, ran.stderr
    return seconds, set(ran.stderr.splitlines())


def test_help_imports_no_demo_study_scenario_or_command_group(tmp_path, install_package):
    install_package(tmp_path, "slowtip", SLOW_TO_IMPORT, "slowtip = slowtip:SYSTEM")
    alone = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    beside = {**alone, "PYTHONPATH": os.pathsep.join([str(tmp_path), *sys.path])}
    baseline, toolkit_modules = _help_and_its_modules(alone)
    with_plug_in, modules = _help_and_its_modules(beside)
    assert "slowtip" in modules and "slowtip.heavy" not in modules  # its record only
    # no system's bench, demo, command group, benchmark, study or scenario, and no numerical library
    references = [reference for system in registry.systems().values()
                  for named in (system.benches, system.demos, system.commands, system.bench_commands, system.scenarios)
                  for reference in named.values()]
    references += [study.analysis for study in registry.studies().values()] + [registry.default("demo")]
    assert len(references) > 20 and not {reference.partition(":")[0] for reference in references} & modules
    assert not {"numpy", "scipy", "pydantic", "softtip.cli.bench"} & modules
    assert with_plug_in < baseline + 1.0, (with_plug_in, baseline)  # its 3 s import not paid
    listed = subprocess.run([sys.executable, "-m", "softtip", "demo", "--help"], env=beside, capture_output=True,
                            text=True, timeout=120)
    assert listed.returncode == 0 and "Its demo." in listed.stdout, listed.stderr  # imported when used


def test_an_edited_or_upgraded_plug_in_gets_new_keys_for_its_cached_artefacts(unread_registry, tmp_path, monkeypatch,
                                                                               install_package, request):
    from test_systems import PACKAGE  # the spring of a lab's own, with its protocol

    from softtip.lab.protocols import load_protocol, protocol_key

    install_package(tmp_path, "springtip", PACKAGE, "springtip = springtip:SYSTEM")
    monkeypatch.syspath_prepend(str(tmp_path))
    request.addfinalizer(lambda: [sys.modules.pop(name, None) for name in ("springtip", "springtip.bench")])
    protocol = load_protocol("spring-push")
    assert registry.provenance(registry.systems()["springtip"]) == {"package": "springtip",
                                                                    "installed": "springtip 0.1"}
    first = protocol_key(protocol)
    assert protocol_key(load_protocol("spring-push")) == first  # the same inputs and code, the same key

    model = tmp_path / "springtip" / "bench.py"
    text = model.read_text()
    assert "read = (depth + " in text
    model.write_text(text.replace("read = (depth + ", "read = (1.01 * depth + "))
    edited = protocol_key(protocol)
    assert edited != first

    (tmp_path / "springtip-0.1.dist-info").rename(tmp_path / "springtip-0.2.dist-info")
    (tmp_path / "springtip-0.2.dist-info" / "METADATA").write_text("Metadata-Version: 2.1\nName: springtip\n"
                                                                   "Version: 0.2\n")
    monkeypatch.setattr(registry, "_REGISTERED", {})
    monkeypatch.setattr(registry, "_entry_points", "unread")
    assert registry.provenance(registry.systems()["springtip"])["installed"] == "springtip 0.2"
    assert protocol_key(protocol) not in (first, edited)
