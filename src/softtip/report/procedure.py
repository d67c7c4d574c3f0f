"""A run's settings beside the publication's procedure: each protocol parameter the publication states
gets its published value beside softtip's, and every difference is marked (a report's protocol table,
and ``--json``).

The procedures are declared once per system, in its ``published.toml`` (``[procedures.PROTOCOL]``,
:class:`softtip.published.PublishedProcedure`); nothing here knows a system.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from softtip.published import PublishedProcedure

PROCEDURE_COLUMN = "published procedure"
DIFFERS = "differs"


def shown(value: Any) -> str:
    """A setting as its protocol file spells it: lists as JSON, [x, y] pairs included."""
    if isinstance(value, tuple):
        value = [list(item) if isinstance(item, tuple) else item for item in value]
    return json.dumps(value, ensure_ascii=False) if isinstance(value, (list, dict)) else str(value)


@dataclass(frozen=True)
class ProcedureDifference:
    """A setting of the run that is not the publication's."""

    setting: str
    softtip: Any
    published: Any
    source: str

    def to_dict(self) -> dict:
        published = self.published
        if isinstance(published, tuple):
            published = [list(item) if isinstance(item, tuple) else item for item in published]
        return {"setting": self.setting, "softtip": self.softtip, "published": published, "source": self.source}


def procedure_cell(procedure: PublishedProcedure | None, key: str, value: Any) -> str | None:
    """The protocol table's cell for parameter ``key``: None (blank) where the publication states no value,
    'same' where softtip's is the publication's, else 'differs: published VALUE'."""
    differs = None if procedure is None else procedure.differs(key, value)
    if differs is None:
        return None
    return f"{DIFFERS}: published {shown(procedure.settings[key])}" if differs else "same"


def procedure_differences(procedure: PublishedProcedure | None, section: str,
                          values: dict[str, Any]) -> list[ProcedureDifference]:
    """Every value of ``values`` (one section of a protocol's settings) that the publication states otherwise."""
    if procedure is None:
        return []
    return [ProcedureDifference(f"{section}.{key}", value, procedure.settings[key], procedure.source)
            for key, value in values.items() if procedure.differs(key, value)]


def procedure_caption(procedure: PublishedProcedure | None, differences: list[ProcedureDifference]) -> str:
    """What the protocol table's published column says, in one sentence."""
    if procedure is None:
        return "The publication states no procedure softtip compares this protocol with."
    if not differences:
        return f"Every setting the publication states is the publication's ({procedure.source})."
    return (f"{len(differences)} setting{'s' if len(differences) > 1 else ''} differ{'' if len(differences) > 1 else 's'}"
            f" from the publication's procedure ({procedure.source}): marked '{DIFFERS}', the published value beside.")
