"""What every command shares: the consoles, the spinner, one-line user errors, and output paths checked
before the work.

A user error is one line on stderr and exit code 2: a ``ValueError`` (every config, argument and file
refusal of the library), an ``OSError`` (a file missing, unreadable, unwritable, a directory where a
file was expected ...), a computation that did not converge, or any other error softtip defines. Any
other exception is a bug and keeps its traceback. What an error quotes (a value typed, a line of a
file) is shown as text, never as rich markup, and control characters or undecodable bytes in it are
shown escaped (``\\x1b``, ``\\udcff``), so neither a markup tag nor a terminal escape sequence in a
file can change what the line says.
"""

from __future__ import annotations

import errno
import functools
import os
from collections.abc import Iterable
from pathlib import Path

import typer
from rich.console import Console
from rich.text import Text

from softtip._core.errors import NotConverged
from softtip._core.progress import SILENT, Progress, RichProgress

console = Console()
errors = Console(stderr=True)

# What an OSError means for the file it names, where the system's words say it less plainly.
_FILE_PROBLEMS = {
    errno.ENOENT: "does not exist",
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted",
    errno.EISDIR: "is a directory, expected a file",
    errno.ENOTDIR: "a folder on its path is a file",
    errno.EEXIST: "already exists",
    errno.EROFS: "is on a read-only file system",
    errno.ENOSPC: "no space left on the device",
}


class OutputPathError(ValueError):
    """An output path that cannot, or must not, be written."""


def printable(value: object) -> str:
    """``str(value)`` on one line with every non-printable character (control characters, a lone
    surrogate standing for an undecodable byte) written as its Python escape."""
    return "".join(character if character.isprintable() else repr(character)[1:-1] for character in str(value))


def progress_for(json_output: bool) -> Progress:
    """Progress bars on stderr, none when the output is JSON."""
    return SILENT if json_output else RichProgress(errors)


def fail(message: str) -> None:
    """A user mistake: one line, no traceback, exit code 2. ``message`` is shown as plain text."""
    errors.print(Text.assemble(("error:", "bold red"), " ", printable(message)), highlight=False, soft_wrap=True,
                 emoji=False)
    raise typer.Exit(2)


def describe_os_error(error: OSError) -> str:
    """An OSError as one line naming its file(s) and what went wrong."""
    if error.errno is None or error.filename is None:  # raised with words of its own, or about no file
        return error.strerror or str(error) or type(error).__name__
    problem = _FILE_PROBLEMS.get(error.errno, error.strerror)
    files = [os.fsdecode(name) if isinstance(name, (str, bytes, os.PathLike)) else str(name)
             for name in (error.filename, error.filename2) if name is not None]
    return f"{' -> '.join(files)}: {problem}"


def _is_softtip_error(error: BaseException) -> bool:
    return any(cls.__module__.split(".")[0] == "softtip" for cls in type(error).__mro__)


def user_errors(function):
    """Turn user errors (see the module notes) into one-line messages and exit code 2; a bug keeps its
    traceback."""
    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        try:
            return function(*args, **kwargs)
        except OSError as error:
            fail(describe_os_error(error))
        except (ValueError, NotConverged) as error:  # every config and argument error is a ValueError
            fail(str(error))
        except Exception as error:
            if not _is_softtip_error(error):
                raise
            fail(str(error))

    return wrapper


def check_output(path: str | os.PathLike, option: str, inputs: Iterable[str | os.PathLike] = (), *,
                 force: bool = False) -> Path:
    """``path`` if a command may write its output there, checked before any work starts.

    Refuses (:class:`OutputPathError`, naming ``option``) a directory, a path whose folder is missing,
    not a folder, or not writable, an output that is one of ``inputs`` (the same file however named:
    resolved paths, hard and symbolic links), and an existing file unless ``force``.
    """
    path = Path(path)
    named = f"{option} = {path}"
    if path.is_dir():
        raise OutputPathError(f"{named}: is a directory, expected a file to write")
    folder = path.parent
    if not folder.exists():
        raise OutputPathError(f"{named}: folder {folder} does not exist")
    if not folder.is_dir():
        raise OutputPathError(f"{named}: {folder} is not a folder")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputPathError(f"{named}: folder {folder} is read-only (files cannot be created there)")
    for source in map(Path, inputs):
        if path.resolve() == source.resolve() or (path.exists() and source.exists() and path.samefile(source)):
            raise OutputPathError(f"{named}: is the input {source}; the output must be another file")
    if path.exists() and not force:
        raise OutputPathError(f"{named}: the file exists (pass --force to replace it)")
    return path
