"""The core every stage shares: the TOML reader, config schemas, atomic writes and the progress protocol."""

from __future__ import annotations

import io
import os
import stat
from dataclasses import field

import numpy as np
import pytest
from rich.console import Console

from softtip._core.config import (
    ConfigError,
    Fraction,
    NonNegativeNumber,
    Number,
    OpenFraction,
    PositiveNumber,
    Refusal,
    PositiveInteger,
    Text,
    checked,
    choice,
    instance,
    integer,
    parse,
    read_toml,
    schema,
    where,
)
from softtip._core.files import atomic_write
from softtip._core.progress import SILENT, Progress, RichProgress, Task
from softtip._core.units import MM
from softtip.design.model import DesignError
from softtip.optimize.cache import FEResultCache
from softtip.optimize.config import study_from_dict
from softtip.optimize.runs import FEResult
from softtip.optimize.study import run_study

# --------------------------------------------------------------------------- the TOML reader


def test_a_toml_file_reads_as_its_table(tmp_path):
    path = tmp_path / "study.toml"
    path.write_text('name = "grid"\n[search]\nbudget = 20\n', encoding="utf-8")
    assert read_toml(path, "study") == {"name": "grid", "search": {"budget": 20}}


@pytest.mark.parametrize("content, message", [
    (None, r"^study file \S+missing\.toml does not exist$"),
    (b"name = 'grid'\n[search\n", r"^study file \S+missing\.toml: not valid TOML \(.*line 2.*\)$"),
    (b"name = '\xff\xfe'\n", r"^study file \S+missing\.toml: not UTF-8 text \(invalid start byte at byte 8\)$"),
])
def test_the_toml_reader_refuses_a_file_in_one_line_naming_it(tmp_path, content, message):
    path = tmp_path / "missing.toml"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(ConfigError, match=message) as refusal:
        read_toml(path, "study")
    assert "\n" not in str(refusal.value)


def test_the_toml_reader_raises_the_callers_error():
    with pytest.raises(DesignError, match="design file nowhere.toml does not exist"):
        read_toml("nowhere.toml", "design", DesignError)


# --------------------------------------------------------------------------- schemas


@schema
class Span:
    min: Number
    max: Number
    step: PositiveNumber | None = None

    def __post_init__(self):
        if self.max < self.min:
            raise Refusal("max", f"expected max >= min = {self.min}")


@schema(section="search")
class Search:
    budget: integer(1) = 25
    tolerance: NonNegativeNumber = 1e-3
    method: choice("grid", "bayes") = "grid"


@schema
class Study:
    design: Text
    search: Search = Search()
    parameters: dict[str, Span] = field(default_factory=dict)


def refusal(table) -> str:
    with pytest.raises(ConfigError) as error:
        parse(Study, table, "s.toml")
    assert "\n" not in str(error.value)
    return str(error.value)


def test_a_valid_table_becomes_the_schema_with_its_defaults():
    study = parse(Study, {"design": "cylindrical-A", "search": {"budget": 3, "tolerance": 0},
                          "parameters": {"cavity.radius_mm": {"min": 8, "max": 9}}}, "s.toml")
    assert study == Study(design="cylindrical-A", search=Search(budget=3, tolerance=0.0, method="grid"),
                          parameters={"cavity.radius_mm": Span(min=8.0, max=9.0)})
    assert isinstance(study.search.tolerance, float) and isinstance(study.parameters["cavity.radius_mm"].min, float)


@pytest.mark.parametrize("table, message", [
    # wrong type: the kind of value is named before its range
    ({"design": "A", "search": {"budget": "many"}}, "s.toml: search.budget = 'many': expected an integer"),
    ({"design": "A", "search": {"budget": 2.0}}, "s.toml: search.budget = 2.0: expected an integer"),
    ({"design": "A", "search": {"budget": True}}, "s.toml: search.budget = True: expected an integer"),
    ({"design": "A", "search": {"tolerance": True}}, "s.toml: search.tolerance = True: expected a number"),
    ({"design": "A", "search": {"tolerance": float("nan")}}, "s.toml: search.tolerance = nan: expected a number"),
    ({"design": 7}, "s.toml: design = 7: expected a non-empty string"),
    ({"design": "A", "search": 3}, "s.toml: search = 3: expected a table"),
    (["design"], "s.toml: expected a table"),
    # out of range
    ({"design": "A", "search": {"budget": 0}}, "s.toml: search.budget = 0: expected an integer >= 1"),
    ({"design": "A", "search": {"tolerance": -1}}, "s.toml: search.tolerance = -1: expected a number >= 0"),
    ({"design": "A", "search": {"method": "random"}}, "s.toml: search.method = 'random': expected one of grid, bayes"),
    ({"design": "A", "parameters": {"a.b": {"min": 1, "max": 2, "step": 0}}},
     's.toml: parameters."a.b".step = 0: expected a positive number'),
    # unknown key: the expected ones are listed
    ({"design": "A", "serch": {}}, "s.toml: serch: unknown key (expected one of design, parameters, search)"),
    ({"design": "A", "search": {"budgt": 3}}, "s.toml: search.budgt: unknown key (expected one of budget, method, "
                                              "tolerance)"),
    ({"design": "A", "parameters": {"a": {"min": 1, "max": 2, "stp": 1}}},
     "s.toml: parameters.a.stp: unknown key (expected one of max, min, step)"),
    # missing key
    ({"search": {}}, "s.toml: design is missing"),
    ({"design": "A", "parameters": {"a": {"max": 2}}}, "s.toml: parameters.a.min is missing"),
    # a check between keys names the key it refuses, with its value as written
    ({"design": "A", "parameters": {"cavity.radius_mm": {"min": 9, "max": 8}}},
     's.toml: parameters."cavity.radius_mm".max = 8: expected max >= min = 9.0'),
])
def test_a_schema_refuses_a_table_in_one_line_naming_file_key_and_expectation(table, message):
    assert refusal(table) == message


def test_constructing_a_schema_validates_it_the_same_way():
    with pytest.raises(ConfigError, match=r"^search\.budget = 0: expected an integer >= 1$"):
        Search(budget=0)
    with pytest.raises(ConfigError, match=r"^search\.budgt: unknown key \(expected one of budget, method, tolerance\)$"):
        Search(budgt=3)
    with pytest.raises(ConfigError, match=r"^max = 8: expected max >= min = 9\.0$"):
        Span(9, 8)  # positional arguments are named by their field
    assert Search(budget=np.int64(4), tolerance=np.float32(0.5)) == Search(budget=4, tolerance=0.5)


def test_an_argument_is_checked_against_a_type_in_one_line_naming_it():
    assert checked(PositiveNumber, "rate_hz", np.float32(2.5)) == 2.5
    assert checked(PositiveInteger, "frames", np.int64(3)) == 3 and type(checked(PositiveNumber, "x", 2)) is float
    for kind, value, message in [
        (PositiveNumber, 0, "rate_hz = 0: expected a positive number"),
        (PositiveNumber, True, "rate_hz = True: expected a number"),
        (PositiveNumber, float("inf"), "rate_hz = inf: expected a number"),
        (PositiveInteger, 2.0, "rate_hz = 2.0: expected an integer"),
        (PositiveInteger, 0, "rate_hz = 0: expected a positive integer"),
        (instance(Search), {"budget": 3}, "rate_hz = {'budget': 3}: expected Search"),
    ]:
        with pytest.raises(ConfigError) as error:
            checked(kind, "rate_hz", value)
        assert str(error.value) == message
    with pytest.raises(DesignError, match=r"^port = 7: expected a non-empty string$"):
        checked(Text, "port", 7, DesignError)
    search = Search()
    assert checked(instance(Search), "search", search) is search


def test_a_fraction_includes_its_ends_and_an_open_fraction_excludes_them():
    assert checked(Fraction, "share", 0) == 0.0 and checked(Fraction, "share", 1) == 1.0
    assert checked(OpenFraction, "tolerance", 0.02) == 0.02
    for value in (0, 1, -0.5, 1.5):
        with pytest.raises(ConfigError, match=rf"^tolerance = {value}: expected a number strictly between 0 and 1$"):
            checked(OpenFraction, "tolerance", value)
    with pytest.raises(ConfigError, match=r"^share = 1.5: expected a number from 0 to 1$"):
        checked(Fraction, "share", 1.5)


def test_a_refusal_of_a_parsed_table_is_located_there():
    table = {"magnet": 7}
    error = Refusal("magnet", "expected an index 0..3").locate(table, "s.toml", "objective")
    assert str(error) == "s.toml: objective.magnet = 7: expected an index 0..3"
    assert str(Refusal("magnet", "expected an index").locate({}, "s.toml")) == "s.toml: magnet: expected an index"


def test_places_are_spelled_as_toml_keys():
    assert where("s.toml", "parameters", "cavity.radius_mm", "max") == 's.toml: parameters."cavity.radius_mm".max'
    assert where("d.toml", "sensor", "positions_mm", 0) == "d.toml: sensor.positions_mm[0]"
    assert where("", "sensor", "gain_sel") == "sensor.gain_sel"
    assert where("s.toml") == "s.toml"


# --------------------------------------------------------------------------- atomic writes


def test_atomic_write_writes_bytes_text_and_writers(tmp_path):
    assert atomic_write(tmp_path / "a.bin", b"\x00\x01").read_bytes() == b"\x00\x01"
    assert atomic_write(tmp_path / "b.txt", "µT\n").read_bytes() == "µT\n".encode()
    path = atomic_write(tmp_path / "c.npz", lambda handle: np.savez(handle, x=np.arange(3)))
    with np.load(path) as data:
        np.testing.assert_array_equal(data["x"], [0, 1, 2])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.bin", "b.txt", "c.npz"]


def test_a_write_that_fails_midway_leaves_the_old_file_intact_and_no_debris(tmp_path):
    path = atomic_write(tmp_path / "results.json", '{"best": 1}')

    def failing(handle):
        handle.write(b'{"best": ')
        raise OSError("no space left on device")

    with pytest.raises(OSError, match="no space left"):
        atomic_write(path, failing)
    assert path.read_text() == '{"best": 1}'
    assert list(tmp_path.iterdir()) == [path]


def test_the_data_is_on_disk_before_it_replaces_the_old_file(tmp_path, monkeypatch):
    steps = []
    fsync, replace = os.fsync, os.replace
    monkeypatch.setattr(os, "fsync", lambda fd: (steps.append("fsync"), fsync(fd)))
    monkeypatch.setattr(os, "replace", lambda a, b: (steps.append("replace"), replace(a, b)))
    atomic_write(tmp_path / "model.npz", b"weights")
    assert steps == ["fsync", "replace"]


def test_a_written_file_has_the_permissions_of_any_new_file(tmp_path):
    reference = tmp_path / "plain"
    reference.write_bytes(b"")
    written = atomic_write(tmp_path / "atomic", b"")
    assert stat.S_IMODE(written.stat().st_mode) == stat.S_IMODE(reference.stat().st_mode)


# --------------------------------------------------------------------------- progress


class Recorder(Progress):
    """Every call a job makes, in order."""

    def __init__(self):
        self.calls = []

    def task(self, description, total=None):
        self.calls.append(("task", description, total))
        calls = self.calls

        class Recorded(Task):
            def advance(self, steps=1, note=None):
                calls.append(("advance", steps, note))

            def done(self):
                calls.append(("done",))

        return Recorded()


class CannedExecutor:
    """FE results made up from the design: the feature point moves cavity radius / 10 mm down."""

    description = "canned"

    def run(self, jobs):
        for job in jobs:
            displacement = np.zeros((4, 3))
            displacement[:, 2] = job.design_spec["cavity"]["radius_mm"] / 10 * MM
            result = FEResult(feature_displacements_m=displacement, magnet_positions_m=np.zeros((4, 3)),
                              magnet_rotvecs_rad=np.zeros((4, 3)), force_N=np.zeros(3), field_rest_T=np.zeros((1, 3)),
                              field_change_T=np.zeros((1, 3)), contact_nodes=0, tetrahedra=0, unknowns=0)
            yield job, {"results": [result.to_dict()] * len(job.simulations), "error": None,
                        "seconds": [0.0] * len(job.simulations)}

    def close(self):
        pass


def test_a_study_reports_one_task_advanced_once_per_design(tmp_path):
    study = study_from_dict({"name": "sweep", "design": "cylindrical-A",
                             "parameters": {"cavity.radius_mm": {"min": 8.0, "max": 9.0, "step": 1.0}}})
    recorder = Recorder()
    result = run_study(study, CannedExecutor(), FEResultCache(tmp_path), progress=recorder)
    assert [r.objective for r in result.records] == pytest.approx([0.8, 0.9])
    assert recorder.calls == [("task", "sweep (grid)", 2), ("advance", 1, "last: 8 -> 0.8"),
                              ("advance", 1, "last: 9 -> 0.9"), ("done",)]


def test_the_silent_default_reports_nothing_and_rich_leaves_a_line_per_finished_task():
    with SILENT.task("anything", total=3) as task:
        task.advance(note="quiet")
    screen = io.StringIO()
    progress = RichProgress(Console(file=screen, width=100))
    with progress.task("trials", total=2) as task:
        task.advance()
        with progress.task("influence matrices"):
            pass
        task.advance(note="last trial")
    lines = [line for line in screen.getvalue().splitlines() if line]
    assert [line.split(" (")[0] for line in lines] == ["✓ influence matrices", "✓ trials"]
    assert lines[1].startswith("✓ trials (2/2, ")


def test_rich_progress_in_lines_says_each_task_as_it_starts_every_tenth_and_its_end():
    screen = io.StringIO()
    progress = RichProgress(Console(file=screen, width=40), lines=True)  # narrow: no line is wrapped
    with progress.task("unit load responses of the fingertip's surface", total=25) as task:
        for _ in range(25):
            task.advance()
    lines = screen.getvalue().splitlines()
    assert lines[0] == "… unit load responses of the fingertip's surface"
    # 25 steps: the tenths 1..9 are passed at steps 3, 5, 8, 10, 13, 15, 18, 20, 23
    assert [line.split(": ")[1].split(" (")[0] for line in lines[1:-1]] == [
        "3/25", "5/25", "8/25", "10/25", "13/25", "15/25", "18/25", "20/25", "23/25"]
    assert lines[-1].startswith("✓ unit load responses of the fingertip's surface (25/25, ")
