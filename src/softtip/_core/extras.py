"""Optional dependencies: what a command needs beyond softtip's own installation, checked before its
work and refused in one line that names the extra installing it (``pip install 'softtip[EXTRA]'``)."""

from __future__ import annotations

import importlib


class MissingExtra(RuntimeError):
    """An optional dependency does not import; the message names the extra that installs it."""


def install_hint(extra: str) -> str:
    return f"pip install 'softtip[{extra}]'"


def require(what: str, extra: str, *modules: str) -> None:
    """Raises :class:`MissingExtra` unless every one of ``modules`` imports: ``what`` needs them."""
    missing = []
    for module in modules:
        try:
            importlib.import_module(module)
        except ImportError:
            missing.append(module)
    if missing:
        raise MissingExtra(f"{what} needs {', '.join(missing)}, not installed: {install_hint(extra)}")
