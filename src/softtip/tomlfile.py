"""Reading the project's TOML files (designs, studies) with one-line errors."""

from __future__ import annotations

import tomllib
from pathlib import Path


def read_toml(path: Path, what: str, error: type[Exception]) -> dict:
    """The table in ``path``; a missing or malformed file raises ``error`` naming ``what`` and the file."""
    if not path.is_file():
        raise error(f"{what} file {path} does not exist")
    try:
        return tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as problem:
        raise error(f"{what} file {path}: not valid TOML ({problem})") from None
