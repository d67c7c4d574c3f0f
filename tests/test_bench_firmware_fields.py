"""What ``softtip bench firmware`` feeds the emulated chips: a live scenario's fields sampled one row
per conversion, and ``--export-fields`` writing them in the simulator's format (``--fields``' own).
The twin's default fields streamed through the firmware are checked in test_firmware_sim.py."""

from __future__ import annotations

import json

import numpy as np
from typer.testing import CliRunner

from softtip.bench.firmware import FIELD_RATE_HZ, read_fields, scenario_fields
from softtip.cli.main import app
from softtip.realtime.scenario import LiveScenario

runner = CliRunner()


def two_chips(t_s: float) -> np.ndarray:
    """A scenario's fields (chips, 3) µT at ``t_s``: each axis its own line in time."""
    return np.array([[10 + t_s, -20 + 2 * t_s, 3000 - 100 * t_s], [5.0, 7 * t_s, -8.0]])


def test_a_scenarios_fields_are_its_samples_one_row_per_conversion_each_chip_in_turn():
    scenario = LiveScenario("two lines", "emulator", (), chips=2, emulator_source=two_chips)
    fields = scenario_fields(scenario, 3, rows=5)
    assert fields.shape == (5, 3, 3) and FIELD_RATE_HZ == 200
    # row 3 is the scenario at 15 ms: chip 0 (10.015, -19.97, 2998.5), chip 1 (5, 0.105, -8); chip 2 reads chip 0
    assert np.allclose(fields[3], [[10.015, -19.97, 2998.5], [5.0, 0.105, -8.0], [10.015, -19.97, 2998.5]])
    assert np.allclose(fields[:, :2], [two_chips(k / 200) for k in range(5)])


def test_a_scenario_that_emulates_no_chips_is_refused():
    scenario = LiveScenario("a paced source", "emulator", (), chips=1)
    try:
        scenario_fields(scenario, 1)
    except ValueError as problem:
        assert "streams from a source of its own" in str(problem)
    else:
        raise AssertionError("a scenario without emulated fields fed the chips")


def test_export_fields_writes_the_rows_in_the_format_fields_reads(tmp_path):
    rows = np.random.default_rng(3).uniform(-900, 900, (7, 2, 3)).round(6)
    given, exported = tmp_path / "given.txt", tmp_path / "exported.txt"
    np.savetxt(given, rows.reshape(7, 6))
    result = runner.invoke(app, ["bench", "firmware", "--chips", "2", "--fields", str(given), "--export-fields",
                                 str(exported), "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report == {"export_fields": str(exported), "rows": 7, "chips": 2, "source": f"the field file {given}"}
    assert np.array_equal(read_fields(exported, 2), rows)
    assert exported.read_text().startswith("# x y z (uT) of each chip, one row per conversion\n")
    again = runner.invoke(app, ["bench", "firmware", "--chips", "2", "--fields", str(given), "--export-fields",
                                str(exported)])
    assert again.exit_code == 2 and "--export-fields" in again.stderr and "--force" in again.stderr
