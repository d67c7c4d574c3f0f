"""What every bench of the virtual lab gives its protocols."""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any, Self

import numpy as np

from softtip.mechanics.viscoelastic import PronySeries

class RealismTable:
    """What every bench's ``[realism]`` schema shares: each effect switches off (false, or 0)."""

    @classmethod
    def off(cls) -> Self:
        return cls(**{item.name: False if isinstance(item.default, bool) else 0.0 for item in fields(cls)})

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class SeededBench:
    """What every bench gives its protocols: the relaxation of what is pressed, the realism settings, a
    seeded random stream and the sample rate."""

    prony: PronySeries
    realism: Any
    rng: np.random.Generator
    rate_hz: float

    def scatter(self, sd: float, size=None):
        """A normal scatter of standard deviation ``sd`` (zeros when ``sd`` is 0, drawing nothing)."""
        return self.rng.normal(0.0, sd, size) if sd > 0 else np.zeros(size) if size else 0.0
