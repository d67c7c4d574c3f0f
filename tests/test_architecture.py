"""The layering of the packages, as docs/architecture.md draws it, enforced by import-linter's
contracts in pyproject.toml: each stage imports only the stages below it, siblings stay
independent, and data and calibration know nothing of the physics."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("importlinter", reason="import-linter is not installed (pip install -e '.[test]')")

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"
# in a process of its own: import-linter reconfigures logging, which would silence the loggers of
# the tests that run after it
LINT = "import sys; from importlinter.cli import lint_imports; sys.exit(lint_imports(config_filename=sys.argv[1], no_cache=True))"


def test_import_contracts_hold():
    checked = subprocess.run([sys.executable, "-c", LINT, str(PYPROJECT)], capture_output=True, text=True)
    assert checked.returncode == 0, checked.stdout[-4000:] + checked.stderr[-2000:]
    assert "0 broken" in checked.stdout
