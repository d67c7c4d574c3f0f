"""Model files: one ``.npz`` archive of arrays and one JSON metadata entry, checksummed, never pickled.

The archive (written by ``numpy.savez``, read with ``allow_pickle=False``) holds the arrays under
their names and one text entry, ``metadata``: a JSON object whose ``format`` names the kind of file
and whose ``sha256`` is the hex digest of the metadata without this field (canonical JSON: sorted
keys, no spaces) followed, for each array in sorted name order, by name NUL dtype NUL shape NUL and
the C-order bytes. Writing is atomic; every refusal is one line naming the file.

The file as a whole is sealed too: the zip archive's comment (which no zip CRC covers) is
``softtip-sha256:`` and the SHA-256 of the whole file with those 64 hex digits written as zeros, and
the metadata says so (``sealed``), so a byte changed anywhere, in the arrays, in the metadata, or in
the zip structure around them that readers otherwise ignore (local headers, the central directory),
is refused. Files written before the seal (no ``sealed``) are verified by their content checksum.
"""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
import zlib
from pathlib import Path

import numpy as np

from softtip._core.files import atomic_write, not_a_file

ZIP_MAGIC = b"PK\x03\x04"
SEAL_PREFIX = b"softtip-sha256:"
_UNSEALED = b"0" * 64
SEALED_KEY = "sealed"
# What numpy's and zipfile's readers raise for a damaged archive (a flipped flag bit reads as an
# encrypted entry, RuntimeError; a flipped method as an unknown compression, NotImplementedError).
_UNREADABLE = (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, KeyError, RuntimeError,
               NotImplementedError)


class ModelFileError(ValueError):
    """A model file that cannot be written or trusted."""


def canonical_json(value: dict) -> bytes:
    """``value`` as canonical JSON: sorted keys, no spaces, no NaN."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()


def hash_arrays(digest, arrays: dict[str, np.ndarray]) -> None:
    """Feeds ``digest`` (a hashlib object) with each array in sorted name order: name NUL dtype NUL
    shape NUL and the C-order bytes."""
    for name in sorted(arrays):
        array = np.ascontiguousarray(arrays[name])
        digest.update(f"{name}\0{array.dtype.str}\0{array.shape}\0".encode())
        digest.update(array.tobytes())


def archive_digest(metadata: dict, arrays: dict[str, np.ndarray]) -> str:
    """The checksum of a model file: its metadata without ``sha256``, then its arrays."""
    digest = hashlib.sha256(canonical_json({k: v for k, v in metadata.items() if k != "sha256"}))
    hash_arrays(digest, arrays)
    return digest.hexdigest()


def write_archive(path: Path, metadata: dict, arrays: dict[str, np.ndarray]) -> Path:
    """Writes ``arrays`` and ``metadata`` (with its checksum added), sealed, atomically: a crash leaves
    either the old file or the new one, never half of it."""
    metadata = metadata | {SEALED_KEY: True}
    metadata |= {"sha256": archive_digest(metadata, arrays)}
    buffer = io.BytesIO()
    np.savez(buffer, metadata=np.array(canonical_json(metadata).decode()), **arrays)
    with zipfile.ZipFile(buffer, "a") as archive:
        archive.comment = SEAL_PREFIX + _UNSEALED
    content = bytearray(buffer.getvalue())
    content[-len(_UNSEALED):] = hashlib.sha256(content).hexdigest().encode()
    return atomic_write(path, bytes(content))


def _seal(content: bytes) -> bool | None:
    """Whether the sealed file ``content`` is intact; None if it carries no seal."""
    tail = content[-len(SEAL_PREFIX) - len(_UNSEALED):]
    if not tail.startswith(SEAL_PREFIX):
        return None
    return hashlib.sha256(content[:-len(_UNSEALED)] + _UNSEALED).hexdigest().encode() == tail[len(SEAL_PREFIX):]


def archive_format(path: Path) -> str | None:
    """The ``format`` an archive's metadata names, or None for anything that is not a readable archive
    (its reader then says why)."""
    try:
        with np.load(path, allow_pickle=False) as archive:
            metadata = json.loads(str(archive["metadata"]))
    except _UNREADABLE:
        return None
    return metadata.get("format") if isinstance(metadata, dict) else None


def read_archive(path: Path, format_name: str, schema_version: int, what: str,
                 error: type[ValueError]) -> tuple[dict, dict[str, np.ndarray]]:
    """(metadata, arrays) of the ``what`` file ("model" ...) ``path`` of format ``format_name``.

    Refuses, with ``error``, a missing file, one that is not an npz archive, a truncated one, one
    without a JSON metadata entry of that format, one of another schema version, and one whose
    checksum does not match its content.
    """
    problem = not_a_file(path)
    if problem:
        raise error(f"{what} file {path} {problem}")
    content = path.read_bytes()
    if not content.startswith(ZIP_MAGIC):
        raise error(f"{path} is not a softtip {what} file (not an npz archive)")
    sealed = _seal(content)
    if sealed is False:
        raise error(f"{path}: checksum mismatch: the file was altered or damaged after it was written")
    try:
        with np.load(io.BytesIO(content), allow_pickle=False) as archive:
            arrays = {name: archive[name] for name in archive.files}
    except _UNREADABLE as problem:
        raise error(f"{path} is truncated or unreadable ({type(problem).__name__}: {problem})") from None
    text = arrays.pop("metadata", None)
    if text is None or text.dtype.kind != "U" or text.ndim != 0:
        raise error(f"{path} is not a softtip {what} file (no metadata entry)")
    try:
        metadata = json.loads(str(text))
    except json.JSONDecodeError:
        metadata = None
    if not isinstance(metadata, dict) or metadata.get("format") != format_name:
        raise error(f"{path} is not a softtip {what} file (format is not {format_name!r})")
    if metadata.get("schema_version") != schema_version:
        raise error(f"{path}: unsupported schema version {metadata.get('schema_version')!r} "
                    f"(this softtip reads version {schema_version})")
    if metadata.get("sha256") != archive_digest(metadata, arrays) or (metadata.get(SEALED_KEY) and not sealed):
        raise error(f"{path}: checksum mismatch: the file was altered or damaged after it was written")
    return metadata, arrays
