"""What every command shares: the consoles, the spinner, and one-line user errors."""

from __future__ import annotations

import contextlib
import functools

import typer
from rich.console import Console

console = Console()
errors = Console(stderr=True)


def status(message: str, quiet: bool):
    """A spinner with ``message`` on the terminal, nothing when the output is JSON."""
    return contextlib.nullcontext() if quiet else console.status(message)


def fail(message: str) -> None:
    """A user mistake: one line, no traceback, exit code 2."""
    errors.print(f"[bold red]error:[/] {message}", highlight=False, soft_wrap=True)
    raise typer.Exit(2)


def user_errors(function):
    """Turn the library's validation errors into one-line messages."""
    from softtip.design.model import DesignError

    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        try:
            return function(*args, **kwargs)
        except (DesignError, ValueError) as error:
            fail(str(error))

    return wrapper

