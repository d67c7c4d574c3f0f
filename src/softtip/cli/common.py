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

import contextlib
import errno
import functools
import inspect
import json
import math
import os
import typing
from collections.abc import Iterable
from pathlib import Path

import typer
from rich.console import Console
from rich.text import Text
from typer._click.exceptions import NoArgsIsHelpError, UsageError
from typer.core import TyperArgument, TyperGroup

from softtip._core.errors import NotConverged
from softtip._core.files import OutputClaimed, claim, not_a_file
from softtip._core.progress import Progress, RichProgress
from softtip._core.systems import load

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
    """Progress on stderr: bars on a terminal; lines when the output is JSON (stdout stays the JSON alone)
    or stderr goes to a file or a pipe (where bars would not show)."""
    return RichProgress(errors, lines=json_output or not errors.is_terminal)


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
        if _same_file(path, source):
            raise OutputPathError(f"{named}: is the input {source}; the output must be another file")
    if path.exists() and not force:
        raise OutputPathError(f"{named}: the file exists (pass --force to replace it)")
    return path


def _same_file(path: Path, other: Path) -> bool:
    """Whether two paths name one file however written: resolved paths, hard and symbolic links."""
    return path.resolve() == other.resolve() or (path.exists() and other.exists() and path.samefile(other))


def check_outputs(outputs: Iterable[tuple[str, str | os.PathLike | None]],
                  inputs: Iterable[str | os.PathLike] = (), *, force: bool = False) -> None:
    """:func:`check_output` for each of a command's outputs given as (option, path or None: not asked
    for), and two of them on one file refused: one would silently replace the other."""
    inputs = list(inputs)
    given: list[tuple[str, Path]] = []
    for option, path in outputs:
        if path is None:
            continue
        path = check_output(path, option, inputs, force=force)
        for other, earlier in given:
            if _same_file(path, earlier):
                raise OutputPathError(f"{option} = {path}: is also {other}'s output; each output needs a file "
                                      "of its own")
        given.append((option, path))


@contextlib.contextmanager
def claimed(path: str | os.PathLike | None, option: str):
    """The block run with ``path`` (None: no output) claimed for this process (:func:`softtip._core.files.claim`):
    another softtip writing the same file is refused in one line naming ``option``."""
    if path is None:
        yield
        return
    with contextlib.ExitStack() as stack:
        try:
            stack.enter_context(claim(path))
        except OutputClaimed:
            raise OutputPathError(f"{option} = {path}: another process is writing this file") from None
        yield


def check_number(value: float | None, option: str, *, minimum: float | None = None, above: float | None = None,
                 maximum: float | None = None, unit: str = "") -> float | None:
    """``value`` (None: the option was not given) if it lies within the limits, else an error naming
    ``option``: at least ``minimum``, more than ``above``, at most ``maximum``."""
    if value is None:
        return None
    unit = f" {unit}" if unit else ""
    bounds = [f">= {minimum:g}{unit}" if minimum is not None else "", f"> {above:g}{unit}" if above is not None else "",
              f"<= {maximum:g}{unit}" if maximum is not None else ""]
    if (not math.isfinite(value) or (minimum is not None and value < minimum) or (above is not None and value <= above)
            or (maximum is not None and value > maximum)):
        raise ValueError(f"{option} = {value}: expected a number {' and '.join(b for b in bounds if b)}")
    return value


def _numbers(value: object) -> list[float]:
    if isinstance(value, float):
        return [value]
    if isinstance(value, (list, tuple)):
        return [item for item in value if isinstance(item, float)]
    return []


def _checked(callback, command):
    """``callback`` refusing, before it runs, a number that is not finite (NaN, ±inf): no option of
    softtip means "forever" or "undefined" by one."""
    options = {param.name: (param.opts[0] if param.opts[0].startswith("-") else param.name.upper())
               for param in command.params}

    @functools.wraps(callback)
    def wrapper(**kwargs):
        for name, value in kwargs.items():
            if any(not math.isfinite(number) for number in _numbers(value)):
                fail(f"{options.get(name, name)} = {printable(value)}: expected a finite number")
        return callback(**kwargs)

    return wrapper


def _paragraphs(text: str | None) -> str | None:
    """A help text as paragraphs: a docstring's line breaks are where the source wrapped, not the reader's
    terminal."""
    if not text:
        return text
    return "\n\n".join(" ".join(part.split()) for part in inspect.cleandoc(text).split("\n\n"))


# What a value looks like in the help, by the option's type (a flag takes none).
_METAVARS = {float: "NUMBER", int: "INTEGER", str: "TEXT", Path: "PATH"}


def _metavar(param) -> str | None:
    described = param.type_descriptor
    if getattr(param, "is_flag", False) or described.annotation is bool:
        return ""
    if described.is_choice:
        return "|".join(str(getattr(choice, "value", choice)) for choice in described.choices or ())
    annotation = described.annotation
    if described.is_tuple:
        return " ".join(_METAVARS.get(item, "VALUE") for item in typing.get_args(annotation))
    if described.is_list:
        (item,) = typing.get_args(annotation)
        return _METAVARS.get(item, "VALUE") + " (repeatable)"
    return _METAVARS.get(annotation, "VALUE")


def _flag_help(get_help_option):
    """The --help option shown as the flag it is."""
    @functools.wraps(get_help_option)
    def wrapper(ctx):
        option = get_help_option(ctx)
        if option is not None:
            option.metavar = ""
        return option

    return wrapper


def commands_of(command, path: tuple[str, ...] = ()):
    """Every command under ``command`` as (its words, the command), groups included, depth first."""
    yield path, command
    for name, sub in (getattr(command, "commands", None) or {}).items():
        yield from commands_of(sub, (*path, name))


class Deferred(TyperGroup):
    """A command group imported when it is used, not when the command line loads (a system's commands,
    its demos, its benchmarks): the root's help lists it by ``summary``; :meth:`Toolkit.get_command`
    replaces it with the group ``build`` returns the first time a command line names it."""

    def __init__(self, name: str, summary: str, build: typing.Callable[[], TyperGroup]):
        super().__init__(name=name, help=summary)
        self.build = build


class Toolkit(TyperGroup):
    """The root command: every command below it, whichever system registered it, refuses non-finite
    numbers and turns user errors into one line; a usage error (an unknown option, a value of the wrong
    type) is one line too; help reads as text. ``deferred``: its groups built when used."""

    deferred: tuple[Deferred, ...] = ()

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._listing = False
        self._make_ours(self)
        for group in self.deferred:
            self.commands[group.name] = group

    def _make_ours(self, root) -> None:
        for _, command in commands_of(root):
            command.help = _paragraphs(command.help)
            for param in command.params:
                if param.metavar is not None or not hasattr(param, "type_descriptor"):
                    continue
                if isinstance(param, TyperArgument):
                    # an argument keeps its name in the usage line; its type column reads as an option's does
                    param.display_type_rich = functools.partial(lambda metavar, ctx: metavar, _metavar(param))
                    param.metavar = param.name.upper()
                else:
                    param.metavar = _metavar(param)
            command.get_help_option = _flag_help(command.get_help_option)
            if command.callback is not None and command is not self:
                command.callback = _checked(user_errors(command.callback), command)

    def get_command(self, ctx, cmd_name):
        command = super().get_command(ctx, cmd_name)
        if isinstance(command, Deferred) and not self._listing:
            command = self.commands[cmd_name] = command.build()
            self._make_ours(command)
        return command

    def format_help(self, ctx, formatter):
        self._listing = True  # the root's help lists deferred groups by their summary, importing none
        try:
            return super().format_help(ctx, formatter)
        finally:
            self._listing = False

    def parse_args(self, ctx, args):
        with _one_line_usage_errors():
            return super().parse_args(ctx, args)

    def invoke(self, ctx):
        with _one_line_usage_errors():
            return super().invoke(ctx)


@contextlib.contextmanager
def _one_line_usage_errors():
    try:
        yield
    except NoArgsIsHelpError:
        raise
    except UsageError as error:
        where = f" (see {error.ctx.command_path} --help)" if error.ctx is not None else ""
        fail(error.format_message() + where)


def check_output_folder(path: str | os.PathLike, option: str, files: Iterable[str] = (), *,
                        force: bool = False) -> Path:
    """``path`` if a command may write its files into it (existing or to be made), checked before the work:
    not a file, its nearest existing folder writable, and none of ``files`` (the names the command
    writes there) already in it unless ``force``."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OutputPathError(f"{option} = {path}: is a file, expected a folder for the outputs")
    existing = next(folder for folder in (path, *path.parents) if folder.exists())
    if not existing.is_dir() or not os.access(existing, os.W_OK | os.X_OK):
        raise OutputPathError(f"{option} = {path}: {existing} is not a writable folder")
    for name in files:
        if (path / name).is_dir():
            raise OutputPathError(f"{option} = {path}: {name} in it is a directory, expected a file to write")
        if (path / name).exists() and not force:
            raise OutputPathError(f"{option} = {path}: {name} exists in it (pass --force to replace it)")
    return path


FORCE = typer.Option(False, "--force", help="Replace output files that exist.")
LONGEST_S = 7 * 24 * 3600.0  # a week: the longest a duration option may ask for (no --duration: until Ctrl-C)


def check_distinct(values: list[str], option: str, why: str = "") -> None:
    """Refuses a value of a repeatable ``option`` given twice (``why``: what a repeat would mean)."""
    repeated = [value for k, value in enumerate(values) if value in values[:k]]
    if repeated:
        fail(f"{option} {repeated[0]!r}: given twice" + (f"; {why}" if why else ""))


def demo_report(run: str, seed: int, duration: float | None, record: Path | None, force: bool,
                json_output: bool) -> dict | None:
    """A demo's common options checked before any work, then its ``run`` (``"module:function"``, imported
    only then) called with them: its report, or None once printed as JSON."""
    check_number(duration, "--duration", above=0, maximum=LONGEST_S, unit="s")
    check_number(seed, "--seed", minimum=0)
    if record is not None:
        check_output(record, "--record", force=force)
    with claimed(record, "--record"):
        report = load(run)(seed=seed, duration_s=duration, dashboard=not json_output, record=record,
                           progress=progress_for(json_output))
    if json_output:
        print(json.dumps(report, indent=2, default=float))
        return None
    return report


def check_input(path: str | os.PathLike, option: str) -> Path:
    """``path`` if it is a readable file, checked before the work that comes before reading it."""
    path = Path(path)
    problem = not_a_file(path)
    if problem:
        raise ValueError(f"{option} = {path}: {problem}")
    if not os.access(path, os.R_OK):
        raise ValueError(f"{option} = {path}: permission denied")
    return path
