"""What every command shares: the consoles, the spinner, and one-line user errors."""

from __future__ import annotations

import functools

import typer
from rich.console import Console

from softtip._core.errors import NotConverged
from softtip._core.progress import SILENT, Progress, RichProgress

console = Console()
errors = Console(stderr=True)


def progress_for(json_output: bool) -> Progress:
    """Progress bars on stderr, none when the output is JSON."""
    return SILENT if json_output else RichProgress(errors)


def fail(message: str) -> None:
    """A user mistake: one line, no traceback, exit code 2."""
    errors.print(f"[bold red]error:[/] {message}", highlight=False, soft_wrap=True)
    raise typer.Exit(2)


def user_errors(function):
    """Turn the library's validation errors, and computations that did not converge, into one-line
    messages."""
    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        try:
            return function(*args, **kwargs)
        except (ValueError, NotConverged) as error:  # every config and argument error is a ValueError
            fail(str(error))

    return wrapper

