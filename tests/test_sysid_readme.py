"""README.md's system-identification walk-through, run as written: every ``softtip`` line of its bash
block in order, from a folder where ``examples`` is the repository's, each line's ``#    ->`` fragments
(separated by `` ... ``) found in what it printed, and then its Python block."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from softtip.cli.main import app

ROOT = Path(__file__).parents[1]


def _walk_through() -> tuple[list[tuple[str, list[str]]], str]:
    """(command, expected fragments) of the walk-through's bash block, and its Python block."""
    text = ROOT.joinpath("README.md").read_text()
    section = text[text.index("**A walk through an identification, on a real record.**"):]
    bash = re.search(r"```bash\n(.*?)```", section, re.S).group(1)
    python = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    steps: list[tuple[str, list[str]]] = []
    for line in bash.splitlines():
        if line.startswith("softtip "):
            steps.append((line, []))
        elif line.startswith("#    -> "):
            steps[-1][1].extend(part.strip() for part in line.removeprefix("#    -> ").split(" ... "))
    return steps, python


def _flat(text: str) -> str:
    return " ".join(text.split())


def test_the_readme_walk_through_runs_as_written(tmp_path, monkeypatch):
    steps, python = _walk_through()
    assert len(steps) == 5
    monkeypatch.chdir(tmp_path)
    (tmp_path / "examples").symlink_to(ROOT / "examples")
    runner = CliRunner()
    for number, (command, expected) in enumerate(steps, start=1):
        result = runner.invoke(app, shlex.split(command)[1:])
        # the first step shows the refusal of an irregular log; every other one runs
        assert result.exit_code == (2 if number == 1 else 0), f"step {number}: {result.output}"
        printed = _flat(result.output)
        for fragment in expected:
            assert _flat(fragment) in printed, f"step {number}: {fragment!r} not in {printed}"
    for name in ("compare.png", "step.png", "bode.png"):
        assert (tmp_path / name).stat().st_size > 10_000
    scope: dict = {}
    exec(compile(python, "README.md", "exec"), scope)
    from softtip.sysid import load_model

    simulated = load_model("eflesh_tf1.npz").simulate(scope["record"])[0]
    np.testing.assert_allclose(np.vstack(scope["grams"]), simulated, rtol=0, atol=1e-9)
