"""On-disk cache of finite-element results, one JSON file per (design, simulation).

The key is a hash of everything that determines a result: the design's
TOML-level spec (its name and description excluded: they do not change the
physics), the simulation (load case, friction, model, mesh size) and the source
of the code that computes it (the twin and the packages it runs on), so a
result of other code is never reused.

Entries are written atomically (:func:`~softtip._core.files.atomic_write`),
so a sweep killed at any moment leaves only complete entries, and a re-run
computes only what is missing. An entry that cannot be read is
removed and recomputed, never trusted. Nothing is pickled.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from softtip._core.cache import artefact_key, cache_dir, code_hash
from softtip._core.files import atomic_write
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
        return self.root / f"{key}.json"

    def get(self, design_spec: dict[str, Any], simulation: Simulation) -> FEResult | None:
        key = cache_key(design_spec, simulation)
        path = self.path(key)
        try:
            entry = json.loads(path.read_text())
            if entry["key"] != key:
                raise ValueError("entry stored under the wrong key")
            return FEResult.from_dict(entry["result"])
        except FileNotFoundError:
            return None
        except (OSError, ValueError, KeyError, TypeError):
            path.unlink(missing_ok=True)  # damaged: recompute rather than trust it
            return None

    def put(self, design_spec: dict[str, Any], simulation: Simulation, result: FEResult,
            seconds: float | None = None) -> Path:
        key = cache_key(design_spec, simulation)
        path = self.path(key)
        entry = {"key": key, "design": design_spec,
                 "simulation": simulation.to_dict(), "seconds": seconds, "result": result.to_dict()}
        self.root.mkdir(parents=True, exist_ok=True)
        return atomic_write(path, json.dumps(entry))
