"""On-disk cache of finite-element results, one entry per (design, simulation).

The key is a hash of everything that determines a result: the design's
TOML-level spec (its name and description excluded: they do not change the
physics), the simulation (load case, friction, model, mesh size) and the source
of the code that computes it (the twin and the packages it runs on), so a
result of other code is never reused.

Entries are the cache's (:func:`~softtip._core.cache.write_entry`): written
atomically, so a sweep killed at any moment leaves only complete entries and a
re-run computes only what is missing; checksummed and holding their key, so a
damaged entry, or another design's result under this one's name, is recomputed,
never trusted. The arrays are stored exactly as computed; nothing is pickled.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from softtip._core.cache import artefact_key, cache_dir, code_hash, read_entry, write_entry
from softtip.optimize.runs import FEResult, Simulation

_NOT_PHYSICS = ("name", "description")


def _canonical(value: Any) -> Any:
    """Integers as floats, so ``radius_mm = 9`` and ``9.0`` describe the same design."""
    if isinstance(value, dict):
        return {k: _canonical(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_canonical(v) for v in value]
    if isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def cache_key(design_spec: dict[str, Any], simulation: Simulation) -> str:
    physics = {k: v for k, v in design_spec.items() if k not in _NOT_PHYSICS}
    code = code_hash("softtip.twin", "softtip.design", "softtip.magnetics", "softtip.mechanics", "softtip.sensors",
                     "softtip.optimize.runs")
    return artefact_key(_canonical({"design": physics, "simulation": simulation.to_dict()}), code)


class FEResultCache:
    """FE results under ``root`` (default: ``cache_dir() / "fe"``)."""

    def __init__(self, root: Path | None = None):
        self.root = Path(root) if root is not None else cache_dir() / "fe"

    def path(self, key: str) -> Path:
        return self.root / f"{key}.npz"

    def get(self, design_spec: dict[str, Any], simulation: Simulation) -> FEResult | None:
        key = cache_key(design_spec, simulation)
        entry = read_entry(self.path(key), key, "FE result")
        if entry is None:
            return None
        metadata, arrays = entry
        return FEResult(**{k: arrays[k] for k in FEResult.ARRAY_FIELDS},
                        **{k: metadata["counts"][k] for k in FEResult.COUNT_FIELDS})

    def put(self, design_spec: dict[str, Any], simulation: Simulation, result: FEResult,
            seconds: float | None = None) -> Path:
        key = cache_key(design_spec, simulation)
        path = self.path(key)
        metadata = {"design": design_spec, "simulation": simulation.to_dict(), "seconds": seconds,
                    "counts": {k: int(getattr(result, k)) for k in FEResult.COUNT_FIELDS}}
        write_entry(path, key, "FE result", metadata, {k: getattr(result, k) for k in FEResult.ARRAY_FIELDS})
        return path
