"""Typed reading of TOML tables with one-line errors that name the dotted key.

Shared by every config file softtip reads (studies, objectives, lab protocols),
so a user mistake anywhere reads the same way: ``study.toml: objective.depth_mm
= -1: expected a positive number``.
"""

from __future__ import annotations

import math
from typing import Any, Sequence


class ConfigError(ValueError):
    """A config file or setting that cannot describe what it should."""


class SettingsReader:
    """Pulls typed values out of one TOML table and refuses keys nobody asked for.

    Call the getters for every key the table may hold, then :meth:`finish`: any
    key left unread is a typo or a setting the reader does not know.
    """

    error: type[ConfigError] = ConfigError  # what the reader raises; subclasses narrow it

    def __init__(self, source: str, table: Any, section: str):
        if not isinstance(table, dict):
            raise self.error(f"{source}: [{section}] must be a table")
        self.source, self.table, self.section = source, table, section
        self._read: set[str] = set()

    def where(self, key: str) -> str:
        return f"{self.source}: {self.section}.{key}" if self.section else f"{self.source}: {key}"

    def fail(self, key: str, message: str) -> ConfigError:
        return self.error(f"{self.where(key)} = {self.table.get(key)!r}: {message}")

    def has(self, key: str) -> bool:
        return key in self.table

    def _get(self, key: str, default: Any) -> Any:
        self._read.add(key)
        if key not in self.table:
            if default is None:
                raise self.error(f"{self.where(key)} is missing")
            return default
        return self.table[key]

    def number(self, key: str, default: float | None = None, positive: bool = False,
               non_negative: bool = False) -> float:
        value = self._get(key, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.fail(key, "expected a number")
        if positive and value <= 0:
            raise self.fail(key, "expected a positive number")
        if non_negative and value < 0:
            raise self.fail(key, "expected a number >= 0")
        return float(value)

    def numbers(self, key: str, default: list[float] | None = None) -> list[float]:
        value = self._get(key, default)
        if (not isinstance(value, list) or not value
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                           for v in value)):
            raise self.fail(key, "expected a non-empty list of numbers")
        return [float(v) for v in value]

    def integer(self, key: str, default: int | None = None, minimum: int = 0) -> int:
        value = self._get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
            raise self.fail(key, f"expected an integer >= {minimum}")
        return value

    def string(self, key: str, default: str | None = None) -> str:
        value = self._get(key, default)
        if not isinstance(value, str) or not value:
            raise self.fail(key, "expected a non-empty string")
        return value

    def choice(self, key: str, options: Sequence[str], default: str | None = None) -> str:
        value = self._get(key, default)
        if value not in options:
            raise self.fail(key, f"expected one of {', '.join(options)}")
        return value

    def pair(self, key: str, default: tuple[float, float] = (0.0, 0.0)) -> tuple[float, float]:
        value = self._get(key, list(default))
        if (not isinstance(value, list) or len(value) != 2
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                           for v in value)):
            raise self.fail(key, "expected [x, y] in mm")
        return float(value[0]), float(value[1])

    def like(self, key: str, default: Any) -> Any:
        """A value of the default's kind: true/false, an integer >= 0, a number >= 0, a list of
        numbers, or a list of [x, y] pairs."""
        if isinstance(default, bool):
            value = self._get(key, default)
            if not isinstance(value, bool):
                raise self.fail(key, "expected true or false")
            return value
        if isinstance(default, int):
            return self.integer(key, default)
        if isinstance(default, float):
            return self.number(key, default, non_negative=True)
        if isinstance(default, list) and default and isinstance(default[0], list):
            value = self._get(key, default)
            if not (isinstance(value, list) and value and all(
                    isinstance(v, list) and len(v) == 2
                    and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v) for v in value)):
                raise self.fail(key, "expected a list of [x, y] pairs in mm")
            return [[float(x) for x in v] for v in value]
        return self.numbers(key, default)

    def raw(self, key: str, default: Any) -> Any:
        """A value whose type the caller checks itself (``default=None``: required)."""
        return self._get(key, default)

    def optional(self, key: str) -> Any:
        """The value if given, else None; the caller checks its type."""
        self._read.add(key)
        return self.table.get(key)

    def finish(self) -> None:
        unknown = sorted(set(self.table) - self._read)
        if unknown:
            expected = ", ".join(sorted(self._read))
            raise self.error(f"{self.where(unknown[0])}: unknown key (expected one of {expected})")
