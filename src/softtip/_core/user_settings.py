"""The schema of the user's settings file (:mod:`softtip._core.user`), imported only when there is one."""

from __future__ import annotations

from dataclasses import field

from softtip._core.config import schema


@schema(section="defaults")
class Defaults:
    system: str | None = None  # the registered system whose offered defaults come first


@schema
class Settings:
    defaults: Defaults = field(default_factory=Defaults)
