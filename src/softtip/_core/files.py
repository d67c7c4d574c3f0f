"""Every file softtip writes: replaced atomically (a reader never sees half a file, and a failed write
leaves the old one), and claimed exclusively where two processes could write it at once."""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import stat
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any, BinaryIO, Callable


# What a path that is not a regular file is, as its mode says: such a path given as an input is refused by
# name before it is opened (a FIFO would block the reader for ever, /dev/zero would fill the memory).
_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def not_a_file(path: str | os.PathLike) -> str | None:
    """What keeps ``path`` from being read as an input file, in words ("does not exist", "is a FIFO (named
    pipe), expected a regular file" ...), or None for a regular file (a link followed)."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return "is a link to nothing" if os.path.islink(path) else "does not exist"
    except OSError as error:
        return f"cannot be read ({error.strerror})"
    if stat.S_ISREG(mode):
        return None
    kind = next((name for test, name in _KINDS if test(mode)), "not a regular file")
    return f"is {kind}, expected a regular file"


class OutputClaimed(OSError):
    """An output another process is writing."""


def atomic_write(path: str | os.PathLike, content: bytes | str | Callable[[BinaryIO], object], *,
                 encoding: str = "utf-8") -> Path:
    """Replace ``path`` by ``content`` in one step and return the path.

    ``content`` is bytes, text (written as ``encoding``) or a writer called with the open binary file
    (``numpy.savez``, ``pyarrow.parquet.write_table``, ``Figure.savefig`` ...). It is written to a new
    file beside ``path``, flushed and synced to disk, and only then renamed over ``path``
    (``os.replace``: atomic), so a crash leaves either the old file or the new one. If writing fails,
    the new file is removed and ``path`` is untouched; an error of the device (a full disk) is raised
    naming ``path``, not the temporary file or nothing.
    """
    path = Path(path)
    temporary = path.with_name(f".{path.name}.{uuid.uuid4().hex[:12]}.tmp")
    try:
        with open(temporary, "xb") as handle:  # created like any new file: the umask applies
            if callable(content):
                content(handle)
            else:
                handle.write(content.encode(encoding) if isinstance(content, str) else content)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(temporary, path)
    except OSError as error:
        temporary.unlink(missing_ok=True)
        if error.errno is not None and error.filename in (None, str(temporary), temporary):
            raise OSError(error.errno, os.strerror(error.errno), str(path)) from error
        raise
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise
    return path


def save_figure(figure: Any, path: str | os.PathLike, **options: Any) -> Path:
    """A matplotlib figure saved atomically to ``path``, in the format its suffix names (PNG without one);
    ``options`` go to ``Figure.savefig`` (``dpi`` ...)."""
    path = Path(path)
    return atomic_write(path, lambda handle: figure.savefig(handle, format=path.suffix[1:].lower() or "png",
                                                            **options))


@contextlib.contextmanager
def claim(path: str | os.PathLike) -> Iterator[Path]:
    """Hold ``path`` as this process's output until the block ends: a second claim of the same file, from
    any process, raises :class:`OutputClaimed` (a file written in place, as a recording is, would
    otherwise be two writers' bytes interleaved).

    The claim is an exclusive ``flock`` on the file itself, created empty if missing; the kernel drops it
    when the process ends, however it ends, so no stale lock outlives a killed writer. A file the claim
    created and nothing wrote is removed at the end.
    """
    path = Path(path)
    try:
        descriptor, created = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666), True
    except FileExistsError:
        descriptor, created = os.open(path, os.O_WRONLY), False
    try:
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise OutputClaimed(errno.EBUSY, "another process is writing it", str(path)) from None
        try:
            yield path
        finally:
            if created and path.is_file() and path.stat().st_size == 0:
                path.unlink(missing_ok=True)
    finally:
        os.close(descriptor)
