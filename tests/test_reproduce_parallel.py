"""Studies reproduced by a pool of processes give the serial run's results: each study is seeded on its
own and runs with single-threaded native pools either way, so its figures match bit for bit."""

from __future__ import annotations

import json

import pytest

from softtip.studies.reproduce import reproduce_studies, write_index

STUDIES = ("cilia", "haptics")  # the two quickest smoke runs, on systems of their own


def _measured(value):
    """The reports' JSON without what is timed rather than computed (the run's own clocks)."""
    if isinstance(value, dict):
        return {key: _measured(item) for key, item in value.items() if key not in ("timings_s", "seconds")}
    if isinstance(value, list):
        return [_measured(item) for item in value]
    return value


@pytest.mark.slow  # both smoke runs twice: 32 min on 2 cores under a load average of 16-30
def test_a_pool_of_processes_reproduces_the_serial_results(tmp_path):
    finished = []
    for run in ("serial", "parallel"):
        (tmp_path / run).mkdir()
    serial = reproduce_studies(STUDIES, tmp_path / "serial", quick=True, workers=1)
    parallel = reproduce_studies(STUDIES, tmp_path / "parallel", quick=True, workers=2,
                                 finished=lambda name, report: finished.append(name))
    assert list(parallel) == list(STUDIES) and sorted(finished) == sorted(STUDIES)
    for name in STUDIES:
        assert _measured(parallel[name]["comparisons"]) == _measured(serial[name]["comparisons"])
        assert _measured(parallel[name]["results"]) == _measured(serial[name]["results"])
        written = json.loads((tmp_path / "parallel" / f"{name}.json").read_text())
        assert written["results"] == parallel[name]["results"]  # each worker wrote its own report
    assert "cilia.html" in write_index(tmp_path / "parallel").read_text()


def test_a_pool_needs_a_worker():
    with pytest.raises(ValueError, match="workers = 0: expected at least 1"):
        reproduce_studies(STUDIES, ".", workers=0)
