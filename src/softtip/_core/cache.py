"""The on-disk cache of derived data (meshes, FE results, trained models, scenarios, streams): where it
lives, keys that tie each entry to its inputs and to the source code that computed it, and one way to
store and read an entry that trusts nothing it did not verify.

An entry is a sealed archive (:mod:`softtip._core.archive`) of format ``softtip-cache-entry`` whose
metadata records the key it was made for: a read checks the whole file's checksum and that key, so a
damaged entry, or another key's valid entry copied under this name, is never served. Anything that
cannot be trusted (not a regular file, unreadable, damaged, of another key or kind) is a miss: the
caller computes the artefact again, and one line on stderr names the entry and why. A directory,
FIFO or symbolic link in place of an entry is never opened or followed (a FIFO would block a reader).
Writes are atomic, so processes filling the cache at once leave one complete entry, never half of one.

A model file that the live pipeline opens by its path stays a model file; its key and the SHA-256 of
its bytes are kept in an entry beside it (:func:`read_file_entry`, :func:`write_file_entry`).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import importlib.util
import json
import os
import stat
import sys
from pathlib import Path
from typing import Any, Callable, Iterator, TypeVar

import numpy as np

from softtip._core.archive import read_archive, write_archive
from softtip._core.user import user_folder

ENTRY_FORMAT, ENTRY_VERSION = "softtip-cache-entry", 1
CACHE_VARIABLE = "SOFTTIP_CACHE_DIR"  # the environment variable that chooses the cache's folder
Loaded = TypeVar("Loaded")
Made = TypeVar("Made")


class CacheEntryError(ValueError):
    """A cache entry that cannot be trusted, or stored where it must be."""


def cache_dir() -> Path:
    """``SOFTTIP_CACHE_DIR`` if set, else ``softtip`` in the XDG cache folder (``XDG_CACHE_HOME`` if an
    absolute path, else ``~/.cache``); read at every call, so a process (or a test session) that sets the
    variable moves the cache for everything it does afterwards. An empty or relative ``HOME`` falls back to
    the user's home in the password database, as XDG readers do; a home that is the filesystem root
    (no home at all) is refused rather than filling ``/.cache``."""
    chosen = os.environ.get(CACHE_VARIABLE)
    if chosen:
        return Path(chosen)
    return user_folder("XDG_CACHE_HOME", ".cache", CacheEntryError, "SOFTTIP_CACHE_DIR")


def code_hash(*modules: str) -> str:
    """SHA-256 of the source of the named modules (found, not imported): a module's file; a package's
    every ``.py`` file below it and the ``.toml`` files it ships (designs, protocols: data the code
    reads). Read at every call (about a megabyte at most), so an edited file changes the hash at once."""
    digest = hashlib.sha256()
    for name in sorted(set(modules)):
        spec = importlib.util.find_spec(name)
        if spec is None or spec.origin is None:
            raise ValueError(f"module {name!r}: expected an importable softtip module with a source file")
        roots = [Path(p) for p in spec.submodule_search_locations or []]
        files = ([(root, f) for root in roots for f in sorted(root.rglob("*")) if f.suffix in (".py", ".toml")]
                 if roots else [(Path(spec.origin).parent, Path(spec.origin))])
        for root, path in files:
            source = path.read_bytes()
            digest.update(f"{name}/{path.relative_to(root).as_posix()}:{len(source)}\n".encode())
            digest.update(source)
    return digest.hexdigest()


def artefact_key(inputs: Any, code: str, length: int = 32) -> str:
    """Key of a cache entry computed from ``inputs`` (JSON-serialisable) by code of hash ``code``."""
    payload = json.dumps({"inputs": inputs, "code": code}, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(payload.encode()).hexdigest()[:length]


def _warn(path: Path, problem: str) -> None:
    """One line on stderr: the entry, what is wrong with it, and that it is not used."""
    print(f"softtip: cache entry {path}: {problem}; not used, computed again", file=sys.stderr)


def _is_folder(path: Path) -> bool:
    """Whether ``path`` itself (not a link's target) is a directory."""
    try:
        return stat.S_ISDIR(os.lstat(path).st_mode)
    except OSError:
        return False


def _regular(path: Path) -> bool | None:
    """True for a regular file at ``path`` (not followed if a link); None if nothing is there; False, with
    the warning, for anything else."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return None
    except OSError as problem:
        _warn(path, f"cannot be read ({problem.strerror})")
        return False
    if not stat.S_ISREG(mode):
        kind = ("a directory" if stat.S_ISDIR(mode) else "a symbolic link" if stat.S_ISLNK(mode)
                else "a FIFO" if stat.S_ISFIFO(mode) else "a special file")
        _warn(path, f"{kind}, not a regular file")
        return False
    return True


def read_entry(path: Path, key: str, kind: str) -> tuple[dict[str, Any], dict[str, np.ndarray]] | None:
    """(metadata, arrays) of the ``kind`` entry ("mesh", "FE result" ...) at ``path`` made for ``key``;
    None for a miss: nothing there, or (with one warning line) anything not to be trusted."""
    if not _regular(path):
        return None
    try:
        metadata, arrays = read_archive(path, ENTRY_FORMAT, ENTRY_VERSION, "cache entry", CacheEntryError)
    except CacheEntryError as problem:  # its message names the path: said once
        _warn(path, str(problem).replace(str(path), "").lstrip(": "))
        return None
    except OSError as problem:  # unreadable (permissions), or gone since it was looked at
        _warn(path, f"cannot be read ({problem.strerror})")
        return None
    if metadata.get("key") != key or metadata.get("kind") != kind:
        _warn(path, f"made for another {metadata.get('kind')} (key {metadata.get('key')!r}), not this "
                    f"{kind} (key {key!r})")
        return None
    return metadata, arrays


def write_entry(path: Path, key: str, kind: str, metadata: dict[str, Any], arrays: dict[str, np.ndarray]) -> bool:
    """Stores the ``kind`` entry made for ``key`` at ``path`` atomically; whether it was stored. A cache
    that cannot take it (a folder in the way, a full disk) is one warning line, not a failure: the
    artefact in hand is still good."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_archive(path, metadata | {"format": ENTRY_FORMAT, "schema_version": ENTRY_VERSION, "key": key,
                                        "kind": kind}, arrays)
    except OSError as problem:
        if not _is_folder(path):  # a folder in the way was named when it was read
            print(f"softtip: cache entry {path} could not be stored ({problem.strerror}); it is computed "
                  "again next time", file=sys.stderr)
        return False
    return True


@contextlib.contextmanager
def computing(path: Path) -> Iterator[None]:
    """Held while this process computes the entry at ``path``: another process about to compute the same
    entry waits here, then finds it stored (read it again inside the block) instead of computing it a
    second time. An exclusive ``flock`` on ``NAME.lock`` beside the entry, which the kernel drops however
    the process ends; the empty lock file stays (removing it would let a third process lock a new one)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    descriptor = os.open(path.with_name(f"{path.name}.lock"), os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW, 0o666)
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX)
        yield
    finally:
        os.close(descriptor)


class EntryPieces:
    """The finished pieces of the entry at ``path`` while it is computed, each an entry of its own for the same
    key (``NAME.pieces/INDEX.npz``): a computation stopped part way (Ctrl-C, a crash) keeps what it finished,
    and the next one computes only the rest. :meth:`clear` removes them once the whole entry is stored."""

    def __init__(self, path: Path, key: str, kind: str):
        self.folder, self.key, self.kind = path.with_name(f"{path.name}.pieces"), key, f"{kind} piece"

    def _path(self, index: int) -> Path:
        return self.folder / f"{index}.npz"

    def read(self, index: int) -> dict[str, np.ndarray] | None:
        """The arrays of piece ``index``, or None when it is still to compute."""
        entry = read_entry(self._path(index), self.key, self.kind)
        return None if entry is None else entry[1]

    def write(self, index: int, arrays: dict[str, np.ndarray]) -> None:
        write_entry(self._path(index), self.key, self.kind, {}, arrays)

    def clear(self) -> None:
        for piece in self.folder.glob("*.npz") if _is_folder(self.folder) else ():
            piece.unlink(missing_ok=True)
        with contextlib.suppress(OSError):
            self.folder.rmdir()


def _entry_of_file(path: Path) -> Path:
    return path.with_name(f"{path.name}.entry")


def _sha256(path: Path) -> str:
    """SHA-256 of the regular file ``path``; opened without following a link or waiting on a FIFO, so a
    file swapped since it was looked at cannot block the reader."""
    with open(os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK), "rb") as handle:
        if not stat.S_ISREG(os.fstat(handle.fileno()).st_mode):
            raise OSError(errno.EINVAL, "not a regular file", str(path))
        return hashlib.file_digest(handle, "sha256").hexdigest()


def read_file_entry(path: Path, key: str, kind: str, load: Callable[[Path], Loaded]) -> Loaded | None:
    """``load(path)`` of the cached file ``path`` (a model file ...) made for ``key``; None for a miss:
    no entry beside it, an entry of another key, a file that is not the one the entry recorded byte for
    byte, or one ``load`` refuses (with one warning line naming it)."""
    entry = read_entry(_entry_of_file(path), key, kind)
    if entry is None or not _regular(path):
        return None
    try:
        if _sha256(path) != entry[0].get("file_sha256"):
            _warn(path, "not the file its entry recorded (checksum mismatch)")
            return None
        return load(path)
    except (ValueError, OSError) as problem:
        _warn(path, f"cannot be loaded ({str(problem).replace(str(path), '').lstrip(': ')})")
        return None


def write_file_entry(path: Path, key: str, kind: str, save: Callable[[Path], object]) -> Path:
    """``save(path)`` writes the cached file; its key and checksum go into the entry beside it. A folder
    in place of the file is refused (the file is needed by its path)."""
    if _is_folder(path):
        raise CacheEntryError(f"cache entry {path} is a folder where a {kind} file belongs: remove it")
    path.parent.mkdir(parents=True, exist_ok=True)
    save(path)
    write_entry(_entry_of_file(path), key, kind, {"file_sha256": _sha256(path)}, {})
    return path


def stored_or_made(path: Path, key: str, kind: str, load: Callable[[Path], Loaded], make: Callable[[], Made],
                   save: Callable[[Made, Path], object]) -> tuple[Loaded | Made, bool]:
    """The cached file ``path`` made for ``key``, read by ``load``; or, on a miss, ``make()`` stored there by
    ``save(made, path)``; and whether it was read. A process making the same entry meanwhile is waited for
    (:func:`computing`) and its entry read, so two processes never make one entry twice."""
    found = read_file_entry(path, key, kind, load)
    if found is not None:
        return found, True
    with computing(path):
        found = read_file_entry(path, key, kind, load)
        if found is not None:
            return found, True
        made = make()
        write_file_entry(path, key, kind, lambda target: save(made, target))
        return made, False
