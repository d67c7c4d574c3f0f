"""The first hour on the live path: long steps say what the user waits for on stderr, also when the
output is JSON, and the start of ``live --emulate`` is timed cold and warm."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from softtip.cli.main import app


def test_simulate_shows_its_mesh_and_every_load_step_on_stderr_under_json():
    result = CliRunner().invoke(app, ["simulate", "--mesh-size", "3", "--depth", "1", "--shear-x", "0.5", "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["force_N"]  # stdout is the JSON alone
    lines = result.stderr.splitlines()
    # sticking contact with a shear: two normal steps, then the default four tangential ones (load_path's notes)
    assert lines[0] == "… mesh of cylindrical-A at 3 mm (kept in the cache)"
    assert lines[2] == "… contact load steps"
    assert [line.split(": ")[1].split(" (")[0] for line in lines[3:-1]] == ["1/6", "2/6", "3/6", "4/6", "5/6"]
    assert lines[-1].startswith("✓ contact load steps (6/6, ")
