"""The on-disk cache of derived data (meshes, FE results, trained models): where it lives, and keys
that tie each entry to its inputs and to the source code that computed it, so an entry made by
other code is never taken for this code's result."""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
from pathlib import Path
from typing import Any


def cache_dir() -> Path:
    """``SOFTTIP_CACHE_DIR`` if set, else ``~/.cache/softtip``; read at every call, so a process (or a
    test session) that sets the variable moves the cache for everything it does afterwards."""
    root = os.environ.get("SOFTTIP_CACHE_DIR") or Path.home() / ".cache" / "softtip"
    return Path(root)


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
