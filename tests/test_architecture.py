"""The layering of the packages, as docs/architecture.md draws it, enforced by import-linter's
contracts in pyproject.toml: each stage imports only the stages below it, siblings stay
independent, and data and calibration know nothing of the physics."""

from __future__ import annotations

from pathlib import Path

import pytest

lint = pytest.importorskip("importlinter.cli", reason="import-linter is not installed (pip install -e '.[test]')")

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"


def test_import_contracts_hold(capsys):
    code = lint.lint_imports(config_filename=str(PYPROJECT), no_cache=True)
    report = capsys.readouterr().out
    assert code == 0, report[-4000:]
    assert "0 broken" in report
