"""Writing files atomically: a reader never sees half a file, and a failed write leaves the old one."""

from __future__ import annotations

import os
import uuid
from pathlib import Path
from typing import BinaryIO, Callable


def atomic_write(path: str | os.PathLike, content: bytes | str | Callable[[BinaryIO], object], *,
                 encoding: str = "utf-8") -> Path:
    """Replace ``path`` by ``content`` in one step and return the path.

    ``content`` is bytes, text (written as ``encoding``) or a writer called with the open binary file
    (``numpy.savez``, ``pyarrow.parquet.write_table``, ``Figure.savefig`` ...). It is written to a new
    file beside ``path``, flushed and synced to disk, and only then renamed over ``path``
    (``os.replace``: atomic), so a crash leaves either the old file or the new one. If writing fails,
    the new file is removed and ``path`` is untouched.
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
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise
    return path
