"""The first hour on the live path: long steps say what the user waits for on stderr, also when the
output is JSON, and the start of ``live --emulate`` is timed cold and warm."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from softtip.cli.main import app


def test_simulate_shows_every_load_step_on_stderr_under_json():
    result = CliRunner().invoke(app, ["simulate", "--mesh-size", "3", "--depth", "1", "--shear-x", "0.5", "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["force_N"]  # stdout is the JSON alone
    lines = result.stderr.splitlines()
    # sticking contact with a shear: two normal steps, then the default four tangential ones (load_path's notes)
    assert lines[0] == "… contact load steps"
    assert [line.split(": ")[1].split(" (")[0] for line in lines[1:-1]] == ["1/6", "2/6", "3/6", "4/6", "5/6"]
    assert lines[-1].startswith("✓ contact load steps (6/6, ")


@pytest.mark.slow  # two starts, one on an empty cache: 224 s beside a cold push start (load average 7-14)
def test_the_start_is_timed_cold_on_an_empty_cache_then_warm_on_what_the_cold_start_left(stage_names):
    from softtip.bench.live import start_times

    progress = stage_names()
    times = start_times("wearable", progress)  # the quickest scenario to compute: a 3 x 3 transfer function
    assert [name.split(":")[0] for name in progress.names] == [
        "start of live --emulate --scenario wearable, cold", "start of live --emulate --scenario wearable, warm"]
    cold, warm = times["cold"], times["warm"]
    for run in (cold, warm):
        # the parent's own clock, from before it started the process to its end, holds the first frame (the
        # stream's second counts from the session's start, so a late first frame leaves less of it after)
        assert 0 < run["first_frame_s"] < run["wall_s"]
        assert len(run["load_average_1_5_15_min"]) == 3
    # the warm start read the identification the cold one stored: about half its CPU time (2.1 of 4.2 s
    # idle), the rest being the start of Python, the emulator and the stream both runs share
    assert warm["cpu_s"] < 0.75 * cold["cpu_s"]
    assert warm["first_frame_s"] < cold["first_frame_s"]
